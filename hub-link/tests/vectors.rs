//! Committed test vectors (`tests/vectors/v1.txt`): the exact wire bytes of version-1 messages.
//! Another implementation (the firmware's, a C or Python receiver) checks itself against them.
//! `HUB_LINK_WRITE_VECTORS=1 cargo test -p hub-link --test vectors` rewrites the file; a change of
//! its contents is a protocol change (docs/hub-link.md, "Compatibility").

use hub_link::{Deframer, Event, Header, Health, Message, PortHealth, FRAME_MAX};

fn vectors() -> Vec<(&'static str, Message<'static>)> {
    static RADAR: [u8; 48] = [
        0x02, 0x01, 0x04, 0x03, 0x06, 0x05, 0x08, 0x07, 0x02, 0x00, 0x03, 0x03, 0x30, 0x00, 0x00,
        0x00, 0x43, 0x68, 0x0A, 0x00, 0x07, 0x00, 0x00, 0x00, 0x78, 0x56, 0x34, 0x12, 0x00, 0x00,
        0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x0F, 0x0F, 0x0F, 0x0F, 0x0F,
        0x0F, 0x0F, 0x0F,
    ];
    static IMU: [u8; 10] = [0xFA, 0xFF, 0x36, 0x05, 0x10, 0x20, 0x02, 0x01, 0x02, 0x91];
    static LONG: [u8; 300] = {
        let mut a = [0u8; 300];
        let mut i = 0;
        while i < 300 {
            a[i] = (i % 255) as u8 + 1;
            i += 1;
        }
        a
    };
    let port = |k: u32| PortHealth {
        rx_bytes: 1000 * k,
        ring_overflow: 0,
        ring_high_water: 64 * k,
        uart_errors: 0,
        frames_ok: 10 * k,
        frames_bad: k,
        bytes_skipped: 40 * k,
        resyncs: k,
        frames_forwarded: 10 * k,
        frames_retracted: 0,
    };
    vec![
        (
            "radar frame 7, seq 0, t 1 s",
            Message::Radar {
                header: Header {
                    flags: 0,
                    seq: 0,
                    t_ns: 1_000_000_000,
                },
                bytes: &RADAR,
            },
        ),
        (
            "imu PacketCounter 258, seq 1, t 1.0025 s",
            Message::Imu {
                header: Header {
                    flags: 0,
                    seq: 1,
                    t_ns: 1_002_500_000,
                },
                bytes: &IMU,
            },
        ),
        (
            "radar body of 300 non-zero bytes (two COBS blocks), seq 0xFFFFFFFF",
            Message::Radar {
                header: Header {
                    flags: 0,
                    seq: u32::MAX,
                    t_ns: u64::MAX,
                },
                bytes: &LONG,
            },
        ),
        (
            "health, seq 2, t 2 s",
            Message::Health {
                header: Header {
                    flags: 0,
                    seq: 2,
                    t_ns: 2_000_000_000,
                },
                health: Health {
                    timer_hz: 12_000_000,
                    radar: port(1),
                    imu: port(2),
                    link_sent: 3,
                    link_dropped: 0,
                    link_dropped_bytes: 0,
                    link_high_water: 512,
                    stamps_merged: 0,
                    isr_max_per_byte: 70,
                    isr_clock: 2,
                    capacities: [8192, 2048, 16384],
                },
            },
        ),
    ]
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn render() -> String {
    let mut s = String::from(
        "# hub-link version 1 test vectors: '# name' then the serial frame (COBS + 0x00) in hex\n",
    );
    for (name, m) in vectors() {
        let mut w = Vec::new();
        m.encode_serial(&mut |b| w.push(b));
        s.push_str(&format!("# {name}\n{}\n", hex(&w)));
    }
    s
}

#[test]
fn committed_vectors_match_and_decode() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors/v1.txt");
    let now = render();
    if std::env::var_os("HUB_LINK_WRITE_VECTORS").is_some() {
        std::fs::write(path, &now).unwrap();
    }
    let committed = std::fs::read_to_string(path).expect("tests/vectors/v1.txt");
    assert_eq!(
        committed, now,
        "the encoder no longer writes the committed bytes"
    );
    let lines: Vec<&str> = committed.lines().filter(|l| !l.starts_with('#')).collect();
    for ((name, want), line) in vectors().into_iter().zip(lines) {
        let bytes: Vec<u8> = (0..line.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&line[i..i + 2], 16).unwrap())
            .collect();
        let mut d: Box<Deframer<FRAME_MAX>> = Box::default();
        let mut input = &bytes[..];
        assert_eq!(d.poll(&mut input), Event::Message(want), "{name}");
        assert!(input.is_empty());
    }
}
