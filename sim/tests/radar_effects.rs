//! Radar failure modes of real rigs: coarse Doppler steps and near-field leakage.

mod common;

use common::{decode_radar, radar_truth};
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::Scenario;
use milliego_sim::world::Family;

#[test]
fn coarse_doppler_is_a_multiple_of_the_step() {
    let step = 0.49;
    let s = common::simulate_with(Family::Corridor, MotionKind::Handheld, 4, |s| {
        s.duration_s = 10.0;
        s.doppler_step_mps = step;
    });
    assert!(s.session.meta.description.contains("0.49 m/s steps"));
    let model = s.scenario.radar_model().unwrap();
    let vmax = model.derived.max_velocity_mps;
    let (frames, _) = decode_radar(&s.session);
    let truth = radar_truth(&s.path());
    let mut rows = truth.iter();
    let mut levels = std::collections::BTreeSet::new();
    let mut res = Vec::new();
    for f in &frames {
        for p in &f.points {
            let r = rows.next().unwrap();
            let v = f64::from(p[3]);
            let n = (v / step).round();
            assert!(
                (v - n * step).abs() < 1e-5,
                "frame {}: {v} m/s is not a multiple of {step}",
                f.frame_number
            );
            assert!(v.abs() <= vmax + 1e-5);
            levels.insert(n as i64);
            if r.class == "inlier" && r.true_v.abs() < vmax - step {
                res.push(v - r.true_v);
            }
        }
    }
    let rms = (res.iter().map(|x| x * x).sum::<f64>() / res.len() as f64).sqrt();
    let sigma = model.doppler_sigma_mps();
    eprintln!(
        "{} levels used; inlier Doppler error rms {rms:.3} m/s, expected {sigma:.3}",
        levels.len()
    );
    assert!(levels.len() >= 4, "{levels:?}");
    assert!((sigma - (0.04f64.powi(2) + step * step / 12.0).sqrt()).abs() < 1e-12);
    assert!(rms > 0.8 * sigma && rms < 1.2 * sigma, "rms {rms}");
    for bad in [-0.1, 0.005, 2.5, f64::NAN] {
        let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 1);
        sc.doppler_step_mps = bad;
        let e = sc.validate().unwrap_err().to_string();
        assert!(e.contains("Doppler step"), "{e}");
    }
}
