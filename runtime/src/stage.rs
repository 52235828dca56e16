//! The estimator stage: runs the estimator(s) on the synchroniser's ordered stream, composes the
//! trajectory, builds pose messages (radar rate, and IMU-propagated ones flagged PREDICTED), and
//! decides the health flags.

use crate::composer::{wxyz_f32, Composed, Composer};
use crate::estimator::{Built, Estimator, ImuInput, Mounting, RadarInput, RelativePose};
use crate::reader::RadarItem;
use crate::sync::SyncOut;
use milliego_odometry::runner::UNAIDED_AFTER_S;
use milliego_odometry::strapdown::{ImuSample, NavState, Strapdown, STANDARD_GRAVITY};
use nalgebra::{Isometry3, Vector3};
use pose_link::{Estimator as Code, Health, PoseMessage};

/// IMU samples kept to re-integrate the prediction from a radar-rate pose that arrives after
/// later samples were previewed.
const RECENT: usize = 256;

/// What the estimators made of one radar frame.
enum Step {
    /// A relative pose on the current chain.
    Pose(RelativePose),
    /// The fallback took over: its relative pose, and the world pose of its `from` frame.
    Handover(RelativePose, Isometry3<f64>),
}

/// A pose on its way to the outputs.
#[derive(Debug, Clone, Copy)]
pub struct PoseOut {
    /// The message (seq and host time filled by the output stage).
    pub msg: PoseMessage,
    /// Time \[s\] on the common clock.
    pub t: f64,
    /// Host read time of the input that produced it \[ns since the epoch\].
    pub read_ns: u64,
    /// When the estimator stage emitted it \[ns since the epoch\].
    pub emitted_ns: u64,
}

/// Settings of the estimator stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageConfig {
    /// Publish IMU-propagated poses between radar-rate poses (PREDICTED).
    pub imu_rate_output: bool,
    /// Sensor placement (to propagate the body pose with the IMU).
    pub mounting: Mounting,
}

/// Counters of the estimator stage.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StageCounters {
    /// Radar-rate poses.
    pub radar_poses: u64,
    /// Predicted poses.
    pub predicted_poses: u64,
    /// Radar frames that produced no pose (levelling, model stride).
    pub no_pose: u64,
    /// Estimator errors.
    pub errors: u64,
    /// Origin resets.
    pub resets: u64,
    /// Hand-overs from the primary estimator to the fallback (the trajectory goes on).
    pub handovers: u64,
}

/// The estimator stage.
pub struct Stage {
    cfg: StageConfig,
    built: Built,
    use_fallback: bool,
    /// The trajectory.
    pub composer: Composer,
    /// The fallback's own chain while the primary runs: at a hand-over it carries the fallback's
    /// motion from the trajectory's last frame, so the trajectory goes on without a new origin.
    shadow: Composer,
    // Handed over, but the fallback's first pose (the bridge) is still to come.
    bridging: bool,
    pending_handover: bool,
    /// Why the stage handed over to the fallback, once it did.
    handover_reason: Option<String>,
    predict: Option<Strapdown>,
    // World pose of the IMU-integration frame's origin: predicted poses are the last radar-rate
    // pose moved by what the IMU integrated since.
    anchor: Option<(Isometry3<f64>, NavState)>,
    last_imu: Option<ImuSample>,
    last_radar_rate_t: f64,
    pending_reset: bool,
    previews: bool,
    recent: [ImuSample; RECENT],
    recent_head: usize,
    recent_len: usize,
    /// Counters.
    pub counters: StageCounters,
}

impl std::fmt::Debug for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Stage")
            .field("built", &self.built)
            .field("counters", &self.counters)
            .finish()
    }
}

impl Stage {
    /// The radar-to-IMU time offset the estimators estimated \[s\] (estimate, deviation), the
    /// primary's first.
    pub fn radar_time_offset(&self) -> Option<(f64, f64)> {
        self.built.primary.radar_time_offset().or_else(|| {
            self.built
                .fallback
                .as_ref()
                .and_then(|f| f.radar_time_offset())
        })
    }

    /// The Doppler step \[m/s\], configured and seen in the points, the primary's first.
    pub fn doppler_step(&self) -> Option<(f32, Option<f32>)> {
        self.built
            .primary
            .doppler_step()
            .or_else(|| self.built.fallback.as_ref().and_then(|f| f.doppler_step()))
    }

    /// What the Doppler filter did, the primary's first.
    pub fn filter(&self) -> Option<crate::summary::FilterSummary> {
        self.built
            .primary
            .filter()
            .or_else(|| self.built.fallback.as_ref().and_then(|f| f.filter()))
    }

