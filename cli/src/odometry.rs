//! `milliego odometry`: the classical estimators over a session (Doppler radar-inertial odometry
//! or IMU dead reckoning), writing the body trajectory as TUM for `milliego eval`.

use clap::{Args, ValueEnum};
use milliego_odometry::offline::{run as run_offline, Estimator, OfflineConfig, TimeOffsetMode};
use milliego_odometry::runner::UNAIDED_AFTER_S;
use milliego_session::{write_tum, Session};
use serde_json::json;
use std::path::PathBuf;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum EstimatorArg {
    /// Radar ego-velocity fused with the IMU (error-state Kalman filter).
    Doppler,
    /// IMU dead reckoning (the weakest baseline).
    Imu,
}

#[derive(Debug, Args)]
pub struct OdometryArgs {
    /// Session directory (or bare captures).
    #[arg(long)]
    session: PathBuf,
    /// Estimator.
    #[arg(long, value_enum, default_value_t = EstimatorArg::Doppler)]
    estimator: EstimatorArg,
    /// Output trajectory (TUM; body in world, session host clock).
    #[arg(short, long)]
    out: PathBuf,
    /// Doppler noise of a static point besides quantisation, in m/s (default 0.05; the quantisation step is the .cfg's velocity resolution).
    #[arg(long)]
    doppler_sigma: Option<f32>,
    /// Doppler quantisation step in m/s (0: continuous). Default: the step the points' radial
    /// velocities show once they show one (reported as `doppler_step`), until then the .cfg's
    /// velocity resolution when the session has a .cfg, else continuous.
    #[arg(long)]
    doppler_step: Option<f32>,
    /// Near field in m: points closer than this with zero Doppler are skipped as leakage.
    /// Default: off until the points show leakage (near points at zero Doppler where the
    /// filter's motion says a static point could not read zero; reported as `near_field`), then
    /// 1.0. Stating it (0: off) turns that test off
    #[arg(long)]
    near_field: Option<f32>,
    /// Let radar updates correct the heading and the vertical gyro bias (off by default: body
    /// velocity cannot observe heading, and on tilted or yawed mounts those corrections made it
    /// worse than the gyro alone; see docs/odometry.md).
    #[arg(long)]
    radar_heading: bool,
    /// Ignore the barometer readings in the IMU stream (by default they aid the height).
    #[arg(long)]
    no_barometer: bool,
    /// Vertical velocity bound in m/s: at frames that cannot see vertical motion, "vertical
    /// velocity 0" with this deviation (default 0.5; 0 turns it off).
    #[arg(long)]
    vertical_bound: Option<f64>,
    /// Horizontal velocity bound in m/s: when the filter is less sure of a horizontal velocity
    /// component than this (the radar gave no velocity for long), "that component 0" with this
    /// deviation (default 1.0, walking pace; 0 turns it off; ground vehicles, --vehicle, never).
    #[arg(long)]
    horizontal_bound: Option<f64>,
    /// Walking-pace bound in m/s: when the filter is less sure of its horizontal speed than
    /// this (the radar gave no velocity for a while), "the speed is the one it held at its last
    /// radar update" with this deviation (default 0.25; 0 turns it off; ground vehicles,
    /// --vehicle, never).
    #[arg(long)]
    pace_bound: Option<f64>,
    /// Radar-to-IMU time offset: `auto` estimates it online where the session's radar times are
    /// late by an unknown amount (imported scans timed by their arrival in the bag), `off`
    /// never, or a number, the initial uncertainty in seconds to estimate it from (e.g. 0.05,
    /// for a driver that stamps scans when it publishes them).
    #[arg(long, default_value = "auto", value_parser = parse_time_offset)]
    time_offset: TimeOffsetMode,
    /// The IMU's noise preset for the filter: mti1 (Xsens MTi-1 series), mti600 (MTi-600
    /// series) or mems (BMI088/ICM class). Default: the one the session's IMU device names,
    /// else the MTi-1's noise with a gyro bias prior wide enough for any part (docs/odometry.md,
    /// "IMU noise", "Gyro bias prior").
    #[arg(long, value_name = "PRESET")]
    imu_noise: Option<milliego_odometry::rio::ImuNoise>,
    /// A known radar latency in seconds added to every radar frame's time (positive: frames
    /// were taken later than stamped).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    radar_time_shift: f64,
    /// The rig is a ground vehicle (car, wheeled robot): its body frame's lateral and vertical
    /// velocity are held at zero at each radar frame, within 0.01 m/s at standstill and 0.02 of
    /// the forward speed in motion (body frame: x forward, z up).
    #[arg(long)]
    vehicle: bool,
    /// How long a radar frame that gives no velocity alone (too few points, no consensus) is kept
    /// in seconds: its points, carried forward with the IMU's motion, join the next frames'
    /// (default 0: off; docs/odometry.md, "Known weaknesses": 0.15 helps this filter on the
    /// validation sets, not the fused estimators).
    #[arg(long)]
    stack_window: Option<f64>,
    /// How far back a radar point counts as seen again \[s\]: points a static reflector gave in
    /// the frames before weigh more in the ego-velocity consensus than points seen once (clutter,
    /// multipath). Default 0.125, chosen on the validation sets (docs/odometry.md,
    /// "Points seen again"); 0: off; keep it off a multiple of the frame period
    #[arg(long, value_name = "SECONDS")]
    persist_window: Option<f64>,
    /// Radar updates over which the filter adapts the scale of the radar velocity covariance
    /// (default 300; 0: off, the covariance as the ego-velocity stage states it; docs/odometry.md
    /// "Radar noise adaptation"). The JSON's `filter.radar_noise_scale` gives the scale it
    /// ended with.
    #[arg(long, value_name = "N")]
    radar_noise_window: Option<f64>,
    /// Correlation time of the rounding a coarse Doppler step leaves shared by a frame's points,
    /// kept as a filter state \[s\] (default 2; 0: off, that rounding taken as fresh noise each
    /// frame; docs/odometry.md "The rounding a frame's points share is a state").
    #[arg(long, value_name = "SECONDS")]
    radar_error_time: Option<f64>,
}

