//! Xsens MTi driver: the Xbus protocol from bytes to typed samples, on firmware (no_std, no
//! allocation) and on hosts (`std` feature: a timestamping reader and device control over a serial
//! port).
//!
//! The pipeline, one layer per module:
//!
//! 1. [`frame`]: [`XbusFrame`], a zero-copy view of one checked frame (`FA BID MID LEN DATA CS`,
//!    standard or extended length).
//! 2. [`framer`]: [`Framer`], which cuts frames out of arbitrary chunks, resyncs one byte at a time
//!    and keeps [`Counters`].
//! 3. [`message`]: [`Message`], a frame decoded by MID (acks, Error, DeviceID, OutputConfiguration,
//!    legacy MTData, ...).
//! 4. [`mtdata2`]: the MTData2 item iterator and its typed [`Value`]s in all four precisions.
//! 5. [`time`]: SampleTimeFine unwrapping, PacketCounter continuity and plausibility [`Flags`].
//! 6. [`encode`]: frames for every host message, and an MTData2 writer.
//! 7. [`reduced`]: the reduced Xbus of the MTi-1 series over I2C/SPI (MTSSP pipes).
//! 8. `host` (feature `std`): a reader that stamps frames with host time, and device control.
//!
//! ```
//! use imu_driver::{Framer, Message, Poll, Value};
//! let bytes = [0xFA, 0xFF, 0x36, 0x05, 0x10, 0x20, 0x02, 0x01, 0x02, 0x91];
//! let mut framer = Framer::<{ imu_driver::frame_capacity(2048) }>::new();
//! let mut input = &bytes[..];
//! let Poll::Frame(frame) = framer.poll(&mut input) else { panic!() };
//! let Ok(Message::MtData2(data)) = Message::decode(&frame) else { panic!() };
//! let item = data.items().next().unwrap().unwrap();
//! assert_eq!(item.value(), Ok(Value::PacketCounter(258)));
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(feature = "alloc")]
extern crate alloc;

#[cfg(all(test, not(feature = "std")))]
extern crate std;

pub mod encode;
pub mod frame;
pub mod framer;
pub mod message;
pub mod mtdata2;
pub mod reduced;
pub mod time;

#[cfg(feature = "alloc")]
pub mod host;

pub use encode::{encode_frame, EncodeError, HostMessage, MtData2Writer, BID_MASTER};
pub use frame::{frame_capacity, FrameError, XbusFrame, FRAME_OVERHEAD};
pub use framer::{Counters, Framer, Poll};
pub use message::{mid, Baudrate, ErrorCode, Message, MessageError, OutputSetting};
pub use mtdata2::{
    CoordinateFrame, DataId, DataKind, Item, MtData2, Mtdata2Error, Precision, Sample, Value,
};
pub use time::{Checker, Flags, TimeWrap};

/// A framer for live devices: payloads up to 2048 bytes (the LLD limit).
pub type DeviceFramer = Framer<{ frame_capacity(2048) }>;
/// A framer for MT Manager `.mtb` logs and any stream: payloads up to 65535 bytes.
pub type LogFramer = Framer<{ frame_capacity(frame::MAX_EXTENDED_PAYLOAD) }>;
