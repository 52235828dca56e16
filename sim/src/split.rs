//! The benchmark split: which (family, motion, seed) scenarios train, validate and test a model.
//!
//! The held-out test set uses a world family never seen in training (`household`) and, for the
//! other families, seeds never used in training or validation. Because the world layout, the
//! trajectory, the clocks and all noise derive from the seed, an unseen seed means an unseen floor
//! plan and an unseen path. The table is documented in docs/simulator.md.

use crate::motion::MotionKind;
use crate::scenario::Scenario;
use crate::world::Family;
use std::fmt;
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

/// One benchmark session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Entry {
    /// Which subset.
    pub set: Set,
    /// World family.
    pub family: Family,
    /// Motion.
    pub motion: MotionKind,
    /// Seed (world, trajectory, clocks, noise).
    pub seed: u64,
    /// Length \[s\].
    pub duration_s: u32,
}

impl Entry {
    /// The scenario (default sensor rates) of this entry.
    pub fn scenario(&self) -> Scenario {
        let mut s = Scenario::new(self.family, self.motion, self.seed);
        s.duration_s = f64::from(self.duration_s);
        s
    }

    /// Directory name of the session: `SET/FAMILY-MOTION-SEED`.
    pub fn dir_name(&self) -> String {
        format!("{}/{}-{}-{}", self.set, self.family, self.motion, self.seed)
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
/// Moving kinds in the benchmark.
pub const MOTIONS: [MotionKind; 3] = [
    MotionKind::Robot,
    MotionKind::Handheld,
    MotionKind::Headworn,
];
/// Training seeds.
pub const TRAIN_SEEDS: std::ops::Range<u64> = 100..104;
/// Validation seeds.
pub const VAL_SEEDS: std::ops::Range<u64> = 200..201;
/// Test seeds.
pub const TEST_SEEDS: std::ops::Range<u64> = 300..302;
/// Session length in the benchmark \[s\].
pub const DURATION_S: u32 = 60;

/// The benchmark: train 4 seen families x 3 motions x 4 seeds (48), validation 4 x 3 x 1 (12),
/// test 5 families (the held-out one included) x 3 motions x 2 unseen seeds (30).
pub fn benchmark() -> Vec<Entry> {
    let mut out = Vec::new();
    let mut add = |set, families: &[Family], seeds: std::ops::Range<u64>| {
        for &family in families {
            for motion in MOTIONS {
                for seed in seeds.clone() {
                    out.push(Entry {
                        set,
                        family,
                        motion,
                        seed,
                        duration_s: DURATION_S,
                    });
                }
            }
        }
    };
    add(Set::Train, &SEEN_FAMILIES, TRAIN_SEEDS);
    add(Set::Val, &SEEN_FAMILIES, VAL_SEEDS);
    let mut test_families = SEEN_FAMILIES.to_vec();
    test_families.push(HELD_OUT_FAMILY);
    add(Set::Test, &test_families, TEST_SEEDS);
    out
}

/// The entries of one set.
pub fn entries(set: Set) -> Vec<Entry> {
    benchmark().into_iter().filter(|e| e.set == set).collect()
}
