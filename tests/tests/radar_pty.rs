//! The radar's serial paths on real pseudo-terminals: the CLI-port upload against a scripted
//! device, and the data-port reader stamping frames with the host time of their last byte.

use radar_driver::encode::FrameBuilder;
use radar_driver::host::{CliError, CliPort, FrameReader, ReadEvent};
use radar_driver::LayoutHint;
use serialport::{SerialPort, TTYPort};
use std::io::{Read, Write};
use std::thread;
use std::time::{Duration, Instant};

/// A scripted radar CLI: echoes each line, answers per the script, prints the prompt.
fn fake_radar(
    mut dev: TTYPort,
    answer: fn(&str) -> Option<String>,
) -> thread::JoinHandle<Vec<String>> {
    thread::spawn(move || {
        let mut seen = Vec::new();
        let mut line = Vec::new();
        let mut b = [0u8; 1];
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            match dev.read(&mut b) {
                Ok(1) if b[0] == b'\n' => {
                    let text = String::from_utf8_lossy(&line).trim().to_string();
                    line.clear();
                    let _ = write!(dev, "{text}\r\n");
                    if let Some(reply) = answer(&text) {
                        let _ = write!(dev, "{reply}\r\nmmwDemo:/>");
                    }
                    let quit = text == "sensorStart";
                    seen.push(text);
                    if quit {
                        // Closing the master discards what the host has not read yet: linger.
                        thread::sleep(Duration::from_millis(300));
                        break;
                    }
                }
                Ok(1) => line.push(b[0]),
                _ => {}
            }
        }
        seen
    })
}

fn pair() -> (TTYPort, Box<dyn SerialPort>) {
    let (mut master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
    master.set_timeout(Duration::from_millis(20)).unwrap();
    let path = slave.name().expect("slave path");
    let port = serialport::new(&path, 115_200)
        .timeout(Duration::from_millis(20))
        .open()
        .expect("open slave");
    std::mem::forget(slave); // keep the slave side open for the port opened by path
    (master, port)
}

const CFG: &str =
    "% a comment\nsensorStop\nflushCfg\nprofileCfg 0 60 7 3 39 0 0 70 1 256 7200 0 0 30\n\
                   trackingCfg 1 2 3\nframeCfg 0 0 16 0 100 1 0\nsensorStart\n";

#[test]
fn upload_sends_every_line_and_reads_every_answer() {
    let (master, port) = pair();
    let dev = fake_radar(master, |l| {
        Some(match l {
            l if l.starts_with('%') => "Skipped".into(),
            l if l.starts_with("trackingCfg") => "Ignored: not supported\r\nDone".into(),
            _ => "Done".into(),
        })
    });
    let mut cli = CliPort::new(port, Duration::from_secs(2));
    let report = cli.upload(CFG).expect("upload");
    let seen = dev.join().unwrap();
    assert_eq!(seen.len(), 7);
    assert_eq!(seen[0], "% a comment");
    assert_eq!(seen.last().map(String::as_str), Some("sensorStart"));
    assert_eq!(report.skipped, 1);
    assert_eq!(report.done, 5);
    assert_eq!(report.ignored, vec![(5, "not supported".to_string())]);
}

#[test]
fn upload_adds_the_lifecycle_commands_a_file_lacks() {
    let (master, port) = pair();
    let dev = fake_radar(master, |_| Some("Done".into()));
    let mut cli = CliPort::new(port, Duration::from_secs(2));
    cli.upload("frameCfg 0 0 16 0 100 1 0\n").expect("upload");
    assert_eq!(
        dev.join().unwrap(),
        vec![
            "sensorStop",
            "flushCfg",
            "frameCfg 0 0 16 0 100 1 0",
            "sensorStart"
        ]
    );
}

#[test]
fn a_rejected_line_is_named_with_its_code() {
    let (master, port) = pair();
    let _dev = fake_radar(master, |l| {
        Some(if l.starts_with("profileCfg") {
            "Error -2".into()
        } else {
            "Done".into()
        })
    });
    let mut cli = CliPort::new(port, Duration::from_secs(2));
    match cli.upload(CFG) {
        Err(CliError::Rejected {
            line_no,
            code,
            line,
            ..
        }) => {
            assert_eq!((line_no, code), (4, -2));
            assert!(line.starts_with("profileCfg"));
        }
        other => panic!("expected a rejection, got {other:?}"),
    }
}

#[test]
fn a_silent_device_times_out_on_the_first_line() {
    let (master, port) = pair();
    let _dev = fake_radar(master, |_| None);
    let mut cli = CliPort::new(port, Duration::from_millis(300));
    let t = Instant::now();
    match cli.upload(CFG) {
        Err(e @ CliError::Timeout { line_no: 1, .. }) => {
            assert!(e.to_string().contains("no Done/Error"))
        }
        other => panic!("expected a timeout, got {other:?}"),
    }
    assert!(t.elapsed() < Duration::from_secs(5));
}

#[test]
fn data_port_frames_carry_the_host_time_of_their_last_byte() {
    let (mut master, port) = pair();
    let frames: Vec<Vec<u8>> = (1..=5)
        .map(|n| {
            FrameBuilder::oob(0x0303_0002, 0xA6843, n)
                .points(&[[1.0, 2.0, 0.0, 0.5]; 4])
                .to_vec()
        })
        .collect();
    let sent = frames.clone();
    let writer = thread::spawn(move || {
        let mut last_byte_at = Vec::new();
        for f in &sent {
            // First half, a pause, then the rest: the frame is complete only at the second write.
            let (a, b) = f.split_at(f.len() / 2);
            master.write_all(a).unwrap();
            thread::sleep(Duration::from_millis(30));
            last_byte_at.push(Instant::now());
            master.write_all(b).unwrap();
            thread::sleep(Duration::from_millis(30));
        }
        thread::sleep(Duration::from_millis(100));
        last_byte_at
    });
    let mut reader = FrameReader::new(port, LayoutHint::Auto, 4096);
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    while got.len() < frames.len() && Instant::now() < deadline {
        match reader.next_event().unwrap() {
            Some(ReadEvent::Frame(f)) => {
                got.push((f.header().frame_number, f.host_time, f.as_bytes().to_vec()))
            }
            Some(ReadEvent::Dropped { error, .. }) => panic!("dropped: {error}"),
            Some(ReadEvent::Idle) => {}
            None => break,
        }
    }
    let last_byte_at = writer.join().unwrap();
    assert_eq!(
        got.iter().map(|g| g.0).collect::<Vec<_>>(),
        vec![1, 2, 3, 4, 5]
    );
    for (i, (_, host_time, bytes)) in got.iter().enumerate() {
        assert_eq!(bytes, &frames[i]);
        assert!(
            *host_time >= last_byte_at[i],
            "frame {i} stamped before its last byte was sent"
        );
        assert!(
            host_time.duration_since(last_byte_at[i]) < Duration::from_millis(25),
            "stamp is late"
        );
    }
}