fn parse_time_offset(s: &str) -> std::result::Result<TimeOffsetMode, String> {
    match s {
        "auto" => Ok(TimeOffsetMode::Auto),
        "off" => Ok(TimeOffsetMode::Off),
        _ => match s.parse::<f64>() {
            Ok(v) if v.is_finite() && v > 0.0 => Ok(TimeOffsetMode::Estimate(v)),
            _ => Err(format!(
                "`{s}`: give auto, off, or the initial uncertainty in seconds (> 0)"
            )),
        },
    }
}

pub fn run(a: OdometryArgs) -> Result<()> {
    let session = Session::open(&a.session)?;
    let mut cfg = OfflineConfig {
        estimator: match a.estimator {
            EstimatorArg::Doppler => Estimator::Doppler,
            EstimatorArg::Imu => Estimator::ImuOnly,
        },
        ..OfflineConfig::default()
    };
    if let Some(s) = a.doppler_sigma {
        cfg.ego.sigma = s;
    }
    if let Some(s) = a.doppler_step {
        cfg.ego.doppler_step = s;
        cfg.ego.step_from_data = false;
        cfg.doppler_step_from_cfg = false;
    }
    cfg.rio.radar_heading = a.radar_heading;
    cfg.use_barometer = !a.no_barometer;
    if let Some(v) = a.vertical_bound {
        cfg.rio.vertical_velocity_std = if v > 0.0 { v } else { f64::INFINITY };
    }
    if let Some(v) = a.horizontal_bound {
        cfg.rio.horizontal_velocity_std = if v > 0.0 { v } else { f64::INFINITY };
    }
    if let Some(v) = a.pace_bound {
        cfg.rio.pace_std = if v > 0.0 { v } else { f64::INFINITY };
    }
    cfg.time_offset = a.time_offset;
    cfg.imu_noise = a.imu_noise;
    if a.vehicle {
        cfg = cfg.ground_vehicle();
    }
    cfg.radar_time_shift_s = a.radar_time_shift;
    if let Some(w) = a.persist_window {
        cfg.persist.window_s = w.max(0.0);
    }
    if let Some(n) = a.radar_noise_window {
        cfg.rio.radar_noise_window = n.max(0.0);
    }
    if let Some(t) = a.radar_error_time {
        cfg.rio = cfg.rio.with_radar_error_time(t);
    }
    if let Some(w) = a.stack_window {
        cfg.stack_window_s = w.max(0.0);
    }
    if let Some(m) = a.near_field {
        cfg.ego.near_field_m = m;
        cfg.ego.near_field_from_data = false;
    }
    let r = run_offline(&session, &cfg).map_err(|e| format!("{}: {e}", a.session.display()))?;
    write_tum(&a.out, &r.trajectory)?;
    eprintln!(
        "{}",
        json!({
            "session": a.session.display().to_string(), "estimator": format!("{:?}", a.estimator).to_lowercase(),
            "poses": r.trajectory.len(), "radar_frames": r.radar_frames, "imu_samples": r.imu_samples,
            "ego_velocity": {"ok": r.ego_ok, "degenerate": r.ego_degenerate, "too_few_points": r.ego_too_few, "no_consensus": r.ego_no_consensus, "stacked": r.ego_stacked},
            "points_seen_again": {"frames": r.persist.frames, "seen_again": r.persist.seen_again, "fresh": r.persist.fresh},
            "unaided": {"longest_s": r.unaided.length_s, "from_s": r.unaided.from_s, "poses_over_s": UNAIDED_AFTER_S, "poses": r.unaided.poses_unaided},
            "filter": {"updates": r.updates, "gated": r.gated, "rest_samples": r.rest_samples, "rest_updates": r.rest_updates, "rest_refuted": r.rest_refuted, "vertical_bounds": r.vertical_bounds, "horizontal_bounds": r.horizontal_bounds, "pace_bounds": r.pace_bounds, "nis_mean": r.nis_mean, "radar_noise_scale": r.radar_noise_scale},
            "barometer": if r.pressure_readings == 0 { json!("none in the session: height from radar and IMU only") } else if a.no_barometer { json!(format!("{} readings ignored (--no-barometer)", r.pressure_readings)) } else { json!({"readings": r.pressure_readings, "updates": r.baro_updates, "rejected": r.baro_rejected, "reanchors": r.baro_reanchors}) },
            "doppler_step": doppler_step_json(r.doppler_step, a.doppler_step.is_some()),
            "imu_noise": r.imu_noise,
            "near_field_points": r.near_field_points,
            "near_field": near_field_json(r.near_field, a.near_field.is_some()),
            "ground_vehicle": if a.vehicle { json!({"applied": r.nonholonomic.0, "gated": r.nonholonomic.1}) } else { json!("not asked (--vehicle)") },
            "radar_stream": {"frames_bad": r.radar.bad, "bytes_skipped": r.radar.bytes_skipped},
            "imu_stream": {"frames_bad": r.imu.bad, "bytes_skipped": r.imu.bytes_skipped, "not_samples": r.imu.not_samples, "pressure": r.imu.pressure},
            "clock_unsynced": r.clock_unsynced,
            "radar_time_offset": match &r.time_offset { Some((o, sd, why)) => json!({"estimate_s": o, "std_s": sd, "why": why}), None => json!("not estimated (radar stamps trusted)") },
            "radar_clock": r.radar_clock.map(|c| json!({"offset_s": c.offset, "rate": c.rate, "residual_rms_s": c.residual_rms})),
            "imu_clock": r.imu_clock.map(|c| json!({"offset_s": c.offset, "rate": c.rate, "residual_rms_s": c.residual_rms})),
            "out": a.out.display().to_string(),
        })
    );
    Ok(())
}

/// The near field's report: the range in use \[m\] and where it came from, with the leakage test's
/// counts when it was left to the data.
fn near_field_json(
    (range_m, learned): (f32, Option<(u32, u32, bool)>),
    stated: bool,
) -> serde_json::Value {
    let from = match learned {
        _ if stated => "--near-field",
        Some((_, _, true)) => "leakage seen in the points",
        Some(_) => "off: the points showed no leakage",
        None => "off",
    };
    json!({
        "used_m": range_m,
        "from": from,
        "tested_points": learned.map(|l| l.0),
        "tested_at_zero_doppler": learned.map(|l| l.1),
    })
}

/// The Doppler step's report: configured, seen in the data, and the one used [m/s].
fn doppler_step_json((configured, seen): (f32, Option<f32>), stated: bool) -> serde_json::Value {
    json!({
        "configured_mps": configured,
        "from": if stated { "--doppler-step" } else if configured > 0.0 { "the .cfg's velocity resolution" } else { "none (no .cfg): continuous" },
        "seen_in_data_mps": seen,
        "used_mps": seen.unwrap_or(configured),
    })
}
