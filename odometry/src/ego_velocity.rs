//! Ego-velocity from radar Doppler.
//!
//! A static point seen in direction `d` (unit vector from the sensor) while the sensor moves with
//! velocity `v` has radial velocity `v_r = -d . v` (negative when approaching, as TI reports it).
//! Stacking the points gives an over-determined linear system in `v`. Moving objects and multipath
//! ghosts violate it, so a RANSAC consensus on minimal samples picks the static set first; least
//! squares on that set gives `v` and its covariance `sigma^2 (D^T D)^-1`.
//!
//! Geometry decides what is observable: points that all lie in one plane (a 2D radar, or a narrow
//! elevation field) cannot tell the velocity across that plane. [`EgoVelocityEstimator`] checks the
//! spread of the directions and reports [`Status::Degenerate`] naming the weak direction; with
//! [`Model::Planar`] it estimates only the in-plane components.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One radar detection as the estimator sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Position in the radar frame \[m\] (x right, y boresight, z up).
    pub position: [f32; 3],
    /// Radial (Doppler) velocity \[m/s\]; negative when approaching.
    pub radial_velocity: f32,
}

impl Detection {
    /// The position in the radar frame \[m\], in double precision.
    pub fn position_m(&self) -> Vector3<f64> {
        Vector3::from(self.position.map(f64::from))
    }
}

/// Which velocity components to estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Model {
    /// Full 3D velocity (needs elevation spread).
    #[default]
    Full3d,
    /// x and y only, with z fixed to 0 (ground robots, or radars without elevation resolution).
    Planar,
}

/// Estimator settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Components to estimate.
    pub model: Model,
    /// Doppler noise of a static point, fine quantisation included \[m/s\].
    pub sigma: f32,
    /// Doppler quantisation step \[m/s\] (the radar's velocity resolution: TI's demos report
    /// `bin x resolution`; 0: continuous). A static point's radial velocity is then off by up to
    /// half a step: see [`Config::inlier_threshold`] and [`Config::doppler_std`].
    pub doppler_step: f32,
    /// Take the step from the points' own radial velocities when they lie on a lattice of one
    /// ([`crate::lattice`]), in place of `doppler_step`, once the stream shows it (the runner
    /// does this; default on). Off when the caller states the step.
    pub step_from_data: bool,
    /// Direction error of a point \[rad\] (angular resolution, cell merging): a point's radial
    /// velocity is then off by about `|v| direction_sigma`, which adds to `sigma` in the
    /// covariance of the estimate (not in the inlier gate, which would let ghosts in).
    pub direction_sigma: f32,
    /// Count the rounding of a coarse Doppler step as shared by a frame's points where the noise
    /// cannot dither it (default on; see [`quantisation_correlation`]). Off: every point's
    /// rounding is independent (`step / sqrt(12)` each, averaged over the points).
    pub quantisation_correlation: bool,
    /// Estimate the velocity as the maximum likelihood of the rounded readings (each point's
    /// reading is its radial velocity plus Gaussian noise of `sigma`, rounded to the Doppler step:
    /// an interval-censored Gaussian, solved by Fisher scoring from the least squares on the
    /// consensus), with the covariance of that likelihood, where the rounding is coarse against the
    /// noise ([`quantisation_correlation`] above 0.05). Least squares takes every reading as the
    /// radial velocity: a slow robot whose points read 0 or one step reads 10-14% slow, or at
    /// rest while it creeps. Off by default; the runner turns it on for ground vehicles
    /// ([`crate::runner::ClassicalConfig::rounding_likelihood`]), where the velocity is along the
    /// body and direction errors, which this likelihood does not model, move little.
    pub rounding_likelihood: bool,
    /// Inlier threshold as a multiple of the effective noise.
    pub inlier_sigmas: f32,
    /// Minimum inliers to accept a solution.
    pub min_inliers: usize,
    /// Minimum inlier share of the usable points.
    pub min_inlier_share: f32,
    /// Maximum RANSAC iterations (fewer when the consensus is clear).
    pub max_iterations: u32,
    /// Desired probability of drawing one all-inlier sample.
    pub confidence: f32,
    /// Smallest direction spread accepted: the smallest eigenvalue of the normalised direction
    /// scatter (sum d d^T / n) must exceed this, else that direction is unobservable.
    pub min_spread: f32,
    /// Points closer than this are skipped (direction undefined) \[m\].
    pub min_range: f32,
    /// Near field \[m\]: points this close with zero Doppler (within the inlier gate of 0) may be
    /// TX-RX leakage or reflections off the mount, which stay at zero Doppler whatever the
    /// motion: they do not vote for a consensus (a frame of leakage and a few real points must
    /// not read "at rest"), though the least squares keeps them where they fit. 0 (the default)
    /// turns this off: at rest with few far points it lets ghosts outvote the zero, and without
    /// leakage the near points at zero Doppler are real static points abeam. Set it (1 m) for
    /// rigs whose radar shows leakage, or leave it to the data ([`Config::near_field_from_data`]).
    pub near_field_m: f32,
    /// Widen the near field to [`crate::leakage::LEAK_RANGE_M`] once the points show leakage
    /// ([`crate::leakage`]; the runner does this; default on). A caller that states
    /// [`Config::near_field_m`] turns this off (`milliego odometry --near-field` does), else a
    /// stated range under 1 m is widened once leakage shows.
    pub near_field_from_data: bool,
    /// RNG seed (the estimate is deterministic for a seed and input).
    pub seed: u64,
}