    /// What became of the learned measurements (the fused estimator only).
    pub fn learned(&self) -> Option<crate::summary::LearnedSummary> {
        let mut l = self.built.primary.learned()?;
        l.handover = self.handover_reason.clone();
        Some(l)
    }

    /// Why the stage handed over to the fallback, once it did.
    pub fn handover_reason(&self) -> Option<&str> {
        self.handover_reason.as_deref()
    }

    /// A stage running `built`.
    pub fn new(cfg: StageConfig, built: Built) -> Self {
        Stage {
            cfg,
            built,
            use_fallback: false,
            composer: Composer::default(),
            shadow: Composer::default(),
            bridging: false,
            pending_handover: false,
            handover_reason: None,
            predict: None,
            anchor: None,
            last_imu: None,
            last_radar_rate_t: f64::NEG_INFINITY,
            pending_reset: false,
            previews: false,
            recent: [ImuSample {
                t: 0.0,
                accel: [0.0; 3],
                gyro: [0.0; 3],
            }; RECENT],
            recent_head: 0,
            recent_len: 0,
            counters: StageCounters::default(),
        }
    }

    /// The estimator producing the poses: the primary, or the fallback once handed over.
    fn active(&self) -> Option<&dyn Estimator> {
        if self.use_fallback {
            self.built.fallback.as_deref()
        } else {
            Some(&*self.built.primary)
        }
    }

    fn code(&self, radar_missing: bool) -> Code {
        let name = self.active().map_or("doppler", |e| e.name());
        if radar_missing {
            return Code::Imu;
        }
        match name {
            "model" => Code::Model,
            "fused" => Code::Fused,
            "imu" => Code::Imu,
            _ => Code::Doppler,
        }
    }

    /// The flags of a pose at `t` \[s\]: the synchroniser's `health`, the fallback, and
    /// `DEAD_RECKONING` when the estimator producing it took no velocity aid for longer than
    /// [`UNAIDED_AFTER_S`].
    fn flags(&self, health: Health, t: f64) -> Health {
        let mut h = health.0;
        if self.built.model_fallback || self.use_fallback {
            h |= Health::MODEL_FALLBACK.0;
        }
        if self
            .active()
            .and_then(|e| e.last_aid_s())
            .is_some_and(|at| t - at > UNAIDED_AFTER_S)
        {
            h |= Health::DEAD_RECKONING.0;
        }
        Health(h)
    }

    /// Processes one synchroniser output; `emit` gets each pose; `recycle` gets radar boxes back.
    pub fn process(
        &mut self,
        ev: SyncOut,
        now_ns: u64,
        mut emit: impl FnMut(PoseOut),
        recycle: impl FnOnce(Box<RadarItem>),
    ) {
        match ev {
            SyncOut::Imu {
                input,
                read_ns,
                health,
            } => {
                self.on_imu(&input, read_ns, health, now_ns, &mut emit);
            }
            SyncOut::Preview {
                input,
                read_ns,
                health,
            } => self.on_preview(&input, read_ns, health, now_ns, &mut emit),
            SyncOut::Radar { item, health } => {
                self.on_radar(&item, health, now_ns, &mut emit);
                recycle(item);
            }
            SyncOut::Tick { t, health } => {
                // Radar (and maybe IMU) missing: the last known pose, flagged.
                self.emit_predicted(health, t, true, now_ns, now_ns, &mut emit);
            }
        }
    }

    fn on_imu(
        &mut self,
        s: &ImuInput,
        read_ns: u64,
        health: Health,
        now_ns: u64,
        emit: &mut impl FnMut(PoseOut),
    ) {
        // After a hand-over the primary is done with: it gets nothing more.
        if !self.use_fallback {
            self.built.primary.push_imu(s);
        }
        if let Some(f) = self.built.fallback.as_mut() {
            f.push_imu(s);
        }
        let sample = ImuSample {
            t: s.t,
            accel: s.accel,
            gyro: s.gyro,
        };
        self.last_imu = Some(sample);
        if self.previews {
            // The previews already propagated and published this sample.
            return;
        }
        let Some(sd) = self.predict.as_mut() else {
            return;
        };
        sd.push(sample);
        let radar_missing = health.contains(Health::RADAR_MISSING);
        // Between radar-rate poses at IMU rate when asked; while the radar is missing, at least
        // once per radar period so the stream keeps flagging the gap.
        let due =
            self.cfg.imu_rate_output || (radar_missing && s.t - self.last_radar_rate_t >= 0.1);
        if !due {
            return;
        }
        if radar_missing {
            self.last_radar_rate_t = s.t;
        }
        self.emit_predicted(health, s.t, radar_missing, read_ns, now_ns, emit);
    }

