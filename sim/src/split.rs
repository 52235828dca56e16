//! The benchmark split: which (family, motion, seed) scenarios train, validate and test a model.
//!
//! The held-out test set uses a world family never seen in training (`household`) and, for the
//! other families, seeds never used in training or validation. Because the world layout, the
//! trajectory, the clocks and all noise derive from the seed, an unseen seed means an unseen floor
//! plan and an unseen path. The tables are documented in docs/simulator.md.
//!
//! A split version is a value ([`SplitVersion`]): [`SplitVersion::V1`] is the benchmark of
//! before (benign rigs: default mounts, MTi-1 at 200 Hz, no rests, indoor families), kept byte for
//! byte so its figures stay comparable; [`SplitVersion::V2`] adds the outdoor family (handheld and
//! vehicle) and draws each session's rig from its seed: rests, IMU grade, rate and gaps, radar
//! mount, near-field leakage, coarse Doppler, barometer and height change ([`Entry::scenario`]).
//! The free functions [`benchmark`] and [`entries`] are version 1.

use crate::imu::ImuGrade;
use crate::motion::MotionKind;
use crate::rng::SimRng;
use crate::scenario::Scenario;
use crate::world::{Family, World};
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// A subset of the benchmark.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Set {
    /// Training.
    Train,
    /// Validation (model selection): seen families, unseen seeds.
    Val,
    /// Held-out test: the unseen family, and unseen seeds of the seen families.
    Test,
}

impl Set {
    /// All sets.
    pub const ALL: [Set; 3] = [Set::Train, Set::Val, Set::Test];

    /// Name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Set::Train => "train",
            Set::Val => "val",
            Set::Test => "test",
        }
    }
}

impl fmt::Display for Set {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Set {
    type Err = String;
    fn from_str(s: &str) -> Result<Set, String> {
        Set::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| format!("unknown set {s:?} (expected train, val or test)"))
    }
}

/// A version of the benchmark split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub enum SplitVersion {
    /// Version 1: benign rigs (default mount, MTi-1 at 200 Hz, no rests, no barometer), the
    /// five indoor families. Its sessions are those of before, byte for byte.
    #[default]
    V1,
    /// Version 2: version 1's families and motions plus the outdoor family (handheld and
    /// vehicle), each session's rig drawn from its seed (docs/simulator.md, "Benchmark split
    /// versions").
    V2,
}

impl SplitVersion {
    /// All versions.
    pub const ALL: [SplitVersion; 2] = [SplitVersion::V1, SplitVersion::V2];

    /// Name on the command line: `v1`, `v2`.
    pub fn name(self) -> &'static str {
        match self {
            SplitVersion::V1 => "v1",
            SplitVersion::V2 => "v2",
        }
    }

    /// Seeds of a set. Version 2's are disjoint from version 1's.
    pub fn seeds(self, set: Set) -> Range<u64> {
        match (self, set) {
            (SplitVersion::V1, Set::Train) => TRAIN_SEEDS,
            (SplitVersion::V1, Set::Val) => VAL_SEEDS,
            (SplitVersion::V1, Set::Test) => TEST_SEEDS,
            (SplitVersion::V2, Set::Train) => V2_TRAIN_SEEDS,
            (SplitVersion::V2, Set::Val) => V2_VAL_SEEDS,
            (SplitVersion::V2, Set::Test) => V2_TEST_SEEDS,
        }
    }

    /// The (family, motion) pairs of a set, in listing order.
    pub fn pairs(self, set: Set) -> Vec<(Family, MotionKind)> {
        let mut families = SEEN_FAMILIES.to_vec();
        if set == Set::Test {
            families.push(HELD_OUT_FAMILY);
        }
        let mut out: Vec<_> = families
            .into_iter()
            .flat_map(|f| MOTIONS.map(|m| (f, m)))
            .collect();
        if self == SplitVersion::V2 {
            out.extend(V2_OUTDOOR_MOTIONS.map(|m| (Family::Outdoor, m)));
        }
        out
    }

    /// Every session of this version: train, then val, then test.
    pub fn benchmark(self) -> Vec<Entry> {
        Set::ALL
            .into_iter()
            .flat_map(|set| self.entries(set))
            .collect()
    }

    /// The sessions of one set.
    pub fn entries(self, set: Set) -> Vec<Entry> {
        let seeds = self.seeds(set);
        self.pairs(set)
            .into_iter()
            .flat_map(|(family, motion)| {
                seeds.clone().map(move |seed| Entry {
                    version: self,
                    set,
                    family,
                    motion,
                    seed,
                    duration_s: DURATION_S,
                })
            })
            .collect()
    }
}