impl Config {
    /// This configuration for a radar whose Doppler is quantised in steps of
    /// `velocity_resolution_mps` \[m/s\] (a TI `.cfg`'s derived velocity resolution).
    pub fn with_velocity_resolution(mut self, velocity_resolution_mps: f64) -> Config {
        if velocity_resolution_mps.is_finite() && velocity_resolution_mps > 0.0 {
            self.doppler_step = velocity_resolution_mps as f32;
        }
        self
    }

    /// The Doppler gate around zero and around a hypothesis \[m/s\]: `inlier_sigmas x sigma`,
    /// but never narrower than half a quantisation step plus `sigma` (a coarse step's rounding
    /// alone reaches `step / 2`).
    pub fn inlier_threshold(&self) -> f32 {
        (self.inlier_sigmas * self.sigma).max(self.doppler_step.max(0.0) / 2.0 + self.sigma)
    }

    /// Doppler standard deviation of a static point \[m/s\]: `sigma`, but never below the
    /// rounding of a quantisation step (`step / sqrt(12)`).
    pub fn doppler_std(&self) -> f32 {
        self.sigma.max(self.doppler_step.max(0.0) / 12f32.sqrt())
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            model: Model::Full3d,
            sigma: 0.05,
            inlier_sigmas: 3.0,
            min_inliers: 5,
            min_inlier_share: 0.1,
            max_iterations: 1000,
            confidence: 0.999,
            min_spread: 1e-3,
            min_range: 0.1,
            near_field_m: 0.0,
            near_field_from_data: true,
            doppler_step: 0.0,
            step_from_data: true,
            seed: 0x5EED,
            direction_sigma: 0.3,
            quantisation_correlation: true,
            rounding_likelihood: false,
        }
    }
}

/// A velocity the estimate should agree with (radar frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// Velocity \[m/s\].
    pub velocity: [f64; 3],
    /// Its covariance \[m^2/s^2\].
    pub covariance: [[f64; 3]; 3],
    /// Chi-square gate a hypothesis must pass (3 dof; 16.27 = 99.9%).
    pub gate: f64,
}

/// Why no (or only a partial) estimate is available.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Status {
    /// A full estimate.
    Ok,
    /// Fewer usable points than a minimal sample.
    TooFewPoints {
        /// Usable points (range above `min_range`).
        usable: usize,
        /// Points a solution needs.
        need: usize,
    },
    /// The directions do not span the estimated components.
    Degenerate {
        /// The weakest direction (unit vector, radar frame).
        weak_direction: [f32; 3],
        /// Its normalised spread (eigenvalue of the direction scatter).
        spread: f32,
    },
    /// No hypothesis gathered enough inliers.
    NoConsensus {
        /// Best inlier count found.
        best_inliers: usize,
        /// Inliers required.
        need: usize,
    },
}

