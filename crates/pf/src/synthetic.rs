//! Synthetic action models and an oracle observation model, for tests, benches and demos.
//!
//! The models are hand-written linear parametric HMMs (built with `Phmm::from_params`, no
//! training): each action is a minimum-jerk movement of the fingertip from a rest pose to the
//! table target θ, with an action-specific end height, lift and elbow path, so that
//! μ_i(θ) = μ̄_i + W_i θ with W_i growing with progress. The oracle scores a pose by its distance
//! to a known ground-truth pose. Nothing here is used by the filter itself.

use actrack_phmm::{EndMode, Phmm};
use nalgebra::{DMatrix, DVector};
use rand::Rng;

use crate::{ObservationModel, PfError, TableRegion};

/// Height of the table top in the actor frame (the shoulder is the origin), metres.
pub const TABLE_Z: f64 = -0.30;

/// A table region in the actor frame that the synthetic actions reach over: centre (0, 0.45) m,
/// half-extents 0.40 × 0.15 m (SPEC §3.1's 80 × 30 cm).
pub fn table_region() -> TableRegion {
    TableRegion::new([0.0, 0.45], [0.40, 0.15])
}

/// Shape of one synthetic action.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActionShape {
    /// Fingertip height above the table at the end of the movement, metres.
    pub end_height: f64,
    /// Extra fingertip lift in the middle of the movement, metres.
    pub lift: f64,
    /// Fraction of θ the elbow moves towards.
    pub elbow_reach: f64,
    /// Sideways (x) offset of the elbow at the end, metres.
    pub elbow_out: f64,
    /// Elbow height at the end (actor frame), metres.
    pub elbow_z: f64,
}

/// Three distinguishable actions: point (hover above the target), push (on the table, low elbow),
/// reach (slightly above the table, elbow out).
pub const SHAPES: [(&str, ActionShape); 3] = [
    (
        "point",
        ActionShape {
            end_height: 0.12,
            lift: 0.05,
            elbow_reach: 0.45,
            elbow_out: 0.05,
            elbow_z: -0.12,
        },
    ),
    (
        "push",
        ActionShape {
            end_height: 0.0,
            lift: 0.0,
            elbow_reach: 0.55,
            elbow_out: 0.0,
            elbow_z: -0.22,
        },
    ),
    (
        "reach",
        ActionShape {
            end_height: 0.04,
            lift: 0.10,
            elbow_reach: 0.40,
            elbow_out: 0.12,
            elbow_z: -0.15,
        },
    ),
];

/// Rest pose (p, q, r): shoulder at the origin, elbow below it, fingertip in front, on the lap.
pub const REST_POSE: [f64; 9] = [0.0, 0.0, 0.0, 0.03, 0.02, -0.29, 0.05, 0.40, -0.36];

fn min_jerk(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
}

/// A linear parametric HMM of one synthetic action: `n_states` ≥ 4 states, J = 3, self-transition
/// 0.5 and forward jumps 0.40 / 0.08 / 0.02 (renormalised where the band is truncated), exit
/// probability `exit` from the last state (EndMode::MustEnd), or no exit at all when `exit` is
/// 0 (EndMode::None). Diagonal covariance with standard deviation `pose_std` metres.
pub fn action_model(
    shape: &ActionShape,
    n_states: usize,
    exit: f64,
    pose_std: f64,
) -> Result<Phmm, PfError> {
    let n = n_states.max(2);
    let bad = |e: actrack_phmm::PhmmError| PfError::BadModel {
        action: 0,
        reason: e.to_string(),
    };
    let jumps = [0.5, 0.40, 0.08, 0.02];
    let mut a = DMatrix::zeros(n, n);
    let mut exit_p = vec![0.0; n];
    for i in 0..n {
        if i + 1 == n {
            a[(i, i)] = 1.0 - exit;
            exit_p[i] = exit;
            continue;
        }
        let avail: f64 = (0..jumps.len())
            .filter(|o| i + o < n)
            .map(|o| jumps[o])
            .sum();
        for (o, p) in jumps.iter().enumerate() {
            if i + o < n {
                a[(i, i + o)] = p / avail;
            }
        }
    }
    let mut start = vec![0.0; n];
    start[0] = 1.0;
    let mut bias = Vec::with_capacity(n);
    let mut weights = Vec::with_capacity(n);
    let mut covs = Vec::with_capacity(n);
    for i in 0..n {
        let s = i as f64 / (n - 1) as f64;
        let m = min_jerk(s);
        let bump = (std::f64::consts::PI * s).sin();
        let mut b = DVector::zeros(9);
        let mut w = DMatrix::zeros(9, 2);
        // Shoulder: fixed, a slight forward lean.
        b[0] = REST_POSE[0];
        b[1] = REST_POSE[1] + 0.03 * m;
        b[2] = REST_POSE[2] - 0.01 * m;
        // Elbow: towards elbow_reach·θ, out and to its end height.
        b[3] = (1.0 - m) * REST_POSE[3] + m * shape.elbow_out;
        b[4] = (1.0 - m) * REST_POSE[4];
        b[5] = (1.0 - m) * REST_POSE[5] + m * shape.elbow_z + 0.5 * shape.lift * bump;
        w[(3, 0)] = m * shape.elbow_reach;
        w[(4, 1)] = m * shape.elbow_reach;
        // Fingertip: to (θ, table + end height), lifted on the way.
        b[6] = (1.0 - m) * REST_POSE[6];
        b[7] = (1.0 - m) * REST_POSE[7];
        b[8] = (1.0 - m) * REST_POSE[8] + m * (TABLE_Z + shape.end_height) + shape.lift * bump;
        w[(6, 0)] = m;
        w[(7, 1)] = m;
        bias.push(b);
        weights.push(w);
        covs.push(DMatrix::from_diagonal_element(9, 9, pose_std * pose_std));
    }
    let end_mode = if exit > 0.0 {
        EndMode::MustEnd
    } else {
        EndMode::None
    };
    Phmm::from_params(&start, &a, &exit_p, &bias, &weights, &covs, 3, end_mode).map_err(bad)
}

