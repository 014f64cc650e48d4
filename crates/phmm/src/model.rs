//! The model type [`Phmm`]: parameters, validation, accessors and serde.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::PhmmError;
use crate::linalg;

/// Tolerance on `Σ_j a_ij + a_iE = 1` and `Σ_i π_i = 1` when parameters are given explicitly.
const ROW_SUM_TOL: f64 = 1e-6;

/// `½ log 2π`.
pub(crate) const HALF_LN_2PI: f64 = 0.918_938_533_204_672_8;

/// Covariance structure of the emission densities.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum CovarianceKind {
    /// Full d × d covariance per state (the paper's choice).
    #[default]
    Full,
    /// Diagonal covariance per state: off-diagonal terms are kept at zero during training.
    Diagonal,
}

/// How sequences end (SPEC §1.1). `a_iE` is the probability of leaving the model from state i.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum EndMode {
    /// SPEC default "must end in the final state": `a_iE = 0` for `i < N`, `a_NE > 0` learned.
    /// Every sequence ends in state N; `log P` includes `log a_NE`. This is the exit rate the
    /// tracker's loop grammar uses.
    #[default]
    MustEnd,
    /// Sequences may end in any state: `a_iE` is learned for every state and `log P` includes
    /// `log a_{q_T,E}`. Sampling then stops after a learned, state-dependent time.
    Free,
    /// No exit modelling at all (SPEC's `free_end`, a plain left-right HMM like hmmlearn):
    /// `a_iE = 0`, every row sums to one over the band (so `a_NN = 1`) and `β_T(i) = 1`,
    /// i.e. sequences are treated as truncated at arbitrary points.
    None,
}

/// A left-right Gaussian HMM with banded forward topology whose state means depend linearly on
/// a parameter θ: `μ_i(θ) = μ̄_i + W_i θ` (the linear parametric HMM of Wilson & Bobick).
///
/// With `theta_dim() == 0` it is a plain Gaussian HMM. All public methods take θ in the
/// caller's units; internally θ is centred and scaled (the transform is part of the model) so
/// the normal equations are well conditioned.
///
/// Invariants (checked on construction and deserialisation): `a_ij = 0` outside
/// `i ≤ j ≤ i + J`, `Σ_j a_ij + a_iE = 1` for every row, the exit pattern matches
/// [`EndMode`], `Σ_i π_i = 1`, every covariance is symmetric positive definite and every value
/// is finite.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(try_from = "PhmmRepr", into = "PhmmRepr")]
pub struct Phmm {
    pub(crate) n: usize,
    pub(crate) d: usize,
    pub(crate) p: usize,
    pub(crate) j: usize,
    pub(crate) end_mode: EndMode,
    pub(crate) covariance_kind: CovarianceKind,
    /// π, length N.
    pub(crate) start: Vec<f64>,
    /// Banded transitions, N × (J+1): `trans[i*(J+1)+k] = a_{i,i+k}` (0 where `i+k ≥ N`).
    pub(crate) trans: Vec<f64>,
    /// Exit probabilities `a_iE`, length N.
    pub(crate) exit: Vec<f64>,
    /// μ̄_i in internal θ units (the mean at θ_internal = 0, i.e. θ = centre).
    pub(crate) mean_bias: Vec<DVector<f64>>,
    /// W_i, d × p, in internal θ units.
    pub(crate) weights: Vec<DMatrix<f64>>,
    /// θ_internal = (θ − centre) / scale, component-wise.
    pub(crate) theta_center: Vec<f64>,
    pub(crate) theta_scale: Vec<f64>,
    pub(crate) covariances: Vec<DMatrix<f64>>,
    /// Lower Cholesky factors of the covariances.
    pub(crate) cholesky: Vec<DMatrix<f64>>,
    /// Derived: packed lower factors (row-major triangle), `1/L_kk`, and the log normaliser
    /// `−Σ log L_kk − (d/2) log 2π` per state.
    pub(crate) chol_packed: Vec<Vec<f64>>,
    pub(crate) chol_inv_diag: Vec<Vec<f64>>,
    pub(crate) log_norm: Vec<f64>,
    /// Derived: the band by diagonal, (J+1) × N: `band_in[k*N + j] = a_{j−k, j}` (0 if k > j)
    /// and `band_out[k*N + i] = a_{i, i+k}` (0 past the last state).
    pub(crate) band_in: Vec<f64>,
    pub(crate) band_out: Vec<f64>,
    /// Distinct training θ (internal units), the starting points of multi-start θ estimation.
    pub(crate) training_thetas: Vec<Vec<f64>>,
}

