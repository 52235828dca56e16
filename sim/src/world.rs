//! Worlds: procedurally generated indoor floors, deterministic from (family, seed).
//!
//! World frame: x, y horizontal, z up, the floor at z = 0 \[m\]. A world is a list of primitives
//! (vertical wall segments, axis-aligned boxes, vertical cylinders; floor and ceiling planes
//! implied), each with a [`Material`] that decides how it reflects at 77 GHz, plus point
//! scatterers at edges and corners (door frames, box corners, room corners), which are what a
//! real single-chip radar sees most reliably indoors.

use crate::rng::SimRng;
use crate::SimError;
use nalgebra::Vector3;
use std::fmt;
use std::str::FromStr;

/// A family of indoor floors (a family can be held out for testing).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Family {
    /// Long corridor, 1.8-2.8 m wide: smooth walls, recessed doors, glass fire door, pillars.
    Corridor,
    /// Open-plan office: desk clusters, chairs, metal cabinets, glass meeting room, windows.
    Office,
    /// Large hall, 6-12 m high: pillar grid, glass facade, planters, benches.
    Atrium,
    /// Cluttered store room: rows of metal shelving, boxes and pallets, narrow aisles.
    StoreRoom,
    /// Apartment: rooms behind partition walls with doors, sofa, bed, wardrobe, kitchen.
    Household,
    /// Open ground outdoors (a plaza or car park): no ceiling, weak ground returns, a few distant
    /// scatterers: lamp posts, parked cars, building facades 10-40 m away. Not in the benchmark
    /// split.
    Outdoor,
}

impl Family {
    /// All families.
    pub const ALL: [Family; 6] = [
        Family::Corridor,
        Family::Office,
        Family::Atrium,
        Family::StoreRoom,
        Family::Household,
        Family::Outdoor,
    ];

    /// The family's name on the command line and in split tables.
    pub fn name(self) -> &'static str {
        match self {
            Family::Corridor => "corridor",
            Family::Office => "office",
            Family::Atrium => "atrium",
            Family::StoreRoom => "store_room",
            Family::Household => "household",
            Family::Outdoor => "outdoor",
        }
    }
}

impl fmt::Display for Family {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Family {
    type Err = String;
    fn from_str(s: &str) -> Result<Family, String> {
        Family::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| {
                format!("unknown world family {s:?} (expected corridor, office, atrium, store_room, household or outdoor)")
            })
    }
}

/// What a surface is made of, for its 77 GHz reflection.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Material {
    /// Concrete or brick: rough, some diffuse return.
    Concrete,
    /// Smooth painted plasterboard: almost mirror-like.
    Drywall,
    /// Glass: a mirror, returns only near normal incidence.
    Glass,
    /// Metal (shelving, cabinets, radiators): strong specular and diffuse return.
    Metal,
    /// Wood and chipboard furniture.
    Wood,
    /// Upholstery, beds, cardboard.
    Fabric,
    /// Floor covering.
    Floor,
    /// Suspended ceiling.
    Ceiling,
}

/// Reflection of a material: σ⁰(θ) = diffuse cos θ + specular exp(-(θ/lobe)²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reflectivity {
    /// Diffuse backscatter coefficient (relative).
    pub diffuse: f64,
    /// Specular (mirror) peak at normal incidence (relative).
    pub specular: f64,
    /// Width of the specular lobe \[rad\].
    pub lobe_rad: f64,
}

impl Material {
    /// How the material reflects (relative units; see docs/simulator.md).
    pub fn reflectivity(self) -> Reflectivity {
        let (diffuse, specular, lobe_deg): (f64, f64, f64) = match self {
            Material::Concrete => (0.10, 10.0, 8.0),
            Material::Drywall => (0.02, 15.0, 5.0),
            Material::Glass => (0.002, 30.0, 3.0),
            Material::Metal => (0.25, 40.0, 6.0),
            Material::Wood => (0.08, 6.0, 8.0),
            Material::Fabric => (0.04, 1.0, 15.0),
            Material::Floor => (0.01, 2.0, 5.0),
            Material::Ceiling => (0.02, 3.0, 5.0),
        };
        Reflectivity {
            diffuse,
            specular,
            lobe_rad: lobe_deg.to_radians(),
        }
    }

    /// True for surfaces that act as mirrors (sources of multipath ghosts).
    pub fn is_mirror(self) -> bool {
        matches!(
            self,
            Material::Drywall | Material::Glass | Material::Metal | Material::Concrete
        )
    }
}

/// The geometry of a primitive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A vertical wall segment from `a` to `b` (x, y \[m\]) between heights `z0` and `z1` \[m\].
    Wall {
        /// One end \[m\].
        a: [f64; 2],
        /// Other end \[m\].
        b: [f64; 2],
        /// Bottom \[m\].
        z0: f64,
        /// Top \[m\].
        z1: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Lower corner \[m\].
        min: [f64; 3],
        /// Upper corner \[m\].
        max: [f64; 3],
    },
    /// A vertical cylinder (pillar).
    Cylinder {
        /// Axis position \[m\].
        c: [f64; 2],
        /// Radius \[m\].
        r: f64,
        /// Bottom \[m\].
        z0: f64,
        /// Top \[m\].
        z1: f64,
    },
}

