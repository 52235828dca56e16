//! The IMU model: an MTi-1-like accelerometer and gyroscope, and its MTData2 byte stream.
//!
//! Each axis measures the truth plus white noise, a bias that wanders as a first-order
//! Gauss-Markov process (the datasheet's in-run bias stability), a bias random walk, and a
//! constant turn-on bias. The accelerometer measures specific force (acceleration minus
//! gravity) at the IMU's own origin, in the IMU frame; the gyroscope the IMU frame's angular
//! velocity.

use crate::rng::SimRng;
use imu_driver::{DataId, MtData2Writer, Value, BID_MASTER};
use nalgebra::Vector3;

/// Standard gravity used for the world \[m/s^2\] (world z up: g = (0, 0, −9.81)).
pub const GRAVITY: f64 = 9.81;

/// PacketCounter data id.
pub const ID_PACKET_COUNTER: DataId = DataId(0x1020);
/// SampleTimeFine data id (10 kHz ticks).
pub const ID_SAMPLE_TIME_FINE: DataId = DataId(0x1060);
/// Acceleration, Float32.
pub const ID_ACCELERATION: DataId = DataId(0x4020);
/// RateOfTurn, Float32.
pub const ID_RATE_OF_TURN: DataId = DataId(0x8020);
/// StatusWord.
pub const ID_STATUS_WORD: DataId = DataId(0xE020);
/// StatusWord sent with every sample: bit 0, self test passed.
pub const STATUS_WORD: u32 = 0x0000_0001;

/// Noise of one sensor triad (same on all three axes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseSpec {
    /// White noise density \[unit/√Hz\] (unit: rad/s for the gyro, m/s^2 for the accelerometer).
    pub white: f64,
    /// Bias instability: standard deviation of the Gauss-Markov bias \[unit\].
    pub bias_sigma: f64,
    /// Correlation time of the Gauss-Markov bias \[s\].
    pub bias_tau_s: f64,
    /// Bias random walk \[unit/√s\] (unit·√Hz).
    pub random_walk: f64,
    /// Turn-on bias, 1 σ \[unit\] (constant over a session).
    pub turn_on: f64,
}

impl NoiseSpec {
    /// The Allan deviation these parameters give at averaging time `tau` \[s\] \[unit\]: white
    /// noise N²/τ, the Gauss-Markov bias (IEEE Std 952 form) and the random walk K²τ/3.
    pub fn allan_deviation(&self, tau: f64) -> f64 {
        let white = self.white * self.white / tau;
        let rw = self.random_walk * self.random_walk * tau / 3.0;
        let t = self.bias_tau_s;
        let qc = 2.0 * self.bias_sigma * self.bias_sigma / t;
        let x = tau / t;
        let gm = qc * t * t / tau * (1.0 - (3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp()) / (2.0 * x));
        (white + rw + gm).sqrt()
    }
}

/// The IMU's noise: gyroscope and accelerometer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSpec {
    /// Gyroscope \[rad/s\].
    pub gyro: NoiseSpec,
    /// Accelerometer \[m/s^2\].
    pub accel: NoiseSpec,
}

impl ImuSpec {
    /// MTi-1 series datasheet figures: gyro 0.007 °/s/√Hz, 10 °/h in-run bias stability;
    /// accelerometer 120 µg/√Hz, 0.03 mg (30 µg) in-run bias stability. Random walks and turn-on
    /// biases are assumptions (see docs/simulator.md).
    pub fn mti1() -> ImuSpec {
        let deg = std::f64::consts::PI / 180.0;
        let ug = GRAVITY * 1e-6;
        ImuSpec {
            gyro: NoiseSpec {
                white: 0.007 * deg,
                bias_sigma: 10.0 / 3600.0 * deg,
                bias_tau_s: 100.0,
                random_walk: 2e-5 * deg,
                turn_on: 0.05 * deg,
            },
            accel: NoiseSpec {
                white: 120.0 * ug,
                bias_sigma: 30.0 * ug,
                bias_tau_s: 100.0,
                random_walk: 2.0 * ug,
                turn_on: 2000.0 * ug,
            },
        }
    }
}

