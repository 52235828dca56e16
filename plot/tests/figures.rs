//! Each figure written as PNG and SVG from generated inputs; the PNG decoded and its pixels checked;
//! bad inputs give errors that name the file.

use milliego_eval::{Align, Trajectory};
use milliego_plot::{
    ate_cdf, doppler_colour, error_colour, error_over_time, radar_frame, trajectory_top_view,
    Matched, RGBColor, RadarPoint, GROUND_TRUTH, SERIES,
};
use nalgebra::{UnitQuaternion, Vector3};

use std::path::Path;

const SIZE: (u32, u32) = (900, 700);

/// Columns left of the colour bar strip (8 tick-label heights, 112 px at this size).
const PLOT_X: u32 = SIZE.0 - 115;

/// A scratch directory; with `MILLIEGO_PLOT_KEEP=DIR` the figures stay in DIR to be looked at.
struct Out {
    /// Kept alive so the directory lasts the test; `None` when keeping.
    _temp: Option<tempfile::TempDir>,
    dir: std::path::PathBuf,
}

impl Out {
    fn path(&self) -> &Path {
        &self.dir
    }
}

fn tempdir_or_keep(name: &str) -> Out {
    match std::env::var_os("MILLIEGO_PLOT_KEEP") {
        Some(d) => {
            let p = Path::new(&d).join(name);
            std::fs::create_dir_all(&p).unwrap();
            Out {
                _temp: None,
                dir: p,
            }
        }
        None => {
            let t = tempfile::tempdir().unwrap();
            Out {
                dir: t.path().to_path_buf(),
                _temp: Some(t),
            }
        }
    }
}

/// A loop of 20 s at 10 Hz with an x-y extent of 20 m by 12 m.
fn ground_truth() -> Trajectory {
    let mut t = Trajectory::default();
    for i in 0..200 {
        let a = f64::from(i) / 200.0 * std::f64::consts::TAU;
        t.t.push(f64::from(i) * 0.1);
        t.p.push(Vector3::new(10.0 * a.cos(), 6.0 * a.sin(), 0.2 * a.sin()));
        t.q.push(UnitQuaternion::identity());
    }
    t
}

/// The ground truth with an error growing from 0 to about 1 m.
fn drifting(gt: &Trajectory) -> Trajectory {
    let mut e = gt.clone();
    for (i, p) in e.p.iter_mut().enumerate() {
        let s = i as f64 / 200.0;
        *p += Vector3::new(0.8 * s, -0.5 * s * s, 0.1 * s);
    }
    e
}

/// Width, height and RGB pixels of a PNG.
fn decode(path: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    let file = std::fs::File::open(path).unwrap();
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    let px = buf[..info.buffer_size()]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    (info.width, info.height, px)
}

/// Whether `c` appears among the pixels left of column `max_x`.
fn has(img: &(u32, u32, Vec<[u8; 3]>), c: RGBColor, max_x: u32) -> bool {
    let (w, _, px) = img;
    px.iter()
        .enumerate()
        .any(|(i, p)| (i as u32 % w) < max_x && *p == [c.0, c.1, c.2])
}

