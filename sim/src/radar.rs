//! The radar model: an AWR1843-like FMCW radar with the out-of-box demo's detection chain.
//!
//! Per frame: a grid of rays over the field of view finds the surfaces in view (diffuse return
//! ∝ cos θ, specular return only near normal incidence), edge and corner scatterers in line of
//! sight add point returns (∝ RCS / R⁴), each return fades (exponential power), a CFAR-like
//! threshold keeps the strong ones, and returns closer than the range window and the angular
//! resolution (15° azimuth, 58° elevation) merge into one point. Outliers are then added at the
//! configured share: mirror ghosts of real points behind walls, multipath returns at a longer range
//! along a real point's ray, and false alarms. Every point carries a Doppler radial velocity
//! (from the true sensor motion, static world) plus noise, quantised to the Doppler bin.

use crate::rng::SimRng;
use crate::world::World;
use crate::SimError;
use nalgebra::{UnitQuaternion, Vector3};
use radar_driver::cfg::{Derived, RadarConfig};
use radar_driver::encode::{FrameBuilder, TlvOut};

/// Header version word of the frames: mmWave SDK 3.5.0.4.
pub const SDK_VERSION: u32 = 0x0305_0004;
/// Header platform word: AWR1843.
pub const PLATFORM: u32 = 0xA1843;
/// Rate of the timeCpuCycles counter (R4F PMU, SDK 3.x) \[Hz\].
pub const CPU_HZ: f64 = 200e6;

/// The chirp configuration the simulator runs (a real AWR1843 .cfg for SDK 3.x, 3 TX x 4 RX,
/// 3.75 GHz sampled bandwidth: 4 cm range bins, 10.2 m range, ±4.3 m/s, 64 Doppler bins), with
/// the frame period for `frame_hz` \[Hz\].
pub fn cfg_text(frame_hz: f64) -> String {
    let period_ms = 1000.0 / frame_hz;
    format!(
        "% milliego sim: AWR1843, mmWave SDK 3.5 out-of-box demo, 3 TX x 4 RX (12 virtual antennas)\n\
% 60 MHz/us x 62.5 us sampled = 3.75 GHz: 4.0 cm range bins, 10.24 m max range (complex 1x)\n\
% 64 loops x 3 TX, Tc = 73.5 us: 0.134 m/s Doppler bins, +-4.3 m/s\n\
% frame period {period_ms:.6} ms ({frame_hz} Hz); points + side info + stats on the data port\n\
sensorStop\n\
flushCfg\n\
dfeDataOutputMode 1\n\
channelCfg 15 7 0\n\
adcCfg 2 1\n\
adcbufCfg -1 0 1 1 1\n\
profileCfg 0 77 7 3 66.5 0 0 60 1 256 4096 0 0 30\n\
chirpCfg 0 0 0 0 0 0 0 1\n\
chirpCfg 1 1 0 0 0 0 0 4\n\
chirpCfg 2 2 0 0 0 0 0 2\n\
frameCfg 0 2 64 0 {period_ms:.6} 1 0\n\
lowPower 0 0\n\
guiMonitor -1 1 0 0 0 0 1\n\
cfarCfg -1 0 2 8 4 3 0 15 1\n\
cfarCfg -1 1 0 4 2 3 1 15 1\n\
multiObjBeamForming -1 1 0.5\n\
clutterRemoval -1 0\n\
calibDcRangeSig -1 0 -5 8 256\n\
extendedMaxVelocity -1 0\n\
lvdsStreamCfg -1 0 0 0\n\
compRangeBiasAndRxChanPhase 0.0 1 0 -1 0 1 0 -1 0 1 0 -1 0 1 0 -1 0 1 0 -1 0 1 0 -1 0\n\
measureRangeBiasAndRxChanPhase 0 1.5 0.2\n\
CQRxSatMonitor 0 3 4 63 0\n\
CQSigImgMonitor 0 127 4\n\
analogMonitor 0 0\n\
aoaFovCfg -1 -60 60 -20 20\n\
cfarFovCfg -1 0 0.25 10.0\n\
cfarFovCfg -1 1 -4.3 4.3\n\
calibData 0 0 0\n\
sensorStart\n"
    )
}