/// A primitive: a shape and what it is made of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Primitive {
    /// Geometry.
    pub shape: Shape,
    /// Material.
    pub material: Material,
}

/// A point scatterer: an edge or corner that returns energy over a wide range of angles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scatterer {
    /// Position in the world \[m\].
    pub p: Vector3<f64>,
    /// Radar cross section \[m^2\].
    pub rcs: f64,
}

/// Where a ray first hits the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray \[m\].
    pub t: f64,
    /// Unit surface normal, facing the ray.
    pub normal: Vector3<f64>,
    /// Material hit.
    pub material: Material,
    /// True when the hit primitive is a wall (a plane that can mirror the scene).
    pub is_wall: bool,
}

/// A generated indoor floor.
#[derive(Debug, Clone)]
pub struct World {
    /// Family.
    pub family: Family,
    /// Seed it was generated from.
    pub seed: u64,
    /// Floor-plan extent: lower corner (x, y) \[m\].
    pub min: [f64; 2],
    /// Floor-plan extent: upper corner (x, y) \[m\].
    pub max: [f64; 2],
    /// Ceiling height \[m\].
    pub height: f64,
    /// Walls, boxes and pillars.
    pub prims: Vec<Primitive>,
    /// Edge and corner scatterers.
    pub scatterers: Vec<Scatterer>,
}

/// Obstacles lower than this do not block a walker or robot \[m\] (everything from the floor up
/// to head height blocks).
const BLOCK_HEIGHT: f64 = 2.0;

struct Builder {
    prims: Vec<Primitive>,
    scat: Vec<Scatterer>,
    rng: SimRng,
}

impl Builder {
    fn wall(&mut self, a: [f64; 2], b: [f64; 2], z0: f64, z1: f64, m: Material) {
        self.prims.push(Primitive {
            shape: Shape::Wall { a, b, z0, z1 },
            material: m,
        });
    }

    /// A wall whose free ends are edges (door frames, partition ends).
    fn wall_edges(&mut self, a: [f64; 2], b: [f64; 2], z0: f64, z1: f64, m: Material) {
        self.wall(a, b, z0, z1, m);
        for e in [a, b] {
            self.edge(e, z0, z1, 0.15);
        }
    }

    /// Scatterers along a vertical edge (a few heights, since the radar's elevation resolution
    /// blurs them anyway).
    fn edge(&mut self, p: [f64; 2], z0: f64, z1: f64, rcs: f64) {
        for z in [0.4, 1.2, 2.0] {
            if z > z0 && z < z1 {
                self.scat.push(Scatterer {
                    p: Vector3::new(p[0], p[1], z),
                    rcs,
                });
            }
        }
    }

    fn boxed(&mut self, min: [f64; 3], max: [f64; 3], m: Material) {
        self.prims.push(Primitive {
            shape: Shape::Box { min, max },
            material: m,
        });
        let rcs = match m {
            Material::Metal => 0.3,
            Material::Concrete => 0.15,
            Material::Wood => 0.08,
            _ => 0.03,
        };
        for x in [min[0], max[0]] {
            for y in [min[1], max[1]] {
                self.scat.push(Scatterer {
                    p: Vector3::new(x, y, max[2]),
                    rcs,
                });
                if max[2] - min[2] > 1.2 {
                    self.scat.push(Scatterer {
                        p: Vector3::new(x, y, 0.5 * (min[2] + max[2])),
                        rcs: rcs * 0.7,
                    });
                }
            }
        }
    }

    /// A parked car (metal, 1.8 x 4.5 x 1.5 m) at `at` (lower corner), if 1.5 m clear of everything.
    fn car(&mut self, at: [f64; 2]) {
        let min = [at[0], at[1], 0.0];
        let max = [at[0] + 1.8, at[1] + 4.5, 1.5];
        if !self
            .prims
            .iter()
            .all(|p| rect_gap(p, [min[0], min[1]], [max[0], max[1]]) >= 1.5)
        {
            return;
        }
        self.prims.push(Primitive {
            shape: Shape::Box { min, max },
            material: Material::Metal,
        });
        for (cx, cy, z, rcs) in [
            (min[0], min[1], 0.5, 0.3),
            (max[0], min[1], 0.5, 0.3),
            (min[0], max[1], 0.5, 0.3),
            (max[0], max[1], 0.5, 0.3),
            (min[0], 0.5 * (min[1] + max[1]), 0.7, 1.0),
            (max[0], 0.5 * (min[1] + max[1]), 0.7, 1.0),
        ] {
            self.scat.push(Scatterer {
                p: Vector3::new(cx, cy, z),
                rcs,
            });
        }
    }