impl ImuSpec {
    /// Xsens MTi-600 series (MTi-630 class) datasheet figures: gyro 0.007 °/s/√Hz, 8 °/h in-run
    /// bias stability; accelerometer 60 µg/√Hz, 10 µg in-run bias stability. Random walks and
    /// turn-on biases are assumptions, smaller than the MTi-1's (see docs/simulator.md).
    pub fn mti600() -> ImuSpec {
        let deg = std::f64::consts::PI / 180.0;
        let ug = GRAVITY * 1e-6;
        ImuSpec {
            gyro: NoiseSpec {
                white: 0.007 * deg,
                bias_sigma: 8.0 / 3600.0 * deg,
                bias_tau_s: 100.0,
                random_walk: 1e-5 * deg,
                turn_on: 0.03 * deg,
            },
            accel: NoiseSpec {
                white: 60.0 * ug,
                bias_sigma: 10.0 * ug,
                bias_tau_s: 100.0,
                random_walk: 1.0 * ug,
                turn_on: 1000.0 * ug,
            },
        }
    }

    /// A consumer MEMS IMU (Bosch BMI088 / TDK ICM-class): gyro 0.014 °/s/√Hz (BMI088), zero-rate
    /// offset ±1 °/s taken as 0.5 °/s 1 σ; accelerometer 175 µg/√Hz (BMI088), zero-g offset
    /// ±20 mg taken as 10 mg 1 σ; bias instability 20 °/h and 100 µg and the random walks are
    /// assumptions typical of such parts' Allan curves (the datasheets do not give them).
    pub fn mems() -> ImuSpec {
        let deg = std::f64::consts::PI / 180.0;
        let ug = GRAVITY * 1e-6;
        ImuSpec {
            gyro: NoiseSpec {
                white: 0.014 * deg,
                bias_sigma: 20.0 / 3600.0 * deg,
                bias_tau_s: 100.0,
                random_walk: 1e-4 * deg,
                turn_on: 0.5 * deg,
            },
            accel: NoiseSpec {
                white: 175.0 * ug,
                bias_sigma: 100.0 * ug,
                bias_tau_s: 100.0,
                random_walk: 10.0 * ug,
                turn_on: 10_000.0 * ug,
            },
        }
    }
}

/// IMU presets by name: noise and the device named in the session's metadata.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ImuGrade {
    /// Xsens MTi-1 series (the default): [`ImuSpec::mti1`].
    Mti1,
    /// Xsens MTi-600 series: [`ImuSpec::mti600`].
    Mti600,
    /// Consumer MEMS (BMI088 / ICM class): [`ImuSpec::mems`].
    Mems,
}

impl ImuGrade {
    /// All grades.
    pub const ALL: [ImuGrade; 3] = [ImuGrade::Mti1, ImuGrade::Mti600, ImuGrade::Mems];

    /// Name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ImuGrade::Mti1 => "mti1",
            ImuGrade::Mti600 => "mti600",
            ImuGrade::Mems => "mems",
        }
    }

    /// The noise of this grade.
    pub fn spec(self) -> ImuSpec {
        match self {
            ImuGrade::Mti1 => ImuSpec::mti1(),
            ImuGrade::Mti600 => ImuSpec::mti600(),
            ImuGrade::Mems => ImuSpec::mems(),
        }
    }

    /// The device written to the session's metadata.
    pub fn device(self) -> &'static str {
        match self {
            ImuGrade::Mti1 => "MTi-1 (simulated)",
            ImuGrade::Mti600 => "MTi-630 (simulated)",
            ImuGrade::Mems => "BMI088-class MEMS IMU (simulated, MTData2 stream)",
        }
    }

    /// The grade whose noise `spec` is, if any.
    pub fn of(spec: &ImuSpec) -> Option<ImuGrade> {
        ImuGrade::ALL.into_iter().find(|g| g.spec() == *spec)
    }
}

