//! TLV decoding of arbitrary payloads under every type number and dialect: never panics, and a
//! typed view never reads past its payload.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radar_driver::tlv::{Dialect, Tlv};
use radar_driver::RawTlv;

fuzz_target!(|data: &[u8]| {
    if data.len() < 5 {
        return;
    }
    let ty = u32::from_le_bytes([data[0], data[1], data[2], data[3]]) % 1100;
    let sdk = data[4] % 4;
    let payload = &data[5..];
    for dialect in [Dialect::Oob { sdk_major: sdk }, Dialect::PeopleCounting] {
        let raw = RawTlv { index: 0, ty, payload };
        if let Ok(t) = raw.decode(dialect) {
            match t {
                Tlv::Points(p) => assert!(p.iter().count() * 16 <= payload.len()),
                Tlv::PointsQ(p) => assert_eq!(p.iter().count(), p.len()),
                Tlv::CompressedPoints(p) => {
                    for s in p.iter() {
                        let _ = s.to_cartesian();
                    }
                }
                Tlv::SideInfo(s) => assert_eq!(s.iter().count(), s.len()),
                Tlv::Targets(t) => assert_eq!(t.iter().count(), t.len()),
                _ => {}
            }
        }
    }
});