/// The long-range chirp configuration of outdoor scenes: [`cfg_text`] with a 15 MHz/µs slope
/// (0.94 GHz sampled: 16 cm range bins, 41 m max range), the same chirp timing (so the same
/// Doppler bins, ±4.3 m/s) and the CFAR range window opened to 40 m.
pub fn cfg_text_outdoor(frame_hz: f64) -> String {
    cfg_text(frame_hz)
        .replace(
            "% 60 MHz/us x 62.5 us sampled = 3.75 GHz: 4.0 cm range bins, 10.24 m max range (complex 1x)",
            "% outdoor: 15 MHz/us x 62.5 us sampled = 0.94 GHz: 16 cm range bins, 40.96 m max range (complex 1x)",
        )
        .replace(
            "profileCfg 0 77 7 3 66.5 0 0 60 1 256 4096 0 0 30",
            "profileCfg 0 77 7 3 66.5 0 0 15 1 256 4096 0 0 30",
        )
        .replace("cfarFovCfg -1 0 0.25 10.0", "cfarFovCfg -1 0 0.25 40.0")
}

/// The chirp configuration of a car outdoors: short chirps so that car speeds do not alias.
/// 30 MHz/µs, 128 samples at 8 Msps (0.48 GHz sampled: 31 cm range bins, 40 m max range),
/// idle 5 µs + ramp end 22 µs per chirp, 64 loops x 3 TX: 81 µs per loop, ±12 m/s in 0.375 m/s
/// Doppler bins; the CFAR windows opened to 40 m and ±12 m/s.
pub fn cfg_text_vehicle(frame_hz: f64) -> String {
    cfg_text(frame_hz)
        .replace(
            "% 60 MHz/us x 62.5 us sampled = 3.75 GHz: 4.0 cm range bins, 10.24 m max range (complex 1x)",
            "% vehicle: 30 MHz/us x 16 us sampled = 0.48 GHz: 31 cm range bins, 40 m max range (complex 1x)",
        )
        .replace(
            "% 64 loops x 3 TX, Tc = 73.5 us: 0.134 m/s Doppler bins, +-4.3 m/s",
            "% 64 loops x 3 TX, Tc = 27 us: 0.375 m/s Doppler bins, +-12 m/s",
        )
        .replace(
            "profileCfg 0 77 7 3 66.5 0 0 60 1 256 4096 0 0 30",
            "profileCfg 0 77 5 3 22 0 0 30 1 128 8000 0 0 30",
        )
        .replace("cfarFovCfg -1 0 0.25 10.0", "cfarFovCfg -1 0 0.25 40.0")
        .replace("cfarFovCfg -1 1 -4.3 4.3", "cfarFovCfg -1 1 -12.0 12.0")
        .replace("calibDcRangeSig -1 0 -5 8 256", "calibDcRangeSig -1 0 -5 8 128")
}

/// Why a point is in the cloud.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PointClass {
    /// A real surface or scatterer, at its true place (up to resolution and noise).
    Inlier,
    /// The mirror image of a real point in a wall: appears behind the wall.
    Mirror,
    /// A multipath return along a real point's ray, at a longer range and wrong Doppler.
    Multipath,
    /// A false alarm (noise, clutter).
    Clutter,
    /// Near-field leakage: a spurious return within 1 m, fixed in the radar frame, zero Doppler
    /// (TX-RX coupling, the mount's own structure).
    Leakage,
}

impl PointClass {
    /// Name in `radar_truth.csv`.
    pub fn name(self) -> &'static str {
        match self {
            PointClass::Inlier => "inlier",
            PointClass::Mirror => "mirror",
            PointClass::Multipath => "multipath",
            PointClass::Clutter => "clutter",
            PointClass::Leakage => "leakage",
        }
    }
}

/// One point of a simulated frame (radar frame: x right, y boresight, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimPoint {
    /// Reported position \[m\].
    pub xyz: [f32; 3],
    /// Reported radial velocity \[m/s\] (positive: moving away).
    pub v: f32,
    /// Reported SNR \[dB\].
    pub snr_db: f64,
    /// Reported noise level \[dB\].
    pub noise_db: f64,
    /// Why the point is there.
    pub class: PointClass,
    /// Where the return really comes from (apparent position for ghosts) \[m\].
    pub true_xyz: Vector3<f64>,
    /// Noise-free radial velocity \[m/s\] (for inliers and mirror ghosts: −v_sensor · ray).
    pub true_v: f64,
}