/// The serialised form: plain nested arrays, easy to read from any language.
#[derive(Serialize, Deserialize)]
struct PhmmRepr {
    n_states: usize,
    dim: usize,
    theta_dim: usize,
    max_jump: usize,
    end_mode: EndMode,
    covariance_kind: CovarianceKind,
    start_prob: Vec<f64>,
    /// Row i lists `a_{i,i} … a_{i,i+J}` (zeros past the last state).
    transitions_banded: Vec<Vec<f64>>,
    exit_prob: Vec<f64>,
    /// μ̄_i (internal θ units).
    mean_bias: Vec<Vec<f64>>,
    /// W_i row-major d × p (internal θ units).
    weights: Vec<Vec<f64>>,
    theta_center: Vec<f64>,
    theta_scale: Vec<f64>,
    /// Σ_i row-major d × d.
    covariances: Vec<Vec<f64>>,
    /// Training θ values (internal units), for multi-start θ estimation.
    #[serde(default)]
    training_thetas: Vec<Vec<f64>>,
}

impl From<Phmm> for PhmmRepr {
    fn from(m: Phmm) -> Self {
        let w = m.j + 1;
        PhmmRepr {
            n_states: m.n,
            dim: m.d,
            theta_dim: m.p,
            max_jump: m.j,
            end_mode: m.end_mode,
            covariance_kind: m.covariance_kind,
            start_prob: m.start.clone(),
            transitions_banded: m.trans.chunks(w).map(<[f64]>::to_vec).collect(),
            exit_prob: m.exit.clone(),
            mean_bias: m.mean_bias.iter().map(|v| v.as_slice().to_vec()).collect(),
            weights: m.weights.iter().map(row_major).collect(),
            theta_center: m.theta_center.clone(),
            theta_scale: m.theta_scale.clone(),
            covariances: m.covariances.iter().map(row_major).collect(),
            training_thetas: m.training_thetas.clone(),
        }
    }
}

fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    let mut v = Vec::with_capacity(m.len());
    for r in 0..m.nrows() {
        for c in 0..m.ncols() {
            v.push(m[(r, c)]);
        }
    }
    v
}

impl TryFrom<PhmmRepr> for Phmm {
    type Error = PhmmError;
    fn try_from(r: PhmmRepr) -> Result<Self, PhmmError> {
        let bad = |s: String| Err(PhmmError::InvalidModel(s));
        let (n, d, p, j) = (r.n_states, r.dim, r.theta_dim, r.max_jump);
        if r.transitions_banded.len() != n
            || r.transitions_banded.iter().any(|row| row.len() != j + 1)
        {
            return bad(format!(
                "transitions_banded must be {n} rows of {} values",
                j + 1
            ));
        }
        if r.mean_bias.len() != n || r.weights.len() != n || r.covariances.len() != n {
            return bad(format!(
                "mean_bias, weights and covariances need {n} entries each"
            ));
        }
        let mut mean_bias = Vec::with_capacity(n);
        let mut weights = Vec::with_capacity(n);
        let mut covs = Vec::with_capacity(n);
        for i in 0..n {
            if r.mean_bias[i].len() != d
                || r.weights[i].len() != d * p
                || r.covariances[i].len() != d * d
            {
                return bad(format!(
                    "state {i}: mean_bias needs {d}, weights {}, covariance {} values",
                    d * p,
                    d * d
                ));
            }
            mean_bias.push(DVector::from_row_slice(&r.mean_bias[i]));
            weights.push(DMatrix::from_row_slice(d, p, &r.weights[i]));
            covs.push(DMatrix::from_row_slice(d, d, &r.covariances[i]));
        }
        if r.training_thetas
            .iter()
            .any(|t| t.len() != p || t.iter().any(|v| !v.is_finite()))
        {
            return bad(format!(
                "training_thetas must be finite vectors of length {p}"
            ));
        }
        let trans: Vec<f64> = r.transitions_banded.into_iter().flatten().collect();
        Phmm::assemble(
            false,
            j,
            r.end_mode,
            r.covariance_kind,
            r.start_prob,
            trans,
            r.exit_prob,
            mean_bias,
            weights,
            r.theta_center,
            r.theta_scale,
            covs,
        )
        .map(|m| m.with_training_thetas(r.training_thetas))
    }
}

