//! The radar stream: decodes with the real framer, matches its .cfg, and its points have the
//! configured statistics and Doppler consistent with the ground truth.

mod common;

use common::{decode_radar, radar_header_time, radar_truth, Gt, Sim};
use milliego_sim::motion::MotionKind;
use milliego_sim::radar::{RadarModel, CPU_HZ, PLATFORM, SDK_VERSION};
use milliego_sim::scenario::{self, sensor_pose, RADAR_START_S};
use milliego_sim::world::Family;
use radar_driver::cfg::RadarConfig;
use std::sync::OnceLock;

const DURATION_S: f64 = 20.0;

fn sessions() -> &'static [Sim] {
    static S: OnceLock<Vec<Sim>> = OnceLock::new();
    S.get_or_init(|| {
        vec![
            common::simulate(Family::Office, MotionKind::Handheld, 7, DURATION_S),
            common::simulate_with(Family::Corridor, MotionKind::Robot, 3, |s| {
                s.duration_s = DURATION_S;
                s.radar_hz = 30.0;
            }),
            common::simulate_with(Family::Household, MotionKind::Headworn, 11, |s| {
                s.duration_s = DURATION_S;
                s.radar_hz = 10.0;
            }),
        ]
    })
}

#[test]
fn stream_decodes_without_bad_frames_and_with_the_implied_frame_count() {
    for s in sessions() {
        let (frames, c) = decode_radar(&s.session);
        assert_eq!(c.frames_bad_total(), 0, "{:?}", s.scenario);
        assert_eq!(c.bytes_skipped, 0);
        assert_eq!(c.bytes_in, s.summary.radar_bytes);
        let period = 1.0 / s.scenario.radar_hz;
        let implied = (DURATION_S - RADAR_START_S) / period;
        assert!(
            (frames.len() as f64 - implied).abs() <= 1.0,
            "{} frames, the duration implies {implied}",
            frames.len()
        );
        for (i, f) in frames.iter().enumerate() {
            assert_eq!(
                f.frame_number,
                i as u32 + 1,
                "frame numbers are contiguous from 1"
            );
            assert_eq!((f.version, f.platform), (SDK_VERSION, PLATFORM));
            assert_eq!(f.total_len % 32, 0, "SDK 3 frames are padded to 32 B");
            for ty in [1, 7, 6] {
                assert!(
                    f.tlv_types.contains(&ty),
                    "frame {} lacks TLV {ty}",
                    f.frame_number
                );
            }
            assert_eq!(f.points.len(), f.side.len());
        }
    }
}