/// The radar model's parameters (defaults: see docs/simulator.md).
#[derive(Debug, Clone)]
pub struct RadarModel {
    /// The .cfg text it runs.
    pub cfg: String,
    /// What the .cfg implies (range bins, Doppler bins, frame period).
    pub derived: Derived,
    /// Azimuth field of view, each side \[deg\].
    pub fov_az_deg: f64,
    /// Elevation field of view, each side \[deg\].
    pub fov_el_deg: f64,
    /// Azimuth resolution \[deg\].
    pub az_res_deg: f64,
    /// Elevation resolution \[deg\].
    pub el_res_deg: f64,
    /// Range window within which returns merge (CFAR guard cells + peak grouping) \[m\].
    pub merge_range_m: f64,
    /// Detection threshold on the faded SNR \[dB\].
    pub threshold_db: f64,
    /// Surface return scale (SNR of a unit reflector at 1 m per ray) \[dB\].
    pub surface_gain_db: f64,
    /// Point-scatterer return scale (SNR of 1 m^2 at 1 m) \[dB\].
    pub point_gain_db: f64,
    /// Share of outliers in the cloud (the paper: ~75 %; used clamped to 0-0.95).
    pub outlier_share: f64,
    /// Doppler measurement noise before quantisation, 1 σ \[m/s\].
    pub doppler_noise_mps: f64,
    /// Most points per frame.
    pub max_points: usize,
    /// Fewest points per frame (false alarms fill up).
    pub min_points: usize,
    /// Noise floor reported in the side info \[dB\].
    pub noise_floor_db: f64,
    /// Ray grid step \[deg\].
    pub ray_step_deg: f64,
    /// Farthest return modelled \[m\] (also capped by the .cfg's maximum range).
    pub max_range_m: f64,
    /// One chirp's time, idle + ramp end \[s\] (as the .cfg's profileCfg sets it).
    pub chirp_time_s: f64,
    /// Coarse Doppler: reported radial velocities are multiples of this step \[m/s\] instead of
    /// the .cfg's Doppler bin (0: off, the bin).
    pub doppler_step_mps: f64,
}

impl RadarModel {
    /// The model at `frame_hz` \[Hz\] (10-30).
    pub fn new(frame_hz: f64) -> Result<RadarModel, SimError> {
        RadarModel::with_cfg(frame_hz, cfg_text)
    }

    /// The model for open outdoor scenes at `frame_hz` \[Hz\] (10-30): the long-range .cfg
    /// ([`cfg_text_outdoor`], 40 m), fewer outliers (40 %: no walls to mirror or bounce off)
    /// and a floor of 3 points per frame instead of 5.
    pub fn outdoor(frame_hz: f64) -> Result<RadarModel, SimError> {
        let mut m = RadarModel::with_cfg(frame_hz, cfg_text_outdoor)?;
        m.max_range_m = 40.0;
        m.outlier_share = 0.4;
        m.min_points = 3;
        Ok(m)
    }

    /// The model for a car outdoors at `frame_hz` \[Hz\] (10-30): [`RadarModel::outdoor`] with the
    /// short-chirp .cfg of [`cfg_text_vehicle`] (±12 m/s unambiguous Doppler).
    pub fn vehicle(frame_hz: f64) -> Result<RadarModel, SimError> {
        let mut m = RadarModel::with_cfg(frame_hz, cfg_text_vehicle)?;
        m.max_range_m = 40.0;
        m.outlier_share = 0.4;
        m.min_points = 3;
        m.chirp_time_s = 27e-6;
        Ok(m)
    }

