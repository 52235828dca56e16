//! Ego-velocity against ground truth on a simulated session: how good is each frame's velocity,
//! and at which time offset does it agree best with the truth?
//!
//! `cargo run --release -p milliego-odometry --example ego_check -- SESSION_DIR`

use milliego_odometry::ego_velocity::{Config, Detection, EgoVelocityEstimator, Status};
use milliego_session::streams::{radar_frames, ClockFit};
use milliego_session::Session;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .ok_or("usage: ego_check SESSION_DIR")?;
    let s = Session::open(&dir)?;
    let gt = s.groundtruth()?.ok_or("no ground truth")?;
    let (frames, _) = radar_frames(&s)?;
    let baud = s.meta.radar.as_ref().map_or(921_600, |r| r.baud);
    let fit = ClockFit::fit(
        &frames
            .iter()
            .filter_map(|f| {
                Some((
                    f.sensor_s?,
                    f.host_s? - f.bytes as f64 * 10.0 / f64::from(baud),
                ))
            })
            .collect::<Vec<_>>(),
    )
    .ok_or("no clock fit")?;
    let e = s.meta.extrinsics.radar;
    let q_br = UnitQuaternion::from_quaternion(Quaternion::new(
        e.rotation_wxyz[0],
        e.rotation_wxyz[1],
        e.rotation_wxyz[2],
        e.rotation_wxyz[3],
    ));
    let t_br = Vector3::from(e.translation_m);
    // Radar origin position and orientation from ground truth at time t (linear interpolation).
    let pose = |t: f64| -> Option<(Vector3<f64>, UnitQuaternion<f64>)> {
        let i = gt.partition_point(|p| p.t <= t);
        if i == 0 || i >= gt.len() {
            return None;
        }
        let (a, b) = (&gt[i - 1], &gt[i]);
        let w = (t - a.t) / (b.t - a.t);
        let qa = UnitQuaternion::from_quaternion(Quaternion::new(a.q[3], a.q[0], a.q[1], a.q[2]));
        let qb = UnitQuaternion::from_quaternion(Quaternion::new(b.q[3], b.q[0], b.q[1], b.q[2]));
        let q = qa.slerp(&qb, w);
        let p = Vector3::from(a.p) * (1.0 - w) + Vector3::from(b.p) * w;
        Some((p + q * t_br, q * q_br))
    };
    let radar_v = |t: f64| -> Option<Vector3<f64>> {
        let h = 0.002;
        let (p0, _) = pose(t - h)?;
        let (p1, _) = pose(t + h)?;
        let (_, q) = pose(t)?;
        Some(q.inverse() * ((p1 - p0) / (2.0 * h)))
    };
    let mut est = EgoVelocityEstimator::new(Config {
        sigma: 0.067,
        ..Config::default()
    });
    let mut rows = Vec::new();
    for f in &frames {
        let Some(sensor) = f.sensor_s else { continue };
        let ready = fit.host(sensor);
        let proc = f
            .cloud
            .stats
            .map_or(0.0, |s| f64::from(s.inter_frame_processing_time_us) * 1e-6);
        let dets: Vec<Detection> = f
            .cloud
            .points
            .iter()
            .map(|p| Detection {
                position: [p.x, p.y, p.z],
                radial_velocity: p.velocity,
            })
            .collect();
        let r = est.estimate(&dets);
        if r.status != Status::Ok {
            continue;
        }
        if f.frame_number <= 4 {
            println!(
                "frame {}: estimate {:?} inliers {}, truth {:?}",
                f.frame_number,
                r.velocity,
                r.inliers,
                radar_v(ready - proc - 0.00706).map(|v| [v.x, v.y, v.z])
            );
        }
        rows.push((
            ready,
            proc,
            Vector3::new(
                f64::from(r.velocity[0]),
                f64::from(r.velocity[1]),
                f64::from(r.velocity[2]),
            ),
        ));
    }
    for (name, shift) in [
        ("ready", 0.0),
        ("ready-proc", -1.0),
        ("ready-proc-7ms", -2.0),
    ] {
        let mut errs = Vec::new();
        for (ready, proc, v) in &rows {
            let t = match shift as i32 {
                0 => *ready,
                -1 => ready - proc,
                _ => ready - proc - 0.00706,
            };
            if let Some(tv) = radar_v(t) {
                errs.push((v - tv).norm());
            }
        }
        errs.sort_by(f64::total_cmp);
        let n = errs.len();
        let big = errs.iter().filter(|e| **e > 0.3).count();
        println!(
            "{name:<16} frames {n}, median error {:.3} m/s, p90 {:.3}, > 0.3 m/s: {big}",
            errs[n / 2],
            errs[n * 9 / 10]
        );
    }
    Ok(())
}
