//! Driver for the data UART of TI single-chip mmWave radars (AWR/IWR 14xx, 16xx, 18xx, 68xx).
//!
//! Data flow: **bytes -> [`Framer`] -> [`Frame`] -> [`tlv::Tlv`] -> points**.
//!
//! * [`Framer`] takes bytes in chunks of any size and releases each frame the moment its last
//!   byte is in. It never loses sync: a bad candidate costs only its magic word, a truncated
//!   frame is reported and the next frame is still found, and every byte is counted.
//! * [`Frame`] is a zero-copy checked view (out-of-box demo 36/40-byte headers, people-counting
//!   48/52-byte headers); after [`Frame::new_checked`] no accessor panics.
//! * [`tlv`] decodes TLV payloads into typed views; unknown types pass through raw.
//! * [`cfg`](mod@cfg) parses `.cfg` files and derives range/velocity resolution, frame period and the
//!   points-per-frame bound; [`clock`] unwraps the sensor clock.
//! * [`plausible`] judges each released frame against what is known (frame-number continuity,
//!   the sensor clock, the .cfg's range/velocity/point limits, finite values): the format has no
//!   checksum, so a corrupted byte inside a frame is caught there or not at all.
//! * [`encode`] writes frames of every layout (tests, fuzz seeds, the simulator).
//! * [`host`] (feature `alloc`) adds owned point clouds and the streaming bytes -> clouds
//!   decoder; with `std` a timestamping reader over `std::io::Read`; with `serial` (the default)
//!   the CLI-port controller.
//!
//! The core is `no_std` without allocation (heapless), for firmware-side use.
//!
//! ```
//! use radar_driver::{Framer, Poll, tlv::{Dialect, Tlv}, encode::FrameBuilder};
//! let pts = [[0.1, 2.0, 0.0, -0.5]];
//! let mut wire = [0u8; 256];
//! let n = FrameBuilder::oob(0x0303_0002, 0xA6843, 42).points(&pts).write(&mut wire).unwrap();
//! let mut framer: Framer<4096> = Framer::default();
//! let mut input = &wire[..n];
//! while let Poll::Frame(frame) = framer.poll(&mut input) {
//!     for raw in frame.tlvs() {
//!         if let Ok(Tlv::Points(p)) = raw.decode(Dialect::of(&frame)) {
//!             assert_eq!(p.get(0).unwrap().y, 2.0);
//!         }
//!     }
//! }
//! ```
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(feature = "alloc")]
extern crate alloc;

pub mod cfg;
pub mod clock;
pub mod encode;
pub mod error;
pub mod frame;
pub mod framer;
#[cfg(feature = "alloc")]
pub mod host;
pub mod plausible;
pub mod tlv;

pub use error::{FrameError, TlvError};
pub use frame::{Frame, Header, Layout, LayoutHint, RawTlv, MAGIC};
pub use framer::{Counters, Framer, Poll, DEFAULT_MAX_FRAME};