    fn with_cfg(frame_hz: f64, text: fn(f64) -> String) -> Result<RadarModel, SimError> {
        if !(10.0..=30.0).contains(&frame_hz) {
            return Err(SimError::Config(format!(
                "radar frame rate {frame_hz} Hz is outside 10-30 Hz"
            )));
        }
        let cfg = text(frame_hz);
        let derived = RadarConfig::parse(&cfg)
            .and_then(|c| c.derive(None))
            .map_err(|e| {
                SimError::Config(format!(
                    "generated radar.cfg line {}: {:?}",
                    e.line_no, e.kind
                ))
            })?;
        Ok(RadarModel {
            cfg,
            derived,
            fov_az_deg: 60.0,
            fov_el_deg: 20.0,
            az_res_deg: 15.0,
            el_res_deg: 58.0,
            merge_range_m: 0.3,
            threshold_db: 15.0,
            surface_gain_db: 44.0,
            point_gain_db: 63.0,
            outlier_share: 0.75,
            doppler_noise_mps: 0.04,
            max_points: 100,
            min_points: 5,
            noise_floor_db: 52.0,
            ray_step_deg: 2.0,
            max_range_m: 10.0,
            chirp_time_s: 73.5e-6,
            doppler_step_mps: 0.0,
        })
    }

    /// Frame period \[s\] (as the device quantises it).
    pub fn frame_period_s(&self) -> f64 {
        self.derived.frame_period_ms * 1e-3
    }

    /// Time the chirps of one frame take \[s\].
    pub fn active_time_s(&self) -> f64 {
        // Tc = idle 7 us + ramp end 66.5 us, per chirp.
        f64::from(self.derived.chirps_per_frame) * self.chirp_time_s
    }

    /// Doppler standard deviation the points carry: noise and quantisation \[m/s\].
    pub fn doppler_sigma_mps(&self) -> f64 {
        let q = if self.doppler_step_mps > 0.0 {
            self.doppler_step_mps
        } else {
            self.derived.velocity_resolution_mps
        };
        (self.doppler_noise_mps.powi(2) + q * q / 12.0).sqrt()
    }

    fn quantise_v(&self, v: f64) -> f64 {
        let q = self.derived.velocity_resolution_mps;
        let vmax = self.derived.max_velocity_mps;
        if self.doppler_step_mps > 0.0 {
            // Wrap into ±v_max first, then to the step (towards zero where rounding would pass
            // v_max, which the driver's plausibility check holds points to): the result stays a
            // multiple of the step.
            let step = self.doppler_step_mps;
            let w = (v + vmax).rem_euclid(2.0 * vmax) - vmax;
            let mut n = (w / step).round();
            if (n * step).abs() > vmax {
                n -= n.signum();
            }
            return n * step;
        }
        let mut b = (v / q).round() * q;
        while b >= vmax {
            b -= 2.0 * vmax;
        }
        while b < -vmax {
            b += 2.0 * vmax;
        }
        b
    }

    fn gain(&self, az: f64, el: f64) -> f64 {
        // Two-way pattern of the AWR1843BOOST patches: about -6 dB at ±50° azimuth, ±20° elevation.
        let db = -6.0 * (az.to_degrees() / 50.0).powi(2) - 6.0 * (el.to_degrees() / 20.0).powi(2);
        10f64.powf(db / 10.0)
    }

    fn in_fov(&self, az: f64, el: f64) -> bool {
        az.abs() <= self.fov_az_deg.to_radians() && el.abs() <= self.fov_el_deg.to_radians()
    }