    fn pillar(&mut self, c: [f64; 2], r: f64, z1: f64, m: Material) {
        self.prims.push(Primitive {
            shape: Shape::Cylinder { c, r, z0: 0.0, z1 },
            material: m,
        });
    }

    /// The outer walls of a rectangular room, with strong corner reflectors (dihedral corners
    /// and trihedral floor/ceiling corners).
    fn room(&mut self, w: f64, d: f64, h: f64, m: Material) {
        let c = [[0.0, 0.0], [w, 0.0], [w, d], [0.0, d]];
        for i in 0..4 {
            self.wall(c[i], c[(i + 1) % 4], 0.0, h, m);
            for (z, rcs) in [(0.02, 1.0), (1.0, 0.4), (h - 0.02, 1.0)] {
                self.scat.push(Scatterer {
                    p: Vector3::new(c[i][0], c[i][1], z),
                    rcs,
                });
            }
        }
    }

    /// Splits the wall from `a` to `b` into segments with `windows` glass panes between
    /// concrete mullions.
    fn window_wall(&mut self, a: [f64; 2], b: [f64; 2], h: f64, sill: f64) {
        let n = 3 + self.rng.below(4);
        for i in 0..n {
            let f0 = (i as f64 + 0.1) / n as f64;
            let f1 = (i as f64 + 0.9) / n as f64;
            let p = |f: f64| [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f];
            self.wall(p(f0), p(f1), sill, h - 0.2, Material::Glass);
            self.edge(p(f0), sill, h, 0.1);
        }
    }

    /// Places a box of footprint `sx` x `sy` somewhere in `[x0, x1] x [y0, y1]` at least `gap`
    /// away from every blocking primitive; false when no place was found.
    #[allow(clippy::too_many_arguments)]
    fn place(
        &mut self,
        area: ([f64; 2], [f64; 2]),
        sx: f64,
        sy: f64,
        h: f64,
        gap: f64,
        m: Material,
    ) -> bool {
        let (lo, hi) = area;
        for _ in 0..40 {
            let (sx, sy) = if self.rng.chance(0.5) {
                (sx, sy)
            } else {
                (sy, sx)
            };
            if hi[0] - lo[0] < sx || hi[1] - lo[1] < sy {
                continue;
            }
            let x = self.rng.uniform(lo[0], hi[0] - sx);
            let y = self.rng.uniform(lo[1], hi[1] - sy);
            let min = [x, y, 0.0];
            let max = [x + sx, y + sy, h];
            let ok = self
                .prims
                .iter()
                .all(|p| rect_gap(p, [x, y], [x + sx, y + sy]) >= gap);
            if ok {
                self.boxed(min, max, m);
                return true;
            }
        }
        false
    }
}

/// Smallest 2D distance between primitive `p` and the rectangle (`lo`, `hi`); walls and pillars
/// count by their footprint.
fn rect_gap(p: &Primitive, lo: [f64; 2], hi: [f64; 2]) -> f64 {
    let rect_dist = |q: [f64; 2]| {
        let dx = (lo[0] - q[0]).max(q[0] - hi[0]).max(0.0);
        let dy = (lo[1] - q[1]).max(q[1] - hi[1]).max(0.0);
        dx.hypot(dy)
    };
    match p.shape {
        Shape::Wall { a, b, z0, .. } => {
            if z0 > BLOCK_HEIGHT {
                return f64::INFINITY;
            }
            // Sample the segment (walls are long and few; exactness is not needed here).
            (0..=20)
                .map(|i| {
                    let f = f64::from(i) / 20.0;
                    rect_dist([a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f])
                })
                .fold(f64::INFINITY, f64::min)
        }
        Shape::Box { min, max } => {
            let dx = (lo[0] - max[0]).max(min[0] - hi[0]).max(0.0);
            let dy = (lo[1] - max[1]).max(min[1] - hi[1]).max(0.0);
            dx.hypot(dy)
        }
        Shape::Cylinder { c, r, .. } => (rect_dist(c) - r).max(0.0),
    }
}

impl World {
    /// Generates the floor of `family` for `seed` (same inputs, same world).
    pub fn generate(family: Family, seed: u64) -> World {
        let mut b = Builder {
            prims: Vec::new(),
            scat: Vec::new(),
            rng: SimRng::new(seed, &format!("world/{}", family.name())),
        };
        let (w, d, h) = match family {
            Family::Corridor => corridor(&mut b),
            Family::Office => office(&mut b),
            Family::Atrium => atrium(&mut b),
            Family::StoreRoom => store_room(&mut b),
            Family::Household => household(&mut b),
            Family::Outdoor => outdoor(&mut b, 1.0),
        };
        World {
            family,
            seed,
            min: [0.0, 0.0],
            max: [w, d],
            height: h,
            prims: b.prims,
            scatterers: b.scat,
        }
    }

