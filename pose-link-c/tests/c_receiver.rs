//! The C receiver example (`examples/receiver.c`), compiled with the system C compiler against
//! the static library and the committed header, listening on loopback UDP while a real
//! `milliego run` streams a simulated session's poses to it: it prints exactly the poses the run
//! wrote to its TUM file, and counts a corrupted and a truncated datagram by name. Its serial
//! mode reads a damaged COBS stream through the deframer with the Rust deframer's counters.
//!
//! Needs `cc` (prints a skip line without one). The `milliego` binary and the static library
//! are the ones this test build made (`target/<profile>/`); either is built with `$CARGO build`
//! when absent, and `MILLIEGO_BIN` may name another `milliego`.

use pose_link::{cobs, Deframer, PoseMessage, MESSAGE_LEN, SERIAL_FRAME_MAX};
use std::ffi::OsString;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// `target/<profile>`: the test binary lives in its `deps/`.
fn build_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    exe.parent().unwrap().parent().unwrap().to_path_buf()
}

/// `build_dir()/file`, built with `cargo build -p package` when it is not there.
fn artifact(package: &str, file: &str) -> PathBuf {
    let path = build_dir().join(file);
    if path.is_file() {
        return path;
    }
    let cargo = std::env::var_os("CARGO")
        .or_else(|| option_env!("CARGO").map(OsString::from))
        .unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(crate_dir().parent().unwrap())
        .args(["build", "-p", package]);
    if build_dir().file_name().is_some_and(|n| n == "release") {
        cmd.arg("--release");
    }
    eprintln!("{} not found: building it ({cmd:?})", path.display());
    assert!(cmd.status().unwrap().success(), "{cmd:?} failed");
    assert!(
        path.is_file(),
        "{} still missing after {cmd:?}",
        path.display()
    );
    path
}

fn milliego() -> PathBuf {
    match std::env::var_os("MILLIEGO_BIN") {
        Some(p) => p.into(),
        None => artifact("milliego", "milliego"),
    }
}

/// The C compiler (`$CC` or `cc`), or None when there is none.
fn c_compiler() -> Option<OsString> {
    let cc = std::env::var_os("CC").unwrap_or_else(|| "cc".into());
    let ok = Command::new(&cc)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    ok.then_some(cc)
}

/// Compiles receiver.c into `dir` (warnings are errors) against the static library and returns
/// the executable.
fn build_receiver(cc: &OsString, dir: &Path) -> PathBuf {
    let lib = artifact("pose-link-c", "libpose_link_c.a");
    let exe = dir.join("receiver");
    // What `cargo rustc -p pose-link-c --lib --crate-type staticlib -- --print
    // native-static-libs` prints on Linux; elsewhere the usual three.
    let native: &[&str] = if cfg!(target_os = "linux") {
        &[
            "-lgcc_s",
            "-lutil",
            "-lrt",
            "-lpthread",
            "-lm",
            "-ldl",
            "-lc",
        ]
    } else {
        &["-lpthread", "-ldl", "-lm"]
    };
    let out = Command::new(cc)
        .args(["-std=c99", "-D_POSIX_C_SOURCE=200809L"])
        .args(["-Wall", "-Wextra", "-Werror", "-I"])
        .arg(crate_dir().join("include"))
        .arg(crate_dir().join("examples/receiver.c"))
        .arg(&lib)
        .args(native)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "compiling receiver.c failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// One `pose ...` line of the receiver, split into fields.
struct PoseLine {
    seq: u32,
    t_ns: u64,
    /// x y z as printed (%.6f).
    position: [String; 3],
    /// qw qx qy qz as printed (%.9f).
    quaternion: [String; 4],
    estimator: String,
    flags: u16,
}

fn pose_lines(out: &str) -> Vec<PoseLine> {
    out.lines()
        .filter_map(|l| l.strip_prefix("pose "))
        .map(|l| {
            let f: Vec<&str> = l.split(' ').collect();
            assert_eq!(f.len(), 11, "{l}");
            PoseLine {
                seq: f[0].parse().unwrap(),
                t_ns: seconds_to_ns(f[1]),
                position: [f[2], f[3], f[4]].map(String::from),
                quaternion: [f[5], f[6], f[7], f[8]].map(String::from),
                estimator: f[9].to_string(),
                flags: u16::from_str_radix(f[10].trim_start_matches("0x"), 16).unwrap(),
            }
        })
        .collect()
}

/// "12.345678901" -> ns, exactly.
fn seconds_to_ns(s: &str) -> u64 {
    let (whole, frac) = s.split_once('.').unwrap();
    assert_eq!(frac.len(), 9, "{s}");
    whole.parse::<u64>().unwrap() * 1_000_000_000 + frac.parse::<u64>().unwrap()
}

/// The receiver's `NAME=COUNT` pairs on the line starting with `prefix`.
fn counts(out: &str, prefix: &str) -> Vec<(String, u64)> {
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("no {prefix:?} line in:\n{out}"));
    line.split_whitespace()
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap();
            (k.to_string(), v.parse().unwrap())
        })
        .collect()
}

