//! Simulates every family and motion for many seeds and prints per-family statistics (checks
//! that no seed fails and that the radar statistics hold across layouts).
use milliego_sim::{
    motion::MotionKind,
    scenario::{run, Scenario},
    world::Family,
};
fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10);
    let dur: f64 = std::env::args()
        .nth(2)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5.0);
    for f in Family::ALL {
        for m in MotionKind::ALL {
            if m == MotionKind::Vehicle && f != Family::Outdoor {
                continue; // cars drive outdoors only
            }
            let (mut pts, mut fr, mut out, mut lo, mut hi) = (0, 0, 0, u64::MAX, 0);
            for seed in 0..seeds {
                let mut sc = Scenario::new(f, m, seed);
                sc.duration_s = dur;
                let dir = std::env::temp_dir().join(format!("sweep-{f}-{m}-{seed}"));
                let _ = std::fs::remove_dir_all(&dir);
                match run(&sc, &dir, &mut |_| {}) {
                    Ok(s) => {
                        pts += s.points;
                        fr += s.frames;
                        out += s.outliers;
                        lo = lo.min(s.points_min);
                        hi = hi.max(s.points_max);
                    }
                    Err(e) => println!("{f} {m} seed {seed}: {e}"),
                }
                let _ = std::fs::remove_dir_all(&dir);
            }
            println!(
                "{f:10} {m:8} {:.1} points per frame [{lo}..{hi}], outlier share {:.3}",
                pts as f64 / fr.max(1) as f64,
                out as f64 / pts.max(1) as f64
            );
        }
    }
}
