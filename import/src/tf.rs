//! Extrinsics from a recording's static transforms (`/tf_static`, `tf2_msgs/TFMessage`), used
//! when no calibration file is given.
//!
//! The transforms form a tree (each child has one parent). A frame's pose in the body frame is
//! the product along the path between them: `T_body_f = T_root_body^-1 * T_root_f`. The body
//! frame is the ground truth's child frame when the tree knows it, else the root shared by the
//! radar and IMU frames (`base_link` on most robots; the IMU's frame when the rig is described
//! from the IMU).

use crate::ros::TransformStamped;
use milliego_session::Extrinsic;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::collections::BTreeMap;

/// The static transform tree: child frame -> (parent frame, T_parent_child).
#[derive(Debug, Default, Clone)]
pub struct StaticTf {
    edges: BTreeMap<String, (String, Isometry3<f64>)>,
}

/// Frames of a rig resolved in the tree.
#[derive(Debug, Clone, PartialEq)]
pub struct RigFrames {
    /// The body frame's name.
    pub body: String,
    /// Body <- radar frame (the frame the scans are published in).
    pub radar: Option<Extrinsic>,
    /// Body <- IMU frame.
    pub imu: Option<Extrinsic>,
}

impl StaticTf {
    /// Adds a transform (a later one for the same child replaces the earlier).
    pub fn add(&mut self, x: &TransformStamped) {
        let [qx, qy, qz, qw] = x.rotation;
        let q = UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz));
        let t = Translation3::new(x.translation[0], x.translation[1], x.translation[2]);
        let parent = x.header.frame_id.trim_start_matches('/').to_string();
        let child = x.child_frame_id.trim_start_matches('/').to_string();
        if parent != child && q.coords.iter().all(|v| v.is_finite()) {
            self.edges
                .insert(child, (parent, Isometry3::from_parts(t, q)));
        }
    }

    /// No transforms.
    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    /// Whether a transform names `frame` (as child or parent).
    fn knows(&self, frame: &str) -> bool {
        let f = frame.trim_start_matches('/');
        self.edges.contains_key(f) || self.edges.values().any(|(p, _)| p == f)
    }

    /// `frame`'s root and T_root_frame (`None` for a cycle).
    fn to_root(&self, frame: &str) -> Option<(String, Isometry3<f64>)> {
        let mut f = frame.trim_start_matches('/').to_string();
        let mut t = Isometry3::identity();
        for _ in 0..=self.edges.len() {
            match self.edges.get(&f) {
                Some((parent, x)) => {
                    t = x * t;
                    f = parent.clone();
                }
                None => return Some((f, t)),
            }
        }
        None
    }

    /// T_a_b when both are in one tree.
    fn between(&self, a: &str, b: &str) -> Option<Isometry3<f64>> {
        let (ra, ta) = self.to_root(a)?;
        let (rb, tb) = self.to_root(b)?;
        (ra == rb).then(|| ta.inverse() * tb)
    }

    /// Resolves the radar and IMU frames in the body frame: `body` when given and in the same
    /// tree as one of them, else the root they share (or that of the one present).
    pub fn rig(
        &self,
        body: Option<&str>,
        radar: Option<&str>,
        imu: Option<&str>,
    ) -> Option<RigFrames> {
        let radar = radar.filter(|f| self.knows(f));
        let imu = imu.filter(|f| self.knows(f));
        let frames: Vec<&str> = radar.into_iter().chain(imu).collect();
        let root = |f: &str| self.to_root(f).map(|r| r.0);
        let body = body
            .filter(|b| frames.iter().any(|f| self.between(b, f).is_some()))
            .map(|b| b.trim_start_matches('/').to_string())
            .or_else(|| {
                let roots: Vec<String> = frames.iter().filter_map(|f| root(f)).collect();
                roots
                    .first()
                    .filter(|r| roots.iter().all(|x| x == *r))
                    .cloned()
            })?;
        let get = |f: Option<&str>| self.between(&body, f?).map(|x| extrinsic(&x));
        let (r, i) = (get(radar), get(imu));
        (r.is_some() || i.is_some()).then_some(RigFrames {
            body,
            radar: r,
            imu: i,
        })
    }
}

fn extrinsic(x: &Isometry3<f64>) -> Extrinsic {
    let t = x.translation.vector;
    let q = x.rotation;
    Extrinsic {
        translation_m: [t.x, t.y, t.z],
        rotation_wxyz: [q.w, q.i, q.j, q.k],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::Header;

    fn tf(parent: &str, child: &str, t: [f64; 3], q_xyzw: [f64; 4]) -> TransformStamped {
        TransformStamped {
            header: Header {
                frame_id: parent.into(),
                ..Header::default()
            },
            child_frame_id: child.into(),
            translation: t,
            rotation: q_xyzw,
        }
    }

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn chains_compose_and_the_body_is_the_shared_root_or_the_one_named() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let mut tree = StaticTf::default();
        // base_link -> mount (1 m ahead, yawed +90 deg) -> radar (0.1 m along the mount's x).
        tree.add(&tf("base_link", "mount", [1.0, 0.0, 0.0], [0.0, 0.0, s, s]));
        tree.add(&tf(
            "mount",
            "/radar",
            [0.1, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ));
        tree.add(&tf(
            "/base_link",
            "imu",
            [0.0, 0.0, 0.2],
            [0.0, 0.0, 0.0, 1.0],
        ));
        let rig = tree.rig(None, Some("radar"), Some("imu")).unwrap();
        assert_eq!(rig.body, "base_link");
        let r = rig.radar.unwrap();
        assert!(close(r.translation_m, [1.0, 0.1, 0.0]), "{r:?}");
        assert!((r.rotation_wxyz[0] - s).abs() < 1e-12 && (r.rotation_wxyz[3] - s).abs() < 1e-12);
        assert!(close(rig.imu.unwrap().translation_m, [0.0, 0.0, 0.2]));
        // Described from the IMU: the radar relative to it.
        let rig = tree.rig(Some("imu"), Some("radar"), Some("imu")).unwrap();
        assert_eq!(rig.body, "imu");
        assert!(close(rig.radar.unwrap().translation_m, [1.0, 0.1, -0.2]));
        assert_eq!(rig.imu.unwrap(), Extrinsic::default());
        // A body frame the tree does not know falls back to the shared root.
        assert_eq!(
            tree.rig(Some("odom"), Some("radar"), None).unwrap().body,
            "base_link"
        );
    }

    #[test]
    fn disconnected_frames_and_cycles_resolve_to_nothing() {
        let mut tree = StaticTf::default();
        tree.add(&tf("a", "radar", [0.0; 3], [0.0, 0.0, 0.0, 1.0]));
        tree.add(&tf("b", "imu", [0.0; 3], [0.0, 0.0, 0.0, 1.0]));
        assert_eq!(tree.rig(None, Some("radar"), Some("imu")), None);
        assert_eq!(tree.rig(None, Some("nowhere"), None), None);
        let mut cyc = StaticTf::default();
        cyc.add(&tf("x", "y", [0.0; 3], [0.0, 0.0, 0.0, 1.0]));
        cyc.add(&tf("y", "x", [0.0; 3], [0.0, 0.0, 0.0, 1.0]));
        assert_eq!(cyc.rig(None, Some("x"), None), None);
    }
}
