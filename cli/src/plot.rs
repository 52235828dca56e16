//! `milliego plot`: figures without leaving the terminal: trajectory top view coloured by error,
//! per-axis error over time and the ATE CDF of one or more estimates; one radar frame by Doppler.

use crate::eval::AlignArg;
use clap::{Args, Subcommand, ValueEnum};
use milliego_eval::{Align, Stats, Trajectory};
use milliego_plot::{
    ate_cdf, error_over_time, radar_frame, trajectory_top_view, Matched, RadarPoint, DEFAULT_SIZE,
};
use milliego_session::streams::radar_frames;
use milliego_session::Session;
use std::path::{Path, PathBuf};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Subcommand)]
pub enum PlotCmd {
    /// Estimates against ground truth: DIR/trajectory.png (top view coloured by ATE),
    /// DIR/errors.png (x, y, z error over time), DIR/ate_cdf.png. With several estimates:
    /// trajectory_STEM.png and errors_STEM.png per estimate, one ate_cdf.png with all.
    Trajectory(TrajectoryArgs),
    /// One radar frame of a session or capture: points coloured by Doppler velocity.
    Radar(RadarArgs),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// PNG image.
    Png,
    /// SVG drawing.
    Svg,
}

#[derive(Debug, Args)]
pub struct TrajectoryArgs {
    /// Estimated trajectory (TUM); repeat for several, each labelled by its file stem.
    #[arg(long, required = true)]
    est: Vec<PathBuf>,
    /// Ground truth (TUM).
    #[arg(long)]
    gt: PathBuf,
    /// Alignment of each estimate onto the ground truth (as `milliego eval`).
    #[arg(long, value_enum, default_value_t = AlignArg::Se3)]
    align: AlignArg,
    /// Largest time difference for associating poses, in seconds.
    #[arg(long, default_value_t = 0.01)]
    max_diff: f64,
    /// Output directory (created if missing).
    #[arg(short, long)]
    out: PathBuf,
    /// Image format.
    #[arg(long, value_enum, default_value_t = FormatArg::Png)]
    format: FormatArg,
}

#[derive(Debug, Args)]
pub struct RadarArgs {
    /// Session directory or a raw radar capture (.dat, .bin).
    input: PathBuf,
    /// Frame counter of the frame to draw (default: the frame with the most points).
    #[arg(long)]
    frame: Option<u32>,
    /// Output file: .png or .svg.
    #[arg(short, long)]
    out: PathBuf,
}

pub fn run(cmd: PlotCmd) -> Result<()> {
    match cmd {
        PlotCmd::Trajectory(a) => trajectory(a),
        PlotCmd::Radar(a) => radar(a),
    }
}

fn load(p: &Path) -> Result<Trajectory> {
    let t = Trajectory::from_tum(&milliego_session::read_tum(p)?);
    if t.is_empty() {
        return Err(format!("{}: no poses", p.display()).into());
    }
    Ok(t)
}

fn label(p: &Path) -> String {
    p.file_stem()
        .map_or_else(|| p.display().to_string(), |s| s.to_string_lossy().into())
}

fn trajectory(a: TrajectoryArgs) -> Result<()> {
    let how: Align = a.align.into();
    let ext = match a.format {
        FormatArg::Png => "png",
        FormatArg::Svg => "svg",
    };
    let gt = load(&a.gt)?;
    let mut runs: Vec<(String, Matched)> = Vec::new();
    for p in &a.est {
        let name = label(p);
        if runs.iter().any(|(n, _)| *n == name) {
            return Err(format!(
                "{}: a second estimate labelled {name:?} (labels are file stems; rename one)",
                p.display()
            )
            .into());
        }
        let m = Matched::new(&gt, &load(p)?, how, a.max_diff)
            .map_err(|e| format!("{} vs {}: {e}", p.display(), a.gt.display()))?;
        runs.push((name, m));
    }
    let single = runs.len() == 1;
    let file = |kind: &str, name: &str| {
        if single {
            a.out.join(format!("{kind}.{ext}"))
        } else {
            a.out.join(format!("{kind}_{name}.{ext}"))
        }
    };
    for (name, m) in &runs {
        let s = Stats::of(&m.errors);
        println!(
            "{name}: {} matched poses, ATE rmse {:.4} m, max {:.4} m",
            s.count, s.rmse, s.max
        );
        let top = file("trajectory", name);
        trajectory_top_view(&m.gt, &m.est, &m.errors, name, &top, DEFAULT_SIZE)?;
        println!("wrote {}", top.display());
        let err = file("errors", name);
        error_over_time(
            &m.gt,
            &m.est,
            name,
            &err,
            (DEFAULT_SIZE.0, DEFAULT_SIZE.1 * 3 / 4),
        )?;
        println!("wrote {}", err.display());
    }
    let sets: Vec<(&str, &[f64])> = runs
        .iter()
        .map(|(n, m)| (n.as_str(), m.errors.as_slice()))
        .collect();
    let cdf = a.out.join(format!("ate_cdf.{ext}"));
    ate_cdf(&sets, &cdf, (DEFAULT_SIZE.0, DEFAULT_SIZE.1 * 3 / 4))?;
    println!("wrote {}", cdf.display());
    Ok(())
}

fn radar(a: RadarArgs) -> Result<()> {
    let at = |e: &dyn std::fmt::Display| format!("{}: {e}", a.input.display());
    let session = Session::open(&a.input).map_err(|e| at(&e))?;
    let (frames, _) = radar_frames(&session).map_err(|e| at(&e))?;
    let frame = match a.frame {
        Some(n) => frames.iter().find(|f| f.frame_number == n).ok_or_else(|| {
            let range = match (frames.first(), frames.last()) {
                (Some(f), Some(l)) => format!("frames {}..={}", f.frame_number, l.frame_number),
                _ => "no frames".into(),
            };
            at(&format!("no radar frame numbered {n} ({range})"))
        })?,
        // The first of the fullest frames.
        None => frames
            .iter()
            .rev()
            .max_by_key(|f| f.cloud.points.len())
            .ok_or_else(|| at(&"no radar frames"))?,
    };
    let all = frame.cloud.points.len();
    // A corrupt float in a frame must not cost the whole figure: such points are counted instead.
    let points: Vec<RadarPoint> = frame
        .cloud
        .points
        .iter()
        .filter(|p| p.x.is_finite() && p.y.is_finite())
        .map(|p| RadarPoint {
            x: f64::from(p.x),
            y: f64::from(p.y),
            velocity: if frame.cloud.velocity_known && p.velocity.is_finite() {
                f64::from(p.velocity)
            } else {
                0.0
            },
        })
        .collect();
    let mut title = format!(
        "{}: frame {}, {} points",
        label(&a.input),
        frame.frame_number,
        points.len()
    );
    if points.len() < all {
        title.push_str(&format!(" ({} non-finite dropped)", all - points.len()));
    }
    if !frame.cloud.velocity_known {
        title.push_str(" (Doppler unknown: no .cfg)");
    }
    // About 2:1 like the half-disc of range rings, so little of the figure is empty.
    radar_frame(&points, &title, &a.out, (1200, 680))?;
    println!("wrote {} ({title})", a.out.display());
    Ok(())
}