    /// The outdoor world for a ground vehicle: the `outdoor` family at four times the size (a
    /// 120-180 x 80-120 m car park with rows of parked cars and lamp posts every 16-24 m across
    /// it), from
    /// a stream of its own (`world/outdoor-vehicle`), so walkers' outdoor worlds stay as they are.
    pub fn generate_vehicle_lot(seed: u64) -> World {
        let mut b = Builder {
            prims: Vec::new(),
            scat: Vec::new(),
            rng: SimRng::new(seed, "world/outdoor-vehicle"),
        };
        let (w, d, h) = outdoor(&mut b, VEHICLE_LOT_SCALE);
        World {
            family: Family::Outdoor,
            seed,
            min: [0.0, 0.0],
            max: [w, d],
            height: h,
            prims: b.prims,
            scatterers: b.scat,
        }
    }

    /// Free space around the floor-plan point `p` \[m\]: the distance to the nearest obstacle that
    /// blocks a person or robot (0 outside the floor).
    pub fn clearance(&self, p: [f64; 2]) -> f64 {
        if p[0] <= self.min[0] || p[1] <= self.min[1] || p[0] >= self.max[0] || p[1] >= self.max[1]
        {
            return 0.0;
        }
        let mut c = (p[0] - self.min[0])
            .min(p[1] - self.min[1])
            .min(self.max[0] - p[0])
            .min(self.max[1] - p[1]);
        for prim in &self.prims {
            let dist = match prim.shape {
                Shape::Wall { a, b, z0, .. } => {
                    if z0 > BLOCK_HEIGHT {
                        continue;
                    }
                    seg_dist(p, a, b)
                }
                Shape::Box { min, max } => {
                    if min[2] > BLOCK_HEIGHT {
                        continue;
                    }
                    let dx = (min[0] - p[0]).max(p[0] - max[0]).max(0.0);
                    let dy = (min[1] - p[1]).max(p[1] - max[1]).max(0.0);
                    if dx == 0.0 && dy == 0.0 {
                        0.0
                    } else {
                        dx.hypot(dy)
                    }
                }
                Shape::Cylinder { c: cc, r, .. } => {
                    ((p[0] - cc[0]).hypot(p[1] - cc[1]) - r).max(0.0)
                }
            };
            c = c.min(dist);
        }
        c
    }

    /// True when the straight floor-plan path from `a` to `b` keeps at least `clearance` \[m\].
    pub fn path_free(&self, a: [f64; 2], b: [f64; 2], clearance: f64) -> bool {
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let n = (len / 0.05).ceil().max(1.0) as usize;
        (0..=n).all(|i| {
            let f = i as f64 / n as f64;
            self.clearance([a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f]) >= clearance
        })
    }

    /// A free starting point with at least `clearance` \[m\] around it, drawn from `rng`.
    pub fn free_point(&self, rng: &mut SimRng, clearance: f64) -> Result<[f64; 2], SimError> {
        for _ in 0..10_000 {
            let p = [
                rng.uniform(self.min[0], self.max[0]),
                rng.uniform(self.min[1], self.max[1]),
            ];
            if self.clearance(p) >= clearance {
                return Ok(p);
            }
        }
        Err(SimError::World(format!(
            "{} world seed {}: no free point with {clearance} m clearance",
            self.family, self.seed
        )))
    }

    /// The first surface a ray from `o` along unit `d` hits within `t_max` \[m\].
    pub fn raycast(&self, o: &Vector3<f64>, d: &Vector3<f64>, t_max: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut consider = |t: f64, n: Vector3<f64>, m: Material, is_wall: bool| {
            if t > 1e-6 && t < best.map_or(t_max, |b| b.t) {
                let n = if n.dot(d) > 0.0 { -n } else { n };
                best = Some(Hit {
                    t,
                    normal: n,
                    material: m,
                    is_wall,
                });
            }
        };
        if d.z < -1e-9 {
            consider(-o.z / d.z, Vector3::z(), Material::Floor, true);
        } else if d.z > 1e-9 {
            consider(
                (self.height - o.z) / d.z,
                -Vector3::z(),
                Material::Ceiling,
                true,
            );
        }
        for p in &self.prims {
            match p.shape {
                Shape::Wall { a, b, z0, z1 } => {
                    let e = [b[0] - a[0], b[1] - a[1]];
                    let den = d.x * e[1] - d.y * e[0];
                    if den.abs() < 1e-12 {
                        continue;
                    }
                    let w = [a[0] - o.x, a[1] - o.y];
                    let t = (w[0] * e[1] - w[1] * e[0]) / den;
                    let s = (w[0] * d.y - w[1] * d.x) / den;
                    let z = o.z + t * d.z;
                    if (0.0..=1.0).contains(&s) && z >= z0 && z <= z1 {
                        let n = Vector3::new(e[1], -e[0], 0.0).normalize();
                        consider(t, n, p.material, true);
                    }
                }
                Shape::Box { min, max } => {
                    let mut t0 = f64::NEG_INFINITY;
                    let mut t1 = f64::INFINITY;
                    let mut axis = 0;
                    let mut inside = true;
                    for k in 0..3 {
                        if d[k].abs() < 1e-12 {
                            if o[k] < min[k] || o[k] > max[k] {
                                inside = false;
                            }
                            continue;
                        }
                        let ta = (min[k] - o[k]) / d[k];
                        let tb = (max[k] - o[k]) / d[k];
                        let (lo, hi) = if ta < tb { (ta, tb) } else { (tb, ta) };
                        if lo > t0 {
                            t0 = lo;
                            axis = k;
                        }
                        t1 = t1.min(hi);
                    }
                    if inside && t0 <= t1 && t0 > 0.0 {
                        let mut n = Vector3::zeros();
                        n[axis] = 1.0;
                        consider(t0, n, p.material, false);
                    }
                }
                Shape::Cylinder { c, r, z0, z1 } => {
                    let (ox, oy) = (o.x - c[0], o.y - c[1]);
                    let a2 = d.x * d.x + d.y * d.y;
                    if a2 < 1e-12 {
                        continue;
                    }
                    let bq = ox * d.x + oy * d.y;
                    let cq = ox * ox + oy * oy - r * r;
                    let disc = bq * bq - a2 * cq;
                    if disc < 0.0 || cq < 0.0 {
                        continue;
                    }
                    let t = (-bq - disc.sqrt()) / a2;
                    let z = o.z + t * d.z;
                    if z >= z0 && z <= z1 {
                        let n = Vector3::new(ox + t * d.x, oy + t * d.y, 0.0).normalize();
                        consider(t, n, p.material, false);
                    }
                }
            }
        }
        best
    }

