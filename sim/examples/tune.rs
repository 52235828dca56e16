//! Prints the summary of a few scenarios (used to tune the radar model).
use milliego_sim::{
    motion::MotionKind,
    scenario::{run, Scenario},
    world::Family,
};
fn main() {
    let dur: f64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10.0);
    for f in Family::ALL {
        for m in [
            MotionKind::Robot,
            MotionKind::Handheld,
            MotionKind::Headworn,
        ] {
            let mut sc = Scenario::new(f, m, 1);
            sc.duration_s = dur;
            let dir = std::env::temp_dir().join(format!("tune-{f}-{m}"));
            let _ = std::fs::remove_dir_all(&dir);
            let t = std::time::Instant::now();
            let s = run(&sc, &dir, &mut |_| {}).unwrap();
            println!(
                "{f:10} {m:8} frames {} pts/frame {:.1} [{}..{}] outliers {:.3} imu {} ({:.2} s)",
                s.frames,
                s.points_mean(),
                s.points_min,
                s.points_max,
                s.outlier_share(),
                s.imu_samples,
                t.elapsed().as_secs_f64()
            );
        }
    }
}