/// An ego-velocity estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// Sensor velocity in the radar frame \[m/s\] (zeros unless `status` is `Ok`).
    pub velocity: [f32; 3],
    /// Covariance of `velocity` \[m^2/s^2\], row-major 3x3.
    pub covariance: [[f32; 3]; 3],
    /// The part of `covariance` that the frame's points share through the rounding of a coarse
    /// Doppler step \[m^2/s^2\] ([`Config::quantisation_correlation`]): an error that does not
    /// shrink with the point count, and lasts while the velocity stays within a fraction of a
    /// step. Zeros for continuous Doppler.
    pub shared_covariance: [[f32; 3]; 3],
    /// What the estimate is worth.
    pub status: Status,
    /// Points used in the final least squares.
    pub inliers: usize,
    /// Usable points (range above the minimum).
    pub usable: usize,
    /// Points skipped for being too close to have a direction.
    pub skipped: usize,
    /// Usable points that did not vote as possible near-field leakage (within
    /// [`Config::near_field_m`] at zero Doppler).
    pub near_field: usize,
    /// RMS residual of the inliers \[m/s\].
    pub residual_rms: f32,
    /// Inlier mask over the input detections (false for skipped points).
    pub inlier_mask: Vec<bool>,
    /// RANSAC iterations run.
    pub iterations: u32,
}

impl Estimate {
    /// An empty estimate whose inlier mask holds `points` without growing (for
    /// [`EgoVelocityEstimator::estimate_guided_into`]).
    pub fn with_capacity(points: usize) -> Estimate {
        Estimate {
            velocity: [0.0; 3],
            covariance: [[0.0; 3]; 3],
            shared_covariance: [[0.0; 3]; 3],
            status: Status::Ok,
            inliers: 0,
            usable: 0,
            skipped: 0,
            near_field: 0,
            residual_rms: 0.0,
            inlier_mask: Vec::with_capacity(points),
            iterations: 0,
        }
    }

    /// True for a usable full estimate.
    pub fn is_ok(&self) -> bool {
        self.status == Status::Ok
    }
}

/// Ego-velocity estimator (reuses its buffers between frames).
#[derive(Debug, Clone)]
pub struct EgoVelocityEstimator {
    cfg: Config,
    dirs: Vec<Vector3<f64>>,
    vr: Vec<f64>,
    // Voting weight of each usable point (0: does not vote).
    weight: Vec<f64>,
    idx: Vec<usize>,
    inl: Vec<usize>,
    inlier_dirs: Vec<Vector3<f64>>,
}

impl EgoVelocityEstimator {
    /// An estimator with `cfg`.
    pub fn new(cfg: Config) -> Self {
        Self::with_capacity(cfg, 0)
    }

    /// An estimator with `cfg` whose working buffers hold frames of up to `points` points
    /// without allocating (a larger frame grows them once).
    pub fn with_capacity(cfg: Config, points: usize) -> Self {
        EgoVelocityEstimator {
            cfg,
            dirs: Vec::with_capacity(points),
            vr: Vec::with_capacity(points),
            weight: Vec::with_capacity(points),
            idx: Vec::with_capacity(points),
            inl: Vec::with_capacity(points),
            inlier_dirs: Vec::with_capacity(points),
        }
    }

    /// The settings.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Sets the Doppler quantisation step \[m/s\] ([`Config::doppler_step`]).
    pub fn set_doppler_step(&mut self, step: f32) {
        self.cfg.doppler_step = step;
    }

    /// Sets the near field \[m\] ([`Config::near_field_m`]).
    pub fn set_near_field(&mut self, range_m: f32) {
        self.cfg.near_field_m = range_m;
    }

    /// Estimates the sensor velocity from one frame.
    pub fn estimate(&mut self, detections: &[Detection]) -> Estimate {
        self.estimate_guided(detections, None)
    }

    /// Estimates the sensor velocity from one frame, choosing the consensus among hypotheses that
    /// agree with `prior` (velocity \[m/s\] and its covariance, e.g. the filter's prediction):
    /// moving objects and mirror ghosts can form a larger coherent set than the static world in a
    /// sparse frame, and the prior tells them apart. The prior only selects the inlier set; the
    /// returned velocity and covariance come from the radar points alone, so a filter can fuse
    /// them without counting its own prediction twice.
    pub fn estimate_guided(&mut self, detections: &[Detection], prior: Option<Prior>) -> Estimate {
        let mut est = Estimate::with_capacity(0);
        self.estimate_guided_into(detections, prior, &mut est);
        est
    }

