//! `auto`'s hand-over from the learned model to the Doppler filter continues the trajectory: no
//! new origin, the pose flagged HANDOVER, and after it the Doppler filter's own motion rigidly
//! attached to where the model left off.

use milliego_runtime::estimator::{
    build_estimator, Built, Estimator, EstimatorError, EstimatorKind, ImuInput, RadarInput,
    RelativePose,
};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use pose_link::{Health, PoseMessage};
use std::path::PathBuf;

mod common;
use common::{drive, drive_timed, frame_at, sim, Driven};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// An estimator that fails from frame `at` on: the primary's fault, injected.
struct FailFrom {
    inner: Box<dyn Estimator>,
    at: u32,
    failed: bool,
    /// IMU samples given to it after it failed (the stage should give none).
    imu_after: Arc<AtomicU64>,
}

impl Estimator for FailFrom {
    fn name(&self) -> &'static str {
        self.inner.name()
    }
    fn push_imu(&mut self, s: &ImuInput) {
        if self.failed {
            self.imu_after.fetch_add(1, Ordering::Relaxed);
        }
        self.inner.push_imu(s);
    }
    fn push_radar(&mut self, f: &RadarInput<'_>) -> Result<Option<RelativePose>, EstimatorError> {
        if f.frame_number >= self.at {
            self.failed = true;
            return Err(EstimatorError::Unhealthy("injected fault".into()));
        }
        self.inner.push_radar(f)
    }
    fn healthy(&self) -> bool {
        !self.failed
    }
}

fn iso(m: &PoseMessage) -> Isometry3<f64> {
    let [w, x, y, z] = m.orientation.map(f64::from);
    Isometry3::from_parts(
        Translation3::from(Vector3::from(m.position)),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    )
}

fn failing(inner: Box<dyn Estimator>, at: u32) -> Box<dyn Estimator> {
    failing_counted(inner, at, Arc::default())
}

fn failing_counted(
    inner: Box<dyn Estimator>,
    at: u32,
    imu_after: Arc<AtomicU64>,
) -> Box<dyn Estimator> {
    Box::new(FailFrom {
        inner,
        at,
        failed: false,
        imu_after,
    })
}

/// After the hand-over the trajectory is `B * doppler(t)` for one rigid `B`: the fallback's motion,
/// attached where the primary left off.
fn assert_attached(handed: &[(f64, PoseMessage)], plain: &[(f64, PoseMessage)], after: f64) {
    let mut offset: Option<Isometry3<f64>> = None;
    let mut compared = 0;
    for (t, m) in handed.iter().filter(|(t, _)| *t > after) {
        let (_, d) = plain
            .iter()
            .find(|(u, _)| (u - t).abs() < 1e-9)
            .unwrap_or_else(|| panic!("no plain Doppler pose at {t}"));
        let b = iso(m) * iso(d).inverse();
        let b0 = *offset.get_or_insert(b);
        let dp = (b.translation.vector - b0.translation.vector).norm();
        let da = b.rotation.angle_to(&b0.rotation);
        assert!(
            dp < 1e-4 && da < 1e-5,
            "at {t}: offset moved {dp} m, {da} rad"
        );
        compared += 1;
    }
    assert!(
        compared > 50,
        "{compared} poses compared after the hand-over"
    );
}

#[test]
fn handover_between_identical_filters_changes_nothing() {
    let s = sim(31);
    let doppler = || build_estimator(EstimatorKind::Doppler, &s.classical, None).unwrap();
    let (plain, _) = drive(
        &s,
        Built {
            primary: doppler(),
            fallback: None,
            model_fallback: false,
        },
    );
    let at = frame_at(&s, 50);
    let imu_after = Arc::new(AtomicU64::new(0));
    let Driven {
        poses: handed,
        counters: c,
        reason,
        ..
    } = drive_timed(
        &s,
        Built {
            primary: failing_counted(doppler(), at, imu_after.clone()),
            fallback: Some(doppler()),
            model_fallback: false,
        },
        0.0,
    );
    assert_eq!(c.handovers, 1);
    assert_eq!(
        reason.as_deref(),
        Some("the doppler estimator failed: estimator unhealthy: injected fault"),
        "the summary says why"
    );
    assert_eq!(
        imu_after.load(Ordering::Relaxed),
        0,
        "the primary gets no IMU sample after the hand-over"
    );
    assert_eq!(c.resets, 1, "only the first pose starts an origin");
    assert_eq!(handed.len(), plain.len());
    for ((t, a), (u, b)) in handed.iter().zip(&plain) {
        assert!((t - u).abs() < 1e-12);
        let d = (0..3)
            .map(|i| (a.position[i] - b.position[i]).abs())
            .fold(0.0, f64::max);
        assert!(d < 1e-9, "at {t}: {d} m from the plain run");
    }
    let flagged: Vec<_> = handed
        .iter()
        .filter(|(_, m)| m.health.contains(Health::HANDOVER))
        .collect();
    assert_eq!(flagged.len(), 1, "one pose flagged HANDOVER");
    assert!(handed
        .iter()
        .skip(1)
        .all(|(_, m)| !m.health.contains(Health::RESET)));
}