#[test]
fn cfg_parses_and_its_frame_period_is_the_simulated_one() {
    for s in sessions() {
        let text = s.session.radar_cfg().unwrap().expect("radar.cfg");
        let d = RadarConfig::parse(&text).unwrap().derive(None).unwrap();
        assert!(
            (d.range_resolution_m - 0.04).abs() < 0.002,
            "{}",
            d.range_resolution_m
        );
        assert_eq!(s.session.meta.radar.as_ref().unwrap().baud, d.data_baud);
        // The frame period on the radar clock: slope of the unwrapped header times over frame
        // numbers (the processing jitter averages out).
        let (frames, _) = decode_radar(&s.session);
        let clk = s.session.meta.clock.unwrap();
        let to_sensor = |h: f64| (1.0 + clk.radar_drift_ppm * 1e-6) * h + clk.radar_offset_s;
        let pts: Vec<(f64, f64)> = frames
            .iter()
            .map(|f| {
                let t = radar_header_time(f.cycles, to_sensor(f.host_ns as f64 * 1e-9) - 0.02);
                (f64::from(f.frame_number), t)
            })
            .collect();
        let n = pts.len() as f64;
        let (mx, my) = (
            pts.iter().map(|p| p.0).sum::<f64>() / n,
            pts.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let slope = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>()
            / pts.iter().map(|p| (p.0 - mx).powi(2)).sum::<f64>();
        let period = d.frame_period_ms * 1e-3;
        assert!(
            (slope - period).abs() < 2e-6,
            "frames come every {slope} s, the .cfg says {period} s"
        );
        // Every frame fits the UART budget the .cfg implies.
        assert!(frames.iter().all(|f| f.total_len <= d.uart_bytes_per_frame));
    }
}

#[test]
fn clock_truth_maps_radar_time_to_host_time() {
    for s in sessions() {
        let (frames, _) = decode_radar(&s.session);
        let clk = s.session.meta.clock.unwrap();
        let baud = f64::from(s.session.meta.radar.as_ref().unwrap().baud);
        let k = 1.0 + clk.radar_drift_ppm * 1e-6;
        for f in &frames {
            let host = f.host_ns as f64 * 1e-9;
            let t = radar_header_time(f.cycles, k * host + clk.radar_offset_s - 0.02);
            let sent = (t - clk.radar_offset_s) / k;
            let on_wire = f64::from(f.total_len) * 10.0 / baud;
            let late = host - (sent + on_wire);
            // The read returns after the last byte: USB latency 0.2-1.5 ms.
            assert!(
                (-1e-6..2e-3).contains(&late),
                "frame {}: read {late} s after its last byte left",
                f.frame_number
            );
        }
    }
}

#[test]
fn points_per_frame_and_outlier_share_match_the_configuration() {
    let model = RadarModel::new(20.0).unwrap();
    let mut all_points = 0usize;
    let mut all_outliers = 0usize;
    for s in sessions() {
        let (frames, _) = decode_radar(&s.session);
        let truth = radar_truth(&s.path());
        let n: usize = frames.iter().map(|f| f.points.len()).sum();
        assert_eq!(truth.len(), n, "one truth row per decoded point");
        // The truth rows describe the decoded points, in order.
        let mut rows = truth.iter();
        for f in &frames {
            for (i, p) in f.points.iter().enumerate() {
                let r = rows.next().unwrap();
                assert_eq!((r.frame, r.index), (f.frame_number, i));
                assert_eq!(&r.xyzv, p);
            }
        }
        for f in &frames {
            assert!(
                (model.min_points..=model.max_points).contains(&f.points.len()),
                "frame {} holds {} points",
                f.frame_number,
                f.points.len()
            );
        }
        let mean = n as f64 / frames.len() as f64;
        assert!((8.0..=60.0).contains(&mean), "{mean} points per frame");
        let outliers = truth.iter().filter(|r| r.class != "inlier").count();
        let share = outliers as f64 / n as f64;
        eprintln!(
            "{:?}/{:?}: {:.1} points per frame, outlier share {share:.3}",
            s.scenario.family, s.scenario.motion, mean
        );
        assert!(
            (share - model.outlier_share).abs() < 0.08,
            "outlier share {share}"
        );
        all_points += n;
        all_outliers += outliers;
    }
    let share = all_outliers as f64 / all_points as f64;
    assert!(
        (share - model.outlier_share).abs() < 0.04,
        "outlier share {share} overall"
    );
}

#[test]
fn inlier_doppler_is_the_ground_truth_velocity_on_the_ray() {
    let model = RadarModel::new(20.0).unwrap();
    let sigma = model.doppler_sigma_mps();
    for s in sessions() {
        let (frames, _) = decode_radar(&s.session);
        let truth = radar_truth(&s.path());
        let gt = Gt::load(&s.session);
        let clk = s.session.meta.clock.unwrap();
        let (t_br, q_br) = sensor_pose(&s.session.meta.extrinsics.radar);
        let k = 1.0 + clk.radar_drift_ppm * 1e-6;
        let active = RadarModel::new(s.scenario.radar_hz)
            .unwrap()
            .active_time_s();
        let mut rows = truth.iter();
        let (mut res_in, mut res_out, mut res_dir) = (Vec::new(), Vec::new(), Vec::new());
        for f in &frames {
            let host = f.host_ns as f64 * 1e-9;
            let header = radar_header_time(f.cycles, k * host + clk.radar_offset_s - 0.02);
            // Middle of the chirps: header time minus the processing delay (its mean) minus
            // half the active time.
            let proc = scenario::RADAR_PROC_S
                + scenario::RADAR_PROC_PER_POINT_S * f.points.len() as f64
                + scenario::RADAR_JITTER_S / 2.0;
            let mid = (header - proc - active / 2.0 - clk.radar_offset_s) / k;
            let v_world = gt.v(mid, &t_br);
            let v_radar = (gt.q(mid) * q_br).inverse() * v_world;
            for p in &f.points {
                let r = rows.next().unwrap();
                let u = r.true_xyz.normalize();
                let expect = -v_radar.dot(&u);
                let res = f64::from(p[3]) - expect;
                match r.class.as_str() {
                    "inlier" => {
                        res_in.push(res);
                        let d = nalgebra::Vector3::new(p[0], p[1], p[2])
                            .cast::<f64>()
                            .normalize();
                        res_dir.push(f64::from(p[3]) + v_radar.dot(&d));
                    }
                    "multipath" | "clutter" => res_out.push(res),
                    _ => {}
                }
            }
        }
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let mean = res_in.iter().sum::<f64>() / res_in.len() as f64;
        eprintln!(
            "{:?}: {} inliers, Doppler residual mean {mean:.4} rms {:.4} m/s (configured {sigma:.4}); along the reported ray {:.4}; outliers {:.3}",
            s.scenario.family,
            res_in.len(),
            rms(&res_in),
            rms(&res_dir),
            rms(&res_out)
        );
        assert!(res_in.len() > 100);
        assert!(mean.abs() < 0.2 * sigma, "mean residual {mean} m/s");
        assert!(
            rms(&res_in) > 0.7 * sigma && rms(&res_in) < 1.3 * sigma,
            "inlier Doppler residual {} m/s vs configured {sigma} m/s",
            rms(&res_in)
        );
        // Along the reported (noisy) direction the angle error adds a little.
        assert!(rms(&res_dir) < 3.0 * sigma, "{}", rms(&res_dir));
        // Multipath and clutter are not consistent with the motion.
        assert!(
            rms(&res_out) > 3.0 * sigma,
            "outliers fit the motion: {}",
            rms(&res_out)
        );
    }
    // Sanity of the figure itself: noise and Doppler-bin quantisation.
    assert!(sigma > model.doppler_noise_mps && sigma < 0.1);
    let _ = CPU_HZ;
}
