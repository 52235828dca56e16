//! The hand-off to a live view (the Foxglove server of `milliego-live-view`): the pipeline offers
//! copies of what it produces (radar frames, ordered IMU samples, poses as sent, periodic status)
//! on a bounded channel with `try_send`. A full channel (a slow or stalled view) loses the item,
//! counts it, and never blocks or delays the pose path: radar frames are copied after their pose
//! was queued, poses after they were sent and timed.

use crate::estimator::Mounting;
use crossbeam_channel::{Receiver, Sender, TrySendError};
use pose_link::PoseMessage;
use radar_driver::host::Point;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Items the view channel holds by default (about 15 s of a 20 Hz radar with a 200 Hz IMU).
pub const DEFAULT_VIEW_CAPACITY: usize = 4096;

/// One thing the pipeline shows the view.
#[derive(Debug, Clone)]
pub enum ViewEvent {
    /// Sent once before any data: what the view needs to draw the frames.
    Start {
        /// Sensor placement in the body frame.
        mounting: Mounting,
        /// The estimator asked for (`auto`, `model`, `doppler`, `imu`).
        estimator: String,
        /// `session` or `devices`.
        input: String,
        /// Session clocks: `session fit` (whole-session fit) or `online`.
        clock: String,
    },
    /// A radar frame as the estimator got it, points in the radar frame.
    Radar {
        /// Measurement time on the common clock \[s\].
        t: f64,
        /// Frame counter.
        frame_number: u32,
        /// Points: x, y, z \[m\], radial velocity \[m/s\].
        points: Vec<Point>,
        /// SNR per point \[dB\]; empty when the frame carries none.
        snr_db: Vec<f32>,
    },
    /// An IMU sample in time order.
    Imu {
        /// Time on the common clock \[s\].
        t: f64,
        /// Specific force \[m/s^2\] (IMU frame).
        accel: [f64; 3],
        /// Rate of turn \[rad/s\] (IMU frame).
        gyro: [f64; 3],
    },
    /// A pose as the outputs sent it (sequence number and host time filled in).
    Pose {
        /// Measurement time on the common clock \[s\] (the TUM file's stamp).
        t: f64,
        /// The message.
        msg: PoseMessage,
    },
    /// The pipeline's counters, about every 100 ms.
    Status(ViewStatus),
}

/// Counters of the running pipeline.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ViewStatus {
    /// Radar frames decoded.
    pub radar_in: u64,
    /// IMU samples decoded.
    pub imu_in: u64,
    /// Drops per queue: radar, IMU, events, poses; and the synchroniser's buffers.
    pub queue_drops: [u64; 5],
    /// Items the view channel lost so far.
    pub view_dropped: u64,
}

/// The pipeline's end of the view channel (cheap to clone; every clone counts into the same
/// drop counter).
#[derive(Debug, Clone)]
pub struct ViewTap {
    tx: Sender<ViewEvent>,
    dropped: Arc<AtomicU64>,
}

impl ViewTap {
    /// A channel of `capacity` items: the tap for the pipeline, the receiver for the view.
    pub fn new(capacity: usize) -> (ViewTap, Receiver<ViewEvent>) {
        let (tx, rx) = crossbeam_channel::bounded(capacity.max(1));
        (
            ViewTap {
                tx,
                dropped: Arc::new(AtomicU64::new(0)),
            },
            rx,
        )
    }

    /// Offers `ev` without waiting; a full channel (or a view that is gone) loses it and counts
    /// it. True when it was queued.
    pub fn offer(&self, ev: ViewEvent) -> bool {
        match self.tx.try_send(ev) {
            Ok(()) => true,
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// Items lost so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_channel_counts_and_never_blocks() {
        let (tap, rx) = ViewTap::new(2);
        let ev = ViewEvent::Imu {
            t: 0.0,
            accel: [0.0; 3],
            gyro: [0.0; 3],
        };
        assert!(tap.offer(ev.clone()));
        assert!(tap.offer(ev.clone()));
        assert!(!tap.offer(ev.clone()));
        assert_eq!(tap.dropped(), 1);
        drop(rx);
        assert!(!tap.clone().offer(ev));
        assert_eq!(tap.dropped(), 2);
    }
}