    /// [`EgoVelocityEstimator::estimate_guided`] into an existing estimate, reusing its inlier
    /// mask: once the buffers have grown to a frame's size, estimating allocates nothing.
    pub fn estimate_guided_into(
        &mut self,
        detections: &[Detection],
        prior: Option<Prior>,
        out: &mut Estimate,
    ) {
        self.estimate_weighted_into(detections, None, prior, out);
    }

    /// [`EgoVelocityEstimator::estimate_guided_into`] with a voting weight per detection
    /// (`weights[i]` for `detections[i]`, in \[0, 1\]; missing or non-finite ones count 1): the
    /// consensus is the hypothesis whose inliers weigh most, so points the caller trusts more
    /// (a static reflector seen again where the motion carried it, [`crate::persist`]) outvote
    /// those it trusts less. The weights only choose the consensus: the inlier count the
    /// settings require, the least squares and the covariance are those of the plain estimate.
    pub fn estimate_weighted_into(
        &mut self,
        detections: &[Detection],
        weights: Option<&[f32]>,
        prior: Option<Prior>,
        out: &mut Estimate,
    ) {
        let cfg = self.cfg;
        let zero_gate = cfg.inlier_threshold();
        let mut near_field = 0;
        self.dirs.clear();
        self.vr.clear();
        self.weight.clear();
        self.idx.clear();
        for (i, d) in detections.iter().enumerate() {
            let p = d.position_m();
            let r = p.norm();
            if !(r.is_finite() && r >= f64::from(cfg.min_range) && d.radial_velocity.is_finite()) {
                continue;
            }
            let leak = r < f64::from(cfg.near_field_m) && d.radial_velocity.abs() <= zero_gate;
            near_field += usize::from(leak);
            let w = weights
                .and_then(|w| w.get(i))
                .map(|&w| f64::from(w))
                .filter(|w| w.is_finite())
                .map_or(1.0, |w| w.clamp(0.0, 1.0));
            self.weight.push(if leak { 0.0 } else { w });
            let mut u = p / r;
            if cfg.model == Model::Planar {
                u.z = 0.0;
            }
            self.dirs.push(u);
            self.vr.push(f64::from(d.radial_velocity));
            self.idx.push(i);
        }
        let usable = self.dirs.len();
        let mut mask = core::mem::take(&mut out.inlier_mask);
        mask.clear();
        mask.resize(detections.len(), false);
        *out = Estimate {
            velocity: [0.0; 3],
            covariance: [[0.0; 3]; 3],
            shared_covariance: [[0.0; 3]; 3],
            status: Status::Ok,
            inliers: 0,
            usable,
            skipped: detections.len() - usable,
            near_field,
            residual_rms: 0.0,
            inlier_mask: mask,
            iterations: 0,
        };
        let est = out;
        let dof = match cfg.model {
            Model::Full3d => 3,
            Model::Planar => 2,
        };
        let need = dof.max(cfg.min_inliers);
        if usable < need {
            est.status = Status::TooFewPoints { usable, need };
            return;
        }
        if let Some((dir, spread)) = weakest_direction(&self.dirs, cfg.model) {
            if spread < f64::from(cfg.min_spread) {
                est.status = Status::Degenerate {
                    weak_direction: [dir.x as f32, dir.y as f32, dir.z as f32],
                    spread: spread as f32,
                };
                return;
            }
        }

        let thresh = f64::from(cfg.inlier_threshold());
        let sd = f64::from(cfg.direction_sigma);
        // Inliers are chosen with the Doppler noise and quantisation alone (a wider gate lets
        // ghosts in); the direction errors enter the covariance.
        let thresh_for = |_v: &Vector3<f64>| thresh;
        // A point's Doppler deviation `s` plus what direction errors add at speed `|v|`.
        let with_direction = |s: f64, v: &Vector3<f64>| (s * s + (v.norm() * sd).powi(2)).sqrt();
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        // (voting inliers, their weight, truncated cost, hypothesis)
        let mut best: Option<(usize, f64, f64, Vector3<f64>)> = None;
        // A hypothesis from a minimal sample is itself uncertain by about the inlier threshold.
        let prior = prior.and_then(|p| {
            let c = Matrix3::from_fn(|r, k| p.covariance[r][k])
                + Matrix3::identity() * (thresh * thresh);
            Some((Vector3::from(p.velocity), c.try_inverse()?, p.gate))
        });
        let agrees = |v: &Vector3<f64>| {
            prior.as_ref().is_none_or(|(pv, ci, gate)| {
                let d = v - pv;
                (d.transpose() * ci * d)[(0, 0)] <= *gate
            })
        };
        if let Some((pv, _, _)) = &prior {
            let mut v = *pv;
            if cfg.model == Model::Planar {
                v.z = 0.0;
            }
            let (count, weight, cost) =
                score(&self.dirs, &self.vr, &self.weight, &v, thresh_for(&v));
            best = Some((count, weight, cost, v));
        }
        let mut max_iter = cfg.max_iterations;
        let mut it = 0;
        let mut sample = [0usize; 3];
        // Samples are drawn uniformly; the stop rule counts the inliers' share of the points'
        // weights (a non-voter, weight 0, as 1), so a heavy consensus among light points (seen
        // once) does not stop the search before the all-inlier sample of a consensus of points
        // seen again came up. Unweighted, the share is inliers / usable.
        let total_mass: f64 = self
            .weight
            .iter()
            .map(|&w| if w > 0.0 { w } else { 1.0 })
            .sum();
        while it < max_iter {
            it += 1;
            for k in 0..dof {
                loop {
                    let c = rng.gen_range(0..usable);
                    if !sample[..k].contains(&c) {
                        sample[k] = c;
                        break;
                    }
                }
            }
            let Some(v) = solve(
                &self.dirs,
                &self.vr,
                sample[..dof].iter().copied(),
                cfg.model,
            ) else {
                continue;
            };
            if !agrees(&v) {
                continue;
            }
            let (count, weight, cost) =
                score(&self.dirs, &self.vr, &self.weight, &v, thresh_for(&v));
            if best
                .as_ref()
                .is_none_or(|b| weight > b.1 || (weight == b.1 && cost < b.2))
            {
                best = Some((count, weight, cost, v));
                // Adaptive stop: iterations for `confidence` with the current inlier share.
                let w = weight / total_mass;
                let p_good = w.powi(dof as i32);
                if p_good > 0.0 && p_good < 1.0 {
                    let n = (1.0 - f64::from(cfg.confidence)).ln() / (1.0 - p_good).ln();
                    max_iter = max_iter.min(n.ceil().max(1.0) as u32).max(it);
                } else if p_good >= 1.0 {
                    max_iter = it;
                }
            }
        }
        est.iterations = it;
        let need_inliers = cfg
            .min_inliers
            .max((cfg.min_inlier_share * usable as f32).ceil() as usize)
            .max(dof);
        let Some((count, _, _, v0)) = best else {
            est.status = Status::NoConsensus {
                best_inliers: 0,
                need: need_inliers,
            };
            return;
        };
        if count < need_inliers {
            est.status = Status::NoConsensus {
                best_inliers: count,
                need: need_inliers,
            };
            return;
        }
        // Least squares on the consensus set, then once more on the refined set.
        let mut v = v0;
        let mut inl = core::mem::take(&mut self.inl);
        inl.clear();
        for _ in 0..2 {
            let th = thresh_for(&v);
            inl.clear();
            inl.extend((0..usable).filter(|&i| (self.vr[i] + self.dirs[i].dot(&v)).abs() <= th));
            if inl.len() < dof {
                break;
            }
            if let Some(nv) = solve(&self.dirs, &self.vr, inl.iter().copied(), cfg.model) {
                v = nv;
            }
        }
        if inl.len() < need_inliers {
            est.status = Status::NoConsensus {
                best_inliers: inl.len(),
                need: need_inliers,
            };
            self.inl = inl;
            return;
        }
        let mut inlier_dirs = core::mem::take(&mut self.inlier_dirs);
        inlier_dirs.clear();
        inlier_dirs.extend(inl.iter().map(|&i| self.dirs[i]));
        let weak = weakest_direction(&inlier_dirs, cfg.model);
        self.inlier_dirs = inlier_dirs;
        if let Some((dir, spread)) = weak {
            if spread < f64::from(cfg.min_spread) {
                est.status = Status::Degenerate {
                    weak_direction: [dir.x as f32, dir.y as f32, dir.z as f32],
                    spread: spread as f32,
                };
                est.inliers = inl.len();
                self.inl = inl;
                return;
            }
        }
        let ss: f64 = inl
            .iter()
            .map(|&i| (self.vr[i] + self.dirs[i].dot(&v)).powi(2))
            .sum();
        let rms = (ss / inl.len() as f64).sqrt();
        let step = f64::from(cfg.doppler_step.max(0.0));
        // The noise before rounding: the Doppler noise without the rounding's own floor, and what
        // direction errors add at this speed.
        let dither = with_direction(f64::from(cfg.sigma.max(0.0)), &v);
        // How much of the rounding that noise leaves tied to the velocity, the same for every
        // point of the frame (0 when off).
        let tied = if cfg.quantisation_correlation {
            quantisation_correlation(step, dither)
        } else {
            0.0
        };
        // Noise: the residual spread, but never below the Doppler noise plus what direction
        // errors add at this speed. The floor counts a point's own rounding (`step / sqrt(12)`)
        // only as far as the noise dithers it: the tied part is counted once, shared, below.
        let own = (1.0 - tied).sqrt() * f64::from(cfg.doppler_std());
        let floor = with_direction(f64::from(cfg.sigma.max(0.0)).max(own), &v);
        let sigma = (ss / (inl.len().saturating_sub(dof).max(1)) as f64)
            .sqrt()
            .max(floor);
        let mut dtd = Matrix3::zeros();
        for &i in &inl {
            dtd += self.dirs[i] * self.dirs[i].transpose();
        }
        if cfg.model == Model::Planar {
            dtd[(2, 2)] = 1.0;
        }
        // Rounding the points' noise cannot dither is nearly the same function of the velocity
        // for every point of the frame: that share does not shrink with the point count.
        let shared = tied * step * step / 12.0 * inl.len() as f64;
        let dtd_inv = dtd.try_inverse().unwrap_or_else(Matrix3::zeros);
        let mut cov = dtd_inv * (sigma * sigma + shared);
        let mut cov_shared = dtd_inv * shared;
        // The likelihood's noise: the Doppler noise alone (direction errors dither the rounding
        // less than their covariance term says: measured, docs/odometry.md).
        let noise = f64::from(cfg.sigma.max(0.0));
        if cfg.rounding_likelihood
            && noise > 0.0
            && quantisation_correlation(step, noise) > ROUNDING_TIED_MIN
        {
            if let Some((v_ml, cov_ml)) =
                rounded_likelihood(&self.dirs, &self.vr, v, step, noise, cfg.model)
            {
                // The likelihood's covariance knows the rounding and the Doppler noise; the
                // least squares' counts the direction errors too: the larger of the two, with
                // its part the frame's points share.
                let ml_cov = cov_ml + dtd_inv * (v_ml.norm() * sd).powi(2);
                if ml_cov.trace() > cov.trace() {
                    (cov, cov_shared) = (ml_cov, cov_ml);
                }
                v = v_ml;
            }
        }
        est.velocity = [v.x as f32, v.y as f32, v.z as f32];
        for r in 0..3 {
            for c in 0..3 {
                let planar_z = cfg.model == Model::Planar && (r == 2 || c == 2);
                est.covariance[r][c] = if planar_z { 0.0 } else { cov[(r, c)] as f32 };
                est.shared_covariance[r][c] = if planar_z {
                    0.0
                } else {
                    cov_shared[(r, c)] as f32
                };
            }
        }
        est.inliers = inl.len();
        est.residual_rms = rms as f32;
        for &i in &inl {
            est.inlier_mask[self.idx[i]] = true;
        }
        self.inl = inl;
    }
}

