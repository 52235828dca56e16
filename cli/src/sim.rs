//! `milliego sim ...`: simulate radar-inertial sessions with ground truth, and the benchmark
//! split.
//!
//! ```text
//! milliego sim --family office --motion handheld --seed 7 --duration 30 -o DIR
//! milliego sim split [--split v1|v2]
//! milliego sim benchmark --set test [--split v1|v2] -o DIR
//! ```

use crate::output;
use clap::{Args, Subcommand};
use milliego_sim::imu::ImuGrade;
use milliego_sim::motion::MotionKind;
use milliego_sim::scenario::{self, Scenario, Summary};
use milliego_sim::split::{self, Set, SplitVersion};
use milliego_sim::world::Family;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::str::FromStr;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// `milliego sim`: one session from the options, or a subcommand.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct SimArgs {
    #[command(subcommand)]
    cmd: Option<SimCmd>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(Debug, Subcommand)]
enum SimCmd {
    /// Print the benchmark split: which (family, motion, seed) train, validate and test (v2: with
    /// each session's drawn settings).
    Split(SplitArgs),
    /// Write every session of one set of the benchmark under DIR/SET/FAMILY-MOTION-SEED (v2:
    /// DIR/v2/SET/FAMILY-MOTION-SEED).
    Benchmark(BenchArgs),
}

#[derive(Debug, Args)]
struct RunArgs {
    /// World family: corridor, office, atrium, store_room, household, outdoor.
    #[arg(long, default_value = "office", value_parser = parse::<Family>)]
    family: Family,
    /// Motion: robot, handheld, headworn, static, vehicle (outdoor only).
    #[arg(long, default_value = "handheld", value_parser = parse::<MotionKind>)]
    motion: MotionKind,
    /// Seed of the world, the trajectory, the clocks and all noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Length in seconds.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    duration: f64,
    /// Output session directory (must not hold a session yet).
    #[arg(short = 'o', long = "out")]
    out: Option<PathBuf>,
    /// Radar frame rate, 10-30 Hz.
    #[arg(long, default_value_t = 20.0)]
    radar_hz: f64,
    /// IMU output rate, 50-400 Hz.
    #[arg(long, default_value_t = 200.0)]
    imu_hz: f64,
    /// IMU UART rate [bit/s].
    #[arg(long, default_value_t = 921_600)]
    imu_baud: u32,
    /// Seconds at rest before the motion starts (it then ramps up over 1.5 s).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    rest_start: f64,
    /// Seconds at rest at the end (the motion ramps down over 1.5 s before).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    rest_end: f64,
    /// Radar origin in the body frame, X,Y,Z in m (x forward, y left, z up; each within ±2 m);
    /// default: the motion's own mount, a few cm ahead.
    #[arg(long, value_parser = parse_xyz, allow_negative_numbers = true)]
    radar_lever: Option<[f64; 3]>,
    /// Radar boresight yawed about body z in degrees, ±180 (positive: left).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    radar_yaw: f64,
    /// Radar boresight tilted up about the radar's x axis in degrees, ±60.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    radar_tilt: f64,
    /// Coarse Doppler: radial velocities in multiples of this step [m/s] (0: off; 0.01-2).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    doppler_step: f64,
    /// Near-field leakage: share of each frame's points that are spurious returns within 1 m at
    /// zero Doppler (0: off; up to 0.5).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    near_field: f64,
    /// IMU noise preset: mti1 (MTi-1 series), mti600 (MTi-600 series), mems (BMI088/ICM class).
    #[arg(long, default_value = "mti1", value_parser = parse::<ImuGrade>)]
    imu_grade: ImuGrade,
    /// Share of IMU messages dropped in bursts, counter and sample time jumping (0: off; up to 0.8).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    imu_gaps: f64,
    /// Barometer rate in Hz: BaroPressure messages in the IMU stream (0: off; 1-100, e.g. 50).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    baro_hz: f64,
    /// Height change over a handheld or headworn walk in m (negative: descend; 0: flat; ±10 m,
    /// peak vertical speed at most 0.5 m/s).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    height_change: f64,
}

#[derive(Debug, Args)]
struct SplitArgs {
    /// Split version: v1 (benign rigs, indoor) or v2 (outdoor too, rigs drawn per session).
    #[arg(long, default_value = "v1", value_parser = parse::<SplitVersion>)]
    split: SplitVersion,
}

#[derive(Debug, Args)]
struct BenchArgs {
    /// Which set: train, val or test.
    #[arg(long, value_parser = parse::<Set>)]
    set: Set,
    /// Split version: v1 or v2.
    #[arg(long, default_value = "v1", value_parser = parse::<SplitVersion>)]
    split: SplitVersion,
    /// Root directory of the benchmark.
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
}

