//! The configuration state machine against a scripted fake device on a pseudo-terminal: the
//! driver opens the real serial path; a thread on the other end plays the device (acks, an Error
//! reply, MTData2 still streaming when GoToConfig arrives, a reset with WakeUp, silence).
#![cfg(unix)]

use imu_driver::host::serialport::{self, SerialPort, TTYPort};
use imu_driver::host::{ControlStep, Device, DeviceError, Plan, RateDifference};
use imu_driver::message::mid;
use imu_driver::{
    encode_frame, Baudrate, DataId, DeviceFramer, ErrorCode, MtData2Writer, OutputSetting, Poll,
    Value,
};
use std::io::{ErrorKind, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::{self, JoinHandle};
use std::time::Duration;

/// How the fake device behaves.
#[derive(Clone, Copy, Default)]
struct Script {
    /// Streams MTData2 from the start, and 3 more frames after GoToConfig before the ack.
    streaming: bool,
    /// Answers SetOutputConfiguration with an Error of this code.
    reject_outputs: Option<u8>,
    /// Never answers.
    silent: bool,
    /// Grants at most this rate [Hz] (other than "max").
    max_rate: u16,
    /// Answers ReqProductCode with this (default: an MTi-G-710's).
    product: Option<&'static str>,
}

struct FakeDevice {
    port: TTYPort,
    script: Script,
    counter: u16,
    streaming: bool,
    received: Vec<u8>,
}

impl FakeDevice {
    fn send(&mut self, mid: u8, payload: &[u8]) {
        let mut buf = vec![0u8; payload.len() + 7];
        let n = encode_frame(&mut buf, 0xFF, mid, payload).unwrap();
        self.port.write_all(&buf[..n]).unwrap();
    }

    fn stream_one(&mut self) {
        let mut buf = [0u8; 64];
        let mut w = MtData2Writer::new(&mut buf);
        w.value(DataId(0x1020), &Value::PacketCounter(self.counter))
            .unwrap();
        w.value(
            DataId(0x1060),
            &Value::SampleTimeFine(u32::from(self.counter) * 100),
        )
        .unwrap();
        w.value(DataId(0x4020), &Value::Acceleration([0.0, 0.0, 9.81]))
            .unwrap();
        w.value(DataId(0x8020), &Value::RateOfTurn([0.0, 0.0, 0.01]))
            .unwrap();
        let n = w.finish(0xFF).unwrap();
        self.port.write_all(&buf[..n]).unwrap();
        self.counter = self.counter.wrapping_add(1);
    }

    fn handle(&mut self, mid: u8, payload: &[u8]) {
        self.received.push(mid);
        if self.script.silent {
            return;
        }
        match mid {
            mid::GO_TO_CONFIG => {
                if self.streaming {
                    for _ in 0..3 {
                        self.stream_one();
                    }
                    self.streaming = false;
                }
                self.send(mid::GO_TO_CONFIG_ACK, &[]);
            }
            mid::REQ_DID => self.send(mid::DEVICE_ID, &[0x03, 0x70, 0x12, 0x34]),
            mid::REQ_PRODUCT_CODE => {
                let code = self.script.product.unwrap_or("MTi-G-710-2A8G4   ");
                self.send(mid::PRODUCT_CODE, code.as_bytes());
            }
            mid::REQ_FW_REV => self.send(mid::FIRMWARE_REV, &[1, 8, 2, 0, 0, 0, 7, 0, 0, 0, 9]),
            mid::SET_OUTPUT_CONFIGURATION => match self.script.reject_outputs {
                Some(code) => self.send(mid::ERROR, &[code]),
                None => {
                    let mut ack = payload.to_vec();
                    for pair in ack.chunks_exact_mut(4) {
                        let rate = u16::from_be_bytes([pair[2], pair[3]]);
                        if rate != 0xFFFF && rate > self.script.max_rate {
                            pair[2..].copy_from_slice(&self.script.max_rate.to_be_bytes());
                        }
                    }
                    self.send(mid::OUTPUT_CONFIGURATION, &ack);
                }
            },
            mid::SET_BAUDRATE => self.send(mid::SET_BAUDRATE_ACK, &[]),
            mid::RESET => {
                self.send(mid::RESET_ACK, &[]);
                thread::sleep(Duration::from_millis(20));
                self.send(mid::WAKE_UP, &[]);
            }
            mid::GO_TO_MEASUREMENT => {
                self.send(mid::GO_TO_MEASUREMENT_ACK, &[]);
                self.streaming = true;
            }
            _ => {}
        }
    }

    fn run(mut self, stop: Arc<AtomicBool>) -> Vec<u8> {
        self.port.set_timeout(Duration::from_millis(2)).unwrap();
        let mut framer = DeviceFramer::new();
        let mut buf = [0u8; 1024];
        while !stop.load(Ordering::Relaxed) {
            if self.streaming {
                self.stream_one();
            }
            let n = match self.port.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == ErrorKind::TimedOut => continue,
                Err(_) => break,
            };
            let mut input = &buf[..n];
            let mut frames = Vec::new();
            loop {
                match framer.poll(&mut input) {
                    Poll::Frame(f) => frames.push((f.mid(), f.payload().to_vec())),
                    Poll::Dropped { .. } => {}
                    Poll::NeedMore => break,
                }
            }
            for (mid, payload) in frames {
                self.handle(mid, &payload);
            }
        }
        self.received
    }
}