    /// Simulates one frame seen from radar position `p` and orientation `q` (radar to world),
    /// the radar moving at `v_world` \[m/s\].
    pub fn frame(
        &self,
        world: &World,
        p: &Vector3<f64>,
        q: &UnitQuaternion<f64>,
        v_world: &Vector3<f64>,
        rng: &mut SimRng,
    ) -> Vec<SimPoint> {
        let inv = q.inverse();
        let v_r = inv * v_world;
        let max_r = self.derived.max_range_m.min(self.max_range_m);
        let thr = 10f64.powf(self.threshold_db / 10.0);
        // (unit ray in radar frame, range, linear SNR)
        let mut cands: Vec<(Vector3<f64>, f64, f64)> = Vec::new();
        let mut mirrors: Vec<(Vector3<f64>, Vector3<f64>)> = Vec::new();
        let step = self.ray_step_deg.to_radians();
        let (naz, nel) = (
            (self.fov_az_deg / self.ray_step_deg).floor() as i32,
            (self.fov_el_deg / self.ray_step_deg).floor() as i32,
        );
        let ray_gain = 10f64.powf(self.surface_gain_db / 10.0) * step * step;
        for ia in -naz..=naz {
            for ie in -nel..=nel {
                let (az, el) = (f64::from(ia) * step, f64::from(ie) * step);
                let d = dir(az, el);
                let dw = q * d;
                let Some(hit) = world.raycast(p, &dw, max_r) else {
                    continue;
                };
                if hit.is_wall && hit.material.is_mirror() {
                    mirrors.push((p + dw * hit.t, hit.normal));
                }
                let cos_i = (-hit.normal.dot(&dw)).clamp(0.0, 1.0);
                let theta = cos_i.acos();
                let r = hit.material.reflectivity();
                let refl = r.diffuse * cos_i + r.specular * (-(theta / r.lobe_rad).powi(2)).exp();
                let snr = ray_gain * refl * self.gain(az, el) / (hit.t * hit.t) * rng.exp1();
                if snr > thr && hit.t > 0.2 {
                    cands.push((d, hit.t, snr));
                }
            }
        }
        let pt_gain = 10f64.powf(self.point_gain_db / 10.0);
        for s in &world.scatterers {
            let local = inv * (s.p - p);
            let r = local.norm();
            if !(0.2..max_r).contains(&r) {
                continue;
            }
            let d = local / r;
            let (az, el) = (d.x.atan2(d.y), d.z.asin());
            if !self.in_fov(az, el) || !world.visible(p, &s.p) {
                continue;
            }
            let snr = pt_gain * s.rcs * self.gain(az, el) / r.powi(4) * rng.exp1();
            if snr > thr {
                cands.push((d, r, snr));
            }
        }
        // Strongest first; weaker returns within the resolution cell of a kept one merge into it.
        cands.sort_by(|a, b| b.2.total_cmp(&a.2));
        let (az_res, el_res) = (self.az_res_deg.to_radians(), self.el_res_deg.to_radians());
        let vq = self.derived.velocity_resolution_mps;
        let mut kept: Vec<(Vector3<f64>, f64, f64, f64, f64, f64)> = Vec::new(); // d, r, snr, az, el, v
        for (d, r, snr) in cands {
            let (az, el) = (d.x.atan2(d.y), d.z.asin());
            let v = -v_r.dot(&d);
            let merged = kept.iter_mut().find(|k| {
                (k.1 - r).abs() < self.merge_range_m
                    && (k.3 - az).abs() < az_res
                    && (k.4 - el).abs() < el_res
                    && (k.5 - v).abs() < 1.5 * vq
            });
            match merged {
                Some(k) => k.2 += snr,
                None => kept.push((d, r, snr, az, el, v)),
            }
        }
        let mut pts = Vec::with_capacity(kept.len() * 4);
        for &(d, r, snr, az, el, v) in &kept {
            pts.push(self.report(d * r, v, snr, az, el, PointClass::Inlier, rng));
        }
        // Outliers at the configured share: each inlier brings on average share/(1-share).
        let share = self.outlier_share.clamp(0.0, 0.95);
        let per = share / (1.0 - share);
        let trials = (2.0 * per).ceil() as usize;
        let mut n_out = 0;
        for _ in 0..kept.len() * trials {
            if rng.chance(per / trials as f64) {
                n_out += 1;
            }
        }
        let n_out = n_out.max(self.min_points.saturating_sub(kept.len()));
        for _ in 0..n_out {
            let pick = (!kept.is_empty()).then(|| kept[rng.below(kept.len())]);
            let kind = rng.unit();
            let pt = match pick {
                Some(k) if kind < 0.4 && !mirrors.is_empty() => {
                    let (mq, mn) = mirrors[rng.below(mirrors.len())];
                    let pw = p + q * (k.0 * k.1);
                    let img = pw - 2.0 * (pw - mq).dot(&mn) * mn;
                    let behind = (p - mq).dot(&mn) * (img - mq).dot(&mn) < 0.0;
                    let local = inv * (img - p);
                    let r = local.norm();
                    let d = local / r.max(1e-9);
                    let (az, el) = (d.x.atan2(d.y), d.z.asin());
                    if behind && r < max_r && r > 0.3 && self.in_fov(az, el) {
                        let snr = k.2 * rng.uniform(0.05, 0.3);
                        Some(self.report(local, -v_r.dot(&d), snr, az, el, PointClass::Mirror, rng))
                    } else {
                        None
                    }
                }
                Some(k) if kind < 0.75 => {
                    let r = (k.1 * rng.uniform(1.3, 2.2)).min(max_r - 0.05);
                    let v = k.5 * rng.uniform(0.3, 1.7) + 0.2 * rng.normal();
                    let snr = k.2 * rng.uniform(0.03, 0.3);
                    Some(self.report(k.0 * r, v, snr, k.3, k.4, PointClass::Multipath, rng))
                }
                _ => None,
            };
            let pt = pt.unwrap_or_else(|| {
                let az = rng.uniform(-1.0, 1.0) * self.fov_az_deg.to_radians();
                let el = rng.uniform(-1.0, 1.0) * self.fov_el_deg.to_radians();
                let r = rng.uniform(0.3, max_r - 0.05);
                let v = (0.8 * rng.normal()).clamp(-3.0, 3.0);
                let snr = thr * (1.0 + 1.5 * rng.exp1());
                self.report(dir(az, el) * r, v, snr, az, el, PointClass::Clutter, rng)
            });
            pts.push(pt);
        }
        // The device reports detections in range-Doppler order, not by cause: shuffle.
        for i in (1..pts.len()).rev() {
            pts.swap(i, rng.below(i + 1));
        }
        while pts.len() > self.max_points {
            pts.swap_remove(rng.below(pts.len()));
        }
        pts
    }

