//! Framer over arbitrary bytes in arbitrary chunks: never panics, every byte is accounted for,
//! every released frame re-checks and its TLVs decode without panicking.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radar_driver::tlv::Dialect;
use radar_driver::{Frame, Framer, LayoutHint, Poll};

fuzz_target!(|data: &[u8]| {
    // The first byte picks the chunk size, so the same bytes are framed in many cuts.
    let (chunk, body) = match data.split_first() {
        Some((c, b)) => (usize::from(*c).max(1), b),
        None => return,
    };
    let mut framer: Framer<8192> = Framer::new(LayoutHint::Auto);
    for c in body.chunks(chunk) {
        let mut input = c;
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => {
                    assert!(Frame::new_checked(f.as_bytes(), f.layout()).is_ok());
                    for t in f.tlvs() {
                        let _ = t.decode(Dialect::of(&f));
                    }
                }
                Poll::Dropped { .. } => {}
                Poll::NeedMore => break,
            }
        }
    }
    framer.finish();
    let c = framer.counters();
    assert_eq!(c.bytes_in, body.len() as u64);
    assert_eq!(c.bytes_in, c.bytes_ok + c.bytes_skipped);
});
