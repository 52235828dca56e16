//! Trajectory evaluation, computed the way evo (`evo_ape`, `evo_rpe`) computes it, so figures agree
//! with the tool users trust (a CI test compares both on generated trajectories to 1e-6).
//!
//! * [`associate`]: nearest-timestamp matching within `max_diff` (evo's `associate_trajectories`).
//! * [`umeyama`]: least-squares rotation, translation and optional scale (Umeyama 1991).
//! * [`ape`]: absolute trajectory error of the translation part, 3D and horizontal (2D).
//! * [`rpe`]: relative pose error of the translation part over a frame or distance delta.
//! * [`Stats`]: rmse, mean, median, std (population), min, max, sse.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

use milliego_session::TumPose;
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use std::fmt;

/// A trajectory: time-stamped poses (body in world).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Trajectory {
    /// Times \[s\].
    pub t: Vec<f64>,
    /// Positions \[m\].
    pub p: Vec<Vector3<f64>>,
    /// Orientations (body to world).
    pub q: Vec<UnitQuaternion<f64>>,
}

impl Trajectory {
    /// From TUM poses.
    pub fn from_tum(poses: &[TumPose]) -> Trajectory {
        let mut tr = Trajectory::default();
        for x in poses {
            tr.t.push(x.t);
            tr.p.push(Vector3::from(x.p));
            tr.q.push(UnitQuaternion::from_quaternion(Quaternion::new(
                x.q[3], x.q[0], x.q[1], x.q[2],
            )));
        }
        tr
    }

    /// Number of poses.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The poses at `ids`, in that order.
    pub fn select(&self, ids: &[usize]) -> Trajectory {
        Trajectory {
            t: ids.iter().map(|&i| self.t[i]).collect(),
            p: ids.iter().map(|&i| self.p[i]).collect(),
            q: ids.iter().map(|&i| self.q[i]).collect(),
        }
    }

    /// Length of the path through the positions \[m\].
    pub fn path_length(&self) -> f64 {
        self.p.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    /// Applies `p -> R (c p) + t`, `q -> R q`.
    pub fn transform(&mut self, a: &Alignment) {
        for p in &mut self.p {
            *p = a.rotation * (*p * a.scale) + a.translation;
        }
        let r = UnitQuaternion::from_matrix(&a.rotation);
        for q in &mut self.q {
            *q = r * *q;
        }
    }
}

/// What went wrong.
#[derive(Debug, Clone, PartialEq)]
pub enum EvalError {
    /// No pose of one trajectory has a pose of the other within `max_diff`.
    NoMatches {
        /// The time tolerance \[s\].
        max_diff: f64,
        /// The offset added to the estimate's times \[s\].
        offset: f64,
    },
    /// Too few poses, or points on a line: the alignment is not determined.
    DegenerateAlignment {
        /// Matched poses.
        points: usize,
    },
    /// No pose pair at the requested RPE delta.
    NoPairs {
        /// The delta.
        delta: f64,
        /// Its unit.
        unit: &'static str,
    },
}

impl fmt::Display for EvalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EvalError::NoMatches { max_diff, offset } => write!(
                f,
                "no matching timestamps between estimate and ground truth within {max_diff} s (offset {offset} s): are both on the same clock?"
            ),
            EvalError::DegenerateAlignment { points } => {
                write!(f, "alignment undetermined: {points} matched positions are too few or collinear")
            }
            EvalError::NoPairs { delta, unit } => write!(f, "no pose pair {delta} {unit} apart"),
        }
    }
}

impl std::error::Error for EvalError {}

/// Associates `reference` and `estimate` by nearest timestamps (evo's rule): the trajectory with
/// fewer poses is matched into the other; pairs further apart than `max_diff` \[s\] are dropped;
/// `offset` \[s\] is added to the estimate's times. Returns both reduced to the matched poses.
pub fn associate(
    reference: &Trajectory,
    estimate: &Trajectory,
    max_diff: f64,
    offset: f64,
) -> Result<(Trajectory, Trajectory), EvalError> {
    let est_longer = estimate.len() > reference.len();
    let (short, long, off) = if est_longer {
        (reference, estimate, offset)
    } else {
        (estimate, reference, -offset)
    };
    let long_t: Vec<f64> = long.t.iter().map(|t| t + off).collect();
    let (is, il) = matching_time_indices(&short.t, &long_t, max_diff);
    if is.is_empty() {
        return Err(EvalError::NoMatches { max_diff, offset });
    }
    let (s, l) = (short.select(&is), long.select(&il));
    Ok(if est_longer { (s, l) } else { (l, s) })
}