impl std::fmt::Display for ImuGrade {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ImuGrade {
    type Err = String;
    fn from_str(s: &str) -> Result<ImuGrade, String> {
        ImuGrade::ALL
            .into_iter()
            .find(|g| g.name() == s)
            .ok_or_else(|| format!("unknown IMU grade {s:?} (expected mti1, mti600 or mems)"))
    }
}

/// Dropped IMU messages: bursts that start and end at random (a two-state Markov chain, mean
/// burst [`GAP_BURST_S`]), so that on average `share` of the samples are never sent.
#[derive(Debug, Clone)]
pub struct Gaps {
    enter: f64,
    leave: f64,
    in_gap: bool,
    rng: SimRng,
}

/// Mean length of a burst of dropped IMU messages \[s\].
pub const GAP_BURST_S: f64 = 0.05;

impl Gaps {
    /// Gaps of mean share `share` (0-0.8) at `rate_hz` \[Hz\], drawn from `rng`.
    pub fn new(share: f64, rate_hz: f64, rng: SimRng) -> Gaps {
        let len = (GAP_BURST_S * rate_hz).max(1.0);
        let leave = 1.0 / len;
        Gaps {
            enter: share / (1.0 - share) * leave,
            leave,
            in_gap: false,
            rng,
        }
    }

    /// True when the next sample is dropped.
    pub fn drop_next(&mut self) -> bool {
        let p = if self.in_gap {
            1.0 - self.leave
        } else {
            self.enter
        };
        self.in_gap = self.rng.chance(p);
        self.in_gap
    }
}

/// The evolving errors of one triad.
#[derive(Debug, Clone)]
struct TriadState {
    spec: NoiseSpec,
    turn_on: Vector3<f64>,
    gm: Vector3<f64>,
    rw: Vector3<f64>,
}

impl TriadState {
    fn new(spec: NoiseSpec, rng: &mut SimRng) -> TriadState {
        let mut v = |s: f64| Vector3::new(s * rng.normal(), s * rng.normal(), s * rng.normal());
        TriadState {
            spec,
            turn_on: v(spec.turn_on),
            gm: v(spec.bias_sigma),
            rw: Vector3::zeros(),
        }
    }

    /// The bias now, then steps the bias processes by `dt` \[s\].
    fn measure(&mut self, truth: Vector3<f64>, dt: f64, rng: &mut SimRng) -> Vector3<f64> {
        let s = self.spec;
        let white = s.white / dt.sqrt();
        let out = truth
            + self.turn_on
            + self.gm
            + self.rw
            + Vector3::new(rng.normal(), rng.normal(), rng.normal()) * white;
        let phi = (-dt / s.bias_tau_s).exp();
        let gm_step = s.bias_sigma * (1.0 - phi * phi).sqrt();
        let rw_step = s.random_walk * dt.sqrt();
        for k in 0..3 {
            self.gm[k] = phi * self.gm[k] + gm_step * rng.normal();
            self.rw[k] += rw_step * rng.normal();
        }
        out
    }

    fn bias(&self) -> Vector3<f64> {
        self.turn_on + self.gm + self.rw
    }
}

/// An IMU: noise processes for both triads.
#[derive(Debug, Clone)]
pub struct Imu {
    gyro: TriadState,
    accel: TriadState,
    rng: SimRng,
}

/// One measured sample and the truth behind it (IMU frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Measured specific force \[m/s^2\].
    pub accel: Vector3<f64>,
    /// Measured angular velocity \[rad/s\].
    pub gyro: Vector3<f64>,
    /// Accelerometer bias at this sample \[m/s^2\].
    pub accel_bias: Vector3<f64>,
    /// Gyroscope bias at this sample \[rad/s\].
    pub gyro_bias: Vector3<f64>,
}

impl Imu {
    /// An IMU with `spec`, its biases drawn from `rng`.
    pub fn new(spec: ImuSpec, mut rng: SimRng) -> Imu {
        Imu {
            gyro: TriadState::new(spec.gyro, &mut rng),
            accel: TriadState::new(spec.accel, &mut rng),
            rng,
        }
    }

    /// Measures true specific force `f` \[m/s^2\] and rate `w` \[rad/s\]; `dt` is the sample
    /// interval \[s\].
    pub fn sample(&mut self, f: Vector3<f64>, w: Vector3<f64>, dt: f64) -> ImuSample {
        let (accel_bias, gyro_bias) = (self.accel.bias(), self.gyro.bias());
        let accel = self.accel.measure(f, dt, &mut self.rng);
        let gyro = self.gyro.measure(w, dt, &mut self.rng);
        ImuSample {
            accel,
            gyro,
            accel_bias,
            gyro_bias,
        }
    }
}