    /// An IMU sample as it arrived (before the estimator sees it in order): propagate the
    /// prediction and publish it at once.
    fn on_preview(
        &mut self,
        s: &ImuInput,
        read_ns: u64,
        health: Health,
        now_ns: u64,
        emit: &mut impl FnMut(PoseOut),
    ) {
        self.previews = true;
        let sample = ImuSample {
            t: s.t,
            accel: s.accel,
            gyro: s.gyro,
        };
        self.recent[self.recent_head] = sample;
        self.recent_head = (self.recent_head + 1) % RECENT;
        self.recent_len = (self.recent_len + 1).min(RECENT);
        let Some(sd) = self.predict.as_mut() else {
            return;
        };
        sd.push(sample);
        let radar_missing = health.contains(Health::RADAR_MISSING);
        self.emit_predicted(health, s.t, radar_missing, read_ns, now_ns, emit);
    }

    /// Publishes the IMU-propagated pose at `t` \[s\], flagged PREDICTED (nothing before the
    /// first radar-rate pose).
    fn emit_predicted(
        &mut self,
        health: Health,
        t: f64,
        radar_missing: bool,
        read_ns: u64,
        now_ns: u64,
        emit: &mut impl FnMut(PoseOut),
    ) {
        if let Some(p) = self.predicted_pose() {
            let msg = self.message(
                &p,
                None,
                Health(self.flags(health, t).0 | Health::PREDICTED.0),
                t,
                radar_missing,
            );
            self.counters.predicted_poses += 1;
            emit(PoseOut {
                msg,
                t,
                read_ns,
                emitted_ns: now_ns,
            });
        }
    }

    /// World pose propagated with the IMU since the last radar-rate pose.
    fn predicted_pose(&self) -> Option<Isometry3<f64>> {
        let (anchor_pose, anchor_nav) = self.anchor.as_ref()?;
        let Some(sd) = self.predict.as_ref() else {
            return Some(*anchor_pose);
        };
        let m = &self.cfg.mounting;
        let body = |n: &NavState| Isometry3::from_parts(n.p.into(), n.q) * m.imu.inverse();
        Some(anchor_pose * (body(anchor_nav).inverse() * body(sd.state())))
    }

    fn on_radar(
        &mut self,
        item: &RadarItem,
        health: Health,
        now_ns: u64,
        emit: &mut impl FnMut(PoseOut),
    ) {
        let f = RadarInput {
            t: item.t.unwrap_or(item.host_s),
            frame_number: item.frame_number,
            points: &item.points,
        };
        let (r, c) = match self.estimate(&f) {
            Some(Step::Pose(r)) => (r, self.composer.push(&r)),
            Some(Step::Handover(r, from_pose)) => {
                self.counters.handovers += 1;
                self.pending_handover = true;
                (r, self.composer.push_from(&r, from_pose))
            }
            None => {
                self.counters.no_pose += 1;
                return;
            }
        };
        if c.reset {
            self.counters.resets += 1;
        }
        self.last_radar_rate_t = r.t_to;
        // Restart the IMU propagation from this pose.
        let m = self.cfg.mounting;
        let imu_pose = c.pose * m.imu;
        let nav = NavState {
            t: r.t_to,
            q: imu_pose.rotation,
            p: imu_pose.translation.vector,
            v: r.velocity_world.unwrap_or_else(Vector3::zeros),
        };
        let mut sd = Strapdown::new(nav, STANDARD_GRAVITY);
        if self.previews {
            // Samples already previewed past this frame: integrate them again from the new pose.
            let mut first = true;
            for k in 0..self.recent_len {
                let x = self.recent[(self.recent_head + RECENT - self.recent_len + k) % RECENT];
                if x.t < r.t_to {
                    continue;
                }
                if first {
                    sd.push(ImuSample { t: r.t_to, ..x });
                    first = false;
                }
                if x.t > r.t_to {
                    sd.push(x);
                }
            }
        } else if let Some(last) = self.last_imu {
            sd.push(ImuSample {
                t: r.t_to.max(last.t),
                ..last
            });
        }
        self.predict = Some(sd);
        self.anchor = Some((c.pose, nav));
        let mut flags = self.flags(health, r.t_to);
        if c.reset || self.pending_reset {
            flags = Health(flags.0 | Health::RESET.0);
            self.pending_reset = false;
        }
        if self.pending_handover {
            flags = Health(flags.0 | Health::HANDOVER.0);
            self.pending_handover = false;
        }
        let msg = self.message(
            &c.pose,
            Some(&c.rel),
            flags,
            r.t_to,
            health.contains(Health::RADAR_MISSING),
        );
        self.counters.radar_poses += 1;
        emit(PoseOut {
            msg,
            t: r.t_to,
            read_ns: item.read_ns,
            emitted_ns: now_ns,
        });
    }