fn matching_time_indices(a: &[f64], b: &[f64], max_diff: f64) -> (Vec<usize>, Vec<usize>) {
    let (mut ia, mut ib) = (Vec::new(), Vec::new());
    if b.is_empty() {
        return (ia, ib);
    }
    let sorted = b.windows(2).all(|w| w[1] >= w[0]);
    for (i, &ta) in a.iter().enumerate() {
        if !sorted {
            let (j, d) = b
                .iter()
                .enumerate()
                .fold((0, f64::INFINITY), |m, (j, &tb)| {
                    let d = (tb - ta).abs();
                    if d < m.1 {
                        (j, d)
                    } else {
                        m
                    }
                });
            if d <= max_diff {
                ia.push(i);
                ib.push(j);
            }
            continue;
        }
        if ta < b[0] - max_diff || ta > b[b.len() - 1] + max_diff {
            continue;
        }
        let mut j = b.partition_point(|&tb| tb <= ta);
        if j >= b.len() {
            j = b.len() - 1;
        }
        let ub = b[j] - ta;
        let lb = if j > 0 { ta - b[j - 1] } else { f64::INFINITY };
        let best = if ub <= max_diff && ub < lb {
            j
        } else if lb <= max_diff && lb <= ub {
            j - 1
        } else {
            continue;
        };
        ia.push(i);
        ib.push(best);
    }
    (ia, ib)
}

/// A similarity transform `y = R (c x) + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// Rotation.
    pub rotation: Matrix3<f64>,
    /// Translation \[m\].
    pub translation: Vector3<f64>,
    /// Scale (1 for SE(3)).
    pub scale: f64,
}

impl Alignment {
    /// The identity.
    pub fn identity() -> Alignment {
        Alignment {
            rotation: Matrix3::identity(),
            translation: Vector3::zeros(),
            scale: 1.0,
        }
    }
}

/// Least-squares `R, t, c` with `y ~ R (c x) + t` (Umeyama 1991), as evo computes it.
pub fn umeyama(
    x: &[Vector3<f64>],
    y: &[Vector3<f64>],
    with_scale: bool,
) -> Result<Alignment, EvalError> {
    let n = x.len();
    if n < 2 || n != y.len() {
        return Err(EvalError::DegenerateAlignment { points: n });
    }
    let nf = n as f64;
    let mx = x.iter().sum::<Vector3<f64>>() / nf;
    let my = y.iter().sum::<Vector3<f64>>() / nf;
    let sigma_x = x.iter().map(|v| (v - mx).norm_squared()).sum::<f64>() / nf;
    let mut cov = Matrix3::zeros();
    for (a, b) in x.iter().zip(y) {
        cov += (b - my) * (a - mx).transpose();
    }
    cov /= nf;
    let svd = cov.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Err(EvalError::DegenerateAlignment { points: n });
    };
    // nalgebra does not promise an order: sort singular values (and vectors) descending.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| svd.singular_values[j].total_cmp(&svd.singular_values[i]));
    let d = Vector3::from_fn(|k, _| svd.singular_values[order[k]]);
    let u = Matrix3::from_fn(|r, k| u[(r, order[k])]);
    let vt = Matrix3::from_fn(|k, c| vt[(order[k], c)]);
    if d.iter().filter(|&&s| s > f64::EPSILON).count() < 2 {
        return Err(EvalError::DegenerateAlignment { points: n });
    }
    let mut s = Matrix3::identity();
    if u.determinant() * vt.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let rotation = u * s * vt;
    let scale = if with_scale {
        (Matrix3::from_diagonal(&d) * s).trace() / sigma_x
    } else {
        1.0
    };
    let translation = my - rotation * mx * scale;
    Ok(Alignment {
        rotation,
        translation,
        scale,
    })
}

/// Error statistics, as evo reports them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stats {
    /// Root mean square.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median (mean of the two middle values for an even count).
    pub median: f64,
    /// Standard deviation (population).
    pub std: f64,
    /// Minimum.
    pub min: f64,
    /// Maximum.
    pub max: f64,
    /// Sum of squares.
    pub sse: f64,
    /// Number of values.
    pub count: usize,
}

impl Stats {
    /// Statistics of `e` (all zero for an empty slice).
    pub fn of(e: &[f64]) -> Stats {
        let n = e.len();
        if n == 0 {
            return Stats {
                rmse: 0.0,
                mean: 0.0,
                median: 0.0,
                std: 0.0,
                min: 0.0,
                max: 0.0,
                sse: 0.0,
                count: 0,
            };
        }
        let nf = n as f64;
        let sse: f64 = e.iter().map(|v| v * v).sum();
        let mean = e.iter().sum::<f64>() / nf;
        let std = (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / nf).sqrt();
        let mut s = e.to_vec();
        s.sort_by(f64::total_cmp);
        let median = if n % 2 == 1 {
            s[n / 2]
        } else {
            (s[n / 2 - 1] + s[n / 2]) / 2.0
        };
        Stats {
            rmse: (sse / nf).sqrt(),
            mean,
            median,
            std,
            min: s[0],
            max: s[n - 1],
            sse,
            count: n,
        }
    }
}

/// How to align the estimate before computing errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// No alignment.
    None,
    /// Rotation and translation.
    Se3,
    /// Rotation, translation and scale.
    Sim3,
}