#[test]
fn c_receiver_prints_exactly_the_poses_milliego_run_streams() {
    let Some(cc) = c_compiler() else {
        println!("skipped: no C compiler (cc or $CC) found, receiver.c not tested");
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let receiver = build_receiver(&cc, tmp.path());
    let bin = milliego();
    let session = tmp.path().join("session");
    run_ok(
        Command::new(&bin)
            .args(["sim", "--family", "office", "--motion", "handheld"])
            .args(["--seed", "7", "--duration", "4", "-o"])
            .arg(&session)
            .stderr(Stdio::null()),
    );
    let run = |outs: &[String]| {
        let mut cmd = Command::new(&bin);
        cmd.args(["run", "--session"])
            .arg(&session)
            .args(["--estimator", "doppler"]);
        for o in outs {
            cmd.args(["--out", o]);
        }
        run_ok(&mut cmd);
    };
    // How many poses the run sends: an offline run is deterministic, so a first run to a TUM
    // file tells the receiver how many datagrams to wait for.
    let first = tmp.path().join("first.tum");
    run(&[format!("tum:{}", first.display())]);
    let n = std::fs::read_to_string(&first).unwrap().lines().count();
    assert!(n > 20, "{n} poses from a 4 s session");

    // Receiver: the run's poses plus a corrupted and a truncated datagram sent from here.
    let mut child = Command::new(&receiver)
        .args(["udp", "0", &(n + 2).to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut first_line = String::new();
    stdout.read_line(&mut first_line).unwrap();
    let addr = first_line
        .trim()
        .strip_prefix("listening udp ")
        .unwrap_or_else(|| panic!("receiver printed {first_line:?}"))
        .to_string();
    let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut bad = [0u8; MESSAGE_LEN];
    PoseMessage {
        seq: 9999,
        ..PoseMessage::default()
    }
    .encode(&mut bad)
    .unwrap();
    bad[40] ^= 0x04;
    tx.send_to(&bad, &addr).unwrap();
    tx.send_to(&bad[..50], &addr).unwrap();

    let tum = tmp.path().join("run.tum");
    run(&[format!("udp://{addr}"), format!("tum:{}", tum.display())]);
    let status = child.wait().unwrap();
    let mut rest = String::new();
    stdout.read_to_string(&mut rest).unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(status.success(), "receiver failed: {status}\n{rest}\n{err}");

    let tum_text = std::fs::read_to_string(&tum).unwrap();
    let tum_lines: Vec<Vec<&str>> = tum_text.lines().map(|l| l.split(' ').collect()).collect();
    let poses = pose_lines(&rest);
    assert_eq!(
        tum_lines.len(),
        n,
        "the second run wrote another trajectory"
    );
    assert_eq!(poses.len(), n, "receiver output:\n{rest}\n{err}");
    for (i, (p, t)) in poses.iter().zip(&tum_lines).enumerate() {
        assert_eq!(p.seq, i as u32, "sequence numbers from 0, none lost");
        // TUM: t x y z qx qy qz qw. The message carries the time in whole ns (truncated), the
        // TUM file in seconds rounded to 9 decimals: at most 1 ns apart.
        assert!(
            p.t_ns.abs_diff(seconds_to_ns(t[0])) <= 1,
            "pose {i}: t {} vs TUM {}",
            p.t_ns,
            t[0]
        );
        assert_eq!(p.position, [t[1], t[2], t[3]], "pose {i} position");
        assert_eq!(
            p.quaternion,
            [t[7], t[4], t[5], t[6]],
            "pose {i} orientation"
        );
        assert_eq!(p.estimator, "doppler", "pose {i}");
        assert_eq!(
            p.flags & pose_link_c::POSE_LINK_HEALTH_PREDICTED,
            0,
            "pose {i}: a session run sends radar-rate poses only"
        );
    }
    let errors = counts(&rest, "errors ");
    for (name, count) in &errors {
        let want = match name.as_str() {
            "bad_crc" | "too_short" => 1,
            _ => 0,
        };
        assert_eq!(*count, want, "{name}: {errors:?}");
    }
    assert!(errors.iter().any(|(k, _)| k == "bad_crc"), "{errors:?}");
    assert!(err.contains("dropped: bad_crc"), "{err}");
}

#[test]
fn c_receiver_reads_a_damaged_serial_stream_through_the_deframer() {
    let Some(cc) = c_compiler() else {
        println!("skipped: no C compiler (cc or $CC) found, receiver.c not tested");
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let receiver = build_receiver(&cc, tmp.path());

    let pose = |seq: u32| PoseMessage {
        seq,
        measurement_time_ns: 1_000_000_000 + u64::from(seq) * 50_000_001,
        position: [f64::from(seq) * 0.1, -1.25, 0.015625 * f64::from(seq)],
        orientation: [0.8, 0.0, 0.6, 0.0],
        health: pose_link::Health(u16::from(seq.is_multiple_of(3)) << 5),
        estimator: pose_link::Estimator::from_code((seq % 4) as u8),
        ..PoseMessage::default()
    };
    let frame = |raw: &[u8], s: &mut Vec<u8>| {
        let mut enc = [0u8; 256];
        let n = cobs::encode(raw, &mut enc).unwrap();
        s.extend_from_slice(&enc[..n]);
        s.push(0);
    };
    let mut stream = vec![0x07, 0x01, 0x02, 0x00]; // joined mid-frame: bad COBS
    let mut want = Vec::new();
    for seq in 0..12u32 {
        let mut raw = [0u8; MESSAGE_LEN];
        pose(seq).encode(&mut raw).unwrap();
        match seq {
            4 => raw[30] ^= 0x80, // bad CRC
            7 => raw[0] = 0x02,   // unknown type
            _ => want.push(seq),
        }
        frame(&raw, &mut stream);
        if seq == 9 {
            stream.extend_from_slice(&[0, 0, 0]); // empty frames
            stream.extend(std::iter::repeat_n(0x11u8, 400)); // overflow
            stream.push(0);
        }
    }
    let path = tmp.path().join("stream.bin");
    std::fs::write(&path, &stream).unwrap();

    let from_file = run_ok(Command::new(&receiver).arg("serial").arg(&path));
    // The same through the dynamic library (what C# and Unity load), on Linux.
    if cfg!(target_os = "linux") {
        let so = artifact("pose-link-c", "libpose_link_c.so");
        let lib_dir = so.parent().unwrap();
        let exe = tmp.path().join("receiver-dyn");
        let out = Command::new(&cc)
            .args([
                "-std=c99",
                "-D_POSIX_C_SOURCE=200809L",
                "-Wall",
                "-Werror",
                "-I",
            ])
            .arg(crate_dir().join("include"))
            .arg(crate_dir().join("examples/receiver.c"))
            .arg("-L")
            .arg(lib_dir)
            .arg("-lpose_link_c")
            .arg(format!("-Wl,-rpath,{}", lib_dir.display()))
            .arg("-o")
            .arg(&exe)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            run_ok(Command::new(&exe).arg("serial").arg(&path)),
            from_file
        );
    }
    // The same from stdin.
    let mut child = Command::new(&receiver)
        .args(["serial", "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    child.stdin.take().unwrap().write_all(&stream).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    assert_eq!(String::from_utf8(out.stdout).unwrap(), from_file);

    let poses = pose_lines(&from_file);
    assert_eq!(poses.iter().map(|p| p.seq).collect::<Vec<_>>(), want);
    for p in &poses {
        let m = pose(p.seq);
        assert_eq!(p.t_ns, m.measurement_time_ns);
        let pos = m.position.map(|v| format!("{v:.6}"));
        assert_eq!(p.position, pos);
        let q = m.orientation.map(|v| format!("{v:.9}"));
        assert_eq!(p.quaternion, q);
        assert_eq!(p.estimator, m.estimator.name());
        assert_eq!(p.flags, m.health.0);
    }

    // Counters: the Rust deframer's over the same bytes, and each drop by its name.
    let mut d = Deframer::<SERIAL_FRAME_MAX>::default();
    let mut input = &stream[..];
    while d.poll(&mut input) != pose_link::Event::NeedMore {}
    let c = d.counters();
    let got = counts(&from_file, "counters ");
    let expect = [
        ("bytes_in", c.bytes_in),
        ("messages_ok", c.messages_ok),
        ("frames_bad_cobs", c.frames_bad_cobs),
        ("frames_bad_message", c.frames_bad_message),
        ("frames_overflow", c.frames_overflow),
        ("bytes_dropped", c.bytes_dropped),
        ("empty_frames", c.empty_frames),
    ]
    .map(|(k, v)| (k.to_string(), v));
    assert_eq!(got, expect);
    assert_eq!(c.bytes_in, stream.len() as u64);
    assert_eq!(
        (
            c.messages_ok,
            c.frames_bad_cobs,
            c.frames_bad_message,
            c.frames_overflow
        ),
        (10, 1, 2, 1)
    );
    assert_eq!(c.empty_frames, 3);
    let errors = counts(&from_file, "errors ");
    for (name, count) in &errors {
        let want = match name.as_str() {
            "bad_cobs" | "bad_crc" | "unknown_type" | "overflow" => 1,
            _ => 0,
        };
        assert_eq!(*count, want, "{name}: {errors:?}");
    }
}
