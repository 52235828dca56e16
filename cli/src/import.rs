//! `milliego import`: ROS 1 bags, ROS 2 bags, MCAP files -> a session (docs/import.md).

use clap::Args;
use milliego_import::calib::Calibration;
use milliego_import::cloud::RadarAxes;
use milliego_import::{import, list, ImportOptions};
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Args)]
pub struct ImportArgs {
    /// Recordings: ROS 1 bags (.bag), ROS 2 bag directories, MCAP files; read in order as one.
    #[arg(required = true)]
    sources: Vec<PathBuf>,
    /// Output session directory (must not hold a session yet).
    #[arg(short, long, required_unless_present = "list")]
    out: Option<PathBuf>,
    /// Print the topics (type, messages, rate) and exit.
    #[arg(long)]
    list: bool,
    /// Radar topic (sensor_msgs/PointCloud2); found by type when not given.
    #[arg(long)]
    radar_topic: Option<String>,
    /// IMU topic (sensor_msgs/Imu).
    #[arg(long)]
    imu_topic: Option<String>,
    /// Trigger topic (std_msgs/Header): scan k is timed by trigger k.
    #[arg(long)]
    trigger_topic: Option<String>,
    /// Barometer topic (sensor_msgs/FluidPressure).
    #[arg(long)]
    baro_topic: Option<String>,
    /// Ground truth (PoseStamped, Odometry, TransformStamped or TFMessage).
    #[arg(long)]
    gt_topic: Option<String>,
    /// The body's child frame in TransformStamped / TFMessage ground truth.
    #[arg(long)]
    gt_child_frame: Option<String>,
    /// Calibration: rio-style YAML (l_b_r_*, q_b_r_*, radar_frame_ms) or TOML (docs/import.md).
    #[arg(long)]
    calib: Option<PathBuf>,
    /// The chirp configuration the radar ran (.cfg), kept with the session (Doppler resolution,
    /// frame period, exposure).
    #[arg(long)]
    radar_cfg: Option<PathBuf>,
    /// Axes of the scans' points: ros (x forward, y left; the default) or session (TI: x right,
    /// y boresight; what export-mcap writes).
    #[arg(long, value_parser = ["ros", "session"])]
    radar_axes: Option<String>,
    /// Name of the Doppler field when it is not velocity / doppler / v / radial_velocity / vel.
    #[arg(long)]
    doppler_field: Option<String>,
    /// Skip this much from the start, in s.
    #[arg(long, default_value_t = 0.0)]
    start: f64,
    /// Import this much, in s (default: all).
    #[arg(long)]
    duration: Option<f64>,
    /// The radar's part name for the session (e.g. IWR6843AOP); default: an export's own name,
    /// else "imported from TOPIC".
    #[arg(long, value_name = "NAME")]
    radar_device: Option<String>,
    /// The IMU's part name for the session (e.g. MTi-630, BMI088): picks the filter's IMU noise
    /// preset and gyro bias prior in every later run (docs/odometry.md, "IMU noise"); default: an
    /// export's own name, else "imported from TOPIC", which picks none.
    #[arg(long, value_name = "NAME")]
    imu_device: Option<String>,
}

pub fn run(a: ImportArgs) -> Result<()> {
    if a.list {
        println!(
            "{:<40} {:<34} {:>9} {:>9}",
            "topic", "type", "messages", "rate Hz"
        );
        for t in list(&a.sources)? {
            let rate = t.rate_hz().map_or("-".into(), |r| format!("{r:.1}"));
            println!(
                "{:<40} {:<34} {:>9} {:>9}",
                t.topic, t.msg_type, t.count, rate
            );
        }
        return Ok(());
    }
    let out = a.out.clone().ok_or("--out is required")?;
    let calib = a.calib.as_deref().map(Calibration::load).transpose()?;
    let radar_cfg = a
        .radar_cfg
        .as_ref()
        .map(|p| std::fs::read_to_string(p).map_err(|e| format!("radar .cfg {}: {e}", p.display())))
        .transpose()?;
    let opts = ImportOptions {
        radar_topic: a.radar_topic,
        imu_topic: a.imu_topic,
        trigger_topic: a.trigger_topic,
        baro_topic: a.baro_topic,
        gt_topic: a.gt_topic,
        gt_child_frame: a.gt_child_frame,
        calib,
        radar_axes: a.radar_axes.as_deref().map(|x| match x {
            "session" => RadarAxes::Session,
            _ => RadarAxes::Ros,
        }),
        doppler_field: a.doppler_field,
        radar_cfg,
        start_s: a.start,
        duration_s: a.duration,
        radar_device: a.radar_device,
        imu_device: a.imu_device,
        description: format!(
            "imported from {}",
            a.sources
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let r = import(&a.sources, &out, &opts)?;
    println!(
        "{:<12} {:<32} {:>9} {:>9} {:>9}  timing",
        "stream", "topic", "messages", "written", "dropped"
    );
    for s in &r.streams {
        let dropped: u64 = s.dropped.values().sum();
        println!(
            "{:<12} {:<32} {:>9} {:>9} {:>9}  {}",
            s.stream, s.topic, s.messages, s.written, dropped, s.timing
        );
        for (why, n) in &s.dropped {
            println!("{:<12}   dropped {n}: {why}", "");
        }
        for n in &s.notes {
            println!("{:<12}   {n}", "");
        }
    }
    println!("session: {}", r.session.display());
    Ok(())
}