fn check_finite_slice(what: &str, v: &[f64]) -> Result<(), PhmmError> {
    if let Some((k, &x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(PhmmError::NonFinite {
            what: what.to_string(),
            row: k,
            col: 0,
            value: x,
        });
    }
    Ok(())
}

fn check_finite_matrix(what: &str, m: &DMatrix<f64>) -> Result<(), PhmmError> {
    for r in 0..m.nrows() {
        for c in 0..m.ncols() {
            let x = m[(r, c)];
            if !x.is_finite() {
                return Err(PhmmError::NonFinite {
                    what: what.to_string(),
                    row: r,
                    col: c,
                    value: x,
                });
            }
        }
    }
    Ok(())
}

impl Phmm {
    /// Build a model from explicit parameters, in the caller's θ units.
    ///
    /// * `start`: π, length N, non-negative, summing to 1.
    /// * `transitions`: N × N matrix `a_ij`; must be zero outside the band `i ≤ j ≤ i + max_jump`.
    /// * `exit`: `a_iE`, length N. With [`EndMode::MustEnd`] only the last entry may be (and must
    ///   be) positive; with [`EndMode::None`] all must be zero. Every row must satisfy
    ///   `Σ_j a_ij + a_iE = 1` (to 1e-6; rows are then renormalised exactly).
    /// * `mean_bias`: μ̄_i (length d each) and `weights`: W_i (d × p each, p = dim θ, may be 0), so
    ///   that `μ_i(θ) = μ̄_i + W_i θ`.
    /// * `covariances`: Σ_i, symmetric positive definite d × d.
    ///
    /// The covariance kind is recorded as [`CovarianceKind::Diagonal`] when every off-diagonal
    /// entry is exactly zero, else [`CovarianceKind::Full`].
    pub fn from_params(
        start: &[f64],
        transitions: &DMatrix<f64>,
        exit: &[f64],
        mean_bias: &[DVector<f64>],
        weights: &[DMatrix<f64>],
        covariances: &[DMatrix<f64>],
        max_jump: usize,
        end_mode: EndMode,
    ) -> Result<Phmm, PhmmError> {
        let n = start.len();
        if n == 0 {
            return Err(PhmmError::InvalidModel(
                "start must have at least one state".into(),
            ));
        }
        if transitions.nrows() != n || transitions.ncols() != n {
            return Err(PhmmError::InvalidModel(format!(
                "transitions is {}×{} but start has {n} states: pass an N×N matrix",
                transitions.nrows(),
                transitions.ncols()
            )));
        }
        check_finite_matrix("transitions", transitions)?;
        let w = max_jump + 1;
        let mut trans = vec![0.0; n * w];
        for i in 0..n {
            for jj in 0..n {
                let a = transitions[(i, jj)];
                if jj >= i && jj - i <= max_jump {
                    trans[i * w + (jj - i)] = a;
                } else if a != 0.0 {
                    return Err(PhmmError::InvalidModel(format!(
                        "transition a[{i}][{jj}] = {a} lies outside the band i ≤ j ≤ i + {max_jump}: \
                         set it to 0 or raise max_jump"
                    )));
                }
            }
        }
        let p = weights.first().map_or(0, DMatrix::ncols);
        Phmm::assemble(
            true,
            max_jump,
            end_mode,
            if covariances.iter().all(is_diagonal) {
                CovarianceKind::Diagonal
            } else {
                CovarianceKind::Full
            },
            start.to_vec(),
            trans,
            exit.to_vec(),
            mean_bias.to_vec(),
            weights.to_vec(),
            vec![0.0; p],
            vec![1.0; p],
            covariances.to_vec(),
        )
    }

    /// Validate internal parameters and compute the derived caches. Used by every constructor
    /// (explicit parameters, training, deserialisation). With `renormalise`, π and the rows are
    /// rescaled to sum to exactly one (explicit parameters); without, values are kept bit for
    /// bit (so a serde round trip is exact).
    #[allow(clippy::needless_pass_by_value)]
    pub(crate) fn assemble(
        renormalise: bool,
        max_jump: usize,
        end_mode: EndMode,
        covariance_kind: CovarianceKind,
        mut start: Vec<f64>,
        mut trans: Vec<f64>,
        mut exit: Vec<f64>,
        mean_bias: Vec<DVector<f64>>,
        weights: Vec<DMatrix<f64>>,
        theta_center: Vec<f64>,
        theta_scale: Vec<f64>,
        covariances: Vec<DMatrix<f64>>,
    ) -> Result<Phmm, PhmmError> {
        let bad = |s: String| Err(PhmmError::InvalidModel(s));
        let n = start.len();
        let w = max_jump + 1;
        if n == 0 {
            return bad("the model needs at least one state".into());
        }
        if max_jump == 0 && n > 1 {
            return bad("max_jump must be at least 1 when there is more than one state".into());
        }
        if trans.len() != n * w || exit.len() != n {
            return bad(format!(
                "transitions need {n}×{w} banded values and exit {n} values"
            ));
        }
        if mean_bias.len() != n || weights.len() != n || covariances.len() != n {
            return bad(format!(
                "mean_bias, weights and covariances need one entry per state ({n}); got {}, {}, {}",
                mean_bias.len(),
                weights.len(),
                covariances.len()
            ));
        }
        let d = mean_bias[0].len();
        if d == 0 {
            return bad("observations must have at least one dimension".into());
        }
        let p = weights[0].ncols();
        if theta_center.len() != p || theta_scale.len() != p {
            return bad(format!("θ centre and scale need {p} values"));
        }
        check_finite_slice("start", &start)?;
        check_finite_slice("transitions", &trans)?;
        check_finite_slice("exit", &exit)?;
        check_finite_slice("theta centre", &theta_center)?;
        check_finite_slice("theta scale", &theta_scale)?;
        if theta_scale.iter().any(|&s| s <= 0.0) {
            return bad("θ scale must be positive".into());
        }
        // π
        if start.iter().any(|&x| x < 0.0) {
            return bad("start probabilities must be non-negative".into());
        }
        let s: f64 = start.iter().sum();
        if (s - 1.0).abs() > ROW_SUM_TOL {
            return bad(format!("start probabilities sum to {s}, not 1"));
        }
        if renormalise {
            for x in &mut start {
                *x /= s;
            }
        }
        // A and a_E
        for i in 0..n {
            for k in 0..w {
                let a = trans[i * w + k];
                if a < 0.0 {
                    return bad(format!("transition a[{i}][{}] = {a} is negative", i + k));
                }
                if i + k >= n && a != 0.0 {
                    return bad(format!(
                        "transition from state {i} jumps past the last state"
                    ));
                }
            }
            if exit[i] < 0.0 {
                return bad(format!("exit probability of state {i} is negative"));
            }
            match end_mode {
                EndMode::MustEnd if i + 1 < n && exit[i] != 0.0 => {
                    return bad(format!(
                        "EndMode::MustEnd needs exit probability 0 for state {i} (only the last state exits): \
                         set it to 0 or use EndMode::Free"
                    ));
                }
                EndMode::MustEnd if i + 1 == n && exit[i] <= 0.0 => {
                    return bad(
                        "EndMode::MustEnd needs a positive exit probability for the last state"
                            .into(),
                    );
                }
                EndMode::None if exit[i] != 0.0 => {
                    return bad(format!(
                        "EndMode::None has no exit: exit probability of state {i} must be 0"
                    ));
                }
                _ => {}
            }
            let row: f64 = trans[i * w..(i + 1) * w].iter().sum::<f64>() + exit[i];
            if (row - 1.0).abs() > ROW_SUM_TOL {
                return bad(format!(
                    "row {i}: Σ_j a_ij + a_iE = {row}, must be 1 (transitions plus exit probability)"
                ));
            }
            if renormalise {
                for x in &mut trans[i * w..(i + 1) * w] {
                    *x /= row;
                }
                exit[i] /= row;
            }
        }
        // Emissions
        let mut cholesky = Vec::with_capacity(n);
        let mut chol_packed = Vec::with_capacity(n);
        let mut chol_inv_diag = Vec::with_capacity(n);
        let mut log_norm = Vec::with_capacity(n);
        for i in 0..n {
            if mean_bias[i].len() != d {
                return bad(format!(
                    "mean of state {i} has length {}, expected {d}",
                    mean_bias[i].len()
                ));
            }
            if weights[i].nrows() != d || weights[i].ncols() != p {
                return bad(format!(
                    "W of state {i} is {}×{}, expected {d}×{p}",
                    weights[i].nrows(),
                    weights[i].ncols()
                ));
            }
            let c = &covariances[i];
            if c.nrows() != d || c.ncols() != d {
                return bad(format!(
                    "covariance of state {i} is {}×{}, expected {d}×{d}",
                    c.nrows(),
                    c.ncols()
                ));
            }
            check_finite_slice(&format!("mean of state {i}"), mean_bias[i].as_slice())?;
            check_finite_matrix(&format!("W of state {i}"), &weights[i])?;
            check_finite_matrix(&format!("covariance of state {i}"), c)?;
            for r in 0..d {
                for cc in 0..r {
                    let (a, b) = (c[(r, cc)], c[(cc, r)]);
                    if (a - b).abs() > 1e-9 * (1.0 + a.abs().max(b.abs())) {
                        return bad(format!(
                            "covariance of state {i} is not symmetric at ({r},{cc})"
                        ));
                    }
                }
            }
            let Some(l) = linalg::cholesky_lower(c) else {
                return bad(format!("covariance of state {i} is not positive definite"));
            };
            let mut packed = Vec::with_capacity(d * (d + 1) / 2);
            linalg::pack_lower(&l, &mut packed);
            chol_inv_diag.push((0..d).map(|k| 1.0 / l[(k, k)]).collect());
            log_norm.push(-linalg::half_log_det(&l) - d as f64 * HALF_LN_2PI);
            chol_packed.push(packed);
            cholesky.push(l);
        }
        let mut band_in = vec![0.0; n * w];
        let mut band_out = vec![0.0; n * w];
        for k in 0..w {
            for j in k..n {
                band_in[k * n + j] = trans[(j - k) * w + k];
                band_out[k * n + (j - k)] = trans[(j - k) * w + k];
            }
        }
        Ok(Phmm {
            n,
            d,
            p,
            j: max_jump,
            end_mode,
            covariance_kind,
            start,
            trans,
            exit,
            mean_bias,
            weights,
            theta_center,
            theta_scale,
            covariances,
            cholesky,
            chol_packed,
            chol_inv_diag,
            log_norm,
            band_in,
            band_out,
            training_thetas: Vec::new(),
        })
    }

    /// Attach the training θ (internal units), deduplicated.
    pub(crate) fn with_training_thetas(mut self, mut thetas: Vec<Vec<f64>>) -> Phmm {
        thetas.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
        thetas.dedup();
        self.training_thetas = thetas;
        self
    }

    /// The exact marginal model of the observation coordinates `dims` (in that order): the same
    /// π, A, exit and θ normalisation (and training θ, for multi-start), with every state's
    /// μ̄_i, W_i and Σ_i restricted to `dims`. The marginal of a Gaussian is the Gaussian of the
    /// sub-blocks, so the model gives the likelihood of the sub-sequence `x[:, dims]` with the
    /// other coordinates integrated out; EM on θ (SPEC §2.6) under it estimates θ from those
    /// coordinates only (for example the fingertip of an arm, whose posture otherwise carries
    /// the demonstrators' build into θ). Errors: `dims` empty, out of range or repeated.
    pub fn marginal(&self, dims: &[usize]) -> Result<Phmm, PhmmError> {
        let bad = |reason: String| {
            Err(PhmmError::InvalidParameter {
                name: "dims",
                reason,
            })
        };
        if dims.is_empty() {
            return bad("a marginal model needs at least one coordinate".into());
        }
        if let Some(&k) = dims.iter().find(|&&k| k >= self.d) {
            return bad(format!(
                "coordinate {k} is out of range: the observations are {}-D (0..{})",
                self.d, self.d
            ));
        }
        for (a, &k) in dims.iter().enumerate() {
            if dims[..a].contains(&k) {
                return bad(format!("coordinate {k} is listed twice"));
            }
        }
        let m = dims.len();
        let mean_bias = self
            .mean_bias
            .iter()
            .map(|b| DVector::from_fn(m, |r, _| b[dims[r]]))
            .collect();
        let weights = self
            .weights
            .iter()
            .map(|w| DMatrix::from_fn(m, self.p, |r, c| w[(dims[r], c)]))
            .collect();
        let covariances = self
            .covariances
            .iter()
            .map(|s| DMatrix::from_fn(m, m, |r, c| s[(dims[r], dims[c])]))
            .collect();
        self.with_outputs(mean_bias, weights, covariances)
    }

    /// This model with other means and covariances (transitions, exits and the rest kept).
    fn with_outputs(
        &self,
        mean_bias: Vec<DVector<f64>>,
        weights: Vec<DMatrix<f64>>,
        covariances: Vec<DMatrix<f64>>,
    ) -> Result<Phmm, PhmmError> {
        self.rebuilt(
            self.trans.clone(),
            self.exit.clone(),
            mean_bias,
            weights,
            covariances,
        )
    }

    /// This model with other transitions, exits, means and covariances (the rest, including
    /// the training θ, kept): the derived tables are recomputed and checked by `assemble`.
    fn rebuilt(
        &self,
        trans: Vec<f64>,
        exit: Vec<f64>,
        mean_bias: Vec<DVector<f64>>,
        weights: Vec<DMatrix<f64>>,
        covariances: Vec<DMatrix<f64>>,
    ) -> Result<Phmm, PhmmError> {
        let model = Phmm::assemble(
            false,
            self.j,
            self.end_mode,
            self.covariance_kind,
            self.start.clone(),
            trans,
            exit,
            mean_bias,
            weights,
            self.theta_center.clone(),
            self.theta_scale.clone(),
            covariances,
        )?;
        Ok(model.with_training_thetas(self.training_thetas.clone()))
    }

    /// The model of the observations scaled coordinate by coordinate: `y' = D y` with
    /// `D = diag(scale)`, so every state's mean `μ̄_i + W_i θ` becomes `D (μ̄_i + W_i θ)` and its
    /// covariance `D Σ_i D`; transitions, θ units and training θ are unchanged. This adapts a
    /// model to an actor who differs from the demonstrators by a known stretch of one axis (the
    /// height of the shoulder above the table, say). Errors: `scale` not of length d, or an entry
    /// that is not finite and positive.
    pub fn with_output_scale(&self, scale: &[f64]) -> Result<Phmm, PhmmError> {
        if scale.len() != self.d || !scale.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(PhmmError::InvalidParameter {
                name: "scale",
                reason: format!(
                    "needs {} finite, positive factors (one per observation coordinate), got {scale:?}",
                    self.d
                ),
            });
        }
        let mean_bias = self
            .mean_bias
            .iter()
            .map(|b| DVector::from_fn(self.d, |r, _| scale[r] * b[r]))
            .collect();
        let weights = self
            .weights
            .iter()
            .map(|w| DMatrix::from_fn(self.d, self.p, |r, c| scale[r] * w[(r, c)]))
            .collect();
        let covariances = self
            .covariances
            .iter()
            .map(|s| DMatrix::from_fn(self.d, self.d, |r, c| scale[r] * s[(r, c)] * scale[c]))
            .collect();
        self.with_outputs(mean_bias, weights, covariances)
    }

    /// The model with every state's covariance multiplied by `c` (means, transitions and θ
    /// unchanged): `c < 1` draws generated poses closer to the state means. Errors: `c` not
    /// finite and positive.
    pub fn with_covariance_scale(&self, c: f64) -> Result<Phmm, PhmmError> {
        if !(c.is_finite() && c > 0.0) {
            return Err(PhmmError::InvalidParameter {
                name: "c",
                reason: format!("must be finite and positive, got {c}"),
            });
        }
        let covariances = self.covariances.iter().map(|s| s * c).collect();
        self.with_outputs(self.mean_bias.clone(), self.weights.clone(), covariances)
    }

    /// The model with every self-transition capped at `max_stay`: a state i with
    /// `a_ii > max_stay` keeps `a_ii = max_stay` and its other transitions and exit scaled by
    /// `(1 − max_stay) / (1 − a_ii)`, so the order of the states, the relative odds of the jumps
    /// and everything else are unchanged and the expected dwell in any state is at most
    /// `1 / (1 − max_stay)` frames. A state that cannot be left (`a_ii = 1`) is unchanged.
    /// This is a tracking-time regulariser for models trained on demonstrators who pause for
    /// very different times (a drink held at the mouth for 10 or 100 frames): EM gives such a
    /// state the pooled, long geometric dwell, which a faster subject's track cannot leave in
    /// time. Errors: `max_stay` not in (0, 1].
    pub fn with_max_self_transition(&self, max_stay: f64) -> Result<Phmm, PhmmError> {
        self.cap_self_transitions(max_stay, self.n)
    }

    /// [`Phmm::with_max_self_transition`] for every state but the last, which keeps its
    /// trained dwell: the cap lets a track pass the pauses inside an action in time, while the
    /// final state, where the demonstrations end at rest, still holds the action until the
    /// motion that follows. Errors: `max_stay` not in (0, 1].
    pub fn with_max_self_transition_before_last(&self, max_stay: f64) -> Result<Phmm, PhmmError> {
        self.cap_self_transitions(max_stay, self.n.saturating_sub(1))
    }

    /// Caps the self-transitions of states `0..n_capped` (see [`Phmm::with_max_self_transition`]).
    fn cap_self_transitions(&self, max_stay: f64, n_capped: usize) -> Result<Phmm, PhmmError> {
        if !(max_stay > 0.0 && max_stay <= 1.0) {
            return Err(PhmmError::InvalidParameter {
                name: "max_stay",
                reason: format!("must be in (0, 1], got {max_stay}"),
            });
        }
        let w = self.j + 1;
        let mut trans = self.trans.clone();
        let mut exit = self.exit.clone();
        for i in 0..n_capped {
            let stay = trans[i * w];
            let leave: f64 = trans[i * w + 1..(i + 1) * w].iter().sum::<f64>() + exit[i];
            if stay > max_stay && leave > 0.0 {
                let scale = (1.0 - max_stay) / leave;
                trans[i * w] = max_stay;
                for k in 1..w {
                    trans[i * w + k] *= scale;
                }
                exit[i] *= scale;
            }
        }
        self.rebuilt(
            trans,
            exit,
            self.mean_bias.clone(),
            self.weights.clone(),
            self.covariances.clone(),
        )
    }

    /// Number of states N.
    pub fn n_states(&self) -> usize {
        self.n
    }

    /// Observation dimension d.
    pub fn dim(&self) -> usize {
        self.d
    }

    /// Dimension of θ (0 for a plain HMM).
    pub fn theta_dim(&self) -> usize {
        self.p
    }

    /// Maximum forward jump J (transitions go from i to i … i+J).
    pub fn max_jump(&self) -> usize {
        self.j
    }

    /// How sequences end.
    pub fn end_mode(&self) -> EndMode {
        self.end_mode
    }

    /// Covariance structure the model was built or trained with.
    pub fn covariance_kind(&self) -> CovarianceKind {
        self.covariance_kind
    }

    /// Initial probability π_i. Panics if `i ≥ n_states()`.
    pub fn start_prob(&self, i: usize) -> f64 {
        self.start[i]
    }

    /// Transition probability `a_ij` (0 outside the band). Panics if `i ≥ n_states()`.
    pub fn transition(&self, i: usize, j: usize) -> f64 {
        assert!(i < self.n && j < self.n, "state index out of range");
        if j >= i && j - i <= self.j {
            self.trans[i * (self.j + 1) + (j - i)]
        } else {
            0.0
        }
    }

    /// Exit probability `a_iE`. Panics if `i ≥ n_states()`.
    pub fn exit_prob(&self, i: usize) -> f64 {
        self.exit[i]
    }

    /// The mean `μ_i(θ) = μ̄_i + W_i θ`, θ in caller units.
    ///
    /// Panics if `i ≥ n_states()` or `theta.len() != theta_dim()`.
    pub fn mean(&self, i: usize, theta: &[f64]) -> DVector<f64> {
        let mut out = DVector::zeros(self.d);
        self.mean_into(i, theta, out.as_mut_slice());
        out
    }

    /// [`Phmm::mean`] into a caller buffer of length `dim()`, without allocating.
    ///
    /// Panics if `i ≥ n_states()`, `theta.len() != theta_dim()` or `out.len() != dim()`.
    pub fn mean_into(&self, i: usize, theta: &[f64], out: &mut [f64]) {
        assert_eq!(theta.len(), self.p, "θ has the wrong dimension");
        assert_eq!(out.len(), self.d, "output buffer has the wrong length");
        out.copy_from_slice(self.mean_bias[i].as_slice());
        let w = &self.weights[i];
        for k in 0..self.p {
            let t = (theta[k] - self.theta_center[k]) / self.theta_scale[k];
            for r in 0..self.d {
                out[r] += w[(r, k)] * t;
            }
        }
    }

    /// `(b, A)` with `μ_i(θ) = b + A θ` for θ in caller units (A is d × theta_dim).
    pub fn mean_affine(&self, i: usize) -> (DVector<f64>, DMatrix<f64>) {
        let mut a = self.weights[i].clone();
        for k in 0..self.p {
            let s = self.theta_scale[k];
            for r in 0..self.d {
                a[(r, k)] /= s;
            }
        }
        let c = DVector::from_row_slice(&self.theta_center);
        let b = &self.mean_bias[i] - &a * c;
        (b, a)
    }

    /// Covariance Σ_i. Panics if `i ≥ n_states()`.
    pub fn covariance(&self, i: usize) -> &DMatrix<f64> {
        &self.covariances[i]
    }

    /// Lower Cholesky factor L_i with `Σ_i = L_i L_iᵀ`. Panics if `i ≥ n_states()`.
    pub fn cov_cholesky(&self, i: usize) -> &DMatrix<f64> {
        &self.cholesky[i]
    }

    /// The θ normalisation the model uses internally: `θ_internal = (θ − centre) / scale`.
    /// Returned for inspection; every API takes θ in caller units.
    pub fn theta_normalisation(&self) -> (&[f64], &[f64]) {
        (&self.theta_center, &self.theta_scale)
    }

    /// Shortest sequence the model can generate (1 unless [`EndMode::MustEnd`]).
    pub fn min_sequence_len(&self) -> usize {
        if self.end_mode != EndMode::MustEnd {
            return 1;
        }
        let first = self.start.iter().position(|&p| p > 0.0).unwrap_or(0);
        (self.n - 1 - first).div_ceil(self.j.max(1)) + 1
    }

    /// θ in internal units into `out` (length p).
    pub(crate) fn theta_internal(&self, theta: &[f64], out: &mut [f64]) {
        for k in 0..self.p {
            out[k] = (theta[k] - self.theta_center[k]) / self.theta_scale[k];
        }
    }

    /// Mean of state i for an internal θ into `out`.
    pub(crate) fn mean_internal_into(&self, i: usize, theta_int: &[f64], out: &mut [f64]) {
        out.copy_from_slice(self.mean_bias[i].as_slice());
        let w = &self.weights[i];
        for k in 0..self.p {
            let t = theta_int[k];
            for r in 0..self.d {
                out[r] += w[(r, k)] * t;
            }
        }
    }
}

fn is_diagonal(m: &DMatrix<f64>) -> bool {
    (0..m.nrows()).all(|r| (0..m.ncols()).all(|c| r == c || m[(r, c)] == 0.0))
}
