//! A session's ground truth for the view: interpolated at the estimate's times and drawn in the
//! estimate's world frame, aligned once at the first radar-rate pose (the estimator's world
//! frame has its own origin and heading).

use crate::ViewError;
use milliego_session::{Session, TumPose};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use std::path::Path;

/// The ground-truth trajectory (body in its world frame, session host clock).
#[derive(Debug, Clone)]
pub struct GroundTruth {
    poses: Vec<TumPose>,
    /// Estimate world <- ground-truth world, fixed at the first radar-rate pose.
    align: Option<Isometry3<f64>>,
}

impl GroundTruth {
    /// The session's ground truth, when it has one.
    pub fn load(dir: &Path) -> Result<Option<GroundTruth>, ViewError> {
        let err = |error| ViewError::GroundTruth {
            dir: dir.to_path_buf(),
            error,
        };
        let s = Session::open(dir).map_err(err)?;
        let Some(mut poses) = s.groundtruth().map_err(err)? else {
            return Ok(None);
        };
        poses.sort_by(|a, b| a.t.total_cmp(&b.t));
        Ok((!poses.is_empty()).then_some(GroundTruth { poses, align: None }))
    }

    /// The ground-truth body pose at `t` (linear in position, slerp in attitude); None outside
    /// the trajectory.
    pub fn at(&self, t: f64) -> Option<Isometry3<f64>> {
        let p = &self.poses;
        let i = p.partition_point(|x| x.t < t);
        let iso = |x: &TumPose| {
            let [qx, qy, qz, qw] = x.q;
            Isometry3::from_parts(
                Translation3::from(Vector3::from(x.p)),
                UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz)),
            )
        };
        if i < p.len() && p[i].t == t {
            return Some(iso(&p[i]));
        }
        if i == 0 || i >= p.len() {
            return None;
        }
        let (a, b) = (&p[i - 1], &p[i]);
        let s = (t - a.t) / (b.t - a.t);
        let (ia, ib) = (iso(a), iso(b));
        let tr = ia.translation.vector.lerp(&ib.translation.vector, s);
        let rot = ia.rotation.slerp(&ib.rotation, s);
        Some(Isometry3::from_parts(Translation3::from(tr), rot))
    }

    /// The ground truth at `t` in the estimate's world frame; the first call with an estimate
    /// fixes the alignment.
    pub fn aligned(&mut self, t: f64, estimate: &Isometry3<f64>) -> Option<Isometry3<f64>> {
        let g = self.at(t)?;
        let align = *self.align.get_or_insert_with(|| estimate * g.inverse());
        Some(align * g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_and_aligns() {
        let mut gt = GroundTruth {
            poses: vec![
                TumPose {
                    t: 0.0,
                    p: [0.0, 0.0, 0.0],
                    q: [0.0, 0.0, 0.0, 1.0],
                },
                TumPose {
                    t: 1.0,
                    p: [2.0, 0.0, 0.0],
                    q: [0.0, 0.0, 0.0, 1.0],
                },
            ],
            align: None,
        };
        let mid = gt.at(0.5).unwrap();
        assert!((mid.translation.vector.x - 1.0).abs() < 1e-12);
        assert!(gt.at(1.5).is_none());
        let est = Isometry3::translation(5.0, 0.0, 0.0);
        let a = gt.aligned(0.5, &est).unwrap();
        assert!((a.translation.vector.x - 5.0).abs() < 1e-12);
        let b = gt.aligned(1.0, &est).unwrap();
        assert!((b.translation.vector.x - 6.0).abs() < 1e-12);
    }
}
