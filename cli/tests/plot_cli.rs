//! `milliego plot` as a user runs it: TUM files in, figures out; a session in, a radar frame out;
//! bad inputs fail with a message naming the file.

use milliego_session::{Meta, SessionWriter, Source, StreamKind};
use radar_driver::encode::FrameBuilder;
use std::fmt::Write as _;
use std::path::Path;
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_milliego");

/// A 20 s loop at 10 Hz; `drift` \[m\] is the error reached at the end, `dt` \[s\] shifts the clock.
fn write_tum(path: &Path, drift: f64, dt: f64) {
    let mut s = String::from("# t tx ty tz qx qy qz qw\n");
    for i in 0..200 {
        let a = f64::from(i) / 200.0 * std::f64::consts::TAU;
        let e = drift * f64::from(i) / 200.0;
        let t = f64::from(i) * 0.1 + dt;
        let (x, y) = (8.0 * a.cos() + e, 5.0 * a.sin() - 0.5 * e);
        writeln!(s, "{t:.6} {x} {y} {} 0 0 0 1", 0.1 * a.sin()).unwrap();
    }
    std::fs::write(path, s).unwrap();
}

fn milliego(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn non_empty(p: &Path) -> bool {
    std::fs::metadata(p).is_ok_and(|m| m.len() > 1000)
}

#[test]
fn trajectory_figures_for_one_and_several_estimates() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_tum(&d.join("gt.tum"), 0.0, 0.0);
    write_tum(&d.join("doppler.tum"), 0.4, 0.0);
    write_tum(&d.join("imu.tum"), 1.5, 0.0);
    let s = |p: &str| d.join(p).to_str().unwrap().to_string();

    let one = milliego(&[
        "plot",
        "trajectory",
        "--est",
        &s("doppler.tum"),
        "--gt",
        &s("gt.tum"),
        "-o",
        &s("one"),
    ]);
    assert!(one.status.success(), "{}", stderr(&one));
    for f in ["trajectory.png", "errors.png", "ate_cdf.png"] {
        assert!(non_empty(&d.join("one").join(f)), "{f} missing");
    }

    let two = milliego(&[
        "plot",
        "trajectory",
        "--est",
        &s("doppler.tum"),
        "--est",
        &s("imu.tum"),
        "--gt",
        &s("gt.tum"),
        "--align",
        "sim3",
        "--format",
        "svg",
        "-o",
        &s("two/nested"),
    ]);
    assert!(two.status.success(), "{}", stderr(&two));
    let out = d.join("two").join("nested");
    for f in [
        "trajectory_doppler.svg",
        "trajectory_imu.svg",
        "errors_doppler.svg",
        "errors_imu.svg",
        "ate_cdf.svg",
    ] {
        assert!(non_empty(&out.join(f)), "{f} missing");
    }
    let cdf = std::fs::read_to_string(out.join("ate_cdf.svg")).unwrap();
    assert!(cdf.contains("doppler (RMSE") && cdf.contains("imu (RMSE"));
    let stdout = String::from_utf8_lossy(&two.stdout);
    assert!(stdout.contains("doppler: 200 matched poses"), "{stdout}");
}

#[test]
fn trajectory_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_tum(&d.join("gt.tum"), 0.0, 0.0);
    write_tum(&d.join("late.tum"), 0.2, 5000.0);
    std::fs::write(d.join("empty.tum"), "# nothing\n").unwrap();
    std::fs::write(d.join("blocker"), "").unwrap();
    let s = |p: &str| d.join(p).to_str().unwrap().to_string();

    let late = milliego(&[
        "plot",
        "trajectory",
        "--est",
        &s("late.tum"),
        "--gt",
        &s("gt.tum"),
        "-o",
        &s("o"),
    ]);
    assert!(!late.status.success());
    let e = stderr(&late);
    assert!(
        e.contains("late.tum") && e.contains("no matching timestamps"),
        "{e}"
    );

    let empty = milliego(&[
        "plot",
        "trajectory",
        "--est",
        &s("empty.tum"),
        "--gt",
        &s("gt.tum"),
        "-o",
        &s("o"),
    ]);
    assert!(!empty.status.success());
    let e = stderr(&empty);
    assert!(e.contains("empty.tum") && e.contains("no poses"), "{e}");

    let blocked = milliego(&[
        "plot",
        "trajectory",
        "--est",
        &s("gt.tum"),
        "--gt",
        &s("gt.tum"),
        "-o",
        &s("blocker/sub"),
    ]);
    assert!(!blocked.status.success());
    let e = stderr(&blocked);
    assert!(
        e.contains("trajectory.png") && e.contains("cannot create directory"),
        "{e}"
    );
    assert!(!e.contains("panicked"), "{e}");
}

#[test]
fn radar_frame_of_a_session() {
    let dir = tempfile::tempdir().unwrap();
    let session = dir.path().join("session");
    let mut w = SessionWriter::create(&session, Meta::new(Source::Simulated)).unwrap();
    let mut radar = w.stream(StreamKind::Radar).unwrap();
    for n in 0..5u32 {
        let pts: Vec<[f32; 4]> = (0..=n)
            .map(|i| [i as f32 - 1.0, 2.0 + i as f32, 0.0, 0.5 * i as f32 - 1.0])
            .collect();
        let f = FrameBuilder::oob(0x0303_0002, 0xA6843, n + 1)
            .points(&pts)
            .to_vec();
        radar.write_chunk(u64::from(n) * 50_000_000, &f).unwrap();
    }
    radar.finish().unwrap();
    w.finish().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();

    let svg = dir.path().join("frame.svg");
    let o = milliego(&[
        "plot",
        "radar",
        &s(&session),
        "--frame",
        "3",
        "-o",
        &s(&svg),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("frame 3, 3 points"), "title missing");

    // Default: the fullest frame.
    let png = dir.path().join("fullest.png");
    let o = milliego(&["plot", "radar", &s(&session), "-o", &s(&png)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(non_empty(&png));
    assert!(String::from_utf8_lossy(&o.stdout).contains("frame 5, 5 points"));

    let o = milliego(&[
        "plot",
        "radar",
        &s(&session),
        "--frame",
        "99",
        "-o",
        &s(&png),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("session") && e.contains("no radar frame numbered 99"),
        "{e}"
    );

    let o = milliego(&[
        "plot",
        "radar",
        &s(&session),
        "-o",
        &s(&dir.path().join("f.jpg")),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("f.jpg"), "{}", stderr(&o));
}
