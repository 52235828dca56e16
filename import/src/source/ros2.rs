//! ROS 2 bag directories: `metadata.yaml` with sqlite3 `.db3` or MCAP storage.

use super::{RawMessage, Source, SourceError, TopicInfo};
use std::path::{Path, PathBuf};

/// A ROS 2 bag directory opened for reading.
#[derive(Debug)]
pub struct Ros2Bag {
    path: PathBuf,
}

impl Ros2Bag {
    /// Opens `path` and reads its metadata.yaml.
    pub fn open(path: &Path) -> Result<Ros2Bag, SourceError> {
        Ok(Ros2Bag { path: path.into() })
    }
}

impl Source for Ros2Bag {
    fn path(&self) -> &Path {
        &self.path
    }
    fn topics(&mut self) -> Result<Vec<TopicInfo>, SourceError> {
        Err(SourceError::Unsupported {
            path: self.path.clone(),
            what: "ROS 2 bags (reader not written yet)".into(),
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
