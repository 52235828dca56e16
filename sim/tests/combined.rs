//! All failure-mode settings at once: the session still opens, decodes with the real drivers
//! and keeps its truth files consistent with the streams.

mod common;

use common::{decode_imu, decode_radar, radar_truth};
use milliego_sim::imu::ImuGrade;
use milliego_sim::motion::MotionKind;
use milliego_sim::world::Family;

#[test]
fn every_setting_at_once() {
    for motion in [MotionKind::Vehicle, MotionKind::Headworn] {
        let s = common::simulate_with(Family::Outdoor, motion, 11, |s| {
            s.duration_s = 20.0;
            s.radar_lever_m = Some([1.1, 0.2, 0.3]);
            s.radar_yaw_deg = -30.0;
            s.radar_tilt_deg = 25.0;
            s.doppler_step_mps = 0.49;
            s.near_field_share = 0.24;
            s.imu_spec = ImuGrade::Mems.spec();
            s.imu_hz = 100.0;
            s.imu_gap_share = 0.32;
            s.baro_hz = 50.0;
            if motion == MotionKind::Headworn {
                s.height_change_m = 2.0;
            }
        });
        let d = &s.session.meta.description;
        for what in [
            "radar mounted at (1.1, 0.2, 0.3) m, yawed -30 deg, tilted up 25 deg",
            "Doppler in 0.49 m/s steps",
            "IMU grade mems",
            "dropped in bursts",
            "barometer 50 Hz",
            "near-field leakage",
        ] {
            assert!(d.contains(what), "{what:?} not in {d:?}");
        }
        let (frames, c) = decode_radar(&s.session);
        assert_eq!(c.frames_bad_total(), 0);
        let truth = radar_truth(&s.path());
        assert_eq!(
            truth.len(),
            frames.iter().map(|f| f.points.len()).sum::<usize>()
        );
        assert!(truth.iter().any(|r| r.class == "leakage"));
        let (imu, bad) = decode_imu(&s.session);
        assert_eq!(bad, 0);
        let (all, baro) = common::decode_imu_all(&s.session);
        assert_eq!(all.len(), imu.len() + baro.len());
        for w in all.windows(2) {
            assert!(w[1].0.wrapping_sub(w[0].0) >= 1, "counter goes back");
            assert!(w[1].1 >= w[0].1, "sample time goes back");
        }
        let rate = imu.len() as f64 / 19.95;
        eprintln!(
            "{motion}: {} frames, {} IMU messages ({rate:.1} Hz), {} pressure messages",
            frames.len(),
            imu.len(),
            baro.len()
        );
        assert!((rate - 68.0).abs() < 8.0, "{rate}");
        assert!((baro.len() as f64 - 50.0 * 19.95).abs() <= 2.0);
    }
}
