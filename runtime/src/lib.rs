//! The on-device runtime of milliEgo: sensor readers, an online synchroniser, estimators, the pose
//! composer and the outputs, as threads joined by bounded lock-free queues that drop their oldest
//! item when full. See `docs/runtime.md`.
#![warn(missing_docs)]

pub mod composer;
pub mod config;
pub mod estimator;
pub mod model;
pub mod output;
pub mod pipeline;
pub mod queue;
pub mod reader;
pub mod stage;
pub mod stats;
pub mod sync;