/// Aligns `est` onto `reference` (associated, same length) and returns the transform used.
pub fn align(
    reference: &Trajectory,
    est: &mut Trajectory,
    how: Align,
) -> Result<Alignment, EvalError> {
    let a = match how {
        Align::None => return Ok(Alignment::identity()),
        Align::Se3 => umeyama(&est.p, &reference.p, false)?,
        Align::Sim3 => umeyama(&est.p, &reference.p, true)?,
    };
    est.transform(&a);
    Ok(a)
}

/// Absolute error of the translation part per matched pose: 3D and horizontal (x, y) \[m\].
pub fn ape(reference: &Trajectory, est: &Trajectory) -> (Vec<f64>, Vec<f64>) {
    reference
        .p
        .iter()
        .zip(&est.p)
        .map(|(r, e)| {
            let d = e - r;
            (d.norm(), d.xy().norm())
        })
        .unzip()
}

/// Unit of an RPE delta.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeltaUnit {
    /// Poses apart.
    Frames,
    /// Metres of path apart (measured on the estimate, as evo does).
    Meters,
}

/// Relative error of the translation part over consecutive pairs `delta` apart \[m\]: for each
/// pair (i, j), `|| trans((Q_i^-1 Q_j)^-1 (P_i^-1 P_j)) ||` with Q the reference, P the estimate.
pub fn rpe(
    reference: &Trajectory,
    est: &Trajectory,
    delta: f64,
    unit: DeltaUnit,
) -> Result<Vec<f64>, EvalError> {
    let pairs = match unit {
        DeltaUnit::Frames => {
            let d = (delta as usize).max(1);
            let ids: Vec<usize> = (0..est.len()).step_by(d).collect();
            ids.windows(2).map(|w| (w[0], w[1])).collect::<Vec<_>>()
        }
        DeltaUnit::Meters => {
            let mut ids = vec![0usize];
            let mut path = 0.0;
            for i in 1..est.len() {
                path += (est.p[i] - est.p[i - 1]).norm();
                if path >= delta {
                    ids.push(i);
                    path = 0.0;
                }
            }
            ids.windows(2).map(|w| (w[0], w[1])).collect()
        }
    };
    if pairs.is_empty() {
        let unit = if unit == DeltaUnit::Frames {
            "frames"
        } else {
            "m"
        };
        return Err(EvalError::NoPairs { delta, unit });
    }
    Ok(pairs
        .into_iter()
        .map(|(i, j)| {
            let q_rel_t = reference.q[i].inverse() * (reference.p[j] - reference.p[i]);
            let q_rel_r = reference.q[i].inverse() * reference.q[j];
            let p_rel_t = est.q[i].inverse() * (est.p[j] - est.p[i]);
            (q_rel_r.inverse() * (p_rel_t - q_rel_t)).norm()
        })
        .collect())
}

/// One evaluation: ATE (3D and 2D), RPE, drift.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Matched poses.
    pub matched: usize,
    /// Poses of the estimate and of the reference before matching.
    pub poses: (usize, usize),
    /// The alignment applied to the estimate.
    pub alignment: Alignment,
    /// ATE of the translation part \[m\].
    pub ate: Stats,
    /// ATE in the horizontal plane \[m\].
    pub ate_2d: Stats,
    /// RPE of the translation part \[m\].
    pub rpe: Stats,
    /// Reference path length over the matched poses \[m\].
    pub path_length: f64,
    /// Final position error over path length \[%\].
    pub final_drift_pct: f64,
    /// ATE RMSE over path length \[%\].
    pub ate_rmse_pct: f64,
}

/// Evaluation settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Alignment.
    pub align: Align,
    /// Association tolerance \[s\].
    pub max_diff: f64,
    /// Offset added to estimate times \[s\].
    pub offset: f64,
    /// RPE delta.
    pub rpe_delta: f64,
    /// RPE delta unit.
    pub rpe_unit: DeltaUnit,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            align: Align::Se3,
            max_diff: 0.01,
            offset: 0.0,
            rpe_delta: 1.0,
            rpe_unit: DeltaUnit::Frames,
        }
    }
}

/// Associates, aligns and computes every figure.
pub fn evaluate(
    reference: &Trajectory,
    estimate: &Trajectory,
    s: &Settings,
) -> Result<Report, EvalError> {
    let (r, mut e) = associate(reference, estimate, s.max_diff, s.offset)?;
    let alignment = align(&r, &mut e, s.align)?;
    let (a3, a2) = ape(&r, &e);
    let rp = rpe(&r, &e, s.rpe_delta, s.rpe_unit)?;
    let path_length = r.path_length();
    let last = a3.last().copied().unwrap_or(0.0);
    let ate = Stats::of(&a3);
    let pct = |x: f64| {
        if path_length > 0.0 {
            100.0 * x / path_length
        } else {
            f64::NAN
        }
    };
    Ok(Report {
        matched: r.len(),
        poses: (estimate.len(), reference.len()),
        alignment,
        ate,
        ate_2d: Stats::of(&a2),
        rpe: Stats::of(&rp),
        path_length,
        final_drift_pct: pct(last),
        ate_rmse_pct: pct(ate.rmse),
    })
}
