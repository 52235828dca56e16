//! The MCAP reader over arbitrary bytes after the MCAP magic: opening, listing topics (summary
//! or scan), the metadata records and reading every message never panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use milliego_import::source::mcap::McapFile;
use milliego_import::source::Source;

mod import_common;

const MAGIC: &[u8] = b"\x89MCAP0\r\n";

fuzz_target!(|data: &[u8]| {
    let mut bytes = MAGIC.to_vec();
    bytes.extend_from_slice(data);
    let p = import_common::scratch("file.mcap", &bytes);
    if let Ok(mut file) = McapFile::open(&p) {
        let _ = file.metadata();
        import_common::read_all(&mut file, true);
    }
});