/// A pty with a fake device on the master side and the driver's port opened by path.
struct Rig {
    stop: Arc<AtomicBool>,
    device: Option<JoinHandle<Vec<u8>>>,
    _slave: TTYPort,
    port: Option<Box<dyn SerialPort>>,
    /// The driver side's path.
    path: String,
}

impl Rig {
    fn new(script: Script) -> Self {
        let (master, slave) = TTYPort::pair().expect("pty pair");
        let path = slave.name().expect("pty path");
        let port = serialport::new(&path, 115_200)
            .timeout(Duration::from_millis(10))
            .open()
            .expect("open pty by path");
        let stop = Arc::new(AtomicBool::new(false));
        let fake = FakeDevice {
            port: master,
            script,
            counter: 0,
            streaming: script.streaming,
            received: Vec::new(),
        };
        let s = stop.clone();
        let device = Some(thread::spawn(move || fake.run(s)));
        Self {
            stop,
            device,
            _slave: slave,
            port: Some(port),
            path,
        }
    }

    fn device(&mut self) -> Device<Box<dyn SerialPort>> {
        Device::new(self.port.take().unwrap()).with_timeout(Duration::from_millis(1500))
    }

    /// Stops the fake device; returns the MIDs it received.
    fn finish(mut self) -> Vec<u8> {
        self.stop.store(true, Ordering::Relaxed);
        self.device.take().unwrap().join().unwrap()
    }
}

fn outputs() -> Vec<OutputSetting> {
    let s = |id, rate_hz| OutputSetting {
        id: DataId(id),
        rate_hz,
    };
    vec![
        s(0x1020, 0xFFFF),
        s(0x1060, 0xFFFF),
        s(0x4020, 400),
        s(0x8020, 400),
        s(0xE020, 0xFFFF),
    ]
}

#[test]
fn configures_a_streaming_device_and_reports_rate_differences() {
    let mut rig = Rig::new(Script {
        streaming: true,
        max_rate: 100,
        ..Script::default()
    });
    let mut dev = rig.device();
    // Let some MTData2 pile up before we start, as on a real port.
    thread::sleep(Duration::from_millis(30));
    let plan = Plan {
        outputs: outputs(),
        baudrate: None,
        measure: true,
    };
    let report = dev.configure(&plan).expect("configure");
    assert_eq!(report.device_id, 0x0370_1234);
    assert_eq!(report.product_code, "MTi-G-710-2A8G4");
    assert_eq!(report.firmware.to_string(), "1.8.2 build 7 rev 9");
    assert!(
        report.other_frames >= 3,
        "MTData2 skipped while waiting: {}",
        report.other_frames
    );
    let out = report.outputs.expect("output report");
    assert_eq!(
        out.differences,
        vec![
            RateDifference {
                id: DataId(0x4020),
                requested: Some(400),
                actual: Some(100)
            },
            RateDifference {
                id: DataId(0x8020),
                requested: Some(400),
                actual: Some(100)
            },
        ]
    );
    // Measurement mode: MTData2 flows again through the same reader.
    let mut seen = 0;
    while seen < 3 {
        if let Ok(Some(imu_driver::host::Event::Frame { frame, .. })) = dev.reader().next_event() {
            if frame.mid() == mid::MTDATA2 {
                seen += 1;
            }
        }
    }
    drop(dev);
    let received = rig.finish();
    let expected = [
        mid::GO_TO_CONFIG,
        mid::REQ_DID,
        mid::REQ_PRODUCT_CODE,
        mid::REQ_FW_REV,
        mid::SET_OUTPUT_CONFIGURATION,
        mid::GO_TO_MEASUREMENT,
    ];
    assert_eq!(received, expected);
}