/// The text elements of an SVG, trimmed, joined by newlines.
fn svg_text(path: &Path) -> String {
    let s = std::fs::read_to_string(path).unwrap();
    assert!(s.starts_with("<svg"), "{}", &s[..s.len().min(80)]);
    s.split("<text")
        .skip(1)
        .filter_map(|t| {
            let body = &t[t.find('>')? + 1..t.find("</text>")?];
            Some(body.trim().to_string())
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn has_line(svg: &str, line: &str) -> bool {
    svg.lines().any(|l| l == line)
}

fn check_png(path: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    assert!(std::fs::metadata(path).unwrap().len() > 1000);
    let img = decode(path);
    assert_eq!((img.0, img.1), SIZE);
    img
}

#[test]
fn top_view_png_and_svg() {
    let dir = tempdir_or_keep("top_view_png_and_svg");
    let gt = ground_truth();
    let m = Matched::new(&gt, &drifting(&gt), Align::None, 0.01).unwrap();
    assert_eq!(m.errors.len(), 200);
    let png_path = dir.path().join("top.png");
    trajectory_top_view(&m.gt, &m.est, &m.errors, "doppler", &png_path, SIZE).unwrap();
    let img = check_png(&png_path);
    // Left of the colour bar (whose bands are mid-band colours anyway): the data alone must bring
    // both ends of the map.
    let plot_x = PLOT_X;
    assert!(has(&img, GROUND_TRUTH, plot_x), "ground truth line missing");
    assert!(
        has(&img, error_colour(0.0), plot_x),
        "smallest error colour missing"
    );
    assert!(
        has(&img, error_colour(1.0), plot_x),
        "largest error colour missing"
    );
    // The colour bar itself is there, on the right.
    assert!(has(&img, error_colour(0.5 + 0.5 / 128.0), SIZE.0));

    let svg_path = dir.path().join("top.svg");
    trajectory_top_view(&m.gt, &m.est, &m.errors, "doppler", &svg_path, SIZE).unwrap();
    let svg = svg_text(&svg_path);
    assert!(svg.contains("doppler: top view, ATE RMSE"));
    assert!(has_line(&svg, "ground truth"));
    assert!(has_line(&svg, "doppler (colour: ATE)"));
    assert!(svg.contains("ATE [m]"));
}

#[test]
fn constant_error_uses_the_middle_of_the_map() {
    let dir = tempdir_or_keep("constant_error_uses_the_middle_of_the_map");
    let gt = ground_truth();
    let mut est = gt.clone();
    for p in &mut est.p {
        p.x += 0.5;
    }
    let m = Matched::new(&gt, &est, Align::None, 0.01).unwrap();
    let path = dir.path().join("flat.png");
    trajectory_top_view(&m.gt, &m.est, &m.errors, "shifted", &path, SIZE).unwrap();
    let img = check_png(&path);
    let plot_x = PLOT_X;
    assert!(has(&img, error_colour(0.5), plot_x));
    assert!(!has(&img, error_colour(0.0), plot_x));
    assert!(!has(&img, error_colour(1.0), plot_x));
}

#[test]
fn errors_over_time_png_and_svg() {
    let dir = tempdir_or_keep("errors_over_time_png_and_svg");
    let gt = ground_truth();
    let m = Matched::new(&gt, &drifting(&gt), Align::None, 0.01).unwrap();
    let png_path = dir.path().join("errors.png");
    error_over_time(&m.gt, &m.est, "imu", &png_path, SIZE).unwrap();
    let img = check_png(&png_path);
    for c in &SERIES[..3] {
        assert!(has(&img, *c, SIZE.0), "axis line colour {c:?} missing");
    }
    let svg_path = dir.path().join("errors.svg");
    error_over_time(&m.gt, &m.est, "imu", &svg_path, SIZE).unwrap();
    let svg = svg_text(&svg_path);
    assert!(svg.contains("imu: position error per axis"));
    assert!(svg.contains("time [s]"));
    for axis in ["x", "y", "z"] {
        assert!(has_line(&svg, axis), "legend entry {axis} missing");
    }
}

#[test]
fn cdf_png_and_svg() {
    let dir = tempdir_or_keep("cdf_png_and_svg");
    let a: Vec<f64> = (0..100).map(|i| f64::from(i) * 0.01).collect();
    let b: Vec<f64> = (0..50).map(|i| f64::from(i) * 0.03).collect();
    let sets = [("doppler", a.as_slice()), ("imu", b.as_slice())];
    let png_path = dir.path().join("cdf.png");
    ate_cdf(&sets, &png_path, SIZE).unwrap();
    let img = check_png(&png_path);
    assert!(has(&img, SERIES[0], SIZE.0));
    assert!(has(&img, SERIES[1], SIZE.0));
    assert!(!has(&img, SERIES[2], SIZE.0));
    let svg_path = dir.path().join("cdf.svg");
    ate_cdf(&sets, &svg_path, SIZE).unwrap();
    let svg = svg_text(&svg_path);
    assert!(svg.contains("Cumulative distribution of ATE"));
    assert!(svg.contains("doppler (RMSE"));
    assert!(svg.contains("imu (RMSE"));
    assert!(svg.contains("fraction of poses"));
    assert!(!svg.contains("log error axis"));

    // A thousandfold apart: the error axis turns logarithmic so the better line is readable.
    let c: Vec<f64> = a.iter().map(|x| x * 1000.0).collect();
    let far = [("doppler", a.as_slice()), ("imu", c.as_slice())];
    let log_path = dir.path().join("cdf_log.svg");
    ate_cdf(&far, &log_path, SIZE).unwrap();
    assert!(svg_text(&log_path).contains("Cumulative distribution of ATE (log error axis)"));
}

#[test]
fn radar_png_and_svg() {
    let dir = tempdir_or_keep("radar_png_and_svg");
    let points: Vec<RadarPoint> = (0..60)
        .map(|i| {
            let a = (30.0 + f64::from(i) * 2.0).to_radians();
            let r = 2.0 + f64::from(i) * 0.15;
            RadarPoint {
                x: r * a.cos(),
                y: r * a.sin(),
                velocity: -2.0 + f64::from(i) * 4.0 / 59.0,
            }
        })
        .collect();
    let png_path = dir.path().join("radar.png");
    radar_frame(&points, "frame 7 (60 points)", &png_path, SIZE).unwrap();
    let img = check_png(&png_path);
    let plot_x = PLOT_X;
    assert!(
        has(&img, doppler_colour(0.0), plot_x),
        "approaching colour missing"
    );
    assert!(
        has(&img, doppler_colour(1.0), plot_x),
        "receding colour missing"
    );
    let svg_path = dir.path().join("radar.svg");
    radar_frame(&points, "frame 7 (60 points)", &svg_path, SIZE).unwrap();
    let svg = svg_text(&svg_path);
    assert!(svg.contains("frame 7 (60 points)"));
    assert!(svg.contains("Doppler velocity [m/s]"));
    assert!(has_line(&svg, "2 m"), "range ring label missing");
    // An empty frame still draws the field of view.
    radar_frame(&[], "empty", &dir.path().join("empty.png"), SIZE).unwrap();
}

#[test]
fn bad_inputs_name_the_file() {
    let dir = tempdir_or_keep("bad_inputs_name_the_file");
    let gt = ground_truth();
    let empty = Trajectory::default();
    let out = dir.path().join("x.png");
    let named = |e: milliego_plot::PlotError, what: &str| {
        let s = e.to_string();
        assert!(s.contains("x.png") || s.contains("blocker"), "{s}");
        assert!(s.contains(what), "{s}");
    };
    named(
        trajectory_top_view(&gt, &empty, &[], "e", &out, SIZE).unwrap_err(),
        "the estimate is empty",
    );
    named(
        error_over_time(&empty, &empty, "e", &out, SIZE).unwrap_err(),
        "the estimate is empty",
    );
    named(ate_cdf(&[], &out, SIZE).unwrap_err(), "is empty");
    named(
        ate_cdf(&[("a", &[])], &out, SIZE).unwrap_err(),
        "an error set is empty",
    );
    named(
        ate_cdf(&[("a", &[0.1, f64::NAN])], &out, SIZE).unwrap_err(),
        "NaN",
    );
    named(
        trajectory_top_view(&gt, &gt, &[0.0; 3], "e", &out, SIZE).unwrap_err(),
        "has 3 entries, expected 200",
    );
    named(
        ate_cdf(&[("a", &[0.1])], &out, (10, 10)).unwrap_err(),
        "10x10",
    );
    let jpg = dir.path().join("x.jpg");
    let e = ate_cdf(&[("a", &[0.1])], &jpg, SIZE).unwrap_err();
    assert!(e.to_string().contains("x.jpg") && e.to_string().contains(".png or .svg"));
    assert!(!out.exists() && !jpg.exists());

    // No matching timestamps: the estimate is on another clock.
    let mut late = gt.clone();
    for t in &mut late.t {
        *t += 1000.0;
    }
    let e = Matched::new(&gt, &late, Align::Se3, 0.01).unwrap_err();
    assert!(e.to_string().contains("no matching timestamps"), "{e}");

    // A directory that cannot be created: a file stands where it should be.
    std::fs::write(dir.path().join("blocker"), b"").unwrap();
    let under = dir.path().join("blocker").join("sub").join("cdf.png");
    let e = ate_cdf(&[("a", &[0.1])], &under, SIZE).unwrap_err();
    let s = e.to_string();
    assert!(
        s.contains("cdf.png") && s.contains("cannot create directory"),
        "{s}"
    );
}

#[test]
fn single_pose_and_far_away_values_draw() {
    let dir = tempdir_or_keep("single_pose_and_far_away_values_draw");
    let mut one = ground_truth();
    one.t.truncate(1);
    one.p.truncate(1);
    one.q.truncate(1);
    let m = Matched::new(&one, &one, Align::None, 0.01).unwrap();
    trajectory_top_view(
        &m.gt,
        &m.est,
        &m.errors,
        "one",
        &dir.path().join("one.png"),
        SIZE,
    )
    .unwrap();
    error_over_time(&m.gt, &m.est, "one", &dir.path().join("one_err.png"), SIZE).unwrap();
    ate_cdf(&[("zero", &[0.0])], &dir.path().join("zero.png"), SIZE).unwrap();
    let far = [RadarPoint {
        x: 1e12,
        y: -1e12,
        velocity: 1e9,
    }];
    radar_frame(&far, "far", &dir.path().join("far.png"), SIZE).unwrap();
    // A figure the SVG size limits allow at its largest and smallest.
    radar_frame(&far, "small", &dir.path().join("small.svg"), (300, 300)).unwrap();
}