fn parse<T: FromStr<Err = String>>(s: &str) -> std::result::Result<T, String> {
    s.parse()
}

fn parse_xyz(s: &str) -> std::result::Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e} (expected X,Y,Z in metres)"))?;
    <[f64; 3]>::try_from(v).map_err(|_| format!("{s:?}: expected three numbers X,Y,Z"))
}

/// Runs `milliego sim`.
pub fn run(args: SimArgs) -> Result<()> {
    match args.cmd {
        Some(SimCmd::Split(a)) => print_split(a.split),
        Some(SimCmd::Benchmark(b)) => benchmark(&b),
        None => {
            let r = args.run;
            let out = r
                .out
                .ok_or("milliego sim needs an output directory: -o DIR")?;
            let mut sc = Scenario::new(r.family, r.motion, r.seed);
            sc.duration_s = r.duration;
            sc.radar_hz = r.radar_hz;
            sc.imu_hz = r.imu_hz;
            sc.imu_baud = r.imu_baud;
            sc.rest_start_s = r.rest_start;
            sc.rest_end_s = r.rest_end;
            sc.radar_lever_m = r.radar_lever;
            sc.radar_yaw_deg = r.radar_yaw;
            sc.radar_tilt_deg = r.radar_tilt;
            sc.doppler_step_mps = r.doppler_step;
            sc.near_field_share = r.near_field;
            sc.imu_spec = r.imu_grade.spec();
            sc.imu_gap_share = r.imu_gaps;
            sc.baro_hz = r.baro_hz;
            sc.height_change_m = r.height_change;
            let s = simulate(&sc, &out, "")?;
            println!("{}", summary_line(&out, &s));
            Ok(())
        }
    }
}

fn simulate(sc: &Scenario, out: &Path, tag: &str) -> Result<Summary> {
    sc.validate()?;
    let mut last = -1;
    let mut err = std::io::stderr();
    let s = scenario::run(sc, out, &mut |f| {
        let pct = (f * 100.0) as i32;
        if pct / 5 != last / 5 {
            last = pct;
            let _ = write!(err, "\r{tag}simulating {}: {pct:3} %", out.display());
            let _ = err.flush();
        }
    });
    eprintln!();
    Ok(s?)
}

fn summary_line(out: &Path, s: &Summary) -> String {
    format!(
        "{}: {} radar frames, {:.1} points per frame ({}..{}), outlier share {:.3}, {} IMU samples, {} + {} B",
        out.display(),
        s.frames,
        s.points_mean(),
        s.points_min,
        s.points_max,
        s.outlier_share(),
        s.imu_samples,
        s.radar_bytes,
        s.imu_bytes
    )
}

fn print_split(version: SplitVersion) -> Result<()> {
    let mut out = output::stdout();
    let mut lines = match version {
        // Version 1: the listing it always had.
        SplitVersion::V1 => vec![
            "# milliEgo simulator benchmark split (docs/simulator.md)".to_string(),
            format!(
                "# held-out family: {}; train seeds {:?}, val seeds {:?}, test seeds {:?}; {} s each",
                split::HELD_OUT_FAMILY,
                split::TRAIN_SEEDS,
                split::VAL_SEEDS,
                split::TEST_SEEDS,
                split::DURATION_S
            ),
            "set,family,motion,seed,duration_s".to_string(),
        ],
        v => vec![
            format!("# milliEgo simulator benchmark split {v} (docs/simulator.md, \"Benchmark split versions\")"),
            format!(
                "# held-out family: {}; train seeds {:?}, val seeds {:?}, test seeds {:?}; {} s each; \
                 settings: the scenario's description",
                split::HELD_OUT_FAMILY,
                v.seeds(Set::Train),
                v.seeds(Set::Val),
                v.seeds(Set::Test),
                split::DURATION_S
            ),
            "set,family,motion,seed,duration_s,dir,settings".to_string(),
        ],
    };
    lines.extend(version.benchmark().iter().map(|e| {
        let row = format!(
            "{},{},{},{},{}",
            e.set, e.family, e.motion, e.seed, e.duration_s
        );
        match version {
            SplitVersion::V1 => row,
            _ => format!(
                "{row},{},\"{}\"",
                e.dir_name(),
                e.scenario().description().replace('"', "\"\"")
            ),
        }
    }));
    for l in &lines {
        if !output::line(&mut out, l)? {
            return Ok(());
        }
    }
    match out.flush() {
        Err(e) if output::is_broken_pipe(&e) => Ok(()),
        r => Ok(r?),
    }
}

