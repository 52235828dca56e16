//! Benchmark split versions: version 1 exactly as before, version 2 deterministic, valid,
//! disjoint, and with the documented shares of each failure-mode setting.

use milliego_sim::imu::ImuGrade;
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::Scenario;
use milliego_sim::split::{self, v2, Entry, Set, SplitVersion};
use milliego_sim::world::{Family, World};
use std::collections::HashSet;

/// Version 1 as the split was written before versions existed.
fn v1_as_before() -> Vec<(Set, Family, MotionKind, u64)> {
    let seen = [
        Family::Corridor,
        Family::Office,
        Family::Atrium,
        Family::StoreRoom,
    ];
    let motions = [
        MotionKind::Robot,
        MotionKind::Handheld,
        MotionKind::Headworn,
    ];
    let mut out = Vec::new();
    let mut add = |set, families: &[Family], seeds: std::ops::Range<u64>| {
        for &f in families {
            for m in motions {
                for s in seeds.clone() {
                    out.push((set, f, m, s));
                }
            }
        }
    };
    add(Set::Train, &seen, 100..104);
    add(Set::Val, &seen, 200..201);
    let mut test = seen.to_vec();
    test.push(Family::Household);
    add(Set::Test, &test, 300..302);
    out
}

#[test]
fn v1_is_unchanged() {
    let before = v1_as_before();
    let v1 = SplitVersion::V1.benchmark();
    assert_eq!(v1.len(), 90);
    assert_eq!(v1, split::benchmark());
    assert_eq!(SplitVersion::default(), SplitVersion::V1);
    for (e, &(set, family, motion, seed)) in v1.iter().zip(&before) {
        assert_eq!(
            (e.set, e.family, e.motion, e.seed),
            (set, family, motion, seed)
        );
        assert_eq!(e.version, SplitVersion::V1);
        assert_eq!(e.duration_s, 60);
        let mut s = Scenario::new(family, motion, seed);
        s.duration_s = 60.0;
        assert_eq!(e.scenario(), s, "{e:?}");
        assert_eq!(e.dir_name(), format!("{set}/{family}-{motion}-{seed}"));
        assert_eq!(
            e.work_dir(std::path::Path::new("/w")),
            std::path::Path::new("/w")
                .join(set.name())
                .join(e.dir_name())
        );
    }
    for set in Set::ALL {
        assert_eq!(split::entries(set), SplitVersion::V1.entries(set));
    }
}

#[test]
fn v2_is_deterministic_valid_and_disjoint() {
    let a = SplitVersion::V2.benchmark();
    let b = SplitVersion::V2.benchmark();
    assert_eq!(a, b);
    let sa: Vec<Scenario> = a.iter().map(Entry::scenario).collect();
    let sb: Vec<Scenario> = b.iter().map(Entry::scenario).collect();
    assert_eq!(sa, sb);
    let counts: Vec<usize> = Set::ALL
        .iter()
        .map(|&s| SplitVersion::V2.entries(s).len())
        .collect();
    assert_eq!(counts, [56, 42, 51]);

    // No (family, motion, seed) in two sets, no seed shared by two sets or with version 1.
    let keys: HashSet<_> = a.iter().map(|e| (e.family, e.motion, e.seed)).collect();
    assert_eq!(keys.len(), a.len(), "a scenario appears twice");
    let seeds =
        |v: SplitVersion, set| -> HashSet<u64> { v.entries(set).iter().map(|e| e.seed).collect() };
    let v1_seeds: HashSet<u64> = split::benchmark().iter().map(|e| e.seed).collect();
    for (i, &x) in Set::ALL.iter().enumerate() {
        assert!(seeds(SplitVersion::V2, x).is_disjoint(&v1_seeds));
        for &y in &Set::ALL[i + 1..] {
            assert!(seeds(SplitVersion::V2, x).is_disjoint(&seeds(SplitVersion::V2, y)));
        }
    }
    // Household only in test; outdoor (handheld and vehicle) in every set; vehicles outdoors.
    for set in Set::ALL {
        let e = SplitVersion::V2.entries(set);
        assert_eq!(
            e.iter().any(|e| e.family == Family::Household),
            set == Set::Test
        );
        for m in [MotionKind::Handheld, MotionKind::Vehicle] {
            assert!(e
                .iter()
                .any(|e| e.family == Family::Outdoor && e.motion == m));
        }
    }
    let dirs: HashSet<String> = a.iter().map(Entry::dir_name).collect();
    assert_eq!(dirs.len(), a.len());
    for e in &a {
        assert!(e.dir_name().starts_with(&format!("v2/{}/", e.set)), "{e:?}");
        assert_eq!(
            e.work_dir(std::path::Path::new("/w")),
            std::path::Path::new("/w").join(e.dir_name())
        );
    }

    // Every scenario validates and keeps within the ranges the split documents.
    for (e, s) in a.iter().zip(&sa) {
        s.validate().unwrap_or_else(|err| panic!("{e:?}: {err}"));
        check_ranges(s);
    }
}

