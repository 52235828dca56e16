//! Xbus framer over arbitrary bytes: never panics, accounts for every byte, releases only frames
//! that re-check, and finds the same frames whether fed at once or in small cuts.
#![no_main]

use imu_driver::{frame_capacity, Framer, Message, Poll, XbusFrame};
use libfuzzer_sys::fuzz_target;

type Small = Framer<{ frame_capacity(256) }>;
type Big = Framer<{ frame_capacity(65_535) }>;

fn check<const N: usize>(f: XbusFrame<'_>, out: &mut Vec<Vec<u8>>) {
    assert_eq!(XbusFrame::new_checked(f.as_bytes()), Ok(f));
    assert!(f.payload().len() <= framer_max::<N>());
    if let Ok(Message::MtData2(m)) = Message::decode(&f) {
        for item in m.items().flatten() {
            let _ = item.value();
        }
    }
    out.push(f.as_bytes().to_vec());
}

/// Frames found (as bytes) feeding `data` in chunks of `chunk` bytes, then ending the input.
fn frames<const N: usize>(framer: &mut Framer<N>, data: &[u8], chunk: usize) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for c in data.chunks(chunk) {
        let mut input = c;
        loop {
            match framer.poll(&mut input) {
                Poll::Frame(f) => check::<N>(f, &mut out),
                Poll::Dropped { bytes, .. } => assert!(bytes > 0),
                Poll::NeedMore => break,
            }
        }
        assert!(input.is_empty());
    }
    loop {
        match framer.poll_end() {
            Poll::Frame(f) => check::<N>(f, &mut out),
            Poll::Dropped { bytes, .. } => assert!(bytes > 0),
            Poll::NeedMore => break,
        }
    }
    assert_eq!(framer.finish(), None);
    let c = framer.counters();
    assert_eq!(c.bytes_in, data.len() as u64);
    assert_eq!(c.frame_bytes + c.bytes_skipped, c.bytes_in);
    assert_eq!(framer.buffered(), 0);
    out
}

fn framer_max<const N: usize>() -> usize {
    N - imu_driver::FRAME_OVERHEAD
}

fuzz_target!(|data: &[u8]| {
    // The cut size comes from the data length, so seeds taken from captures need no prefix.
    let chunk = data.len() % 61 + 1;
    let whole = frames(&mut Small::new(), data, data.len().max(1));
    assert_eq!(frames(&mut Small::new(), data, chunk), whole);
    assert_eq!(frames(&mut Small::new(), data, 1), whole);
    let _ = frames(&mut Big::new(), data, chunk);
});
