//! The online window builder: radar frames and IMU samples in arrival order in, model windows
//! out. The runtime and `milliego dataset build` both feed their streams through this type, so a
//! trained model sees at run time exactly what it saw in training.
//!
//! For each radar frame n it projects the points, overlays frames n-2..n (by frame number; missing
//! frames are simply absent) and, once IMU samples reach past frame n's time, emits the window
//! (n - gap, n): both overlaid panoramas and the IMU window between them. Steady state allocates
//! nothing: the frame ring and the IMU buffer are sized at construction.

use crate::imu::{resample, ImuSample, ImuWindowError};
use crate::panorama::{overlay, project, radar_tensor, ProjectStats};
use crate::{Config, Norm, RadarInput, SettingError, IMU_LEN, PANO_LEN, RADAR_LEN};
use nalgebra::{UnitQuaternion, Vector3};
use radar_driver::tlv::Point;
use std::collections::VecDeque;

/// Counters: everything the builder received, emitted and skipped, with the reason.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// Radar frames accepted.
    pub frames: u64,
    /// Radar frames ignored because their number did not advance (duplicate or out of order).
    pub frames_out_of_order: u64,
    /// Frame-number restarts (a sensor reset): the history was cleared.
    pub restarts: u64,
    /// Projection counts over all frames.
    pub points: ProjectStatsTotal,
    /// IMU samples accepted.
    pub imu_samples: u64,
    /// IMU samples ignored because their time did not advance.
    pub imu_out_of_order: u64,
    /// Windows emitted.
    pub windows: u64,
    /// Frames without a window because frame n - gap was never received.
    pub no_prev_frame: u64,
    /// Frames without a window because the IMU samples did not cover the interval.
    pub imu_not_covered: u64,
    /// Frames without a window because of a gap in the IMU samples.
    pub imu_gap: u64,
}

/// [`ProjectStats`] summed in 64 bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProjectStatsTotal {
    /// Points in a bin.
    pub in_view: u64,
    /// Points outside the field of view.
    pub out_of_view: u64,
    /// Points beyond the maximum range.
    pub out_of_range: u64,
    /// Points with NaN/infinite coordinates.
    pub non_finite: u64,
}

impl ProjectStatsTotal {
    fn add(&mut self, s: ProjectStats) {
        self.in_view += u64::from(s.in_view);
        self.out_of_view += u64::from(s.out_of_view);
        self.out_of_range += u64::from(s.out_of_range);
        self.non_finite += u64::from(s.non_finite);
    }
}

/// Builder settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BuilderConfig {
    /// Preprocessing (gap, overlay, projection).
    pub pre: Config,
    /// Rotation from the IMU frame to the body frame (the session's IMU extrinsic): samples are
    /// rotated into the body frame so one model serves any mounting.
    pub imu_to_body: UnitQuaternion<f64>,
    /// Longest allowed spacing of IMU samples inside a window \[s\].
    pub max_imu_gap_s: f64,
    /// IMU samples kept \[count\]: enough for `gap` radar periods plus the IMU's lag behind the
    /// radar (e.g. 2 s at 400 Hz = 800).
    pub imu_capacity: usize,
}

impl Default for BuilderConfig {
    fn default() -> Self {
        BuilderConfig {
            pre: Config::default(),
            imu_to_body: UnitQuaternion::identity(),
            max_imu_gap_s: 0.05,
            imu_capacity: 1024,
        }
    }
}

#[derive(Debug)]
struct Slot {
    seq: u64,
    frame: u32,
    t: f64,
    single: Box<[f32; PANO_LEN]>,
    single_doppler: Box<[f32; PANO_LEN]>,
    overlaid: Box<[f32; PANO_LEN]>,
    overlaid_doppler: Box<[f32; PANO_LEN]>,
    pending: bool,
}

