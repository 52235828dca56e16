//! The ROS 1 bag reader over arbitrary bytes after the `#ROSBAG V2.0` magic: opening, listing
//! topics (from the index or by scanning) and reading every message never panic, and reading
//! one topic gives what reading all gave of it (the chunk skipping relies on the index).
#![no_main]

use libfuzzer_sys::fuzz_target;
use milliego_import::source::rosbag1::{Bag1, MAGIC};

mod import_common;

fuzz_target!(|data: &[u8]| {
    let mut bytes = MAGIC.to_vec();
    bytes.extend_from_slice(data);
    let p = import_common::scratch("bag1.bag", &bytes);
    if let Ok(mut bag) = Bag1::open(&p) {
        // Chunks are skipped on the index's word, as every bag reader does: a corrupt index
        // may hide messages, never invent them.
        import_common::read_all(&mut bag, false);
    }
});
