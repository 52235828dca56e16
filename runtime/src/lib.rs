//! The on-device runtime of milliEgo: sensor readers, an online synchroniser, estimators, the pose
//! composer and the outputs, as threads joined by bounded lock-free queues that drop their oldest
//! item when full. See `docs/runtime.md`.
#![warn(missing_docs)]

pub mod composer;
pub mod config;
pub mod error;
pub mod estimator;
/// The learned-model estimator (also at [`estimator::model`], where it lives).
pub use estimator::model;
pub mod output;
pub mod pipeline;
pub mod queue;
pub mod reader;
pub mod stage;
pub mod stats;
pub mod summary;
pub mod sync;
pub mod view;
