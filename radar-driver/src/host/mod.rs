//! Host side: owned point clouds and the streaming decoder (feature `alloc`), a reader that
//! stamps frames with host time (`std`), and the CLI-port controller that uploads a .cfg
//! (`serial`).

#[cfg(feature = "serial")]
pub mod cli_port;
pub mod cloud;
pub mod decoder;
#[cfg(feature = "std")]
pub mod reader;

/// The point type clouds carry (re-exported for consumers of [`PointCloud`]).
pub use crate::tlv::Point;
#[cfg(feature = "serial")]
pub use cli_port::{CliError, CliPort};
pub use cloud::PointCloud;
pub use decoder::{DecodeReport, Decoded, Decoder, DecoderConfig};
#[cfg(feature = "std")]
pub use reader::{FrameReader, OwnedFrame, ReadEvent};