    /// A reported point for a return at `true_xyz` (radar frame) with radial velocity `v`.
    #[allow(clippy::too_many_arguments)]
    fn report(
        &self,
        true_xyz: Vector3<f64>,
        v: f64,
        snr: f64,
        az: f64,
        el: f64,
        class: PointClass,
        rng: &mut SimRng,
    ) -> SimPoint {
        let rr = self.derived.range_resolution_m;
        let r = (true_xyz.norm() / rr).round() * rr;
        let s = (2.0 * snr).sqrt().max(1.0);
        let az_m = az + self.az_res_deg.to_radians() / s * 0.5 * rng.normal();
        let el_m = el + self.el_res_deg.to_radians() / s * 0.5 * rng.normal();
        let d = dir(az_m, el_m) * r;
        let vm = self.quantise_v(v + self.doppler_noise_mps * rng.normal());
        let range_db = 2.0 * (true_xyz.norm() + 1.0).log2();
        SimPoint {
            xyz: [d.x as f32, d.y as f32, d.z as f32],
            v: vm as f32,
            snr_db: 10.0 * snr.log10(),
            noise_db: self.noise_floor_db + range_db + 0.5 * rng.normal(),
            class,
            true_xyz,
            true_v: v,
        }
    }

    /// Encodes one frame as the device sends it: SDK 3.x header, points (TLV 1), side info
    /// (TLV 7), stats (TLV 6), padded to 32 bytes with undefined bytes.
    pub fn encode(
        &self,
        frame_number: u32,
        cycles: u32,
        points: &[SimPoint],
        stats: [u32; 6],
        rng: &mut SimRng,
    ) -> Vec<u8> {
        let xyzv: Vec<[f32; 4]> = points
            .iter()
            .map(|p| [p.xyz[0], p.xyz[1], p.xyz[2], p.v])
            .collect();
        let side: Vec<(i16, i16)> = points
            .iter()
            .map(|p| {
                let q = |db: f64| (db * 10.0).round().clamp(0.0, f64::from(i16::MAX)) as i16;
                (q(p.snr_db), q(p.noise_db))
            })
            .collect();
        let mut b = FrameBuilder::oob(SDK_VERSION, PLATFORM, frame_number)
            .cycles(cycles)
            .points(&xyzv)
            .tlv(TlvOut::SideInfo(&side))
            .tlv(TlvOut::Stats(stats));
        b.pad_byte = rng.byte();
        b.to_vec()
    }
}

/// Near-field leakage: spurious returns at 0.1-1.0 m, fixed in the radar frame, with zero
/// Doppler (TX-to-RX coupling and reflections off the mount's own structure), added at a share of
/// each frame's points.
#[derive(Debug, Clone, PartialEq)]
pub struct NearField {
    /// Share of the frame's points that are leakage (0-0.5).
    pub share: f64,
    /// Where the spurious returns come from, radar frame \[m\].
    pub sources: Vec<Vector3<f64>>,
}

