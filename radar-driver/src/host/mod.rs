//! Host side (std): a reader that stamps frames with host time, owned frames, and the CLI-port
//! controller that uploads a .cfg.

pub mod cli_port;
pub mod cloud;
pub mod decoder;
pub mod reader;

/// The point type clouds carry (re-exported for consumers of [`PointCloud`]).
pub use crate::tlv::Point;
pub use cli_port::{CliError, CliPort};
pub use cloud::PointCloud;
pub use decoder::{DecodeReport, Decoded, Decoder, DecoderConfig};
pub use reader::{FrameReader, OwnedFrame, ReadEvent};