/// A window ready for the model (borrowed from the builder until the next push).
#[derive(Debug, Clone, Copy)]
pub struct Window<'a> {
    /// Push sequence number of the previous frame (0 = first frame pushed).
    pub prev_seq: u64,
    /// Push sequence number of the current frame.
    pub cur_seq: u64,
    /// Frame number of the previous frame.
    pub prev_frame: u32,
    /// Frame number of the current frame.
    pub cur_frame: u32,
    /// Time of the previous frame \[s\].
    pub t_prev: f64,
    /// Time of the current frame \[s\].
    pub t_cur: f64,
    /// Overlaid panorama of the previous frame.
    pub prev: &'a [f32; PANO_LEN],
    /// Overlaid panorama of the current frame.
    pub cur: &'a [f32; PANO_LEN],
    /// Radial velocities of the previous frame's overlaid panorama's points \[m/s\].
    pub prev_doppler: &'a [f32; PANO_LEN],
    /// Radial velocities of the current frame's overlaid panorama's points \[m/s\].
    pub cur_doppler: &'a [f32; PANO_LEN],
    /// IMU window (body frame, oldest first).
    pub imu: &'a [[f32; 6]; IMU_LEN],
}

impl Window<'_> {
    /// The model's radar input (6 x 64 x 256) in the model's layout, with its normalisation.
    pub fn radar_tensor(&self, input: RadarInput, norm: &Norm, out: &mut [f32; RADAR_LEN]) {
        radar_tensor(
            input,
            (self.prev, self.prev_doppler),
            (self.cur, self.cur_doppler),
            norm,
            out,
        );
    }
}

/// The online window builder.
#[derive(Debug)]
pub struct WindowBuilder {
    cfg: BuilderConfig,
    ring: VecDeque<Slot>,
    spare: Vec<Slot>,
    imu: VecDeque<ImuSample>,
    imu_row: [[f32; 6]; IMU_LEN],
    counters: Counters,
    next_seq: u64,
}

impl WindowBuilder {
    /// A builder; fails with a message naming the bad setting.
    pub fn new(cfg: BuilderConfig) -> Result<WindowBuilder, SettingError> {
        cfg.pre.validate()?;
        if cfg.max_imu_gap_s.is_nan() || cfg.max_imu_gap_s <= 0.0 {
            return Err(SettingError {
                setting: "window builder max_imu_gap_s",
                value: cfg.max_imu_gap_s.to_string(),
                requirement: "must be > 0 s".into(),
            });
        }
        if cfg.imu_capacity < 2 * IMU_LEN {
            return Err(SettingError {
                setting: "window builder imu_capacity",
                value: cfg.imu_capacity.to_string(),
                requirement: format!("must be at least {} samples", 2 * IMU_LEN),
            });
        }
        // Frames n - gap .. n, plus room for frames waiting on the IMU.
        let cap = cfg.pre.gap.max(cfg.pre.overlay) as usize + 1 + 8;
        let spare = (0..cap)
            .map(|_| Slot {
                seq: 0,
                frame: 0,
                t: 0.0,
                single: Box::new([0.0; PANO_LEN]),
                single_doppler: Box::new([0.0; PANO_LEN]),
                overlaid: Box::new([0.0; PANO_LEN]),
                overlaid_doppler: Box::new([0.0; PANO_LEN]),
                pending: false,
            })
            .collect();
        Ok(WindowBuilder {
            ring: VecDeque::with_capacity(cap),
            spare,
            imu: VecDeque::with_capacity(cfg.imu_capacity),
            imu_row: [[0.0; 6]; IMU_LEN],
            counters: Counters::default(),
            next_seq: 0,
            cfg,
        })
    }

    /// The settings.
    pub fn config(&self) -> &BuilderConfig {
        &self.cfg
    }

    /// What the builder has seen so far.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Adds an IMU sample (IMU frame, common clock); returns false when it was ignored (time did
    /// not advance, counted).
    pub fn push_imu(&mut self, t: f64, accel: [f64; 3], gyro: [f64; 3]) -> bool {
        if self.imu.back().is_some_and(|l| t <= l.t) || !t.is_finite() {
            self.counters.imu_out_of_order += 1;
            return false;
        }
        let r = &self.cfg.imu_to_body;
        let a = r * Vector3::from(accel);
        let g = r * Vector3::from(gyro);
        if self.imu.len() == self.cfg.imu_capacity {
            self.imu.pop_front();
        }
        self.imu.push_back(ImuSample {
            t,
            accel: [a.x, a.y, a.z],
            gyro: [g.x, g.y, g.z],
        });
        self.counters.imu_samples += 1;
        true
    }