/// How much of a Doppler quantisation step's rounding error the noise leaves tied to the
/// signal, 0-1: `exp(-2 pi^2 noise^2 / step^2)`, the magnitude of the noise's characteristic
/// function at the lattice's frequency `2 pi / step` (Widrow's quantisation theory). Gaussian noise
/// of 0.4 of a step or more (0.04 or less) makes the rounding errors of different points
/// independent, uniform over a step, and a frame's least squares averages them; with less noise a
/// point's rounding is set by its true radial velocity, so at low speed a frame's points round
/// alike (a slow radar with 0.38 m/s steps reads most static points as 0) and the frame carries
/// that error whatever its point count. `noise` is the points' Doppler noise before rounding
/// \[m/s\] (Doppler noise and direction errors at the frame's speed); `step` \[m/s\], 0 for continuous
/// Doppler (0 returned).
pub fn quantisation_correlation(step: f64, noise: f64) -> f64 {
    if step <= 0.0 || !step.is_finite() {
        return 0.0;
    }
    let r = noise.max(0.0) / step;
    (-2.0 * core::f64::consts::PI.powi(2) * r * r).exp()
}

/// [`Config::rounding_likelihood`] applies where the rounding is tied to the velocity at least
/// this much ([`quantisation_correlation`]).
const ROUNDING_TIED_MIN: f64 = 0.05;

