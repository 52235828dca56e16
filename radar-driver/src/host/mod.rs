//! Host side (std): a reader that stamps frames with host time, owned frames, and the CLI-port
//! controller that uploads a .cfg.

pub mod cli_port;
pub mod cloud;
pub mod reader;

pub use cli_port::{CliError, CliPort};
pub use cloud::PointCloud;
pub use reader::{FrameReader, OwnedFrame, ReadEvent};
