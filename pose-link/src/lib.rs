//! The milliEgo pose link: how poses leave the device (spec: `docs/pose-link.md`).
//!
//! * [`PoseMessage`] is one pose: sequence number, sensor and host time, absolute pose (position
//!   \[m\] + unit quaternion), relative pose since the previous radar frame, health flags and the
//!   estimator that produced it. [`PoseMessage::encode`] writes the 104-byte version-1 layout with a
//!   CRC-32C; [`PoseMessage::decode`] checks type, version, length and CRC.
//! * Over UDP, one message per datagram. Over serial, each message is COBS-encoded and followed by
//!   a 0x00 delimiter ([`cobs`]); [`Deframer`] turns a byte stream back into messages and counts
//!   every byte and frame it drops.
//!
//! No allocation and no std: the same code decodes on a headset's microcontroller.
//!
//! ```
//! use pose_link::{PoseMessage, Health, Estimator, MESSAGE_LEN};
//! let m = PoseMessage {
//!     seq: 7,
//!     position: [1.0, 2.0, 0.5],
//!     health: Health::PREDICTED,
//!     estimator: Estimator::Doppler,
//!     ..PoseMessage::default()
//! };
//! let mut buf = [0u8; MESSAGE_LEN];
//! m.encode(&mut buf).unwrap();
//! assert_eq!(PoseMessage::decode(&buf).unwrap(), m);
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

/// Buffer size of a [`Deframer`] that holds any version-1 frame \[B\].
pub const SERIAL_FRAME_MAX: usize = cobs::max_encoded_len(MESSAGE_LEN) + 1;

pub mod cobs;
mod crc;
mod deframer;
mod message;

pub use crc::{crc32c, Crc32c};
pub use deframer::{encode_serial, Deframer, DeframerCounters, Event, FrameError};
pub use message::{DecodeError, Estimator, Health, PoseMessage, MESSAGE_LEN, MSG_POSE, VERSION};