    /// Adds a radar frame (points in the radar frame, measurement time on the common clock).
    /// Returns the overlaid depth and Doppler panoramas of this frame (what a dataset stores per
    /// frame), or None when the frame was ignored (its number did not advance; counted).
    pub fn push_radar(
        &mut self,
        frame: u32,
        t: f64,
        points: &[Point],
    ) -> Option<(&[f32; PANO_LEN], &[f32; PANO_LEN])> {
        if let Some(last) = self.ring.back() {
            // Frame numbers advance by 1..2^31 (with wrap-around); anything else is a duplicate,
            // an out-of-order frame (time not advancing: ignored) or a sensor restart (time
            // advancing: the history is cleared).
            let ahead = frame.wrapping_sub(last.frame);
            if ahead == 0 || ahead > u32::MAX / 2 {
                if t > last.t {
                    self.counters.restarts += 1;
                    while let Some(s) = self.ring.pop_front() {
                        self.retire(s);
                    }
                } else {
                    self.counters.frames_out_of_order += 1;
                    return None;
                }
            }
        }
        if self.spare.is_empty() {
            let old = self.ring.pop_front().expect("ring holds every slot");
            self.retire(old);
        }
        let mut slot = self.spare.pop().expect("a spare slot");
        slot.seq = self.next_seq;
        slot.frame = frame;
        slot.t = t;
        slot.pending = true;
        self.next_seq += 1;
        let stats = project(
            &self.cfg.pre,
            points,
            &mut slot.single,
            &mut slot.single_doppler,
        );
        self.counters.points.add(stats);
        let overlay_n = self.cfg.pre.overlay;
        overlay(
            self.ring
                .iter()
                .filter(|s| frame.wrapping_sub(s.frame) < overlay_n)
                .map(|s| (&*s.single, &*s.single_doppler))
                .chain(core::iter::once((&*slot.single, &*slot.single_doppler))),
            &mut slot.overlaid,
            &mut slot.overlaid_doppler,
        );
        self.counters.frames += 1;
        self.ring.push_back(slot);
        self.ring
            .back()
            .map(|s| (&*s.overlaid, &*s.overlaid_doppler))
    }

    fn retire(&mut self, s: Slot) {
        // Evicted while waiting for IMU samples that never came, or evicted as the partner of
        // a frame still waiting for them: either way the IMU is why there is no window.
        if s.pending {
            self.counters.imu_not_covered += 1;
        }
        let partner = s.frame.wrapping_add(self.cfg.pre.gap);
        for p in self
            .ring
            .iter_mut()
            .filter(|p| p.pending && p.frame == partner)
        {
            p.pending = false;
            self.counters.imu_not_covered += 1;
        }
        self.spare.push(s);
    }

    /// Ends the streams: frames still waiting for IMU samples are counted as not covered.
    pub fn finish(&mut self) {
        for s in self.ring.iter_mut().filter(|s| s.pending) {
            s.pending = false;
            self.counters.imu_not_covered += 1;
        }
    }

