//! The run summary: what `milliego run` prints at the end and writes with `--summary-json`. Every
//! count a run keeps is here, so nothing it dropped goes unreported. The JSON keys are the field
//! names; times are in seconds unless the name says otherwise (`_ms`, `_us`).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The whole summary of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// The estimator asked for (`auto`, `model`, `doppler`, `imu`).
    pub estimator: String,
    /// What was read: `session` (a recorded session) or `devices` (live ports).
    pub input: String,
    /// Wall time of the run \[s\].
    pub wall_s: f64,
    /// Radar frames and IMU samples decoded.
    pub frames_in: FramesIn,
    /// Whether a barometer aided the height (or that the input had none).
    #[serde(default)]
    pub barometer: String,
    /// The radar-to-IMU time offset, when it was estimated (imported radar scans not timed by a
    /// trigger), or that the stamps were trusted.
    #[serde(default)]
    pub radar_time_offset: String,
    /// The Doppler quantisation step the ego-velocity's gate assumed: read from the points'
    /// radial velocities when they show one, else the `.cfg`'s velocity resolution.
    #[serde(default)]
    pub doppler_step: String,
    /// The IMU noise preset the filter assumed and where it came from (the session's IMU
    /// device, `--imu-noise`, or the defaults).
    #[serde(default)]
    pub imu_noise: String,
    /// What the estimator stage and the outputs produced.
    pub frames_out: FramesOut,
    /// Items dropped by every queue and buffer.
    pub drops: Drops,
    /// The synchroniser's counters and clocks.
    pub sync: SyncSummary,
    /// Serial port counters.
    pub ports: Ports,
    /// Latency histograms.
    pub latency: LatencySummary,
    /// Radar frames the plausibility checks rejected, re-anchored, retracted or held.
    pub radar_plausibility: Plausibility,
    /// Wall time per decoded radar frame \[us\] (0 without radar).
    pub per_radar_frame_us: f64,
    /// Items the live view's hand-off lost (a slow view; `--foxglove`): radar frames, IMU
    /// samples, poses and status updates it never showed. The pose path never waits for it.
    #[serde(default)]
    pub view_dropped: u64,
    /// Channel messages the live view dropped for clients that read too slowly (all clients
    /// together; each client keeps its newest `--foxglove-backlog` messages). Set by the CLI
    /// when the view stops; the pose path never waits for a client either.
    #[serde(default)]
    pub view_client_dropped: u64,
    /// The learned model's measurements in the fused estimator (`auto` with a model, `fused`);
    /// absent for the other estimators.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learned: Option<LearnedSummary>,
    /// What the Doppler filter did with its measurements (the estimators that run it: `doppler`,
    /// `fused`, `auto`); absent for the others.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub filter: Option<FilterSummary>,
}

/// What the error-state filter did with each kind of measurement (docs/odometry.md).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct FilterSummary {
    /// Radar ego-velocities applied.
    pub radar_updates: u64,
    /// Radar ego-velocities beyond the chi-square gate (not applied).
    pub radar_gated: u64,
    /// Times a run of gated radar measurements re-anchored the velocity.
    pub radar_reanchors: u64,
    /// Zero-velocity, position-hold and zero-rate updates at rest.
    pub rest_updates: u64,
    /// "Vertical velocity 0" bounds at frames that could not see it.
    pub vertical_bounds: u64,
    /// "Horizontal velocity 0" bounds where the filter had lost its velocity (no radar velocity
    /// for long; not for ground vehicles).
    pub horizontal_bounds: u64,
    /// "Horizontal speed = the pace" bounds where the filter had lost its speed after the radar
    /// last measured it (not for ground vehicles).
    pub pace_bounds: u64,
    /// Ground vehicle constraints applied ("sideways and vertical velocity 0" at each radar
    /// frame; `--vehicle` only).
    #[serde(default)]
    pub ground_vehicle_applied: u64,
    /// Ground vehicle constraints beyond their gate (not applied): many of them say the vehicle
    /// slid, or its body frame sits off the point that does not slide sideways (docs/odometry.md,
    /// "How tight the ground vehicle constraint is").
    #[serde(default)]
    pub ground_vehicle_gated: u64,
    /// Barometric heights applied.
    pub baro_updates: u64,
    /// Barometric heights rejected (not finite, or beyond the 99.9% gate).
    pub baro_rejected: u64,
    /// Times the height re-anchored to the barometer after a second of rejections.
    pub baro_reanchors: u64,
    /// Radar frames whose points were weighed by whether they were seen again (`--persist-window`;
    /// 0 when that is off).
    #[serde(default)]
    pub frames_weighed: u64,
    /// Points of those frames seen again (an earlier frame's point within the radius; weight 1).
    #[serde(default)]
    pub points_seen_again: u64,
    /// Points of those frames seen for the first time (the lower weight).
    #[serde(default)]
    pub points_fresh: u64,
    /// Mean normalised innovation square of the applied radar ego-velocities (3 degrees of
    /// freedom: 3 when the stated Doppler noise fits the radar; well below, the filter trusts the
    /// radar less than it could; above, more than it should). None before the first update.
    #[serde(default)]
    pub radar_nis_mean: Option<f64>,
    /// The scale the filter applies, at the end of the run, to the covariances of the radar
    /// ego-velocities (1: as stated; above: the innovations said the radar is noisier than
    /// stated, docs/odometry.md "Radar noise adaptation"). None when no filter ran.
    #[serde(default)]
    pub radar_noise_scale: Option<f64>,
    /// The near field in use at the end \[m\]: points this close at zero Doppler do not vote
    /// for the ego-velocity (0: off; turned on, at 1 m, once the points showed near-field leakage,
    /// docs/odometry.md "Near-field leakage").
    #[serde(default)]
    pub near_field_m: f32,
    /// Near points the leakage test judged (their static Doppler clearly away from 0 under the
    /// filter's motion), and how many of them read zero Doppler anyway.
    #[serde(default)]
    pub near_field_tested: (u32, u32),
    /// Points that did not vote as possible near-field leakage.
    #[serde(default)]
    pub near_field_points: u64,
    /// The longest stretch the filter's poses rested on the IMU alone \[s\]: no radar
    /// velocity, rest or learned measurement applied (a scene the radar could not see).
    #[serde(default)]
    pub unaided_longest_s: f64,
    /// When it began \[s, the run's clock\].
    #[serde(default)]
    pub unaided_from_s: f64,
    /// The filter's poses given more than a second after an aid (published flagged
    /// `dead_reckoning`).
    #[serde(default)]
    pub poses_unaided: u64,
}