/// Nearest leakage source \[m\].
pub const NEAR_FIELD_MIN_M: f64 = 0.1;
/// Farthest leakage source \[m\].
pub const NEAR_FIELD_MAX_M: f64 = 1.0;

impl NearField {
    /// 3-8 sources in the field of view at 0.1-1.0 m, drawn from `rng`, for `share`.
    pub fn new(model: &RadarModel, share: f64, rng: &mut SimRng) -> NearField {
        let n = 3 + rng.below(6);
        let sources = (0..n)
            .map(|_| {
                let az = rng.uniform(-1.0, 1.0) * model.fov_az_deg.to_radians();
                let el = rng.uniform(-1.0, 1.0) * model.fov_el_deg.to_radians();
                dir(az, el) * rng.uniform(NEAR_FIELD_MIN_M, NEAR_FIELD_MAX_M)
            })
            .collect();
        NearField { share, sources }
    }

    /// Adds leakage to a frame's points so that on average `share` of the result is leakage:
    /// each other point brings share/(1 − share) leakage points, inserted at random places
    /// (the frame still holds at most `max_points`).
    pub fn add(&self, model: &RadarModel, pts: &mut Vec<SimPoint>, rng: &mut SimRng) {
        if self.sources.is_empty() || self.share <= 0.0 {
            return;
        }
        let share = self.share.min(0.95);
        let expect = pts.len() as f64 * share / (1.0 - share);
        let n = (expect + rng.unit()).floor() as usize;
        for _ in 0..n {
            let src = self.sources[rng.below(self.sources.len())];
            let d = src.normalize();
            let (az, el) = (d.x.atan2(d.y), d.z.asin());
            let snr = 10f64.powf(rng.uniform(20.0, 35.0) / 10.0);
            let mut p = model.report(src, 0.0, snr, az, el, PointClass::Leakage, rng);
            // The DC Doppler bin: exactly zero, whatever the noise.
            p.v = 0.0;
            let at = rng.below(pts.len() + 1);
            pts.insert(at, p);
        }
        while pts.len() > model.max_points {
            pts.swap_remove(rng.below(pts.len()));
        }
    }
}

/// Unit vector in the radar frame for azimuth `az` (positive right) and elevation `el` \[rad\].
pub fn dir(az: f64, el: f64) -> Vector3<f64> {
    Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cfg_derives_the_modelled_resolutions() {
        for hz in [10.0, 20.0, 30.0] {
            let m = RadarModel::new(hz).unwrap();
            assert!((m.derived.range_resolution_m - 0.04).abs() < 0.002);
            assert!((m.frame_period_s() - 1.0 / hz).abs() < 1e-8);
            assert!(m.active_time_s() < m.frame_period_s() * 0.6);
            assert!(m.derived.max_points_per_frame as usize >= m.max_points);
        }
        assert!(RadarModel::new(40.0).is_err());
        let o = RadarModel::outdoor(20.0).unwrap();
        assert!((o.derived.range_resolution_m - 0.16).abs() < 0.005);
        assert!(o.derived.max_range_m > 40.0);
        // Same chirp timing; the lower sampled band's centre moves the bin by ~2 %.
        let q = RadarModel::new(20.0)
            .unwrap()
            .derived
            .velocity_resolution_mps;
        assert!((o.derived.velocity_resolution_mps / q - 1.0).abs() < 0.03);
        let v = RadarModel::vehicle(20.0).unwrap();
        assert!(
            v.derived.max_velocity_mps > 11.5,
            "{}",
            v.derived.max_velocity_mps
        );
        assert!(v.derived.max_range_m >= 40.0, "{}", v.derived.max_range_m);
        assert!((v.derived.range_resolution_m - 0.31).abs() < 0.01);
        for m in [v, RadarModel::new(20.0).unwrap()] {
            let a = m.derived.active_frame_time_ms * 1e-3;
            assert!(
                (m.active_time_s() - a).abs() < 1e-9,
                "{} vs {a}",
                m.active_time_s()
            );
        }
    }
}