    /// The next window that is ready, if any. Call after every push until it returns None.
    pub fn poll(&mut self) -> Option<Window<'_>> {
        let gap = self.cfg.pre.gap;
        let last_imu = self.imu.back().map(|s| s.t);
        let mut ready = None;
        for i in 0..self.ring.len() {
            if !self.ring[i].pending {
                continue;
            }
            let (frame, t) = (self.ring[i].frame, self.ring[i].t);
            if last_imu.is_none_or(|l| l < t) {
                // IMU has not reached this frame yet: wait (frames are in time order).
                break;
            }
            let want = frame.wrapping_sub(gap);
            let Some(j) = self.ring.iter().position(|s| s.frame == want) else {
                self.ring[i].pending = false;
                self.counters.no_prev_frame += 1;
                continue;
            };
            let t_prev = self.ring[j].t;
            let samples = self.imu.make_contiguous();
            self.ring[i].pending = false;
            match resample(
                samples,
                t_prev,
                t,
                self.cfg.max_imu_gap_s,
                &mut self.imu_row,
            ) {
                Ok(()) => {
                    ready = Some((j, i));
                    break;
                }
                Err(ImuWindowError::Gap { .. }) => self.counters.imu_gap += 1,
                Err(_) => self.counters.imu_not_covered += 1,
            }
        }
        let (j, i) = ready?;
        self.counters.windows += 1;
        let (p, c) = (&self.ring[j], &self.ring[i]);
        Some(Window {
            prev_seq: p.seq,
            cur_seq: c.seq,
            prev_frame: p.frame,
            cur_frame: c.frame,
            t_prev: p.t,
            t_cur: c.t,
            prev: &p.overlaid,
            cur: &c.overlaid,
            prev_doppler: &p.overlaid_doppler,
            cur_doppler: &c.overlaid_doppler,
            imu: &self.imu_row,
        })
    }

    /// Drops all history (after a sensor restart or a long outage); counters are kept (frames
    /// still waiting count as not covered).
    pub fn reset(&mut self) {
        self.finish();
        while let Some(s) = self.ring.pop_front() {
            self.spare.push(s);
        }
        self.imu.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(x: f32, y: f32) -> Point {
        Point {
            x,
            y,
            z: 0.0,
            velocity: 0.0,
        }
    }

    /// Radar at 20 Hz, IMU at 100 Hz, IMU samples pushed up to each frame's time first.
    fn feed(b: &mut WindowBuilder, frames: &[u32], imu_until_s: f64) -> Vec<(u32, u32, f64)> {
        let mut out = Vec::new();
        let mut imu_t = 0.0;
        for &n in frames {
            let t = f64::from(n) * 0.05;
            while imu_t <= t.min(imu_until_s) {
                b.push_imu(imu_t, [imu_t, 0.0, 9.81], [0.0, 0.0, 0.1]);
                imu_t += 0.01;
                while let Some(w) = b.poll() {
                    out.push((w.prev_frame, w.cur_frame, f64::from(w.imu[19][0])));
                }
            }
            b.push_radar(n, t, &[point(0.0, 1.0 + n as f32 * 0.1)]);
            while let Some(w) = b.poll() {
                out.push((w.prev_frame, w.cur_frame, f64::from(w.imu[19][0])));
            }
        }
        while imu_t <= imu_until_s {
            b.push_imu(imu_t, [imu_t, 0.0, 9.81], [0.0, 0.0, 0.1]);
            imu_t += 0.01;
            while let Some(w) = b.poll() {
                out.push((w.prev_frame, w.cur_frame, f64::from(w.imu[19][0])));
            }
        }
        out
    }

    #[test]
    fn emits_one_window_per_frame_gap_frames_back_once_the_imu_catches_up() {
        let mut b = WindowBuilder::new(BuilderConfig::default()).unwrap();
        let frames: Vec<u32> = (1..=30).collect();
        let w = feed(&mut b, &frames, 2.0);
        assert_eq!(w.len(), 25);
        for (k, (p, c, last_ax)) in w.iter().enumerate() {
            assert_eq!((*p, *c), (k as u32 + 1, k as u32 + 6));
            // The last IMU row is at the current frame's time (accel x = t).
            assert!((last_ax - f64::from(*c) * 0.05).abs() < 1e-5, "{last_ax}");
        }
        let c = b.counters();
        assert_eq!((c.frames, c.windows, c.no_prev_frame), (30, 25, 5));
    }

    #[test]
    fn missing_frames_and_imu_gaps_are_counted_not_hidden() {
        let mut b = WindowBuilder::new(BuilderConfig::default()).unwrap();
        // Frame 10 lost: frame 15 has no partner, frame 10's own window never exists.
        let frames: Vec<u32> = (1..=20).filter(|n| *n != 10).collect();
        let w = feed(&mut b, &frames, 2.0);
        assert!(!w.iter().any(|(p, c, _)| *p == 10 || *c == 10));
        let c = *b.counters();
        assert_eq!(c.frames, 19);
        assert_eq!(c.windows + c.no_prev_frame, 19);
        assert_eq!(c.no_prev_frame, 6);
        // IMU stops at 0.6 s: later frames wait, then time out when evicted.
        let mut b = WindowBuilder::new(BuilderConfig::default()).unwrap();
        let frames: Vec<u32> = (1..=40).collect();
        let w = feed(&mut b, &frames, 0.6);
        b.finish();
        let c = *b.counters();
        assert!(w.iter().all(|(_, cur, _)| f64::from(*cur) * 0.05 <= 0.6));
        assert!(c.imu_not_covered > 0, "{c:?}");
        assert_eq!((c.windows, c.no_prev_frame), (6, 5), "{c:?}");
        assert_eq!(c.windows + c.no_prev_frame + c.imu_not_covered, 40, "{c:?}");
    }

    #[test]
    fn out_of_order_frames_and_restarts() {
        let mut b = WindowBuilder::new(BuilderConfig::default()).unwrap();
        assert!(b.push_radar(5, 0.25, &[]).is_some());
        assert!(b.push_radar(5, 0.25, &[]).is_none());
        assert!(b.push_radar(4, 0.2, &[]).is_none());
        assert_eq!(b.counters().frames_out_of_order, 2);
        // Counter back to 1 with time advancing: a sensor restart.
        assert!(b.push_radar(1, 0.5, &[]).is_some());
        assert_eq!(b.counters().restarts, 1);
        assert!(!b.push_imu(f64::NAN, [0.0; 3], [0.0; 3]));
        assert!(b.push_imu(1.0, [0.0; 3], [0.0; 3]));
        assert!(!b.push_imu(1.0, [0.0; 3], [0.0; 3]));
        assert_eq!(b.counters().imu_out_of_order, 2);
    }

    #[test]
    fn overlay_uses_the_last_three_frames_by_number() {
        let mut b = WindowBuilder::new(BuilderConfig::default()).unwrap();
        // Each point's Doppler tells its frame apart.
        let pts = |r: f32, v: f32| {
            [Point {
                velocity: v,
                ..point(0.0, r)
            }]
        };
        let px = 8 * 64 + 32;
        b.push_radar(1, 0.05, &pts(10.0, -1.0));
        b.push_radar(2, 0.10, &pts(4.0, -2.0));
        let (p, d) = b.push_radar(3, 0.15, &pts(8.0, -3.0)).unwrap();
        // All three are on boresight: the nearest (4 m) wins, with its Doppler.
        assert!((p[px] - 0.8).abs() < 1e-6);
        assert_eq!(d[px], -2.0);
        let (p, d) = b.push_radar(4, 0.20, &pts(8.0, -4.0)).unwrap();
        assert!((p[px] - 0.8).abs() < 1e-6);
        assert_eq!(d[px], -2.0);
        let (p, d) = b.push_radar(5, 0.25, &pts(8.0, -5.0)).unwrap();
        assert!((p[px] - 0.6).abs() < 1e-6, "frame 2 has left the overlay");
        assert_eq!(d[px], -3.0, "of equal depths, the earliest frame's Doppler");
    }

    #[test]
    fn imu_is_rotated_into_the_body_frame() {
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let mut b = WindowBuilder::new(BuilderConfig {
            imu_to_body: q,
            ..BuilderConfig::default()
        })
        .unwrap();
        let w = feed(&mut b, &(1..=8).collect::<Vec<_>>(), 1.0);
        assert!(!w.is_empty());
        b.reset();
        // accel x = t in the IMU frame becomes body y.
        for n in 1..=8u32 {
            let t = f64::from(n) * 0.05;
            b.push_radar(n + 100, t + 10.0, &[]);
        }
        let mut b = WindowBuilder::new(BuilderConfig {
            imu_to_body: q,
            ..BuilderConfig::default()
        })
        .unwrap();
        for i in 0..100 {
            let t = f64::from(i) * 0.01;
            b.push_imu(t, [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
        }
        b.push_radar(1, 0.1, &[]);
        for n in 2..=6 {
            b.push_radar(n, f64::from(n) * 0.1, &[]);
        }
        let w = b.poll().expect("a window");
        assert!(w.imu[0][0].abs() < 1e-6 && (w.imu[0][1] - 1.0).abs() < 1e-6);
    }
}
