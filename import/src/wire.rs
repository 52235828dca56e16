//! Imported samples re-encoded in the sensors' wire formats, so an imported session is decoded by
//! the same drivers as a recorded one (and `replay` can play it into ptys):
//!
//! - a radar scan -> one TI mmWave SDK 3.x out-of-box frame: points (TLV 1, float32 x y z
//!   velocity in TI axes), side info (TLV 7, SNR in 0.1 dB, noise 0) when the scan has SNR; the
//!   frame's timeCpuCycles counts the scan time at 200 MHz from the session start;
//! - an IMU sample -> one Xbus MTData2 message: PacketCounter, SampleTimeFine (the sample time at
//!   10 kHz from the session start), Acceleration and RateOfTurn in float64;
//! - a pressure sample -> one MTData2 message: PacketCounter, SampleTimeFine, BaroPressure (u32
//!   \[Pa\], as Xsens sends it).
//!
//! What this costs: IMU and pressure times are on the 100 us SampleTimeFine grid, pressure is
//! rounded to 1 Pa (about 8 cm of height), SNR to 0.1 dB; positions and Doppler are float32
//! (the radar's own precision).

use imu_driver::{DataId, MtData2Writer, Value, BID_MASTER};
use radar_driver::encode::{FrameBuilder, TlvOut};

/// Header version word of imported frames: mmWave SDK 3.5.0.4.
pub const SDK_VERSION: u32 = 0x0305_0004;
/// Header platform word of imported frames: IWR6843.
pub const PLATFORM: u32 = 0xA6843;
/// Rate of timeCpuCycles on SDK 3.x \[Hz\].
pub const CPU_HZ: f64 = 200e6;
/// SampleTimeFine rate \[Hz\].
pub const SAMPLE_TIME_HZ: f64 = 10_000.0;
/// Most points one imported frame carries (the radar driver's plausibility limit).
pub const MAX_POINTS: usize = radar_driver::plausible::DEFAULT_MAX_POINTS as usize;

const ID_PACKET_COUNTER: DataId = DataId(0x1020);
const ID_SAMPLE_TIME_FINE: DataId = DataId(0x1060);
/// Acceleration, float64, ENU.
const ID_ACCELERATION: DataId = DataId(0x4023);
/// RateOfTurn, float64, ENU.
const ID_RATE_OF_TURN: DataId = DataId(0x8023);
const ID_BARO_PRESSURE: DataId = DataId(0x3010);

/// timeCpuCycles of a scan at `t_s` seconds after the session start (wraps at 2^32).
pub fn cycles(t_s: f64) -> u32 {
    ((t_s * CPU_HZ).round() as i64).rem_euclid(1 << 32) as u32
}

/// SampleTimeFine of a sample at `t_s` seconds after the session start (wraps at 2^32).
pub fn sample_time_fine(t_s: f64) -> u32 {
    ((t_s * SAMPLE_TIME_HZ).round() as i64).rem_euclid(1 << 32) as u32
}