    /// True when nothing blocks the straight line from `o` to `p` (a 5 cm tolerance at `p`, so
    /// that corners on a surface count as visible).
    pub fn visible(&self, o: &Vector3<f64>, p: &Vector3<f64>) -> bool {
        let v = p - o;
        let dist = v.norm();
        if dist < 1e-6 {
            return false;
        }
        self.raycast(o, &(v / dist), dist)
            .is_none_or(|h| h.t >= dist - 0.05)
    }
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let e = [b[0] - a[0], b[1] - a[1]];
    let l2 = e[0] * e[0] + e[1] * e[1];
    let f = if l2 > 0.0 {
        (((p[0] - a[0]) * e[0] + (p[1] - a[1]) * e[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - f * e[0]).hypot(p[1] - a[1] - f * e[1])
}

fn corridor(b: &mut Builder) -> (f64, f64, f64) {
    let l = b.rng.uniform(30.0, 50.0);
    let w = b.rng.uniform(1.8, 2.8);
    let h = b.rng.uniform(2.6, 3.2);
    // End walls: concrete at one end, a glass fire door at the other.
    b.wall([0.0, 0.0], [0.0, w], 0.0, h, Material::Concrete);
    b.wall([l, 0.0], [l, w], 0.0, h, Material::Glass);
    b.edge([l, 0.0], 0.0, h, 0.5);
    b.edge([l, w], 0.0, h, 0.5);
    for y in [0.0, w] {
        // Side walls with door recesses; the door leaf sits 15 cm behind the wall line.
        let out = if y == 0.0 { -0.15 } else { 0.15 };
        let mut x = 0.0;
        while x < l {
            let seg = b.rng.uniform(3.0, 7.0).min(l - x);
            b.wall([x, y], [x + seg, y], 0.0, h, Material::Drywall);
            x += seg;
            if x + 1.2 < l {
                let door = if b.rng.chance(0.3) {
                    Material::Glass
                } else {
                    Material::Wood
                };
                b.wall([x, y + out], [x + 1.0, y + out], 0.0, 2.1, door);
                b.wall([x, y + out], [x, y], 0.0, h, Material::Drywall);
                b.wall([x + 1.0, y + out], [x + 1.0, y], 0.0, h, Material::Drywall);
                b.wall([x, y + out], [x + 1.0, y + out], 2.1, h, Material::Drywall);
                b.edge([x, y], 0.0, 2.1, 0.2);
                b.edge([x + 1.0, y], 0.0, 2.1, 0.2);
                x += 1.0;
            }
        }
    }
    // Columns protruding from the walls, radiators, fire extinguishers, bins.
    let mut x = b.rng.uniform(2.0, 6.0);
    while x + 0.5 < l {
        let side = b.rng.chance(0.5);
        let (y0, y1) = if side { (0.0, 0.3) } else { (w - 0.3, w) };
        match b.rng.below(3) {
            0 => b.boxed([x, y0, 0.0], [x + 0.4, y1, h], Material::Concrete),
            1 => {
                let (y0, y1) = if side { (0.0, 0.1) } else { (w - 0.1, w) };
                b.boxed([x, y0, 0.1], [x + 1.0, y1, 0.7], Material::Metal)
            }
            _ => {
                let (y0, y1) = if side { (0.0, 0.2) } else { (w - 0.2, w) };
                b.boxed([x, y0, 0.0], [x + 0.25, y1, 0.6], Material::Metal)
            }
        }
        x += b.rng.uniform(4.0, 9.0);
    }
    (l, w, h)
}

fn office(b: &mut Builder) -> (f64, f64, f64) {
    let w = b.rng.uniform(12.0, 20.0);
    let d = b.rng.uniform(9.0, 14.0);
    let h = b.rng.uniform(2.7, 3.2);
    b.room(w, d, h, Material::Drywall);
    b.window_wall([0.5, d - 0.05], [w - 0.5, d - 0.05], h, 0.8);
    // Glass meeting room in a corner, door gap 1 m.
    let (mw, md) = (b.rng.uniform(3.0, 4.5), b.rng.uniform(2.5, 3.5));
    b.wall_edges([w - mw, 0.0], [w - mw, md - 1.2], 0.0, h, Material::Glass);
    b.wall_edges([w - mw, md], [w, md], 0.0, h, Material::Glass);
    b.boxed(
        [w - mw + 0.8, 0.6, 0.0],
        [w - 0.6, md - 0.8, 0.75],
        Material::Wood,
    );
    // Pillars.
    for _ in 0..1 + b.rng.below(2) {
        let x = b.rng.uniform(2.0, w - mw - 2.0);
        let y = b.rng.uniform(2.0, d - 2.0);
        b.boxed([x, y, 0.0], [x + 0.5, y + 0.5, h], Material::Concrete);
    }
    // Desk clusters (two desks face to face with monitors) and chairs, 1.6 m aisles.
    let area = ([0.8, 0.8], [w - mw - 0.5, d - 0.8]);
    for _ in 0..4 + b.rng.below(4) {
        if b.place(area, 3.2, 1.6, 0.75, 1.6, Material::Wood) {
            let Some(Primitive {
                shape: Shape::Box { min, max },
                ..
            }) = b.prims.last().copied()
            else {
                continue;
            };
            let (cx, cy) = (0.5 * (min[0] + max[0]), 0.5 * (min[1] + max[1]));
            b.boxed(
                [cx - 0.3, cy - 0.1, 0.75],
                [cx + 0.3, cy + 0.1, 1.15],
                Material::Fabric,
            );
        }
    }
    for _ in 0..3 + b.rng.below(4) {
        b.place(area, 0.5, 0.5, 0.95, 1.0, Material::Fabric);
    }
    // Metal cabinets along the back wall.
    for _ in 0..2 + b.rng.below(3) {
        b.place(
            ([0.0, 0.0], [w - mw, 0.6]),
            0.9,
            0.45,
            1.9,
            0.8,
            Material::Metal,
        );
    }
    (w, d, h)
}

fn atrium(b: &mut Builder) -> (f64, f64, f64) {
    let w = b.rng.uniform(20.0, 35.0);
    let d = b.rng.uniform(15.0, 25.0);
    let h = b.rng.uniform(6.0, 12.0);
    b.room(w, d, h, Material::Concrete);
    b.window_wall([0.3, 0.05], [w - 0.3, 0.05], h, 0.0);
    let sp = b.rng.uniform(6.0, 8.0);
    let r = b.rng.uniform(0.25, 0.4);
    let mut x = sp / 2.0 + 1.0;
    while x < w - 2.0 {
        let mut y = sp / 2.0 + 1.0;
        while y < d - 2.0 {
            b.pillar([x, y], r, h, Material::Concrete);
            y += sp;
        }
        x += sp;
    }
    let area = ([1.0, 1.0], [w - 1.0, d - 1.0]);
    for _ in 0..3 + b.rng.below(4) {
        b.place(area, 1.2, 1.2, 0.8, 2.0, Material::Concrete);
    }
    for _ in 0..3 + b.rng.below(4) {
        b.place(area, 1.8, 0.5, 0.45, 2.0, Material::Wood);
    }
    b.place(area, 3.0, 0.8, 1.1, 2.5, Material::Wood);
    (w, d, h)
}

fn store_room(b: &mut Builder) -> (f64, f64, f64) {
    let w = b.rng.uniform(9.0, 14.0);
    let d = b.rng.uniform(7.0, 10.0);
    let h = b.rng.uniform(3.0, 4.5);
    b.room(w, d, h, Material::Concrete);
    // Shelving rows along x, 0.5 m deep, aisles 1.3-1.7 m, a cross aisle at one end.
    let len = w - b.rng.uniform(2.5, 3.5);
    let mut y = b.rng.uniform(1.3, 1.7);
    while y + 0.5 < d - 1.3 {
        let x0 = 1.6;
        let mut x = x0;
        while x < x0 + len - 1.0 {
            let seg = b.rng.uniform(1.8, 3.0).min(x0 + len - x);
            let top = b.rng.uniform(1.8, 2.4);
            b.boxed([x, y, 0.0], [x + seg, y + 0.5, top], Material::Metal);
            x += seg;
        }
        y += 0.5 + b.rng.uniform(1.3, 1.7);
    }
    // Boxes and pallets wherever they fit (leaving 1.1 m to pass).
    let area = ([0.0, 0.0], [w, d]);
    for _ in 0..8 + b.rng.below(8) {
        let s = b.rng.uniform(0.4, 0.9);
        let m = if b.rng.chance(0.5) {
            Material::Fabric
        } else {
            Material::Wood
        };
        let hh = b.rng.uniform(0.3, 1.3);
        b.place(area, s, s, hh, 1.1, m);
    }
    (w, d, h)
}

fn household(b: &mut Builder) -> (f64, f64, f64) {
    let w = b.rng.uniform(9.0, 13.0);
    let d = b.rng.uniform(7.0, 10.0);
    let h = b.rng.uniform(2.4, 2.7);
    b.room(w, d, h, Material::Concrete);
    b.window_wall([0.5, 0.05], [w - 0.5, 0.05], h, 0.9);
    // A partition wall across x = xm with two doors, and one across y = ym on the right side.
    let xm = w * b.rng.uniform(0.45, 0.6);
    let ym = d * b.rng.uniform(0.4, 0.6);
    let d1 = b.rng.uniform(0.8, ym - 1.8);
    let d2 = b.rng.uniform(ym + 0.8, d - 1.8);
    b.wall_edges([xm, 0.0], [xm, d1], 0.0, h, Material::Drywall);
    b.wall_edges([xm, d1 + 1.0], [xm, d2], 0.0, h, Material::Drywall);
    b.wall_edges([xm, d2 + 1.0], [xm, d], 0.0, h, Material::Drywall);
    let dx = b.rng.uniform(xm + 0.8, w - 1.8);
    b.wall_edges([xm, ym], [dx, ym], 0.0, h, Material::Drywall);
    b.wall_edges([dx + 1.0, ym], [w, ym], 0.0, h, Material::Drywall);
    // Living room (left): sofa, table, TV stand; bedroom (right top): bed, wardrobe;
    // kitchen (right bottom): counter, fridge, table.
    let living = ([0.0, 0.0], [xm, d]);
    let bedroom = ([xm, ym], [w, d]);
    let kitchen = ([xm, 0.0], [w, ym]);
    b.place(living, 2.0, 0.9, 0.8, 1.1, Material::Fabric);
    b.place(living, 1.2, 0.7, 0.45, 1.1, Material::Wood);
    b.place(living, 1.6, 0.4, 0.6, 1.1, Material::Glass);
    b.place(living, 0.8, 0.8, 0.75, 1.1, Material::Wood);
    b.place(bedroom, 2.0, 1.6, 0.5, 1.0, Material::Fabric);
    b.place(bedroom, 1.8, 0.6, 2.0, 1.0, Material::Wood);
    b.place(kitchen, 2.4, 0.6, 0.9, 1.0, Material::Wood);
    b.place(kitchen, 0.7, 0.7, 1.8, 1.0, Material::Metal);
    b.place(kitchen, 1.0, 0.8, 0.75, 1.0, Material::Wood);
    (w, d, h)
}

/// Size factor of the vehicle's outdoor lot over the walkers' plaza.
pub const VEHICLE_LOT_SCALE: f64 = 4.0;

/// Height of the (absent) sky outdoors: far beyond any radar range \[m\].
pub const OUTDOOR_SKY_M: f64 = 1000.0;

/// An open plaza or car park, 40-60 x 25-40 m of walkable ground: buildings along two or three
/// sides 8-15 m beyond its edge (facades 8-20 m high with window-frame scatterers every 2.5-4 m and
/// strong building corners), a row or two of parked cars, lamp posts every 12-25 m, and sparse weak
/// ground clutter (kerbs, drains, stones). No ceiling; the ground is the weak floor material.
fn outdoor(b: &mut Builder, scale: f64) -> (f64, f64, f64) {
    let w = scale * b.rng.uniform(30.0, 45.0);
    let d = scale * b.rng.uniform(20.0, 30.0);
    // Facades: along the far y side always, and along one or both x sides.
    let sides = 2 + b.rng.below(2);
    for side in 0..sides {
        let gap = b.rng.uniform(4.0, 8.0);
        let depth = 12.0;
        let top = b.rng.uniform(8.0, 20.0);
        // (facade line from a to b, the building behind it)
        let (a, e, min, max) = match side {
            0 => (
                [-gap, d + gap],
                [w + gap, d + gap],
                [-gap, d + gap, 0.0],
                [w + gap, d + gap + depth, top],
            ),
            1 => (
                [-gap, -gap],
                [-gap, d + gap],
                [-gap - depth, -gap, 0.0],
                [-gap, d + gap, top],
            ),
            _ => (
                [w + gap, -gap],
                [w + gap, d + gap],
                [w + gap, -gap, 0.0],
                [w + gap + depth, d + gap, top],
            ),
        };
        b.prims.push(Primitive {
            shape: Shape::Box { min, max },
            material: Material::Concrete,
        });
        for c in [a, e] {
            for z in [0.5, 3.0] {
                b.scat.push(Scatterer {
                    p: Vector3::new(c[0], c[1], z),
                    rcs: 10.0,
                });
            }
        }
        let len = (e[0] - a[0]).hypot(e[1] - a[1]);
        let mut f = b.rng.uniform(1.0, 3.0);
        while f < len - 1.0 {
            let p = [
                a[0] + (e[0] - a[0]) * f / len,
                a[1] + (e[1] - a[1]) * f / len,
            ];
            let mut z = 1.5;
            while z < top - 1.0 {
                b.scat.push(Scatterer {
                    p: Vector3::new(p[0], p[1], z),
                    rcs: 10f64.powf(b.rng.uniform(-0.3, 0.5)),
                });
                z += 3.0;
            }
            f += b.rng.uniform(6.0, 10.0);
        }
    }
    // A row of parked cars along one edge.
    {
        let y = if b.rng.chance(0.5) {
            b.rng.uniform(1.5, 4.0)
        } else {
            d - 4.5 - b.rng.uniform(1.5, 4.0)
        };
        let mut x = b.rng.uniform(2.0, 8.0);
        while x + 2.0 < w - 2.0 {
            if b.rng.chance(0.25) {
                b.car([x, y]);
            }
            x += 2.6;
        }
    }
    // Lamp posts.
    let sp = b.rng.uniform(12.0, 25.0);
    let mut x = b.rng.uniform(2.0, sp);
    while x < w - 1.0 {
        let (y0, y1) = (b.rng.uniform(1.0, 3.0), d - b.rng.uniform(1.0, 3.0));
        for y in [y0, y1] {
            let c = [x, y];
            let ok = b.prims.iter().all(|p| rect_gap(p, c, c) >= 1.0);
            if ok {
                let top = b.rng.uniform(5.0, 8.0);
                b.pillar(c, 0.08, top, Material::Metal);
                for (z, rcs) in [(0.5, 0.3), (2.0, 0.2)] {
                    b.scat.push(Scatterer {
                        p: Vector3::new(c[0], c[1], z),
                        rcs,
                    });
                }
            }
        }
        x += sp;
    }
    // Weak ground clutter, about one per 30 m^2.
    for _ in 0..(w * d / 30.0) as usize {
        let p = Vector3::new(b.rng.uniform(0.0, w), b.rng.uniform(0.0, d), 0.02);
        b.scat.push(Scatterer {
            p,
            rcs: b.rng.uniform(0.001, 0.005),
        });
    }
    if scale > 1.0 {
        // A large lot: rows of parked cars (half the slots taken) every 16-24 m across it, with
        // lamp posts every 15-25 m in each row.
        let mut y = b.rng.uniform(12.0, 18.0);
        while y < d - 10.0 {
            let mut x = b.rng.uniform(4.0, 10.0);
            while x + 2.0 < w - 4.0 {
                if b.rng.chance(0.5) {
                    b.car([x, y]);
                }
                x += 2.6;
            }
            let mut x = b.rng.uniform(5.0, 15.0);
            while x < w - 5.0 {
                let c = [x, y + 2.25];
                if b.prims.iter().all(|p| rect_gap(p, c, c) >= 1.0) {
                    b.pillar(c, 0.08, 6.0, Material::Metal);
                    for (z, rcs) in [(0.5, 0.3), (2.0, 0.2)] {
                        b.scat.push(Scatterer {
                            p: Vector3::new(c[0], c[1], z),
                            rcs,
                        });
                    }
                }
                x += b.rng.uniform(15.0, 25.0);
            }
            y += b.rng.uniform(16.0, 24.0);
        }
    }
    (w, d, OUTDOOR_SKY_M)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worlds_are_deterministic_and_have_free_space() {
        for f in Family::ALL {
            let a = World::generate(f, 3);
            let b = World::generate(f, 3);
            assert_eq!(a.prims, b.prims, "{f}");
            let c = World::generate(f, 4);
            assert_ne!(a.prims, c.prims, "{f}: seeds 3 and 4 gave the same world");
            let mut rng = SimRng::new(1, "t");
            let p = a.free_point(&mut rng, 0.6).unwrap();
            assert!(a.clearance(p) >= 0.6);
        }
    }

    #[test]
    fn raycast_hits_the_nearest_wall_facing_the_ray() {
        let w = World::generate(Family::Corridor, 1);
        let o = Vector3::new(5.0, 0.9, 1.2);
        let h = w.raycast(&o, &Vector3::new(0.0, -1.0, 0.0), 50.0).unwrap();
        assert!((h.t - 0.9).abs() < 0.31, "t = {}", h.t);
        assert!(h.normal.y > 0.99);
        assert_eq!("store_room".parse::<Family>().unwrap(), Family::StoreRoom);
        assert!("garage".parse::<Family>().is_err());
    }
}
