//! One benchmark command for the milliEgo stack: every figure beside its peer, measured in one
//! run on the same inputs, printed as a table and written as JSON (`milliego-bench --json FILE`).
//!
//! - [`decode`]: radar and Xbus decoder throughput \[MB/s\] on the real captures against the
//!   `mmwave-tlv` and `xsens-mti` crates, interleaved rounds, medians.
//! - [`infer`]: model latency \[ms\] (batch 1, one thread) and peak RSS delta \[MB\], tract fp32 /
//!   int8 against onnxruntime fp32 / its best int8, for the shipped compact model and the
//!   paper-size graph (untrained weights); plus a per-op-type profile of a graph in tract.
//! - [`e2e`]: the `milliego run` rows, from a command printing a JSON summary.
//! - [`report`]: rows, table, JSON, machine info.
//!
//! No figure is asserted anywhere: the machine may be shared.

pub mod decode;
pub mod e2e;
pub mod infer;
pub mod report;

pub use report::{format_table, ratio, Better, Machine, Report, Row};
