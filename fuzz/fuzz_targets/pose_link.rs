//! Pose-link decoding of arbitrary bytes: as a datagram and as a serial stream. Never panics; a
//! decoded message re-encodes to the same bytes; the deframer accounts for every byte.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pose_link::{Deframer, Event, PoseMessage, MESSAGE_LEN, SERIAL_FRAME_MAX};

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = PoseMessage::decode(data) {
        let mut b = [0u8; MESSAGE_LEN];
        m.encode(&mut b).unwrap();
        if data.len() == MESSAGE_LEN {
            assert_eq!(&b[..], data);
        }
    }
    let mut d: Deframer<SERIAL_FRAME_MAX> = Deframer::default();
    let mut input = data;
    while !matches!(d.poll(&mut input), Event::NeedMore) {}
    assert_eq!(d.counters().bytes_in, data.len() as u64);
});