/// The standard normal density and distribution function (the latter through
/// [`erfc`]).
fn phi(x: f64) -> f64 {
    (-0.5 * x * x).exp() / (2.0 * core::f64::consts::PI).sqrt()
}

fn big_phi(x: f64) -> f64 {
    0.5 * erfc(-x / core::f64::consts::SQRT_2)
}

/// The complementary error function, relative error below 1.2e-7 (Chebyshev fit, Numerical
/// Recipes' `erfcc`).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.265_512_23
            + t * (1.000_023_68
                + t * (0.374_091_96
                    + t * (0.096_784_18
                        + t * (-0.186_288_06
                            + t * (0.278_868_07
                                + t * (-1.135_203_98
                                    + t * (1.488_515_87
                                        + t * (-0.822_152_23 + t * 0.170_872_77)))))))))
            .exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Probability of the reading cell `[lo, hi]` (in units of the noise, relative to the mean) and
/// its derivative by the mean: `P = Phi(hi) - Phi(lo)`, `dP/dmu = (phi(lo) - phi(hi)) / noise`.
fn cell(lo: f64, hi: f64) -> (f64, f64) {
    // Differences of the upper tails where both bounds are positive keep their precision.
    let p = if lo > 0.0 {
        big_phi(-lo) - big_phi(-hi)
    } else {
        big_phi(hi) - big_phi(lo)
    };
    (p, phi(lo) - phi(hi))
}