/// The first `n_actions` (≤ 3) of [`SHAPES`] as models with `n_states` states, exit probability
/// 0.2 and 1.5 cm pose noise, with their names.
pub fn demo_models(n_actions: usize, n_states: usize) -> Result<(Vec<Phmm>, Vec<String>), PfError> {
    let mut models = Vec::new();
    let mut names = Vec::new();
    for (name, shape) in SHAPES.iter().take(n_actions.clamp(1, SHAPES.len())) {
        models.push(action_model(shape, n_states, 0.2, 0.015)?);
        names.push((*name).to_string());
    }
    Ok((models, names))
}

/// Generate one performance of an action toward `theta` (metres): states from π and the banded
/// rows until the exit state is drawn (or `max_len` frames), poses x ~ N(μ_k(θ), Σ_k) (G1 of
/// SPEC §2.7). Returns the poses and the 0-based states.
pub fn sample_sequence<R: Rng + ?Sized>(
    model: &Phmm,
    theta: [f64; 2],
    max_len: usize,
    rng: &mut R,
) -> (Vec<[f64; 9]>, Vec<usize>) {
    let n = model.n_states();
    let mut poses = Vec::new();
    let mut states = Vec::new();
    let u: f64 = rng.random();
    let mut acc = 0.0;
    let mut k = n - 1;
    for i in 0..n {
        acc += model.start_prob(i);
        if u < acc {
            k = i;
            break;
        }
    }
    let mut mean = [0.0; 9];
    while poses.len() < max_len {
        model.mean_into(k, &theta, &mut mean);
        let l = model.cov_cholesky(k);
        let z: [f64; 9] = std::array::from_fn(|_| rng.sample(rand_distr::StandardNormal));
        let mut x = mean;
        for r in 0..9 {
            for c in 0..=r {
                x[r] += l[(r, c)] * z[c];
            }
        }
        poses.push(x);
        states.push(k);
        let u: f64 = rng.random();
        let mut acc = 0.0;
        let mut next = None;
        for j in k..n {
            acc += model.transition(k, j);
            if u < acc {
                next = Some(j);
                break;
            }
        }
        match next {
            Some(j) => k = j,
            None => {
                if model.exit_prob(k) > 0.0 {
                    break;
                }
                // Rounding at the end of a row without exit: stay.
            }
        }
    }
    (poses, states)
}

/// An oracle observation: log P(I | x̃) = −Σ_joints ‖x̃_j − x_j^true‖² / (2 s²), from a known
/// ground-truth pose; poses are not corrected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OracleObservation {
    /// The ground-truth pose of the frame.
    pub truth: [f64; 9],
    /// Observation noise s, metres.
    pub sigma: f64,
}

impl ObservationModel for OracleObservation {
    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        let c = 1.0 / (2.0 * self.sigma * self.sigma);
        for (x, o) in poses.iter().zip(out.iter_mut()) {
            let d2: f64 = x
                .iter()
                .zip(&self.truth)
                .map(|(a, b)| (a - b) * (a - b))
                .sum();
            *o = -c * d2;
        }
    }
}