impl From<milliego_odometry::rio::RioCounters> for FilterSummary {
    fn from(c: milliego_odometry::rio::RioCounters) -> Self {
        FilterSummary {
            radar_updates: c.updates,
            radar_gated: c.gated,
            radar_reanchors: c.reanchors,
            rest_updates: c.rest_updates,
            vertical_bounds: c.vertical_bounds,
            horizontal_bounds: c.horizontal_bounds,
            pace_bounds: c.pace_bounds,
            ground_vehicle_applied: c.nonholonomic_updates,
            ground_vehicle_gated: c.nonholonomic_gated,
            baro_updates: c.baro_updates,
            baro_rejected: c.baro_rejected,
            baro_reanchors: c.baro_reanchors,
            ..FilterSummary::default()
        }
    }
}

/// What became of the learned model's relative motions in the fused estimator
/// (docs/model.md, "Fusion"). Every evaluated one has a normalised innovation square (NIS).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct LearnedSummary {
    /// Applied to the filter.
    pub applied: u64,
    /// Beyond the chi-square gate (not applied).
    pub gated: u64,
    /// Within the gate but not applied: the recent ones failed the online check (`auto`).
    pub suspended: u64,
    /// Skipped at rest (the zero-velocity update stands in).
    pub at_rest: u64,
    /// Skipped where the radar updated the filter over the whole interval (off by default).
    #[serde(default)]
    pub covered: u64,
    /// Without a filter pose at one of their keyframes (start-up, IMU gaps).
    pub no_anchor: u64,
    /// Not usable (not finite, no interval).
    pub invalid: u64,
    /// Mean NIS of the evaluated ones (3 when their stated uncertainty is right).
    pub nis_mean: Option<f64>,
    /// The factor the filter applied to their stated covariance at the end, from their error
    /// where the radar covered the motion (1: as stated; docs/model.md, "Fusion").
    #[serde(default)]
    pub noise_factor: Option<f64>,
    /// Whether the online check switched them off (`auto` then handed over to Doppler).
    pub switched_off: bool,
    /// Whether they were being applied when the run ended.
    pub in_use_at_end: bool,
    /// Windows the model ran on.
    pub model_windows: u64,
    /// Model failures (inference errors, outputs that are not a finite pose).
    pub model_failures: u64,
    /// Why the model was switched off, if it was (the Doppler filter went on alone).
    pub model_off: Option<String>,
    /// Why `auto` handed over to the Doppler filter, if it did (the online check, or the model's
    /// failure).
    #[serde(default)]
    pub handover: Option<String>,
}

/// Inputs decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FramesIn {
    /// Radar frames.
    pub radar: u64,
    /// IMU samples.
    pub imu: u64,
    /// Barometer readings (in the IMU stream).
    #[serde(default)]
    pub pressure: u64,
}

/// Outputs produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FramesOut {
    /// Poses sent, of every kind.
    pub poses_sent: u64,
    /// Radar-rate poses sent.
    pub radar_rate: u64,
    /// IMU-rate predicted poses the stage produced.
    pub predicted: u64,
    /// Radar frames that produced no pose (levelling, model stride).
    pub no_pose: u64,
    /// Origin resets.
    pub resets: u64,
    /// Hand-overs from the primary estimator to the fallback.
    pub handovers: u64,
    /// Estimator errors.
    pub estimator_errors: u64,
    /// Sends that failed (counted, the pose is lost for that sink).
    pub send_errors: u64,
}