/// Readings further than half a step and this many noise deviations from a velocity's radial
/// velocity are not its static points (moving objects, ghosts).
const ROUNDING_GATE_SIGMAS: f64 = 4.0;

/// The maximum likelihood velocity of rounded Doppler readings and its covariance (the inverse of
/// the expected Fisher information): point `i` reads `vr_i`, the radial velocity `-d_i . v` plus
/// Gaussian noise of `noise`, rounded to a multiple of `step` \[m/s\]. The points are those whose
/// reading the current velocity explains (within half a step and [`ROUNDING_GATE_SIGMAS`]),
/// chosen again at each step: the consensus's gate, narrower, would cut the readings the noise
/// carried into the next cell, and that cut biases the likelihood. Fisher scoring from `v0` (the
/// least squares on the consensus); `None` where the information is singular or the iteration
/// does not settle.
fn rounded_likelihood(
    dirs: &[Vector3<f64>],
    vr: &[f64],
    v0: Vector3<f64>,
    step: f64,
    noise: f64,
    model: Model,
) -> Option<(Vector3<f64>, Matrix3<f64>)> {
    // Cells of the lattice within this many noise deviations of the mean carry the information.
    let reach = (6.0 * noise / step).ceil() as i64 + 1;
    let mut v = v0;
    for iteration in 0..=20 {
        let mut info = Matrix3::zeros();
        let mut score = Vector3::zeros();
        let gate = step / 2.0 + ROUNDING_GATE_SIGMAS * noise;
        for (d, &r) in dirs.iter().zip(vr) {
            let d = *d;
            let mu = -d.dot(&v);
            if (r - mu).abs() > gate {
                continue;
            }
            // The reading's cell: its score.
            let (p, dp) = cell((r - step / 2.0 - mu) / noise, (r + step / 2.0 - mu) / noise);
            let dlogp_dmu = dp / noise / p.max(1e-300);
            // dmu/dv = -d
            score -= d * dlogp_dmu;
            // Expected information about the mean over the cells a reading can fall in.
            let k0 = (mu / step).round() as i64;
            let mut fisher = 0.0;
            for k in k0 - reach..=k0 + reach {
                let c = k as f64 * step;
                let (p, dp) = cell((c - step / 2.0 - mu) / noise, (c + step / 2.0 - mu) / noise);
                if p > 1e-300 {
                    fisher += (dp / noise).powi(2) / p;
                }
            }
            info += d * d.transpose() * fisher;
        }
        if model == Model::Planar {
            z_apart(&mut info);
            score.z = 0.0;
        }
        let cov = info.try_inverse()?;
        if iteration == 20 {
            return None;
        }
        let dv = cov * score;
        if !dv.iter().all(|x| x.is_finite()) {
            return None;
        }
        // A step no larger than one Doppler step: the information is local.
        let len = dv.norm();
        v += if len > step { dv * (step / len) } else { dv };
        if len < 1e-6 {
            let mut cov = cov;
            if model == Model::Planar {
                cov[(2, 2)] = 0.0;
            }
            return Some((v, cov));
        }
    }
    None
}