impl fmt::Display for SplitVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SplitVersion {
    type Err = String;
    fn from_str(s: &str) -> Result<SplitVersion, String> {
        SplitVersion::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| format!("unknown split version {s:?} (expected v1 or v2)"))
    }
}

/// One benchmark session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Entry {
    /// Split version (decides how [`Entry::scenario`] sets the rig up).
    pub version: SplitVersion,
    /// Which subset.
    pub set: Set,
    /// World family.
    pub family: Family,
    /// Motion.
    pub motion: MotionKind,
    /// Seed (world, trajectory, clocks, noise; in version 2 also the rig).
    pub seed: u64,
    /// Length \[s\].
    pub duration_s: u32,
}

impl Entry {
    /// The scenario of this entry. Version 1: the default rig and sensor rates. Version 2: the
    /// rig drawn from the seed ([`SplitVersion::V2`]; the draws come from streams of their own,
    /// `split/v2/FAMILY/MOTION/WHAT`, so they move nothing else the seed draws).
    pub fn scenario(&self) -> Scenario {
        let mut s = Scenario::new(self.family, self.motion, self.seed);
        s.duration_s = f64::from(self.duration_s);
        if self.version == SplitVersion::V2 {
            draw_v2(&mut s);
        }
        s
    }

    /// Directory name of the session: `SET/FAMILY-MOTION-SEED` (version 1, as always), or
    /// `VERSION/SET/FAMILY-MOTION-SEED` (later versions), so two versions never share one.
    pub fn dir_name(&self) -> String {
        let d = format!("{}/{}-{}-{}", self.set, self.family, self.motion, self.seed);
        match self.version {
            SplitVersion::V1 => d,
            v => format!("{v}/{d}"),
        }
    }

    /// Where `milliego score` and `milliego dataset build` keep this session under their work
    /// directory `root`: `root/SET/` + [`Entry::dir_name`] for version 1 (the layout those
    /// commands always used, so existing sessions are reused), `root/` + [`Entry::dir_name`]
    /// for later versions.
    pub fn work_dir(&self, root: &Path) -> PathBuf {
        match self.version {
            SplitVersion::V1 => root.join(self.set.name()).join(self.dir_name()),
            _ => root.join(self.dir_name()),
        }
    }
    /// Whether a session whose `session.toml` description is `description` holds this entry's
    /// scenario (the simulator's crate version in the description aside): a work directory
    /// made by another version of the split, or of its draws, is not silently reused.
    pub fn is_session(&self, description: &str) -> bool {
        let body = |d: &str| d.split_once(": ").map(|(_, b)| b.to_string());
        body(description).is_some_and(|b| Some(b) == body(&self.scenario().description()))
    }
}

/// Families a model may train on.
pub const SEEN_FAMILIES: [Family; 4] = [
    Family::Corridor,
    Family::Office,
    Family::Atrium,
    Family::StoreRoom,
];
/// The family held out for testing only.
pub const HELD_OUT_FAMILY: Family = Family::Household;
/// Moving kinds in the benchmark (indoor families).
pub const MOTIONS: [MotionKind; 3] = [
    MotionKind::Robot,
    MotionKind::Handheld,
    MotionKind::Headworn,
];
/// Training seeds (version 1).
pub const TRAIN_SEEDS: Range<u64> = 100..104;
/// Validation seeds (version 1).
pub const VAL_SEEDS: Range<u64> = 200..201;
/// Test seeds (version 1).
pub const TEST_SEEDS: Range<u64> = 300..302;
/// Session length in the benchmark \[s\] (both versions).
pub const DURATION_S: u32 = 60;

/// Version 2: motions of the outdoor family (in all three sets, with disjoint seeds).
pub const V2_OUTDOOR_MOTIONS: [MotionKind; 2] = [MotionKind::Handheld, MotionKind::Vehicle];
/// Version 2: training seeds.
pub const V2_TRAIN_SEEDS: Range<u64> = 1100..1104;
/// Version 2: validation seeds.
pub const V2_VAL_SEEDS: Range<u64> = 1200..1203;
/// Version 2: test seeds.
pub const V2_TEST_SEEDS: Range<u64> = 1300..1303;

