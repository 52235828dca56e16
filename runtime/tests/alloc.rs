//! The steady state of the hot path allocates nothing: bytes -> framers -> decoders ->
//! synchroniser -> Doppler estimator -> composer -> pose encoding, counted by a global allocator.
// A counting global allocator needs `unsafe impl GlobalAlloc`; it only forwards to the system
// allocator and counts, and lives alone in this test binary.
#![allow(unsafe_code)]

use milliego_runtime::estimator::{build_run_estimators, ClassicalConfig, EstimatorKind, Mounting};
use milliego_runtime::output::Encoded;
use milliego_runtime::queue::Pool;
use milliego_runtime::reader::{ImuDecoder, RadarDecoder, RadarItem};
use milliego_runtime::stage::{Stage, StageConfig};
use milliego_runtime::sync::{SyncConfig, SyncOut, Synchroniser};
use milliego_session::Session;
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{run as simulate, Scenario};
use milliego_sim::world::Family;
use radar_driver::host::DecoderConfig;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

struct Counting;

static ALLOCS: AtomicU64 = AtomicU64::new(0);
static COUNTING: AtomicBool = AtomicBool::new(false);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

#[test]
fn steady_state_allocates_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut sc = Scenario::new(Family::Office, MotionKind::Handheld, 21);
    sc.duration_s = 8.0;
    simulate(&sc, dir.path(), &mut |_| {}).expect("simulate");
    let s = Session::open(dir.path()).unwrap();
    let radar = s.radar.as_ref().unwrap();
    let imu = s.imu.as_ref().unwrap();
    let (rb, ib) = (radar.read_all().unwrap(), imu.read_all().unwrap());
    // The recorded reads of both ports, merged in host-time order: what the readers would see.
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

    let text = s.radar_cfg().unwrap().unwrap();
    let d = radar_driver::cfg::RadarConfig::parse(&text)
        .unwrap()
        .derive(None)
        .unwrap();
    let mut classical = ClassicalConfig {
        mounting: Mounting::from_session(&s.meta.extrinsics),
        ..ClassicalConfig::default()
    };
    classical.ego = classical
        .ego
        .with_velocity_resolution(d.velocity_resolution_mps);
    let mut sync = Synchroniser::new(SyncConfig {
        radar_period_s: Some(d.frame_period_ms / 1e3),
        half_chirps_s: d.active_frame_time_ms / 2e3,
        radar_baud: s.meta.radar.as_ref().unwrap().baud,
        imu_baud: s.meta.imu.as_ref().unwrap().baud,
        preview_imu: true,
        ..SyncConfig::default()
    });
    let built = build_run_estimators(EstimatorKind::Doppler, &classical, None).unwrap();
    let mut stage = Stage::new(
        StageConfig {
            imu_rate_output: true,
            mounting: classical.mounting,
        },
        built,
    );
    let pool: Pool<RadarItem> = Pool::new(64, 64);
    let mut rdec = RadarDecoder::new(DecoderConfig::from_derived(Some(&d)));
    let mut idec = ImuDecoder::new(imu_driver::TimeWrap::Pow32);
    let mut enc = Encoded::default();
    let events: RefCell<Vec<SyncOut>> = RefCell::new(Vec::with_capacity(4096));
    let (mut poses, mut radar_poses, mut predicted) = (0u64, 0u64, 0u64);
    let mut counted_frames = 0u64;
    let warm_up_ns = 3_000_000_000;

    for &(host_ns, is_radar, a, b) in &reads {
        if host_ns > warm_up_ns && !COUNTING.load(Ordering::Relaxed) {
            COUNTING.store(true, Ordering::Relaxed);
        }
        let host_s = host_ns as f64 * 1e-9;
        if is_radar {
            let before = rdec.frames();
            rdec.feed(&rb[a..b], host_s, host_ns, |fill| {
                let mut it = pool.take();
                fill(&mut it);
                sync.push_radar(it, |old| pool.give(old));
            });
            if COUNTING.load(Ordering::Relaxed) {
                counted_frames += rdec.frames() - before;
            }
        } else {
            idec.feed(&ib[a..b], host_s, host_ns, |it| sync.push_imu(it));
        }
        sync.poll(host_s, |ev| events.borrow_mut().push(ev));
        let mut evs = events.borrow_mut();
        for ev in evs.drain(..) {
            stage.process(
                ev,
                host_ns,
                |p| {
                    enc.encode(&p.msg);
                    poses += 1;
                    if p.msg.health.contains(pose_link::Health::PREDICTED) {
                        predicted += 1;
                    } else {
                        radar_poses += 1;
                    }
                },
                |b| pool.give(b),
            );
        }
    }
    COUNTING.store(false, Ordering::Relaxed);
    let n = ALLOCS.load(Ordering::Relaxed);
    println!(
        "{counted_frames} radar frames counted after warm-up; {poses} poses ({radar_poses} radar-rate, {predicted} predicted); {n} allocations"
    );
    assert!(counted_frames > 80, "the counted part covers the last 5 s");
    assert!(
        radar_poses > 120 && predicted > 1000,
        "the path ran end to end"
    );
    assert_eq!(n, 0, "allocations in the steady state");
}