/// Drops of every queue and buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Drops {
    /// Radar reader -> synchroniser queue.
    pub radar_queue: u64,
    /// IMU reader -> synchroniser queue.
    pub imu_queue: u64,
    /// The synchroniser's reordering buffers.
    pub sync_buffers: u64,
    /// Synchroniser -> estimator queue.
    pub event_queue: u64,
    /// Estimator -> output queue.
    pub pose_queue: u64,
    /// Barometer readings replaced by a later one before an IMU sample could carry them.
    #[serde(default)]
    pub pressure: u64,
    /// All of the above.
    pub total: u64,
}

/// The synchroniser.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SyncSummary {
    /// Radar frames released.
    pub radar_released: u64,
    /// IMU samples released.
    pub imu_released: u64,
    /// Radar frames released after the IMU had passed their time.
    pub radar_late: u64,
    /// Times the radar was declared missing.
    pub radar_gaps: u64,
    /// Items held while the clocks were not yet synchronised (start-up), re-timed after.
    pub warmup_held: u64,
    /// Times the IMU was declared missing.
    pub imu_gaps: u64,
    /// The sensor -> host clock maps.
    pub clocks: Clocks,
}

/// The clock maps at the end of the run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Clocks {
    /// Radar clock, once it has a map.
    pub radar: Option<ClockSummary>,
    /// IMU clock, once it has a map.
    pub imu: Option<ClockSummary>,
    /// True when the session's offline clock fit was used instead of the online clocks.
    pub offline_fit: bool,
}

/// One sensor -> host clock map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClockSummary {
    /// Offset \[s\]: host = offset + rate * sensor.
    pub offset_s: f64,
    /// Rate (host seconds per sensor second).
    pub rate: f64,
    /// (sensor, host) pairs accepted into the fit window.
    pub accepted: u64,
    /// Pairs rejected as late.
    pub rejected_late: u64,
}

/// Serial port counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ports {
    /// Times the radar data port was reopened.
    pub radar_reopens: u64,
    /// Times the IMU port was reopened.
    pub imu_reopens: u64,
    /// Radar bytes read \[B\].
    pub radar_bytes: u64,
    /// IMU bytes read \[B\].
    pub imu_bytes: u64,
}

/// The latency histograms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatencySummary {
    /// Read of the last byte -> released by the synchroniser.
    pub sync: HistogramSummary,
    /// Estimator compute time per event.
    pub estimate: HistogramSummary,
    /// Estimator stage -> sent.
    pub output: HistogramSummary,
    /// Radar-rate poses: sensor byte read -> sent.
    pub end_to_end: HistogramSummary,
    /// Predicted poses: IMU sample read -> sent.
    pub imu_to_pose: HistogramSummary,
    /// Time the estimator and output threads spent handing one item to the live view (copy and
    /// `try_send`; empty without `--foxglove`).
    #[serde(default)]
    pub view_handoff: HistogramSummary,
}

/// One latency histogram.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct HistogramSummary {
    /// Values recorded.
    pub count: u64,
    /// Median \[ms\] (none when empty).
    pub p50_ms: Option<f64>,
    /// 99th percentile \[ms\].
    pub p99_ms: Option<f64>,
    /// Largest \[ms\].
    pub max_ms: Option<f64>,
    /// Mean \[ms\].
    pub mean_ms: f64,
}

/// The radar plausibility verdicts.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Plausibility {
    /// Frames rejected, by reason (every reason listed, zero included).
    pub rejected: BTreeMap<String, u64>,
    /// Frames rejected, all reasons.
    pub rejected_total: u64,
    /// Frames that confirmed a sensor restart or frame-number jump (the frame before them was
    /// rejected as `frame_number`, these were accepted).
    pub reanchored: u64,
    /// Frames the framer retracted (they lost bytes on the wire and ended inside the next
    /// frame's magic word); never published.
    pub retracted: u64,
    /// Frames held for the bytes after them before they were published or retracted (their
    /// last bytes began a magic word).
    pub held: u64,
}

impl Plausibility {
    /// From the per-reason counts, in [`radar_driver::plausible::IMPLAUSIBLE_NAMES`] order.
    pub fn new(rejected: &[u64], reanchored: u64, retracted: u64, held: u64) -> Plausibility {
        Plausibility {
            rejected: radar_driver::plausible::IMPLAUSIBLE_NAMES
                .iter()
                .zip(rejected)
                .map(|(n, c)| ((*n).to_string(), *c))
                .collect(),
            rejected_total: rejected.iter().sum(),
            reanchored,
            retracted,
            held,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plausibility_lists_every_reason_and_the_total() {
        let n = radar_driver::plausible::IMPLAUSIBLE_NAMES.len();
        let counts: Vec<u64> = (1..=n as u64).collect();
        let p = Plausibility::new(&counts, 2, 3, 4);
        assert_eq!(p.rejected.len(), n);
        assert_eq!(p.rejected_total, counts.iter().sum::<u64>());
        let name = radar_driver::plausible::IMPLAUSIBLE_NAMES[0];
        assert_eq!(p.rejected[name], 1);
        let j = serde_json::to_value(&p).unwrap();
        assert_eq!(j["held"], 4);
        assert_eq!(serde_json::from_value::<Plausibility>(j).unwrap(), p);
    }
}