/// Version 2's draws: the share of sessions with each setting and the setting's range. Every
/// range lies within what [`Scenario::validate`] accepts.
pub mod v2 {
    /// Share of sessions at rest before the motion.
    pub const REST_START_SHARE: f64 = 0.8;
    /// Rest before the motion \[s\] (uniform, 0.1 s steps).
    pub const REST_START_S: (f64, f64) = (2.0, 10.0);
    /// Share of sessions at rest after the motion.
    pub const REST_END_SHARE: f64 = 0.5;
    /// Rest after the motion \[s\] (uniform, 0.1 s steps).
    pub const REST_END_S: (f64, f64) = (2.0, 6.0);
    /// IMU grades: share of `mti600` and of `mems` (the rest `mti1`).
    pub const IMU_MTI600_SHARE: f64 = 0.2;
    /// See [`IMU_MTI600_SHARE`].
    pub const IMU_MEMS_SHARE: f64 = 0.2;
    /// Share of sessions with the IMU at [`IMU_LOW_HZ`] (the rest at 200 Hz).
    pub const IMU_LOW_RATE_SHARE: f64 = 0.3;
    /// The lower IMU rate \[Hz\] (the MTi-1's own limit for inertial outputs).
    pub const IMU_LOW_HZ: f64 = 100.0;
    /// Share of sessions with dropped IMU messages.
    pub const IMU_GAPS_SHARE: f64 = 0.1;
    /// Their share of dropped messages (uniform, 0.01 steps; a real MTi-G-710 link: 0.32).
    pub const IMU_GAPS: (f64, f64) = (0.05, 0.35);
    /// Share of sessions with a moderately moved radar (lever, yaw, tilt below).
    pub const MOUNT_MODERATE_SHARE: f64 = 0.3;
    /// Moderate mount: lever arm x, y, z ranges \[m\] (uniform, cm steps; z kept small so a
    /// robot's radar stays above the floor and a walker's below the ceiling).
    pub const MOUNT_LEVER_M: [(f64, f64); 3] = [(-0.5, 0.5), (-0.3, 0.3), (-0.1, 0.2)];
    /// Moderate mount: yaw and tilt, each uniform within ± this \[deg\] (0.1° steps).
    pub const MOUNT_ANGLE_DEG: f64 = 15.0;
    /// Share of sessions (other than vehicles) with the large real-vehicle mount.
    pub const MOUNT_LARGE_SHARE: f64 = 0.1;
    /// Share of vehicle sessions with the large real-vehicle mount.
    pub const MOUNT_LARGE_VEHICLE_SHARE: f64 = 0.4;
    /// The large mount: lever arm \[m\] (1.1 m ahead of the IMU) ...
    pub const MOUNT_LARGE_LEVER_M: [f64; 3] = [1.1, 0.0, 0.0];
    /// ... yawed ± this (sign drawn) \[deg\] ...
    pub const MOUNT_LARGE_YAW_DEG: f64 = 30.0;
    /// ... and tilted up this much \[deg\].
    pub const MOUNT_LARGE_TILT_DEG: f64 = 25.0;
    /// Share of sessions with near-field leakage.
    pub const NEAR_FIELD_SHARE: f64 = 0.2;
    /// Their leakage share (uniform, 0.01 steps).
    pub const NEAR_FIELD: (f64, f64) = (0.05, 0.2);
    /// Share of sessions with coarse Doppler.
    pub const DOPPLER_SHARE: f64 = 0.15;
    /// Their Doppler step \[m/s\] (uniform, 0.01 steps; a real rig: 0.49).
    pub const DOPPLER_STEP_MPS: (f64, f64) = (0.2, 0.5);
    /// Share of sessions with a barometer.
    pub const BARO_SHARE: f64 = 0.5;
    /// Its rate \[Hz\].
    pub const BARO_HZ: f64 = 50.0;
    /// Share of handheld and headworn walks that change height.
    pub const HEIGHT_SHARE: f64 = 0.3;
    /// Smallest height change drawn \[m\] (indoors none where the ceiling leaves less room).
    pub const HEIGHT_MIN_M: f64 = 0.3;
    /// Largest height change indoors \[m\] (and below the ceiling, see [`super::height_room`]).
    pub const HEIGHT_MAX_INDOOR_M: f64 = 3.0;
    /// Largest height change outdoors \[m\].
    pub const HEIGHT_MAX_OUTDOOR_M: f64 = 5.0;
    /// Highest base height of a walker \[m\] (handheld 1.1-1.4, headworn 1.55-1.8).
    pub const fn walker_top_m(headworn: bool) -> f64 {
        if headworn {
            1.8
        } else {
            1.4
        }
    }
}

/// Room for a height change \[m\]: the world's ceiling less the walker's highest base height,
/// the radar's lever arm upwards, the 0.2 m the scenario keeps and 5 cm more.
pub fn height_room(s: &Scenario) -> f64 {
    let ceiling = World::generate(s.family, s.seed).height;
    let lever_up = s.radar_lever_m.map_or(0.0, |t| t[2].max(0.0));
    ceiling - v2::walker_top_m(s.motion == MotionKind::Headworn) - lever_up - 0.2 - 0.05
}

