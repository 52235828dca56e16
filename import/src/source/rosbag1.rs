//! ROS 1 bags (format 2.0).

use super::{RawMessage, Source, SourceError, TopicInfo};
use std::path::{Path, PathBuf};

/// The first bytes of a ROS 1 bag.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

/// A ROS 1 bag opened for reading.
#[derive(Debug)]
pub struct Bag1 {
    path: PathBuf,
}

impl Bag1 {
    /// Opens `path` and reads its header.
    pub fn open(path: &Path) -> Result<Bag1, SourceError> {
        Ok(Bag1 { path: path.into() })
    }
}

impl Source for Bag1 {
    fn path(&self) -> &Path {
        &self.path
    }
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError> {
        Err(SourceError::Unsupported {
            path: self.path.clone(),
            what: "ROS 1 bags (reader not written yet)".into(),
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
