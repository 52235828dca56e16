//! From a frame to a point cloud: the points of whichever point TLV the frame carries, in
//! Cartesian metres and m/s, with side info and the list of TLVs seen.

use crate::error::TlvError;
use crate::frame::Frame;
use crate::tlv::{Dialect, Point, Stats, Target, Tlv};
use alloc::vec::Vec;

/// The decoded content of one frame that egomotion and the dump care about.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// Points (x right, y boresight, z up \[m\]; radial velocity \[m/s\]).
    pub points: Vec<Point>,
    /// False when the velocities could not be scaled (SDK 1/2 Doppler indices without a .cfg);
    /// the velocities are then NaN.
    pub velocity_known: bool,
    /// SNR per point: \[dB\] from OOB side info (TLV 7); the lab's own unit (value x snr unit) for
    /// compressed points.
    pub snr_db: Option<Vec<f32>>,
    /// Noise per point \[dB\], when the frame carries side info.
    pub noise_db: Option<Vec<f32>>,
    /// Tracked targets (people-counting and toolbox frames).
    pub targets: Vec<Target>,
    /// Processing statistics (OOB TLV 6), when sent.
    pub stats: Option<Stats>,
    /// TLV types in frame order.
    pub tlv_types: Vec<u32>,
    /// True when a points TLV was present but empty (the SDK 3.5 zero-point quirk).
    pub empty_points_tlv: bool,
    /// TLVs of a known type whose payload did not fit (left undecoded, passed through raw).
    pub tlv_errors: Vec<TlvError>,
}

impl PointCloud {
    /// Decodes `frame`. `velocity_resolution_mps` scales SDK 1/2 Doppler indices (from
    /// [`crate::cfg::Derived::velocity_resolution_mps`]).
    pub fn from_frame(frame: &Frame<'_>, velocity_resolution_mps: Option<f32>) -> PointCloud {
        let mut c = PointCloud::default();
        c.decode_into(frame, velocity_resolution_mps);
        c
    }

    /// Decodes `frame` into `self`, reusing its buffers: the vectors are cleared and refilled, so
    /// once they have grown to a frame's size decoding allocates nothing (the SNR and noise
    /// vectors are reused while consecutive frames carry side info). Same result as
    /// [`PointCloud::from_frame`].
    pub fn decode_into(&mut self, frame: &Frame<'_>, velocity_resolution_mps: Option<f32>) {
        let dialect = Dialect::of(frame);
        let c = self;
        let mut snr = c.snr_db.take();
        let mut noise = c.noise_db.take();
        let mut snr_set = false;
        let mut noise_set = false;
        c.points.clear();
        c.velocity_known = true;
        c.targets.clear();
        c.stats = None;
        c.tlv_types.clear();
        c.empty_points_tlv = false;
        c.tlv_errors.clear();
        fn refill(v: &mut Option<Vec<f32>>, it: impl Iterator<Item = f32>) {
            let b = v.get_or_insert_with(Vec::new);
            b.clear();
            b.extend(it);
        }
        for raw in frame.tlvs() {
            c.tlv_types.push(raw.ty);
            match raw.decode(dialect) {
                Ok(Tlv::Points(p)) => {
                    c.empty_points_tlv |= p.is_empty();
                    c.points.extend(p.iter());
                }
                Ok(Tlv::PointsQ(p)) => {
                    c.empty_points_tlv |= p.is_empty();
                    c.velocity_known = velocity_resolution_mps.is_some();
                    let scale = velocity_resolution_mps.unwrap_or(f32::NAN);
                    c.points.extend(p.iter().map(|q| Point {
                        x: q.x,
                        y: q.y,
                        z: q.z,
                        velocity: f32::from(q.doppler_idx) * scale,
                    }));
                }
                Ok(Tlv::CompressedPoints(p)) => {
                    c.empty_points_tlv |= p.is_empty();
                    c.points.extend(p.iter().map(|s| s.to_cartesian()));
                    refill(&mut snr, p.iter().map(|s| s.snr));
                    snr_set = true;
                }
                Ok(Tlv::SideInfo(s)) => {
                    refill(&mut snr, s.iter().map(|e| e.snr_db()));
                    refill(&mut noise, s.iter().map(|e| e.noise_db()));
                    snr_set = true;
                    noise_set = true;
                }
                Ok(Tlv::Targets(t)) => c.targets.extend(t.iter()),
                Ok(Tlv::Stats(st)) => c.stats = Some(st),
                Ok(_) => {}
                Err(e) => c.tlv_errors.push(e),
            }
        }
        c.snr_db = if snr_set { snr } else { None };
        c.noise_db = if noise_set { noise } else { None };
    }
}
