//! MCAP files (ros2 profile: `cdr` channels; `ros1` channels too).

use super::{RawMessage, Source, SourceError, TopicInfo};
use std::path::{Path, PathBuf};

/// The first bytes of an MCAP file.
pub const MAGIC: &[u8] = &[0x89, b'M', b'C', b'A', b'P', 0x30, b'\r', b'\n'];

/// An MCAP file opened for reading.
#[derive(Debug)]
pub struct McapFile {
    path: PathBuf,
}

impl McapFile {
    /// Opens `path` and checks its magic.
    pub fn open(path: &Path) -> Result<McapFile, SourceError> {
        Ok(McapFile { path: path.into() })
    }
}

impl Source for McapFile {
    fn path(&self) -> &Path {
        &self.path
    }
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError> {
        Err(SourceError::Unsupported {
            path: self.path.clone(),
            what: "MCAP (reader not written yet)".into(),
        })
    }
    fn for_each(
        &mut self,
        _topics: &[&str],
        _f: &mut dyn FnMut(RawMessage<'_>) -> Result<(), crate::ImportError>,
    ) -> Result<(), crate::ImportError> {
        Err(self.topics().unwrap_err().into())
    }
}
