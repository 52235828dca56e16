//! MTData2 item iterator and every decoder behind it on arbitrary payloads: never panics, never
//! reads past the payload, stops only on an error, and the plausibility checker digests the result.
#![no_main]

use imu_driver::message::{LegacyMtData, Message};
use imu_driver::{Checker, MtData2, TimeWrap};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let m = MtData2::new(data);
    let mut consumed = 0usize;
    let mut ended_by_error = false;
    for item in m.items() {
        assert!(!ended_by_error, "items after an error that ends iteration");
        match item {
            Ok(i) => {
                consumed += 3 + i.data.len();
                if let Ok(v) = i.value() {
                    let _ = v.floats();
                }
                let _ = i.id.to_string();
            }
            Err(_) => ended_by_error = true,
        }
    }
    assert!(consumed <= data.len());
    if !ended_by_error {
        assert_eq!(consumed, data.len());
    }
    let mut checker = Checker::new(TimeWrap::Day);
    let _ = checker.check(&m.sample());
    // The same bytes as every other message and as legacy MTData in a few modes.
    for mid in 0..=255u8 {
        let _ = Message::decode_payload(mid, data);
    }
    if let Some((&mode, rest)) = data.split_first() {
        let _ = LegacyMtData::decode(rest, u16::from(mode) & 0x0807, u32::from(mode) << 2);
    }
});