/// The draws stay within the documented ranges, the ceiling and the motion rules.
fn check_ranges(s: &Scenario) {
    let within = |x: f64, r: (f64, f64)| x >= r.0 && x <= r.1;
    let what = s.description();
    assert_eq!(s.duration_s, 60.0);
    assert!(
        s.rest_start_s == 0.0 || within(s.rest_start_s, v2::REST_START_S),
        "{what}"
    );
    assert!(
        s.rest_end_s == 0.0 || within(s.rest_end_s, v2::REST_END_S),
        "{what}"
    );
    assert!(s.imu_hz == 200.0 || s.imu_hz == v2::IMU_LOW_HZ, "{what}");
    assert!(ImuGrade::of(&s.imu_spec).is_some(), "{what}");
    assert!(
        s.imu_gap_share == 0.0 || within(s.imu_gap_share, v2::IMU_GAPS),
        "{what}"
    );
    assert!(
        s.near_field_share == 0.0 || within(s.near_field_share, v2::NEAR_FIELD),
        "{what}"
    );
    assert!(
        s.doppler_step_mps == 0.0 || within(s.doppler_step_mps, v2::DOPPLER_STEP_MPS),
        "{what}"
    );
    assert!(s.baro_hz == 0.0 || s.baro_hz == v2::BARO_HZ, "{what}");
    assert_eq!(s.radar_hz, 20.0);
    if let Some(t) = s.radar_lever_m {
        if t != v2::MOUNT_LARGE_LEVER_M {
            for (x, r) in t.iter().zip(v2::MOUNT_LEVER_M) {
                assert!(within(*x, r), "{what}");
            }
            assert!(s.radar_yaw_deg.abs() <= v2::MOUNT_ANGLE_DEG, "{what}");
            assert!(s.radar_tilt_deg.abs() <= v2::MOUNT_ANGLE_DEG, "{what}");
        } else {
            assert_eq!(s.radar_yaw_deg.abs(), v2::MOUNT_LARGE_YAW_DEG, "{what}");
            assert_eq!(s.radar_tilt_deg, v2::MOUNT_LARGE_TILT_DEG, "{what}");
        }
    } else {
        assert_eq!((s.radar_yaw_deg, s.radar_tilt_deg), (0.0, 0.0), "{what}");
    }
    if s.motion == MotionKind::Vehicle {
        assert_eq!(s.family, Family::Outdoor);
    }
    let h = s.height_change_m.abs();
    if h != 0.0 {
        assert!(matches!(
            s.motion,
            MotionKind::Handheld | MotionKind::Headworn
        ));
        assert!(h >= v2::HEIGHT_MIN_M, "{what}");
        if s.family == Family::Outdoor {
            assert!(h <= v2::HEIGHT_MAX_OUTDOOR_M, "{what}");
        } else {
            assert!(h <= v2::HEIGHT_MAX_INDOOR_M, "{what}");
            // The scenario's own ceiling rule (base height + |h| + 0.2 m below the ceiling),
            // with the highest base height of the motion and the radar's lever arm on top.
            let top = v2::walker_top_m(s.motion == MotionKind::Headworn)
                + h
                + 0.2
                + s.radar_lever_m.map_or(0.0, |t| t[2].max(0.0));
            let ceiling = World::generate(s.family, s.seed).height;
            assert!(top < ceiling, "{what}: {top} m under a {ceiling} m ceiling");
        }
    }
}

