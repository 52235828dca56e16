//! The radar model in hand-built worlds: specular surfaces return only near normal incidence,
//! returns closer than the angular resolution merge, mirror ghosts appear behind the mirror.

use milliego_sim::radar::{PointClass, RadarModel, SimPoint};
use milliego_sim::rng::SimRng;
use milliego_sim::world::{Family, Material, Primitive, Scatterer, Shape, World};
use nalgebra::{UnitQuaternion, Vector3};

fn world(prims: Vec<Primitive>, scatterers: Vec<Scatterer>, height: f64) -> World {
    World {
        family: Family::Office,
        seed: 0,
        min: [-50.0, -50.0],
        max: [50.0, 50.0],
        height,
        prims,
        scatterers,
    }
}

fn frames(w: &World, p: Vector3<f64>, yaw_deg: f64, n: usize) -> Vec<Vec<SimPoint>> {
    let m = RadarModel::new(20.0).unwrap();
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, yaw_deg.to_radians());
    let mut rng = SimRng::new(1, "radar-model-test");
    (0..n)
        .map(|_| m.frame(w, &p, &q, &Vector3::zeros(), &mut rng))
        .collect()
}

fn inliers(f: &[Vec<SimPoint>]) -> Vec<SimPoint> {
    f.iter()
        .flatten()
        .filter(|p| p.class == PointClass::Inlier)
        .copied()
        .collect()
}

/// A glass wall along x at y = 3 m, the radar 1.5 m above the floor at the origin.
fn glass() -> World {
    world(
        vec![Primitive {
            shape: Shape::Wall {
                a: [-20.0, 3.0],
                b: [20.0, 3.0],
                z0: 0.0,
                z1: 3.0,
            },
            material: Material::Glass,
        }],
        Vec::new(),
        3.0,
    )
}

#[test]
fn glass_returns_only_near_normal_incidence() {
    let w = glass();
    let p = Vector3::new(0.0, 0.0, 1.5);
    // Yawed 30° (radar boresight = world y at yaw 0): the wall's normal is still in view.
    let pts = inliers(&frames(&w, p, 30.0, 100));
    assert!(pts.len() > 30, "{} glass returns", pts.len());
    for pt in &pts {
        // The ray (in the world) from the radar to the return, against the wall normal -y.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, 30f64.to_radians());
        let d = (q * pt.true_xyz).normalize();
        let incidence = d.y.clamp(-1.0, 1.0).acos().to_degrees();
        assert!(incidence < 10.0, "glass return at {incidence}° incidence");
    }
    // Yawed 70°: the normal is outside the ±60° field of view, the glass is invisible.
    assert_eq!(inliers(&frames(&w, p, 70.0, 100)).len(), 0);
}

fn two_scatterers(half_angle_deg: f64) -> World {
    let a = half_angle_deg.to_radians();
    let s = |x: f64| Scatterer {
        p: Vector3::new(x * 4.0 * a.sin(), 4.0 * a.cos(), 50.0),
        rcs: 1.0,
    };
    // Floor and ceiling out of range: only the two scatterers.
    world(Vec::new(), vec![s(-1.0), s(1.0)], 100.0)
}

#[test]
fn returns_closer_than_the_angular_resolution_merge() {
    let p = Vector3::new(0.0, 0.0, 50.0);
    let close = frames(&two_scatterers(3.0), p, 0.0, 100);
    let far = frames(&two_scatterers(20.0), p, 0.0, 100);
    let count = |f: &[Vec<SimPoint>]| {
        f.iter()
            .map(|fr| fr.iter().filter(|p| p.class == PointClass::Inlier).count())
            .collect::<Vec<_>>()
    };
    // 6° apart at the same range and Doppler: one point per frame.
    assert!(count(&close).iter().all(|&n| n == 1), "{:?}", count(&close));
    // 40° apart: two points (unless one fades below the threshold).
    let two = count(&far).iter().filter(|&&n| n == 2).count();
    assert!(
        two > 90,
        "only {two} of 100 frames resolve scatterers 40° apart"
    );
}

#[test]
fn mirror_ghosts_appear_behind_the_mirror() {
    // A drywall at y = 3 m and a strong scatterer in front of it, off to the side.
    let mut w = glass();
    w.prims[0].material = Material::Drywall;
    w.scatterers.push(Scatterer {
        p: Vector3::new(1.0, 1.5, 1.5),
        rcs: 1.0,
    });
    let f = frames(&w, Vector3::new(0.0, 0.0, 1.5), 0.0, 200);
    let ghosts: Vec<SimPoint> = f
        .iter()
        .flatten()
        .filter(|p| p.class == PointClass::Mirror)
        .copied()
        .collect();
    assert!(ghosts.len() > 20, "{} mirror ghosts", ghosts.len());
    for g in &ghosts {
        assert!(
            g.true_xyz.y > 3.0,
            "ghost at y = {} is not behind the wall",
            g.true_xyz.y
        );
    }
    // Outliers make up the configured share here too.
    let all = f.iter().flatten().count();
    let out = f
        .iter()
        .flatten()
        .filter(|p| p.class != PointClass::Inlier)
        .count();
    let share = out as f64 / all as f64;
    assert!((share - 0.75).abs() < 0.06, "outlier share {share}");
}

#[test]
fn outlier_share_follows_the_configuration() {
    let w = World::generate(Family::Office, 4);
    let mut rng = SimRng::new(2, "share-test");
    let p = w.free_point(&mut rng, 1.0).unwrap();
    let p = Vector3::new(p[0], p[1], 1.3);
    for share in [0.5, 0.75, 0.9] {
        let mut m = RadarModel::new(20.0).unwrap();
        m.outlier_share = share;
        m.min_points = 0;
        m.max_points = 1000;
        let (mut all, mut out) = (0, 0);
        for i in 0..400 {
            let q = UnitQuaternion::from_euler_angles(0.0, 0.0, f64::from(i) * 0.05);
            let f = m.frame(&w, &p, &q, &Vector3::new(0.5, 0.0, 0.0), &mut rng);
            all += f.len();
            out += f.iter().filter(|p| p.class != PointClass::Inlier).count();
        }
        let got = out as f64 / all as f64;
        assert!(all > 1000, "{all} points");
        assert!(
            (got - share).abs() < 0.03,
            "configured {share}, measured {got}"
        );
    }
}