/// Encodes one MTData2 message: PacketCounter, SampleTimeFine, Acceleration, RateOfTurn,
/// StatusWord (Float32, the MTi-1's default precision).
pub fn encode(counter: u16, sample_time_fine: u32, s: &ImuSample) -> Vec<u8> {
    let mut buf = [0u8; 128];
    let mut w = MtData2Writer::new(&mut buf);
    let items = [
        (ID_PACKET_COUNTER, Value::PacketCounter(counter)),
        (ID_SAMPLE_TIME_FINE, Value::SampleTimeFine(sample_time_fine)),
        (
            ID_ACCELERATION,
            Value::Acceleration([s.accel.x, s.accel.y, s.accel.z]),
        ),
        (
            ID_RATE_OF_TURN,
            Value::RateOfTurn([s.gyro.x, s.gyro.y, s.gyro.z]),
        ),
        (ID_STATUS_WORD, Value::StatusWord(STATUS_WORD)),
    ];
    for (id, v) in &items {
        // The buffer holds all five items (60 B of payload): these cannot fail.
        let _ = w.value(*id, v);
    }
    let n = w.finish(BID_MASTER).unwrap_or(0);
    buf[..n].to_vec()
}

/// BaroPressure data id (u32, Pa).
pub const ID_BARO_PRESSURE: DataId = DataId(0x3010);

/// Encodes one pressure message as an MTi-100-class device sends it at its own rate:
/// PacketCounter, SampleTimeFine, BaroPressure (u32 \[Pa\]; `pa` rounded, clamped to u32).
pub fn encode_pressure(counter: u16, sample_time_fine: u32, pa: f64) -> Vec<u8> {
    let mut buf = [0u8; 32];
    let mut w = MtData2Writer::new(&mut buf);
    let pa = pa.round().clamp(0.0, f64::from(u32::MAX)) as u32;
    let items = [
        (ID_PACKET_COUNTER, Value::PacketCounter(counter)),
        (ID_SAMPLE_TIME_FINE, Value::SampleTimeFine(sample_time_fine)),
        (ID_BARO_PRESSURE, Value::BaroPressure(pa)),
    ];
    for (id, v) in &items {
        // 19 B of payload: these cannot fail.
        let _ = w.value(*id, v);
    }
    let n = w.finish(BID_MASTER).unwrap_or(0);
    buf[..n].to_vec()
}

/// Bytes of one encoded pressure message \[B\].
pub const PRESSURE_MESSAGE_LEN: usize = 4 + (3 + 2) + (3 + 4) + (3 + 4) + 1;

/// Standard-atmosphere pressure at altitude `h` \[m\] \[Pa\]:
/// p = 101325 (1 − 2.25577e-5 h)^5.25588.
pub fn standard_pressure(h: f64) -> f64 {
    101_325.0 * (1.0 - 2.25577e-5 * h).powf(5.25588)
}

/// Altitude of standard-atmosphere pressure `pa` \[Pa\] \[m\] (inverse of [`standard_pressure`]).
pub fn standard_altitude(pa: f64) -> f64 {
    (1.0 - (pa / 101_325.0).powf(1.0 / 5.25588)) / 2.25577e-5
}

/// Barometer white noise, 1 σ \[Pa\] (~0.1 m).
pub const BARO_NOISE_PA: f64 = 1.2;
/// Barometer bias random walk \[Pa/√s\] (weather and temperature drift).
pub const BARO_BIAS_WALK_PA: f64 = 0.1;
/// Start altitudes are drawn uniformly from 0 to this \[m\].
pub const BARO_MAX_START_ALTITUDE_M: f64 = 500.0;

/// A barometer at the IMU's origin: standard atmosphere from the true altitude, a random start
/// altitude, white noise, a bias random walk, whole pascals.
#[derive(Debug, Clone)]
pub struct Baro {
    /// Altitude of the world's z = 0 \[m\].
    pub start_altitude_m: f64,
    bias_pa: f64,
    rng: SimRng,
}

