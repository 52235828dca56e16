//! What the stage tests share: a simulated session, and a replay of its recorded reads through
//! the decoders, the synchroniser and a stage.
#![allow(dead_code)] // each test binary uses its part

use milliego_runtime::estimator::{Built, ClassicalConfig, Mounting};
use milliego_runtime::queue::Pool;
use milliego_runtime::reader::{ImuDecoder, RadarDecoder, RadarItem};
use milliego_runtime::stage::{Stage, StageConfig, StageCounters};
use milliego_runtime::sync::{SyncConfig, SyncOut, Synchroniser};
use milliego_session::Session;
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;
use pose_link::{Health, PoseMessage};
use radar_driver::host::DecoderConfig;

/// A simulated session and what the stage needs of its radar configuration.
pub struct Sim {
    pub _dir: tempfile::TempDir,
    pub session: Session,
    pub classical: ClassicalConfig,
    pub vres: f32,
    pub period_s: f64,
    pub half_chirps_s: f64,
}

pub fn sim(seed: u64) -> Sim {
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
pub fn drive(s: &Sim, built: Built) -> (Vec<(f64, PoseMessage)>, StageCounters) {
    let d = drive_timed(s, built, 0.0);
    (d.poses, d.counters)
}

/// When a radar-rate pose left the stage.
#[derive(Debug, Clone, Copy)]
pub struct Emitted {
    /// Time \[s\] of the radar frame being processed then (None: an IMU sample).
    pub frame_t: Option<f64>,
}

/// What [`drive_timed`] saw.
pub struct Driven {
    /// Radar-rate poses (time \[s\], message).
    pub poses: Vec<(f64, PoseMessage)>,
    pub counters: StageCounters,
    /// When each of `poses` left the stage.
    pub emitted: Vec<Emitted>,
    /// Why the stage handed over, if it did.
    pub reason: Option<String>,
}

/// [`drive`], with when each pose left the stage and why it handed over; radar frames timed
/// `earlier_s` \[s\] earlier than the session says.
pub fn drive_timed(s: &Sim, built: Built, earlier_s: f64) -> Driven {
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

/// Frame number `k` frames into the session.
pub fn frame_at(s: &Sim, k: usize) -> u32 {
    let (frames, _) = milliego_session::streams::radar_frames(&s.session).unwrap();
    frames[k].frame_number
}