    /// Runs the estimator(s) on one frame. While the primary is healthy the fallback runs beside
    /// it on its own chain; when the primary fails, the fallback takes over from the trajectory's
    /// last pose (a hand-over, never a new origin).
    fn estimate(&mut self, f: &RadarInput<'_>) -> Option<Step> {
        if self.use_fallback {
            let fb = self.built.fallback.as_mut()?;
            let r = fb.push_radar(f).ok().flatten()?;
            if !self.bridging {
                return Some(Step::Pose(r));
            }
            self.bridging = false;
            return Some(match self.composer.last() {
                // Nothing composed yet: the fallback's chain is the trajectory.
                None => Step::Pose(r),
                Some(last) => Step::Handover(r, self.bridge(last, &r)),
            });
        }
        let res = self.built.primary.push_radar(f);
        let Some(fb) = self.built.fallback.as_mut() else {
            return match res {
                Ok(r) => r.map(Step::Pose),
                Err(e) => {
                    self.counters.errors += 1;
                    tracing::warn!(error = %e, "estimator error");
                    None
                }
            };
        };
        let fb = fb.push_radar(f).ok().flatten();
        match res {
            Ok(r) if self.built.primary.healthy() => {
                if let Some(x) = &fb {
                    self.shadow.push(x);
                }
                r.map(Step::Pose)
            }
            res => {
                if let Err(e) = &res {
                    self.counters.errors += 1;
                    tracing::warn!(error = %e, "primary estimator failed");
                }
                if self.handover_reason.is_none() {
                    let name = self.built.primary.name();
                    self.handover_reason = Some(match &res {
                        Err(e) => format!("the {name} estimator failed: {e}"),
                        Ok(_) if name == "fused" => {
                            "the learned measurements failed the online consistency check".into()
                        }
                        Ok(_) => format!("the {name} estimator reported itself unhealthy"),
                    });
                }
                tracing::warn!(
                    reason = self.handover_reason.as_deref().unwrap_or(""),
                    "handing over to the fallback"
                );
                self.use_fallback = true;
                let Some(r) = fb else {
                    // The fallback has no pose for this frame: bridge at its next one.
                    self.bridging = true;
                    return None;
                };
                Some(match self.composer.last() {
                    None => Step::Pose(r),
                    Some(last) => Step::Handover(r, self.bridge(last, &r)),
                })
            }
        }
    }

    /// World pose of `r.from_frame` at a hand-over: the trajectory's last pose moved by the
    /// fallback's own motion from that frame to `r.from_frame` (its shadow chain), or the last
    /// pose itself when the shadow does not hold both frames.
    fn bridge(&self, last: &Composed, r: &RelativePose) -> Isometry3<f64> {
        match (
            self.shadow.pose_of(last.frame),
            self.shadow.pose_of(r.from_frame),
        ) {
            (Some(at_last), Some(at_from)) => last.pose * (at_last.inverse() * at_from),
            _ => last.pose,
        }
    }

    fn message(
        &self,
        pose: &Isometry3<f64>,
        rel: Option<&Isometry3<f64>>,
        health: Health,
        t: f64,
        radar_missing: bool,
    ) -> PoseMessage {
        let p = pose.translation.vector;
        let rel = rel.copied().unwrap_or_else(|| {
            self.composer
                .last()
                .map_or(Isometry3::identity(), |l| l.pose.inverse() * pose)
        });
        PoseMessage {
            health,
            estimator: self.code(radar_missing),
            seq: 0,
            measurement_time_ns: (t.max(0.0) * 1e9) as u64,
            host_time_ns: 0,
            position: [p.x, p.y, p.z],
            orientation: wxyz_f32(&pose.rotation),
            rel_translation: [
                rel.translation.x as f32,
                rel.translation.y as f32,
                rel.translation.z as f32,
            ],
            rel_rotation: wxyz_f32(&rel.rotation),
            dropped_total: 0,
        }
    }
}