/// One radar frame: `points` are `[x, y, z, velocity]` in TI axes \[m, m/s\], `snr_db` one per
/// point when the scan has SNR.
pub fn radar_frame(
    frame_number: u32,
    t_s: f64,
    points: &[[f32; 4]],
    snr_db: Option<&[f64]>,
) -> Vec<u8> {
    let side: Vec<(i16, i16)> = snr_db
        .map(|s| {
            s.iter()
                .map(|db| {
                    (
                        (db * 10.0).round().clamp(0.0, f64::from(i16::MAX)) as i16,
                        0,
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    let mut b = FrameBuilder::oob(SDK_VERSION, PLATFORM, frame_number)
        .cycles(cycles(t_s))
        .points(points);
    if snr_db.is_some() {
        b = b.tlv(TlvOut::SideInfo(&side));
    }
    b.pad_byte = 0x0F;
    b.to_vec()
}

/// One IMU message: accelerometer \[m/s^2\] and gyroscope \[rad/s\] in the IMU's axes.
pub fn imu_message(counter: u16, t_s: f64, accel: [f64; 3], gyro: [f64; 3]) -> Vec<u8> {
    let mut buf = [0u8; 96];
    let mut w = MtData2Writer::new(&mut buf);
    // 4 + 5 + 7 + 27 + 27 + 1 = 71 B: the buffer holds them, so these cannot fail.
    let _ = w.value(ID_PACKET_COUNTER, &Value::PacketCounter(counter));
    let _ = w.value(
        ID_SAMPLE_TIME_FINE,
        &Value::SampleTimeFine(sample_time_fine(t_s)),
    );
    let _ = w.value(ID_ACCELERATION, &Value::Acceleration(accel));
    let _ = w.value(ID_RATE_OF_TURN, &Value::RateOfTurn(gyro));
    let n = w.finish(BID_MASTER).unwrap_or(0);
    buf[..n].to_vec()
}

/// One pressure message \[Pa\] (rounded to whole pascals, clamped to u32).
pub fn pressure_message(counter: u16, t_s: f64, pa: f64) -> Vec<u8> {
    let mut buf = [0u8; 32];
    let mut w = MtData2Writer::new(&mut buf);
    let _ = w.value(ID_PACKET_COUNTER, &Value::PacketCounter(counter));
    let _ = w.value(
        ID_SAMPLE_TIME_FINE,
        &Value::SampleTimeFine(sample_time_fine(t_s)),
    );
    let pa = pa.round().clamp(0.0, f64::from(u32::MAX)) as u32;
    let _ = w.value(ID_BARO_PRESSURE, &Value::BaroPressure(pa));
    let n = w.finish(BID_MASTER).unwrap_or(0);
    buf[..n].to_vec()
}

/// Bytes of one [`imu_message`] \[B\].
pub const IMU_MESSAGE_LEN: usize = 4 + (3 + 2) + (3 + 4) + (3 + 24) + (3 + 24) + 1;

/// The smallest common UART rate \[bit/s\] that sends `bytes` in at most half of `period_s`
/// (8N1: 10 bits a byte), from `rates`; the largest when none does.
pub fn baud_for(bytes: usize, period_s: f64, rates: &[u32]) -> u32 {
    rates
        .iter()
        .copied()
        .find(|&b| bytes as f64 * 10.0 / f64::from(b) <= 0.5 * period_s)
        .unwrap_or(rates.last().copied().unwrap_or(921_600))
}

/// UART rates the TI data port supports \[bit/s\].
pub const RADAR_BAUDS: &[u32] = &[921_600, 1_843_200, 3_125_000, 12_000_000];
/// UART rates Xsens devices support \[bit/s\].
pub const IMU_BAUDS: &[u32] = &[115_200, 230_400, 460_800, 921_600, 2_000_000, 4_000_000];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radar_frame_decodes_to_the_points_and_time() {
        let pts = [[1.0f32, 2.0, 0.5, -0.25], [-3.0, 4.0, 0.0, 1.5]];
        let bytes = radar_frame(7, 30.0, &pts, Some(&[12.34, 40.0]));
        let mut d = radar_driver::host::Decoder::new(radar_driver::host::DecoderConfig::default());
        let mut got = Vec::new();
        let mut keep = |f: &radar_driver::host::Decoded<'_, u32>| {
            got.push((
                f.frame_number,
                f.cloud
                    .points
                    .iter()
                    .map(|p| [p.x, p.y, p.z, p.velocity])
                    .collect::<Vec<_>>(),
                f.cloud.snr_db.clone(),
            ))
        };
        d.feed(&bytes, 0u32, &mut keep);
        d.finish(&mut keep);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, 7);
        assert_eq!(got[0].1, pts.to_vec());
        let snr = got[0].2.clone().unwrap();
        assert!(
            (snr[0] - 12.3).abs() < 1e-4 && (snr[1] - 40.0).abs() < 1e-4,
            "{snr:?}"
        );
        assert_eq!(u64::from(cycles(30.0)), 6_000_000_000u64 % (1 << 32));
    }

    #[test]
    fn imu_and_pressure_messages_decode() {
        let m = imu_message(3, 1.23456, [0.1, -0.2, 9.81], [0.01, 0.02, -0.03]);
        assert_eq!(m.len(), IMU_MESSAGE_LEN);
        let mut d = imu_driver::host::Decoder::new(imu_driver::TimeWrap::Pow32);
        let mut got = Vec::new();
        d.feed(&m, 0u32, |s| got.push((s.accel, s.gyro, s.sensor_s)));
        let p = pressure_message(4, 1.5, 101_325.4);
        let mut baro = Vec::new();
        d.feed_with_pressure(
            &p,
            1u32,
            |_| panic!("a pressure message is not an IMU sample"),
            |b| baro.push((b.pa, b.sensor_s)),
        );
        assert_eq!(baro, [(101_325.0, 1.5)], "whole pascals at their time");
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, [0.1, -0.2, 9.81]);
        assert_eq!(got[0].1, [0.01, 0.02, -0.03]);
        assert!((got[0].2 - 1.2346).abs() < 1e-9, "{}", got[0].2);
        assert_eq!((d.report().pressure, d.report().not_samples), (1, 0));
    }

    #[test]
    fn baud_is_the_smallest_that_keeps_up() {
        assert_eq!(baud_for(71, 0.01, IMU_BAUDS), 230_400);
        assert_eq!(baud_for(71, 0.0025, IMU_BAUDS), 921_600);
        assert_eq!(baud_for(4000, 0.1, RADAR_BAUDS), 921_600);
        assert_eq!(baud_for(40_000, 0.05, RADAR_BAUDS), 12_000_000);
    }
}
