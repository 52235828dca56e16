//! Default settings must keep producing the sessions they produced before the failure-mode
//! settings (mounts, coarse Doppler, near-field leakage, IMU grades and gaps, barometer, vehicle
//! and height-change motion) existed: the benchmark split and many tests depend on those bytes.
//!
//! The hashes below were computed on the commit before those settings were added. Like every
//! byte-identity check here they hold on one platform and toolchain (the last bits of `sin` and
//! friends come from the platform's libm), so the check runs on x86_64 Linux only. When a change
//! is *meant* to move the default output, run `cargo test -p milliego-sim --test golden --
//! --nocapture` and paste the printed table.

mod common;

use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::Scenario;
use milliego_sim::world::Family;

const FILES: [&str; 9] = [
    "session.toml",
    "radar.bin",
    "radar.idx",
    "radar.cfg",
    "imu.bin",
    "imu.idx",
    "groundtruth.tum",
    "radar_truth.csv",
    "imu_truth.csv",
];

/// FNV-1a, 64 bit.
fn fnv(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The scenarios checked: the four motions, five families, other rates, rests.
fn scenarios() -> Vec<(&'static str, Scenario)> {
    let mut v = Vec::new();
    let mut a = Scenario::new(Family::Office, MotionKind::Handheld, 7);
    a.duration_s = 4.0;
    v.push(("office-handheld-7", a));
    let mut b = Scenario::new(Family::Corridor, MotionKind::Robot, 5);
    b.duration_s = 3.0;
    b.radar_hz = 30.0;
    b.imu_hz = 100.0;
    v.push(("corridor-robot-5", b));
    let mut c = Scenario::new(Family::Atrium, MotionKind::Headworn, 9);
    c.duration_s = 5.0;
    c.rest_start_s = 1.0;
    v.push(("atrium-headworn-9-rest", c));
    let mut d = Scenario::new(Family::StoreRoom, MotionKind::Static, 2);
    d.duration_s = 2.0;
    d.imu_hz = 400.0;
    d.radar_hz = 10.0;
    v.push(("store_room-static-2", d));
    let mut e = Scenario::new(Family::Household, MotionKind::Handheld, 300);
    e.duration_s = 3.0;
    v.push(("household-handheld-300", e));
    v
}

/// The hash of each file of each scenario (session.toml with the crate version blanked, so a
/// version bump does not count as a change of output).
fn hashes() -> Vec<(String, u64)> {
    let mut out = Vec::new();
    for (name, sc) in scenarios() {
        let s = common::simulate_with(sc.family, sc.motion, sc.seed, |x| *x = sc.clone());
        for f in FILES {
            let mut bytes = std::fs::read(s.path().join(f)).unwrap();
            if f == "session.toml" {
                let text = String::from_utf8(bytes).unwrap();
                bytes = text
                    .replace(
                        &format!("milliego sim {}", env!("CARGO_PKG_VERSION")),
                        "milliego sim VERSION",
                    )
                    .into_bytes();
            }
            out.push((format!("{name}/{f}"), fnv(&bytes)));
        }
    }
    out
}

const GOLDEN: &[(&str, u64)] = &[
    ("office-handheld-7/session.toml", 0x59d32d2a61ca9134),
    ("office-handheld-7/radar.bin", 0x8c1853fc916a0dd5),
    ("office-handheld-7/radar.idx", 0x8d599325baafb2e2),
    ("office-handheld-7/radar.cfg", 0x0801a79fa2c2f192),
    ("office-handheld-7/imu.bin", 0x5809229240888b99),
    ("office-handheld-7/imu.idx", 0x95b8b01ada0095d3),
    ("office-handheld-7/groundtruth.tum", 0x50d98f12ab49f3e7),
    ("office-handheld-7/radar_truth.csv", 0x6df8d1de677a26c1),
    ("office-handheld-7/imu_truth.csv", 0x0a9f075b7788a75e),
    ("corridor-robot-5/session.toml", 0xa0c8f59a6df882a0),
    ("corridor-robot-5/radar.bin", 0x35447e3b9f0c9917),
    ("corridor-robot-5/radar.idx", 0x72276424341f3a71),
    ("corridor-robot-5/radar.cfg", 0x964f52da375291a9),
    ("corridor-robot-5/imu.bin", 0x77e40c33ccd3892b),
    ("corridor-robot-5/imu.idx", 0x4fa2b32e1dce4f96),
    ("corridor-robot-5/groundtruth.tum", 0x59f3ed3e7e7996b8),
    ("corridor-robot-5/radar_truth.csv", 0x6765956e43a4102f),
    ("corridor-robot-5/imu_truth.csv", 0x47b7784195db296c),
    ("atrium-headworn-9-rest/session.toml", 0x46228cfcc1f3818d),
    ("atrium-headworn-9-rest/radar.bin", 0xc57796e7e08a656f),
    ("atrium-headworn-9-rest/radar.idx", 0x2d9c05de6a435697),
    ("atrium-headworn-9-rest/radar.cfg", 0x0801a79fa2c2f192),
    ("atrium-headworn-9-rest/imu.bin", 0x5c4a11de968418eb),
    ("atrium-headworn-9-rest/imu.idx", 0x466bd313b2a3b120),
    ("atrium-headworn-9-rest/groundtruth.tum", 0x11110155ef25b734),
    ("atrium-headworn-9-rest/radar_truth.csv", 0x80928b00d491c8c2),
    ("atrium-headworn-9-rest/imu_truth.csv", 0x8d00ff8d0f0e83e5),
    ("store_room-static-2/session.toml", 0xfddcab6f00858286),
    ("store_room-static-2/radar.bin", 0x6f406055840327a5),
    ("store_room-static-2/radar.idx", 0x30141cca6dad0f83),
    ("store_room-static-2/radar.cfg", 0xddd0efd766806147),
    ("store_room-static-2/imu.bin", 0xab00909136ff28fd),
    ("store_room-static-2/imu.idx", 0xa0323ad079e5a176),
    ("store_room-static-2/groundtruth.tum", 0xd430b15d782f198f),
    ("store_room-static-2/radar_truth.csv", 0x65e6fb4e217d5cb6),
    ("store_room-static-2/imu_truth.csv", 0xa6416619cc648ab9),
    ("household-handheld-300/session.toml", 0x8961cc2092b4fee8),
    ("household-handheld-300/radar.bin", 0x42548c3d4fbe7037),
    ("household-handheld-300/radar.idx", 0x3704c6ed5821ff51),
    ("household-handheld-300/radar.cfg", 0x0801a79fa2c2f192),
    ("household-handheld-300/imu.bin", 0x7e2b020a0b54f097),
    ("household-handheld-300/imu.idx", 0xc9bb05db1f97098b),
    ("household-handheld-300/groundtruth.tum", 0xba9dabbb0d057d82),
    ("household-handheld-300/radar_truth.csv", 0x87e7ff1a9162fbb0),
    ("household-handheld-300/imu_truth.csv", 0x4365e976106231c4),
];

#[test]
fn default_settings_reproduce_the_sessions_of_before() {
    let got = hashes();
    for (k, h) in &got {
        println!("    (\"{k}\", 0x{h:016x}),");
    }
    if !cfg!(all(target_arch = "x86_64", target_os = "linux")) {
        println!("skipped: golden hashes hold on x86_64 Linux only");
        return;
    }
    assert_eq!(
        got.len(),
        GOLDEN.len(),
        "scenario table and golden table differ"
    );
    let mut bad = Vec::new();
    for ((k, h), (gk, gh)) in got.iter().zip(GOLDEN) {
        assert_eq!(k, gk);
        if h != gh {
            bad.push(k.clone());
        }
    }
    assert!(bad.is_empty(), "default output changed: {bad:?}");
}
