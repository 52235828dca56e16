//! The milliEgo sensor-hub link, version 1 (spec: `docs/hub-link.md`).
//!
//! A sensor hub (the `firmware/` image) reads the radar's data UART and the IMU's UART, frames
//! both with the drivers' `no_std` framers, stamps every frame with one hardware timer at its
//! last byte, and forwards it verbatim on one link, with periodic [`Health`] (counters, ring
//! high-water marks, clock). Each message is a 16-byte [`Header`] (kind, version, flags, link
//! sequence number, hub time in ns), a body and a CRC-32C; on the wire it is COBS-stuffed and
//! ends with a 0x00 delimiter ([`encode_serial`], [`Deframer`]).
//!
//! No allocation and no std: the firmware encodes straight into its transmit ring, byte by byte,
//! with no frame-sized buffer.
//!
//! ```
//! use hub_link::{Deframer, Event, Header, Message, FRAME_MAX};
//! let imu = [0xFA, 0xFF, 0x36, 0x05, 0x10, 0x20, 0x02, 0x01, 0x02, 0x91];
//! let m = Message::Imu { header: Header { seq: 3, t_ns: 1_500_000, ..Header::default() }, bytes: &imu };
//! let mut wire = Vec::new();
//! m.encode_serial(&mut |b| wire.push(b));
//! let mut d: Box<Deframer<FRAME_MAX>> = Box::default();
//! let mut input = &wire[..];
//! assert_eq!(d.poll(&mut input), Event::Message(m));
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

/// COBS framing, shared with the pose link (one implementation for both links).
pub use pose_link::cobs;
mod clock;
mod deframer;
mod message;

pub use clock::{LinkClock, Observed};
pub use deframer::{Deframer, DeframerCounters, Event, FrameError};
pub use message::{
    encode_serial, message_len, serial_len_max, DecodeError, Header, Health, Kind, Message,
    PortHealth, CRC_LEN, HEADER_LEN, HEALTH_LEN, MAX_BODY, VERSION,
};
pub use pose_link::{crc32c, Crc32c};

/// Deframer size that holds any version-1 frame (a body of [`MAX_BODY`] bytes) \[B\].
pub const FRAME_MAX: usize = serial_len_max(MAX_BODY);