/// Shares of the settings over `entries`: (rest start, rest end, mti600, mems, 100 Hz, gaps,
/// moderate mount, large mount, near field, coarse Doppler, barometer, height change among
/// walkers).
fn shares(entries: &[Entry]) -> [f64; 12] {
    let mut c = [0usize; 12];
    let mut walkers = 0;
    for e in entries {
        let s = e.scenario();
        check_ranges(&s);
        let large = s.radar_lever_m == Some(v2::MOUNT_LARGE_LEVER_M);
        let flags = [
            s.rest_start_s > 0.0,
            s.rest_end_s > 0.0,
            ImuGrade::of(&s.imu_spec) == Some(ImuGrade::Mti600),
            ImuGrade::of(&s.imu_spec) == Some(ImuGrade::Mems),
            s.imu_hz == v2::IMU_LOW_HZ,
            s.imu_gap_share > 0.0,
            s.radar_lever_m.is_some() && !large,
            large,
            s.near_field_share > 0.0,
            s.doppler_step_mps > 0.0,
            s.baro_hz > 0.0,
            false,
        ];
        for (k, f) in flags.iter().enumerate() {
            c[k] += usize::from(*f);
        }
        if matches!(e.motion, MotionKind::Handheld | MotionKind::Headworn) {
            walkers += 1;
            c[11] += usize::from(s.height_change_m != 0.0);
        }
    }
    let n = entries.len() as f64;
    let mut out = c.map(|x| x as f64 / n);
    out[11] = c[11] as f64 / f64::from(walkers.max(1));
    out
}

#[test]
fn v2_shares_are_as_documented() {
    let names = [
        "rest start",
        "rest end",
        "mti600",
        "mems",
        "100 Hz",
        "gaps",
        "moderate mount",
        "large mount",
        "near field",
        "coarse Doppler",
        "barometer",
        "height change (walkers)",
    ];
    // Expected over version 2's mix of motions: the large mount is more common on vehicles;
    // indoors the ceiling leaves no room for a height change in some worlds.
    let all = SplitVersion::V2.benchmark();
    let n = all.len() as f64;
    let vehicles = all
        .iter()
        .filter(|e| e.motion == MotionKind::Vehicle)
        .count() as f64;
    let large =
        (vehicles * v2::MOUNT_LARGE_VEHICLE_SHARE + (n - vehicles) * v2::MOUNT_LARGE_SHARE) / n;
    let expected = [
        v2::REST_START_SHARE,
        v2::REST_END_SHARE,
        v2::IMU_MTI600_SHARE,
        v2::IMU_MEMS_SHARE,
        v2::IMU_LOW_RATE_SHARE,
        v2::IMU_GAPS_SHARE,
        v2::MOUNT_MODERATE_SHARE,
        large,
        v2::NEAR_FIELD_SHARE,
        v2::DOPPLER_SHARE,
        v2::BARO_SHARE,
        v2::HEIGHT_SHARE,
    ];
    // The benchmark itself (149 sessions): roughly (binomial: 3 sigma is at most 0.12).
    let got = shares(&all);
    for i in 0..12 {
        println!(
            "v2 benchmark: {:<24} {:.3} (documented {:.3})",
            names[i], got[i], expected[i]
        );
        let tol = if i == 11 { 0.2 } else { 0.12 };
        assert!(
            (got[i] - expected[i]).abs() <= tol,
            "{}: {:.3} vs {:.3}",
            names[i],
            got[i],
            expected[i]
        );
    }
    // Many more seeds of the same (family, motion) mix: close (3 sigma at most 0.025); the
    // height change less the indoor worlds without room for one.
    let many: Vec<Entry> = SplitVersion::V2
        .pairs(Set::Test)
        .into_iter()
        .flat_map(|(family, motion)| {
            (10_000..10_200).map(move |seed| Entry {
                version: SplitVersion::V2,
                set: Set::Test,
                family,
                motion,
                seed,
                duration_s: split::DURATION_S,
            })
        })
        .collect();
    let got = shares(&many);
    for i in 0..11 {
        let e = if i == 7 {
            // Test mix: 1 vehicle pair of 17.
            (v2::MOUNT_LARGE_VEHICLE_SHARE + 16.0 * v2::MOUNT_LARGE_SHARE) / 17.0
        } else {
            expected[i]
        };
        println!(
            "v2, {} sessions: {:<24} {:.3} (documented {e:.3})",
            many.len(),
            names[i],
            got[i],
        );
        assert!(
            (got[i] - e).abs() <= 0.025,
            "{}: {:.3} vs {e:.3}",
            names[i],
            got[i]
        );
    }
    println!("height change among walkers: {:.3}", got[11]);
    assert!(got[11] > 0.5 * v2::HEIGHT_SHARE && got[11] <= v2::HEIGHT_SHARE + 0.03);
}