#[test]
fn an_error_reply_fails_the_step_that_caused_it() {
    let mut rig = Rig::new(Script {
        reject_outputs: Some(0x21),
        max_rate: 400,
        ..Script::default()
    });
    let mut dev = rig.device();
    let plan = Plan {
        outputs: outputs(),
        baudrate: None,
        measure: true,
    };
    let err = dev
        .configure(&plan)
        .expect_err("the device rejects the outputs");
    match &err {
        DeviceError::Rejected { step, code, .. } => {
            assert_eq!(*step, ControlStep::SetOutputConfiguration);
            assert_eq!(*code, ErrorCode::InvalidParameter);
        }
        other => panic!("unexpected {other:?}"),
    }
    assert!(err
        .to_string()
        .starts_with("SetOutputConfiguration: device replied Error 0x21"));
    drop(dev);
    let received = rig.finish();
    assert_eq!(
        received.last(),
        Some(&mid::SET_OUTPUT_CONFIGURATION),
        "stopped there"
    );
}

#[test]
fn a_silent_device_times_out_naming_the_step() {
    let mut rig = Rig::new(Script {
        silent: true,
        ..Script::default()
    });
    let mut dev = rig.device().with_timeout(Duration::from_millis(300));
    let started = std::time::Instant::now();
    let err = dev.go_to_config().expect_err("nobody answers");
    let waited = started.elapsed();
    assert!(
        matches!(
            err,
            DeviceError::Timeout {
                step: ControlStep::GoToConfig,
                ..
            }
        ),
        "{err:?}"
    );
    assert!(err.to_string().starts_with("GoToConfig: no reply within"));
    assert!(
        waited >= Duration::from_millis(300) && waited < Duration::from_secs(3),
        "{waited:?}"
    );
    drop(dev);
    let received = rig.finish();
    assert_eq!(
        received,
        vec![mid::GO_TO_CONFIG; 3],
        "GoToConfig resent three times"
    );
}

#[test]
fn baud_change_resets_and_answers_the_wake_up() {
    let mut rig = Rig::new(Script {
        max_rate: 400,
        ..Script::default()
    });
    let mut dev = rig.device();
    dev.go_to_config().unwrap();
    dev.change_baudrate(Baudrate::B921600).unwrap();
    dev.go_to_measurement().unwrap();
    drop(dev);
    let received = rig.finish();
    assert_eq!(
        received,
        vec![
            mid::GO_TO_CONFIG,
            mid::SET_BAUDRATE,
            mid::RESET,
            mid::WAKE_UP_ACK,
            mid::GO_TO_MEASUREMENT
        ]
    );
}

/// `milliego run` on a live Xsens it configures: the product code the device answers picks the
/// filter's IMU preset (as a session's device name does), and a name the user gives wins.
#[test]
fn a_live_run_names_the_imu_by_its_product_code() {
    use milliego_runtime::estimator::EstimatorKind;
    use milliego_runtime::pipeline::{run, Devices, Input, RunConfig};
    let live = |product: &'static str, given: Option<&str>| {
        let mut rig = Rig::new(Script {
            product: Some(product),
            max_rate: 400,
            ..Script::default()
        });
        // The runtime opens the port by its path.
        drop(rig.port.take());
        let input = Input::Devices(Devices {
            imu: Some(rig.path.clone()),
            imu_baud: 115_200,
            configure: true,
            ..Devices::default()
        });
        let cfg = RunConfig {
            estimator: EstimatorKind::Imu,
            imu_device: given.map(String::from),
            duration_s: Some(0.5),
            ..RunConfig::default()
        };
        let summary = run(&input, &cfg, Arc::new(AtomicBool::new(false))).expect("live run");
        let mids = rig.finish();
        (summary.report, mids)
    };
    let (report, mids) = live("MTi-630-2A5G4       ", None);
    assert_eq!(
        mids,
        [
            mid::GO_TO_CONFIG,
            mid::REQ_PRODUCT_CODE,
            mid::GO_TO_MEASUREMENT
        ],
        "the run's requests"
    );
    assert_eq!(
        report.imu_noise,
        "mti600, from the IMU device \"MTi-630-2A5G4\""
    );
    assert!(
        report.frames_in.imu > 0,
        "no sample read after the configuration"
    );
    let (report, _) = live("MTi-3-8A7G6", None);
    assert_eq!(
        report.imu_noise,
        "mti1, from the IMU device \"MTi-3-8A7G6\""
    );
    let (report, _) = live("MTi-630-2A5G4", Some("BMI088"));
    assert_eq!(report.imu_noise, "mems, from the IMU device \"BMI088\"");
}
