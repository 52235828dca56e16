//! Poses that rest on the IMU alone are flagged `DEAD_RECKONING`: a handheld office walk whose
//! radar goes blind (its frames' points withheld from the estimator) for a stretch of seconds.

use milliego_odometry::runner::UNAIDED_AFTER_S;
use milliego_runtime::estimator::{
    build_estimator, Built, Estimator, EstimatorError, EstimatorKind, ImuInput, RadarInput,
    RelativePose,
};
use pose_link::Health;

mod common;
use common::{drive, sim};

/// An estimator whose radar frames between `from_s` and `to_s` \[s\] come without points.
struct Blind {
    inner: Box<dyn Estimator>,
    from_s: f64,
    to_s: f64,
}

impl Estimator for Blind {
    fn name(&self) -> &'static str {
        self.inner.name()
    }
    fn push_imu(&mut self, s: &ImuInput) {
        self.inner.push_imu(s);
    }
    fn push_radar(&mut self, f: &RadarInput<'_>) -> Result<Option<RelativePose>, EstimatorError> {
        let blind = (self.from_s..self.to_s).contains(&f.t);
        self.inner.push_radar(&RadarInput {
            points: if blind { &[] } else { f.points },
            ..*f
        })
    }
    fn healthy(&self) -> bool {
        self.inner.healthy()
    }
    fn last_aid_s(&self) -> Option<f64> {
        self.inner.last_aid_s()
    }
}

#[test]
fn poses_the_radar_does_not_aid_are_flagged_dead_reckoning() {
    let s = sim(31);
    let doppler = || build_estimator(EstimatorKind::Doppler, &s.classical, None).unwrap();
    let flagged = |poses: &[(f64, pose_link::PoseMessage)], a: f64, b: f64| {
        let within: Vec<bool> = poses
            .iter()
            .filter(|(t, _)| (a..b).contains(t))
            .map(|(_, m)| m.health.contains(Health::DEAD_RECKONING))
            .collect();
        (within.iter().filter(|f| **f).count(), within.len())
    };
    // Seeing: once the filter runs, the radar aids every few frames.
    let (seeing, _) = drive(
        &s,
        Built {
            primary: doppler(),
            fallback: None,
            model_fallback: false,
        },
    );
    let t0 = seeing[0].0;
    let (n, of) = flagged(&seeing, t0 + 2.0, f64::INFINITY);
    assert!(of > 100, "{of} poses");
    assert_eq!(n, 0, "{n} of {of} poses flagged while the radar sees");

    // Blind from 3 to 7 s after the first pose: flagged from a second in until the radar is
    // back, then no more.
    let (from_s, to_s) = (t0 + 3.0, t0 + 7.0);
    let (blind, _) = drive(
        &s,
        Built {
            primary: Box::new(Blind {
                inner: doppler(),
                from_s,
                to_s,
            }),
            fallback: None,
            model_fallback: false,
        },
    );
    let (n, of) = flagged(&blind, t0 + 2.0, from_s + UNAIDED_AFTER_S - 0.05);
    assert_eq!(
        n, 0,
        "{n} of {of} flagged before the radar went blind for a second"
    );
    let (n, of) = flagged(&blind, from_s + UNAIDED_AFTER_S + 0.1, to_s);
    assert!(of > 40, "{of} poses");
    assert_eq!(n, of, "{n} of {of} flagged while blind");
    let (n, of) = flagged(&blind, to_s + 1.0, f64::INFINITY);
    assert!(of > 40, "{of} poses");
    assert_eq!(n, 0, "{n} of {of} flagged after the radar came back");
}