/// `x` rounded down to a multiple of 1/`per` (exact decimal in the description).
fn floor_to(x: f64, per: f64) -> f64 {
    (x * per).floor() / per
}

/// Uniform in `r`, on a grid of 1/`per` (within the range).
fn pick(rng: &mut SimRng, r: (f64, f64), per: f64) -> f64 {
    floor_to(rng.uniform(r.0, r.1), per).clamp(r.0, r.1)
}

/// Version 2's rig for `s` (family, motion, seed and duration already set).
fn draw_v2(s: &mut Scenario) {
    use v2::*;
    let (family, motion, seed) = (s.family, s.motion, s.seed);
    let rng = |what: &str| SimRng::new(seed, &format!("split/v2/{family}/{motion}/{what}"));

    let mut r = rng("rest");
    if r.chance(REST_START_SHARE) {
        s.rest_start_s = pick(&mut r, REST_START_S, 10.0);
    }
    let mut r = rng("rest-end");
    if r.chance(REST_END_SHARE) {
        s.rest_end_s = pick(&mut r, REST_END_S, 10.0);
    }

    let mut r = rng("imu");
    let u = r.unit();
    let grade = if u < IMU_MEMS_SHARE {
        ImuGrade::Mems
    } else if u < IMU_MEMS_SHARE + IMU_MTI600_SHARE {
        ImuGrade::Mti600
    } else {
        ImuGrade::Mti1
    };
    s.imu_spec = grade.spec();
    if r.chance(IMU_LOW_RATE_SHARE) {
        s.imu_hz = IMU_LOW_HZ;
    }
    let mut r = rng("imu-gaps");
    if r.chance(IMU_GAPS_SHARE) {
        s.imu_gap_share = pick(&mut r, IMU_GAPS, 100.0);
    }

    let mut r = rng("mount");
    let u = r.unit();
    let large = if motion == MotionKind::Vehicle {
        MOUNT_LARGE_VEHICLE_SHARE
    } else {
        MOUNT_LARGE_SHARE
    };
    if u < large {
        s.radar_lever_m = Some(MOUNT_LARGE_LEVER_M);
        s.radar_yaw_deg = if r.chance(0.5) {
            MOUNT_LARGE_YAW_DEG
        } else {
            -MOUNT_LARGE_YAW_DEG
        };
        s.radar_tilt_deg = MOUNT_LARGE_TILT_DEG;
    } else if u < large + MOUNT_MODERATE_SHARE {
        s.radar_lever_m = Some(MOUNT_LEVER_M.map(|range| pick(&mut r, range, 100.0)));
        let a = (-MOUNT_ANGLE_DEG, MOUNT_ANGLE_DEG);
        s.radar_yaw_deg = pick(&mut r, a, 10.0);
        s.radar_tilt_deg = pick(&mut r, a, 10.0);
    }

    let mut r = rng("near-field");
    if r.chance(NEAR_FIELD_SHARE) {
        s.near_field_share = pick(&mut r, NEAR_FIELD, 100.0);
    }
    let mut r = rng("doppler");
    if r.chance(DOPPLER_SHARE) {
        s.doppler_step_mps = pick(&mut r, DOPPLER_STEP_MPS, 100.0);
    }
    let mut r = rng("baro");
    if r.chance(BARO_SHARE) {
        s.baro_hz = BARO_HZ;
    }

    let mut r = rng("height");
    if matches!(motion, MotionKind::Handheld | MotionKind::Headworn) && r.chance(HEIGHT_SHARE) {
        let top = if family == Family::Outdoor {
            HEIGHT_MAX_OUTDOOR_M
        } else {
            HEIGHT_MAX_INDOOR_M.min(floor_to(height_room(s), 10.0))
        };
        let up = r.chance(0.5);
        if top >= HEIGHT_MIN_M {
            let h = pick(&mut r, (HEIGHT_MIN_M, top), 10.0);
            s.height_change_m = if up { h } else { -h };
        }
    }
}

/// Version 1's benchmark: train 4 seen families x 3 motions x 4 seeds (48), validation 4 x 3 x 1
/// (12), test 5 families (the held-out one included) x 3 motions x 2 unseen seeds (30).
pub fn benchmark() -> Vec<Entry> {
    SplitVersion::V1.benchmark()
}

/// The entries of one set of version 1.
pub fn entries(set: Set) -> Vec<Entry> {
    SplitVersion::V1.entries(set)
}