#[test]
fn model_to_doppler_handover_continues_the_trajectory() {
    let s = sim(32);
    let model = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/compact/model-int8.onnx");
    let at = frame_at(&s, 60);
    let built = Built {
        primary: failing(
            build_estimator(
                EstimatorKind::Model,
                &s.classical,
                Some(model.as_path().into()),
            )
            .unwrap(),
            at,
        ),
        fallback: Some(build_estimator(EstimatorKind::Doppler, &s.classical, None).unwrap()),
        model_fallback: false,
    };
    let (handed, c) = drive(&s, built);
    let (plain, _) = drive(
        &s,
        Built {
            primary: build_estimator(EstimatorKind::Doppler, &s.classical, None).unwrap(),
            fallback: None,
            model_fallback: false,
        },
    );
    assert_eq!(c.handovers, 1);
    assert_eq!(c.resets, 1, "the hand-over starts no new origin");
    let k = handed
        .iter()
        .position(|(_, m)| m.health.contains(Health::HANDOVER))
        .expect("a HANDOVER pose");
    assert!(k > 0, "model poses before the hand-over");
    assert!(handed[k..]
        .iter()
        .all(|(_, m)| m.health.contains(Health::MODEL_FALLBACK)));
    assert!(handed
        .iter()
        .skip(1)
        .all(|(_, m)| !m.health.contains(Health::RESET)));
    // Continuous: the step across the hand-over is what the body moved, not a jump to the origin.
    let (t0, before) = &handed[k - 1];
    let (t1, after) = &handed[k];
    let step = (iso(after).translation.vector - iso(before).translation.vector).norm();
    let gt = s.session.groundtruth().unwrap().unwrap();
    let at_t = |t: f64| {
        let p = gt
            .iter()
            .min_by(|a, b| (a.t - t).abs().total_cmp(&(b.t - t).abs()))
            .unwrap();
        Vector3::from(p.p)
    };
    let moved = (at_t(*t1) - at_t(*t0)).norm();
    assert!(
        step <= moved + 0.1,
        "hand-over step {step:.3} m, the body moved {moved:.3} m"
    );
    let from_origin = iso(before).translation.vector.norm();
    println!("hand-over at {t1:.2} s: step {step:.3} m (body moved {moved:.3} m), {from_origin:.2} m from the origin");
    assert_attached(&handed, &plain, *t0);
}

#[test]
fn a_model_pose_leaves_with_its_own_frame() {
    let s = sim(33);
    let model = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/compact/model-int8.onnx");
    let primary = build_estimator(
        EstimatorKind::Model,
        &s.classical,
        Some(model.as_path().into()),
    )
    .unwrap();
    // The simulator's frames fall on its IMU sample times; 2.5 ms earlier (half the 200 Hz IMU
    // period, as real clocks fall) a window needs the IMU sample after its frame. The
    // synchroniser releases a frame right after the first IMU sample at or past its time, so
    // the window is complete when the frame reaches the model: its pose goes out then, not with
    // the next frame.
    let Driven {
        poses,
        counters: c,
        emitted: when,
        ..
    } = drive_timed(
        &s,
        Built {
            primary,
            fallback: None,
            model_fallback: false,
        },
        0.0025,
    );
    assert!(poses.len() > 30, "{} model poses", poses.len());
    assert_eq!(c.errors, 0);
    for ((t, _), e) in poses.iter().zip(&when) {
        assert_eq!(
            e.frame_t,
            Some(*t),
            "the pose at {t} s left while processing {e:?}"
        );
    }
}