fn benchmark(b: &BenchArgs) -> Result<()> {
    let entries = b.split.entries(b.set);
    let n = entries.len();
    for (i, e) in entries.iter().enumerate() {
        let out = b.out.join(e.dir_name());
        let s = simulate(&e.scenario(), &out, &format!("[{}/{n}] ", i + 1))?;
        println!("{}", summary_line(&out, &s));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn parse(args: &[&str]) -> std::result::Result<SimArgs, clap::Error> {
        let mut argv = vec!["milliego", "sim"];
        argv.extend_from_slice(args);
        match crate::Cli::try_parse_from(argv)?.command {
            crate::Command::Sim(a) => Ok(a),
            other => panic!("parsed as {other:?}"),
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        assert!(parse(&["--family", "garage", "-o", "x"]).is_err());
        assert!(parse(&["--motion", "flying", "-o", "x"]).is_err());
        assert!(parse(&["benchmark", "--set", "dev", "-o", "x"]).is_err());
        assert!(parse(&["benchmark", "--set", "val", "--split", "v3", "-o", "x"]).is_err());
        assert!(parse(&["split", "--split", "2"]).is_err());
        match parse(&["benchmark", "--set", "val", "--split", "v2", "-o", "x"])
            .unwrap()
            .cmd
        {
            Some(SimCmd::Benchmark(b)) => {
                assert_eq!((b.set, b.split), (Set::Val, SplitVersion::V2))
            }
            other => panic!("{other:?}"),
        }
        match parse(&["split"]).unwrap().cmd {
            Some(SimCmd::Split(a)) => assert_eq!(a.split, SplitVersion::V1),
            other => panic!("{other:?}"),
        }
        assert!(parse(&["--radar-lever", "1,2", "-o", "x"]).is_err());
        assert!(parse(&["--imu-grade", "tactical", "-o", "x"]).is_err());
        let a = parse(&["--imu-grade", "mems", "-o", "x"]).unwrap();
        assert_eq!(a.run.imu_grade, ImuGrade::Mems);
        assert!(parse(&["--radar-lever", "1,a,2", "-o", "x"]).is_err());
        let a = parse(&["--radar-lever", "1.1,0,-0.2", "-o", "x"]).unwrap();
        assert_eq!(a.run.radar_lever, Some([1.1, 0.0, -0.2]));
        let e = run(parse(&[]).unwrap()).unwrap_err().to_string();
        assert!(e.contains("-o DIR"), "{e}");
        let dir = std::env::temp_dir().join(format!("milliego-sim-cli-{}", std::process::id()));
        let d = dir.to_str().unwrap();
        for (args, what) in [
            (vec!["--radar-hz", "50", "-o", d], "radar frame rate 50 Hz"),
            (vec!["--duration", "-3", "-o", d], "duration -3 s"),
            (
                vec!["--imu-hz", "400", "--imu-baud", "115200", "-o", d],
                "115200 baud",
            ),
            (vec!["--radar-lever", "3,0,0", "-o", d], "radar lever arm"),
            (vec!["--radar-yaw", "-190", "-o", d], "radar yaw"),
            (vec!["--radar-tilt", "61", "-o", d], "radar tilt"),
            (vec!["--doppler-step", "3", "-o", d], "Doppler step"),
            (vec!["--near-field", "0.7", "-o", d], "near-field share"),
            (vec!["--imu-gaps", "0.9", "-o", d], "IMU gap share"),
            (vec!["--baro-hz", "500", "-o", d], "barometer rate"),
            (
                vec!["--height-change", "-12", "-o", d],
                "height change -12 m",
            ),
            (
                vec!["--motion", "vehicle", "-o", d],
                "vehicle motion needs the outdoor family",
            ),
            (vec!["--imu-hz", "20", "-o", d], "50-400 Hz"),
        ] {
            let e = run(parse(&args).unwrap()).unwrap_err().to_string();
            assert!(e.contains(what), "{args:?}: {e}");
        }
        assert!(!dir.exists(), "a refused scenario wrote {d}");
    }

    #[test]
    fn simulates_a_session_and_refuses_to_overwrite_it() {
        let dir = std::env::temp_dir().join(format!("milliego-sim-cli-run-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let d = dir.to_str().unwrap();
        let args = [
            "--family",
            "corridor",
            "--motion",
            "robot",
            "--seed",
            "3",
            "--duration",
            "2",
            "-o",
            d,
        ];
        run(parse(&args).unwrap()).unwrap();
        for f in [
            "radar.bin",
            "radar.idx",
            "radar.cfg",
            "imu.bin",
            "imu.idx",
            "groundtruth.tum",
        ] {
            assert!(dir.join(f).is_file(), "{f} missing");
        }
        let meta = std::fs::read_to_string(dir.join("session.toml")).unwrap();
        assert!(
            meta.contains("corridor family, robot motion, seed 3"),
            "{meta}"
        );
        let e = run(parse(&args).unwrap()).unwrap_err().to_string();
        assert!(e.contains("already exists"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
        assert!(summary_line(&dir, &Summary::default()).contains("0 radar frames"));
    }
}
