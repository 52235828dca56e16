//! `auto`'s hand-over from the learned model to the Doppler filter continues the trajectory: no
//! new origin, the pose flagged HANDOVER, and after it the Doppler filter's own motion rigidly
//! attached to where the model left off.

use milliego_runtime::estimator::{
    build_estimator, Built, ClassicalConfig, Estimator, EstimatorError, EstimatorKind, ImuInput,
    Mounting, RadarInput, RelativePose,
};
use milliego_runtime::queue::Pool;
use milliego_runtime::reader::{ImuDecoder, RadarDecoder, RadarItem};
use milliego_runtime::stage::{Stage, StageConfig, StageCounters};
use milliego_runtime::sync::{SyncConfig, SyncOut, Synchroniser};
use milliego_session::Session;
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use pose_link::{Health, PoseMessage};
use radar_driver::host::DecoderConfig;
use std::path::PathBuf;
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

struct Sim {
    _dir: tempfile::TempDir,
    session: Session,
    classical: ClassicalConfig,
    vres: f32,
    period_s: f64,
    half_chirps_s: f64,
}

fn sim(seed: u64) -> Sim {
    let dir = tempfile::tempdir().unwrap();
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, seed);
    sc.duration_s = 12.0;
    simulate(&sc, dir.path(), &mut |_| {}).expect("simulate");
    let session = Session::open(dir.path()).unwrap();
    let text = session.radar_cfg().unwrap().unwrap();
    let d = radar_driver::cfg::RadarConfig::parse(&text)
        .unwrap()
        .derive(None)
        .unwrap();
    let mut classical = ClassicalConfig {
        mounting: Mounting::from_session(&session.meta.extrinsics),
        ..ClassicalConfig::default()
    };
    classical.ego = classical
        .ego
        .with_velocity_resolution(d.velocity_resolution_mps);
    Sim {
        _dir: dir,
        session,
        classical,
        vres: d.velocity_resolution_mps as f32,
        period_s: d.frame_period_ms / 1e3,
        half_chirps_s: d.active_frame_time_ms / 2e3,
    }
}

/// Replays the session's recorded reads through decoders, synchroniser and a stage running
/// `built`; the radar-rate poses (frame time \[s\], message) and the stage's counters.
fn drive(s: &Sim, built: Built) -> (Vec<(f64, PoseMessage)>, StageCounters) {
    let d = drive_timed(s, built, 0.0);
    (d.poses, d.counters)
}

/// When a radar-rate pose left the stage.
#[derive(Debug, Clone, Copy)]
struct Emitted {
    /// Time \[s\] of the radar frame being processed then (None: an IMU sample).
    frame_t: Option<f64>,
}

/// What [`drive_timed`] saw.
struct Driven {
    /// Radar-rate poses (time \[s\], message).
    poses: Vec<(f64, PoseMessage)>,
    counters: StageCounters,
    /// When each of `poses` left the stage.
    emitted: Vec<Emitted>,
    /// Why the stage handed over, if it did.
    reason: Option<String>,
}

/// [`drive`], with when each pose left the stage and why it handed over; radar frames timed
/// `earlier_s` \[s\] earlier than the session says.
fn drive_timed(s: &Sim, built: Built, earlier_s: f64) -> Driven {
    let radar = s.session.radar.as_ref().unwrap();
    let imu = s.session.imu.as_ref().unwrap();
    let (rb, ib) = (radar.read_all().unwrap(), imu.read_all().unwrap());
    let mut reads: Vec<(u64, bool, usize, usize)> = radar
        .chunks()
        .iter()
        .map(|c| (c.host_ns.unwrap(), true, c.start as usize, c.end as usize))
        .chain(
            imu.chunks()
                .iter()
                .map(|c| (c.host_ns.unwrap(), false, c.start as usize, c.end as usize)),
        )
        .collect();
    reads.sort_by_key(|r| r.0);
    let mut sync = Synchroniser::new(SyncConfig {
        radar_period_s: Some(s.period_s),
        half_chirps_s: s.half_chirps_s + earlier_s,
        radar_baud: s.session.meta.radar.as_ref().unwrap().baud,
        imu_baud: s.session.meta.imu.as_ref().unwrap().baud,
        ..SyncConfig::default()
    });
    let mut stage = Stage::new(
        StageConfig {
            imu_rate_output: false,
            mounting: s.classical.mounting,
        },
        built,
    );
    let pool: Pool<RadarItem> = Pool::new(64, 64);
    let mut rdec = RadarDecoder::new(DecoderConfig {
        velocity_resolution_mps: Some(s.vres),
        frame_period_s: Some(s.period_s),
        ..DecoderConfig::default()
    });
    let mut idec = ImuDecoder::new(imu_driver::TimeWrap::Pow32);
    let mut events: Vec<SyncOut> = Vec::new();
    let mut poses = Vec::new();
    let mut emitted = Vec::new();
    for &(host_ns, is_radar, a, b) in &reads {
        let host_s = host_ns as f64 * 1e-9;
        if is_radar {
            rdec.feed(&rb[a..b], host_s, host_ns, |fill| {
                let mut it = pool.take();
                fill(&mut it);
                sync.push_radar(it, |old| pool.give(old));
            });
        } else {
            idec.feed(&ib[a..b], host_s, host_ns, |it| sync.push_imu(it));
        }
        sync.poll(host_s, |ev| events.push(ev));
        for ev in events.drain(..) {
            let frame_t = match &ev {
                SyncOut::Radar { item, .. } => item.t,
                _ => None,
            };
            stage.process(
                ev,
                host_ns,
                |p| {
                    if !p.msg.health.contains(Health::PREDICTED) {
                        poses.push((p.t, p.msg));
                        emitted.push(Emitted { frame_t });
                    }
                },
                |b| pool.give(b),
            );
        }
    }
    Driven {
        reason: stage.handover_reason().map(str::to_string),
        poses,
        counters: stage.counters,
        emitted,
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

/// Frame number `k` frames into the session.
fn frame_at(s: &Sim, k: usize) -> u32 {
    let (frames, _) = milliego_session::streams::radar_frames(&s.session).unwrap();
    frames[k].frame_number
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