/// One barometer sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaroSample {
    /// Reported pressure \[Pa\] (whole pascals).
    pub pa: f64,
    /// Noise-free, bias-free pressure at the true altitude \[Pa\].
    pub true_pa: f64,
    /// Bias at this sample \[Pa\].
    pub bias_pa: f64,
    /// True altitude \[m\].
    pub altitude_m: f64,
}

impl Baro {
    /// A barometer whose start altitude comes from `rng` (its own stream).
    pub fn new(mut rng: SimRng) -> Baro {
        Baro {
            start_altitude_m: rng.uniform(0.0, BARO_MAX_START_ALTITUDE_M),
            bias_pa: 0.0,
            rng,
        }
    }

    /// Measures at world height `z` \[m\]; `dt` \[s\] is the sample interval (steps the bias).
    pub fn sample(&mut self, z: f64, dt: f64) -> BaroSample {
        let altitude_m = self.start_altitude_m + z;
        let true_pa = standard_pressure(altitude_m);
        let bias_pa = self.bias_pa;
        let pa = (true_pa + bias_pa + BARO_NOISE_PA * self.rng.normal()).round();
        self.bias_pa += BARO_BIAS_WALK_PA * dt.sqrt() * self.rng.normal();
        BaroSample {
            pa,
            true_pa,
            bias_pa,
            altitude_m,
        }
    }
}

/// Bytes of one encoded message \[B\].
pub const MESSAGE_LEN: usize = 4 + (3 + 2) + (3 + 4) + (3 + 12) + (3 + 12) + (3 + 4) + 1;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn message_has_the_documented_length_and_decodes() {
        let s = ImuSample {
            accel: Vector3::new(0.1, 0.2, 9.8),
            gyro: Vector3::new(0.01, -0.02, 0.03),
            accel_bias: Vector3::zeros(),
            gyro_bias: Vector3::zeros(),
        };
        let m = encode(65535, 123_456, &s);
        assert_eq!(m.len(), MESSAGE_LEN);
        let mut f = imu_driver::DeviceFramer::new();
        let mut input = &m[..];
        let imu_driver::Poll::Frame(frame) = f.poll(&mut input) else {
            panic!("no frame")
        };
        let Ok(imu_driver::Message::MtData2(d)) = imu_driver::Message::decode(&frame) else {
            panic!("not MTData2")
        };
        let smp = d.sample();
        assert_eq!(smp.packet_counter, Some(65535));
        assert_eq!(smp.sample_time_fine, Some(123_456));
        assert!((smp.acceleration.unwrap()[2] - 9.8).abs() < 1e-5);
    }

    #[test]
    fn pressure_message_decodes_and_atmosphere_inverts() {
        let m = encode_pressure(7, 99, 95_461.4);
        assert_eq!(m.len(), PRESSURE_MESSAGE_LEN);
        let mut f = imu_driver::DeviceFramer::new();
        let mut input = &m[..];
        let imu_driver::Poll::Frame(frame) = f.poll(&mut input) else {
            panic!("no frame")
        };
        let Ok(imu_driver::Message::MtData2(d)) = imu_driver::Message::decode(&frame) else {
            panic!("not MTData2")
        };
        let smp = d.sample();
        assert_eq!(smp.packet_counter, Some(7));
        assert_eq!(smp.sample_time_fine, Some(99));
        assert!(smp.acceleration.is_none());
        assert!(d
            .items()
            .any(|i| matches!(i.and_then(|i| i.value()), Ok(Value::BaroPressure(95_461)))));
        assert!((standard_pressure(0.0) - 101_325.0).abs() < 1e-9);
        assert!((standard_altitude(standard_pressure(432.1)) - 432.1).abs() < 1e-6);
        // About 12 Pa per metre near sea level.
        assert!((standard_pressure(0.0) - standard_pressure(1.0) - 12.0).abs() < 0.2);
    }

    #[test]
    fn allan_formula_limits() {
        let g = ImuSpec::mti1().gyro;
        // Short tau: white noise dominates.
        assert!((g.allan_deviation(0.01) / (g.white / 0.1) - 1.0).abs() < 0.01);
        // Around the correlation time the Gauss-Markov bias shows up.
        assert!(g.allan_deviation(200.0) > g.white / 200f64.sqrt() * 1.5);
    }
}