/// Sets `m`'s z row and column apart from x-y, with 1 on the diagonal ([`Model::Planar`]).
fn z_apart(m: &mut Matrix3<f64>) {
    m[(2, 2)] = 1.0;
    m[(0, 2)] = 0.0;
    m[(2, 0)] = 0.0;
    m[(1, 2)] = 0.0;
    m[(2, 1)] = 0.0;
}

/// Least squares for `v` in `vr_i = -d_i . v` over the given points.
fn solve(
    dirs: &[Vector3<f64>],
    vr: &[f64],
    pts: impl Iterator<Item = usize>,
    model: Model,
) -> Option<Vector3<f64>> {
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for i in pts {
        a += dirs[i] * dirs[i].transpose();
        b -= dirs[i] * vr[i];
    }
    if model == Model::Planar {
        a[(2, 2)] = 1.0;
        b.z = 0.0;
    }
    let chol = a.cholesky()?;
    let v = chol.solve(&b);
    v.iter().all(|x| x.is_finite()).then_some(v)
}

/// Inlier count, inlier weight and truncated squared cost of a hypothesis.
/// Only voters (weight above 0) count (see [`Config::near_field_m`]).
fn score(
    dirs: &[Vector3<f64>],
    vr: &[f64],
    weight: &[f64],
    v: &Vector3<f64>,
    thresh: f64,
) -> (usize, f64, f64) {
    let mut count = 0;
    let mut sum = 0.0;
    let mut cost = 0.0;
    for ((d, r), &w) in dirs.iter().zip(vr).zip(weight) {
        if w <= 0.0 {
            continue;
        }
        let e = (r + d.dot(v)).abs();
        if e <= thresh {
            count += 1;
            sum += w;
            cost += e * e;
        } else {
            cost += thresh * thresh;
        }
    }
    (count, sum, cost)
}

/// The direction the points constrain least, and its normalised spread.
fn weakest_direction(dirs: &[Vector3<f64>], model: Model) -> Option<(Vector3<f64>, f64)> {
    let n = dirs.len() as f64;
    let mut s = Matrix3::zeros();
    for d in dirs {
        s += d * d.transpose();
    }
    s /= n;
    if model == Model::Planar {
        // Only x-y matters: z apart with a large value, so it is never the weakest.
        z_apart(&mut s);
    }
    let e = SymmetricEigen::new(s);
    let (k, val) =
        e.eigenvalues.iter().enumerate().fold(
            (0, f64::INFINITY),
            |m, (i, &v)| if v < m.1 { (i, v) } else { m },
        );
    Some((e.eigenvectors.column(k).into_owned(), val))
}
