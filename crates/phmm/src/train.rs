//! Training: the validated parameter builder, uniform-segmentation initialisation (SPEC §1.4,
//! §2.5 I1) and multi-sequence Baum–Welch with the closed-form PHMM M-step (SPEC §1.3, §2.4) and
//! the safeguards of §1.7.
//!
//! The E-step runs in parallel over sequences (rayon). Each sequence produces its own sufficient
//! statistics; they are reduced afterwards in sequence order, so the fitted model is bitwise the
//! same whatever the number of threads.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use rayon::prelude::*;

use crate::PhmmError;
use crate::inference::{Workspace, check_sequence_shape, rows_into};
use crate::linalg::{cholesky_lower, cholesky_with_jitter, eigen_floor, symmetrise};
use crate::model::{CovarianceKind, EndMode, Phmm};

/// Default seed of the crate's random generators (sampling helpers, the `Hmm` wrapper).
pub const DEFAULT_SEED: u64 = 0x05EE_DAC7_u64;

/// Posteriors below this are left out of the mean/covariance sums (their contribution is below
/// 1e-13 of a frame's weight); they still count in the occupancies and transition counts.
const GAMMA_SKIP: f64 = 1e-13;

/// Training parameters, as a builder. Call [`PhmmParams::check`] to validate them.
///
/// ```
/// use actrack_phmm::{CovarianceKind, EndMode, PhmmParams};
/// let params = PhmmParams::new(12)
///     .max_jump(3)
///     .covariance(CovarianceKind::Full)
///     .end_mode(EndMode::MustEnd)
///     .max_iterations(50)
///     .tolerance(1e-4)
///     .cov_floor(0.005)
///     .check()
///     .unwrap();
/// assert_eq!(params.n_states(), 12);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PhmmParams {
    n_states: usize,
    max_jump: usize,
    covariance: CovarianceKind,
    end_mode: EndMode,
    max_iterations: usize,
    tolerance: f64,
    cov_floor: f64,
    min_occupancy: Option<f64>,
    transition_floor: f64,
    learn_start: bool,
    seed: u64,
}

/// Parameters that passed [`PhmmParams::check`]; the only way to train.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidPhmmParams(PhmmParams);

/// What a fit did.
#[derive(Clone, Debug, PartialEq)]
pub struct FitReport {
    /// Number of Baum–Welch iterations (M-steps) performed.
    pub iterations: usize,
    /// Total log-likelihood Σ_m log P(X^m) of the model before each M-step, and finally of the
    /// returned model (so `log_likelihoods.len() == iterations + 1`).
    pub log_likelihoods: Vec<f64>,
    /// Whether the per-frame change fell below the tolerance before `max_iterations`.
    pub converged: bool,
}

impl PhmmParams {
    /// Defaults: `max_jump = 3`, full covariance, [`EndMode::MustEnd`], 100 iterations,
    /// tolerance 1e-4 per frame, covariance floor σ_min = 0.005 (0.5 cm in metres), minimum
    /// occupancy d + 1 frames, no transition floor, π fixed, seed [`DEFAULT_SEED`].
    pub fn new(n_states: usize) -> Self {
        PhmmParams {
            n_states,
            max_jump: 3,
            covariance: CovarianceKind::Full,
            end_mode: EndMode::MustEnd,
            max_iterations: 100,
            tolerance: 1e-4,
            cov_floor: 0.005,
            min_occupancy: None,
            transition_floor: 0.0,
            learn_start: false,
            seed: DEFAULT_SEED,
        }
    }
    /// Maximum forward jump J (transitions i → i..=i+J).
    #[must_use]
    pub fn max_jump(mut self, j: usize) -> Self {
        self.max_jump = j;
        self
    }
    /// Full or diagonal covariances.
    #[must_use]
    pub fn covariance(mut self, kind: CovarianceKind) -> Self {
        self.covariance = kind;
        self
    }
    /// How sequences end.
    #[must_use]
    pub fn end_mode(mut self, mode: EndMode) -> Self {
        self.end_mode = mode;
        self
    }
    /// Maximum number of Baum–Welch iterations (0: return the initialisation).
    #[must_use]
    pub fn max_iterations(mut self, n: usize) -> Self {
        self.max_iterations = n;
        self
    }
    /// Stop when the per-frame change of the total log-likelihood is below this.
    #[must_use]
    pub fn tolerance(mut self, tol: f64) -> Self {
        self.tolerance = tol;
        self
    }
    /// Covariance floor σ_min (standard deviation, observation units): eigenvalues of every Σ_i
    /// are clamped to at least σ_min². 0 disables the floor.
    #[must_use]
    pub fn cov_floor(mut self, sigma_min: f64) -> Self {
        self.cov_floor = sigma_min;
        self
    }
    /// States with fewer expected frames than this keep their previous mean/W and covariance.
    /// Default: d + 1.
    #[must_use]
    pub fn min_occupancy(mut self, frames: f64) -> Self {
        self.min_occupancy = Some(frames);
        self
    }
    /// Optional transition floor inside the band (SPEC §1.7), 0 = off.
    #[must_use]
    pub fn transition_floor(mut self, floor: f64) -> Self {
        self.transition_floor = floor;
        self
    }
    /// Learn the initial distribution π (default: keep it fixed, π = e_1 after initialisation).
    #[must_use]
    pub fn learn_start(mut self, learn: bool) -> Self {
        self.learn_start = learn;
        self
    }
    /// Seed for randomised parts. The default initialisation (uniform segmentation) and
    /// Baum–Welch are deterministic, so a fit does not depend on it; it seeds
    /// [`crate::Hmm::sample_seeded`]-style helpers that take no RNG.
    #[must_use]
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Validate. Errors name the parameter and what to change.
    pub fn check(self) -> Result<ValidPhmmParams, PhmmError> {
        let err = |name, reason: String| Err(PhmmError::InvalidParameter { name, reason });
        if self.n_states == 0 {
            return err(
                "n_states",
                "must be at least 1: pass PhmmParams::new(n) with n ≥ 1".into(),
            );
        }
        if self.max_jump == 0 && self.n_states > 1 {
            return err(
                "max_jump",
                "must be at least 1 so the model can move forward".into(),
            );
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return err(
                "tolerance",
                format!("{} is not a finite non-negative number", self.tolerance),
            );
        }
        if !(self.cov_floor.is_finite() && self.cov_floor >= 0.0) {
            return err(
                "cov_floor",
                format!(
                    "{} is not a finite non-negative standard deviation (0 disables the floor)",
                    self.cov_floor
                ),
            );
        }
        if let Some(m) = self.min_occupancy
            && !(m.is_finite() && m >= 0.0)
        {
            return err(
                "min_occupancy",
                format!("{m} is not a finite non-negative frame count"),
            );
        }
        let max_floor = 1.0 / (self.max_jump as f64 + 2.0);
        if !(self.transition_floor.is_finite()
            && self.transition_floor >= 0.0
            && self.transition_floor < max_floor)
        {
            return err(
                "transition_floor",
                format!(
                    "{} must be in [0, {max_floor}) (typically 1e-8, or 0 to disable)",
                    self.transition_floor
                ),
            );
        }
        Ok(ValidPhmmParams(self))
    }
}

/// Everything about the training set, validated and converted once.
struct TrainingSet {
    /// Frame-major copies.
    rows: Vec<Vec<f64>>,
    /// Coordinate-major copies.
    cols: Vec<Vec<f64>>,
    lens: Vec<usize>,
    /// Internal (centred, scaled) θ per sequence, p each.
    thetas: Vec<Vec<f64>>,
    d: usize,
    p: usize,
    total_frames: usize,
}

/// Per-sequence sufficient statistics of one E-step.
struct SeqStats {
    log_p: f64,
    /// Γ^m_i.
    occ: Vec<f64>,
    /// γ_1(i).
    first: Vec<f64>,
    /// γ_T(i).
    last: Vec<f64>,
    /// Σ_t ξ_t(i, i+k), N × (J+1).
    xi: Vec<f64>,
    /// Σ_t γ_t(i) y_t, y = x_t − μ_i^old(θ_m); N × d.
    sum_y: Vec<f64>,
    /// Σ_t γ_t(i) y yᵀ, packed lower triangle per state; N × d(d+1)/2.
    outer: Vec<f64>,
}

impl ValidPhmmParams {
    /// Number of states.
    pub fn n_states(&self) -> usize {
        self.0.n_states
    }
    /// The seed.
    pub fn seed(&self) -> u64 {
        self.0.seed
    }
    /// The validated parameters.
    pub fn params(&self) -> &PhmmParams {
        &self.0
    }
    /// The fewest frames a training sequence may have: with [`EndMode::MustEnd`], the shortest
    /// path from the first state to the last with jumps of at most `max_jump`
    /// (⌈(N − 1) / J⌉ + 1 frames); 1 otherwise. [`ValidPhmmParams::fit`] refuses shorter
    /// sequences with [`PhmmError::SequenceTooShort`].
    pub fn min_sequence_len(&self) -> usize {
        if self.0.end_mode == EndMode::MustEnd {
            (self.0.n_states - 1).div_ceil(self.0.max_jump.max(1)) + 1
        } else {
            1
        }
    }

    /// Train a model on sequences (each T_m × d, one row per frame) with one θ per sequence in the
    /// caller's units (pass an empty slice for a plain HMM). Initialisation: uniform segmentation
    /// and the normal equations (SPEC §1.4, §2.5 I1); then Baum–Welch.
    pub fn fit(
        &self,
        seqs: &[DMatrix<f64>],
        thetas: &[DVector<f64>],
    ) -> Result<(Phmm, FitReport), PhmmError> {
        let (set, centre, scale) = self.training_set(seqs, thetas, None)?;
        let init = self.initialise(&set, centre, scale)?;
        self.baum_welch(init, &set)
    }

    /// Baum–Welch from a given initial model (its topology, end mode, θ normalisation and, with
    /// `learn_start(false)`, π are kept). The builder's `n_states`, `max_jump`, `covariance` and
    /// `end_mode` are ignored in favour of the model's; iterations, tolerance, floors and
    /// occupancy apply.
    pub fn fit_from(
        &self,
        init: &Phmm,
        seqs: &[DMatrix<f64>],
        thetas: &[DVector<f64>],
    ) -> Result<(Phmm, FitReport), PhmmError> {
        let (set, _, _) = self.training_set(seqs, thetas, Some(init))?;
        self.baum_welch(init.clone(), &set)
    }

    fn min_occ(&self, d: usize) -> f64 {
        self.0.min_occupancy.unwrap_or(d as f64 + 1.0)
    }

    /// Validate the input and convert it. With `model`, θ uses the model's normalisation;
    /// otherwise the centre/scale are computed (training mean and standard deviation).
    fn training_set(
        &self,
        seqs: &[DMatrix<f64>],
        thetas: &[DVector<f64>],
        model: Option<&Phmm>,
    ) -> Result<(TrainingSet, Vec<f64>, Vec<f64>), PhmmError> {
        if seqs.is_empty() {
            return Err(PhmmError::Empty { what: "sequences" });
        }
        if !thetas.is_empty() && thetas.len() != seqs.len() {
            return Err(PhmmError::ThetaCount {
                sequences: seqs.len(),
                thetas: thetas.len(),
            });
        }
        let p = thetas.first().map_or(0, DVector::len);
        let d = model.map_or(seqs[0].ncols(), |m| m.d);
        let (n, j) = match model {
            Some(m) => (m.n, m.j),
            None => (self.0.n_states, self.0.max_jump),
        };
        if let Some(m) = model
            && m.p != p
        {
            return Err(PhmmError::ThetaDimension {
                what: "theta of sequence 0".into(),
                expected: m.p,
                got: p,
            });
        }
        let min_len = model.map_or_else(|| self.min_sequence_len(), Phmm::min_sequence_len);
        for (index, x) in seqs.iter().enumerate() {
            check_sequence_shape(x, index, d, min_len, n, j)?;
        }
        for (index, t) in thetas.iter().enumerate() {
            if t.len() != p {
                return Err(PhmmError::ThetaDimension {
                    what: format!("theta of sequence {index}"),
                    expected: p,
                    got: t.len(),
                });
            }
            if let Some((k, &v)) = t.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(PhmmError::NonFinite {
                    what: format!("theta of sequence {index}"),
                    row: 0,
                    col: k,
                    value: v,
                });
            }
        }
        let (centre, scale) = match model {
            Some(m) => (m.theta_center.clone(), m.theta_scale.clone()),
            None => theta_normalisation(thetas, p)?,
        };
        if p > 0 {
            check_theta_rank(thetas, p, &centre)?;
        }
        let mut rows = Vec::with_capacity(seqs.len());
        for x in seqs {
            let mut r = Vec::new();
            rows_into(x, &mut r);
            rows.push(r);
        }
        let cols = seqs.iter().map(|x| x.as_slice().to_vec()).collect();
        let thetas_int = thetas
            .iter()
            .map(|t| (0..p).map(|k| (t[k] - centre[k]) / scale[k]).collect())
            .collect::<Vec<Vec<f64>>>();
        let lens: Vec<usize> = seqs.iter().map(DMatrix::nrows).collect();
        let total_frames = lens.iter().sum();
        let thetas_int = if p == 0 {
            vec![Vec::new(); seqs.len()]
        } else {
            thetas_int
        };
        Ok((
            TrainingSet {
                rows,
                cols,
                lens,
                thetas: thetas_int,
                d,
                p,
                total_frames,
            },
            centre,
            scale,
        ))
    }

    /// Uniform segmentation (SPEC §1.4) + normal equations (§2.5 I1).
    fn initialise(
        &self,
        set: &TrainingSet,
        centre: Vec<f64>,
        scale: Vec<f64>,
    ) -> Result<Phmm, PhmmError> {
        let prm = &self.0;
        let (n, d, p, jmax) = (prm.n_states, set.d, set.p, prm.max_jump);
        let q = p + 1;
        // Hard γ: frame t of sequence m → state ⌊t·N/T_m⌋.
        let assign = |t: usize, len: usize| t * n / len;
        // Per state: G (q×q), B (d×q), Γ.
        let mut g = vec![DMatrix::<f64>::zeros(q, q); n];
        let mut b = vec![DMatrix::<f64>::zeros(d, q); n];
        let mut occ = vec![0.0; n];
        for (m, x) in set.rows.iter().enumerate() {
            let len = set.lens[m];
            let omega = omega_of(&set.thetas[m]);
            for t in 0..len {
                let i = assign(t, len);
                occ[i] += 1.0;
                for r in 0..q {
                    for c in 0..q {
                        g[i][(r, c)] += omega[r] * omega[c];
                    }
                    for k in 0..d {
                        b[i][(k, r)] += x[t * d + k] * omega[r];
                    }
                }
            }
        }
        // States without frames (N > some T_m does not cause this, but N > every T_m can)
        // borrow the statistics of the nearest state that has frames.
        let donor = |i: usize| -> usize {
            (0..n)
                .filter(|&k| occ[k] > 0.0)
                .min_by_key(|&k| k.abs_diff(i))
                .unwrap_or(i)
        };
        let mut z: Vec<DMatrix<f64>> = Vec::with_capacity(n);
        for i in 0..n {
            let s = if occ[i] > 0.0 { i } else { donor(i) };
            z.push(solve_normal_equations(&g[s], &b[s]).ok_or_else(|| {
                PhmmError::Numerical(format!(
                    "initial normal equations of state {i} are singular"
                ))
            })?);
        }
        // Residual covariances from the hard assignment; pooled covariance for sparse states.
        let mut cov = vec![DMatrix::<f64>::zeros(d, d); n];
        let mut pooled = DMatrix::<f64>::zeros(d, d);
        let mut mu = vec![0.0; d];
        for (m, x) in set.rows.iter().enumerate() {
            let len = set.lens[m];
            let omega = omega_of(&set.thetas[m]);
            for t in 0..len {
                let i = assign(t, len);
                for k in 0..d {
                    mu[k] = (0..q).map(|c| z[i][(k, c)] * omega[c]).sum();
                }
                for r in 0..d {
                    let yr = x[t * d + r] - mu[r];
                    for c in 0..=r {
                        let v = yr * (x[t * d + c] - mu[c]);
                        cov[i][(r, c)] += v;
                        pooled[(r, c)] += v;
                    }
                }
            }
        }
        let total = set.total_frames as f64;
        fill_upper(&mut pooled);
        pooled /= total;
        let min_occ = self.min_occ(d).max(1.0);
        for i in 0..n {
            if occ[i] >= min_occ && occ[i] > 1.0 {
                fill_upper(&mut cov[i]);
                cov[i] /= occ[i];
            } else {
                cov[i].copy_from(&pooled);
            }
        }
        let global_scale = pooled.trace() / d as f64;
        let covs = cov
            .into_iter()
            .enumerate()
            .map(|(i, c)| self.regularise(c, prm.covariance, global_scale, i))
            .collect::<Result<Vec<_>, _>>()?;
        // Transitions (SPEC §1.4 step 3).
        let mean_len = set.lens.iter().sum::<usize>() as f64 / set.lens.len() as f64;
        let dbar = mean_len / n as f64;
        let stay = (1.0 - 1.0 / dbar).clamp(0.5, 0.95);
        let exit_last = (1.0 / dbar).clamp(0.05, 0.5);
        let jump_w: Vec<f64> = (1..=jmax)
            .map(|k| match k {
                1 => 0.80,
                2 => 0.15,
                3 => 0.05,
                _ => 0.05 * 0.25f64.powi(k as i32 - 3),
            })
            .collect();
        let w = jmax + 1;
        let mut trans = vec![0.0; n * w];
        let mut exit = vec![0.0; n];
        for i in 0..n {
            let row = &mut trans[i * w..(i + 1) * w];
            if i + 1 == n {
                if prm.end_mode == EndMode::None {
                    row[0] = 1.0;
                } else {
                    exit[i] = exit_last;
                    row[0] = 1.0 - exit_last;
                }
                continue;
            }
            let avail = jmax.min(n - 1 - i);
            let tot: f64 = jump_w[..avail].iter().sum();
            row[0] = stay;
            for k in 1..=avail {
                row[k] = (1.0 - stay) * jump_w[k - 1] / tot;
            }
            if prm.end_mode == EndMode::Free {
                // A small initial exit from every state (zeros would stay zero under Baum–Welch).
                exit[i] = 0.01;
                for v in row.iter_mut() {
                    *v *= 0.99;
                }
            }
        }
        let mut start = vec![0.0; n];
        start[0] = 1.0;
        let mean_bias = z.iter().map(|zi| zi.column(p).into_owned()).collect();
        let weights = z.iter().map(|zi| zi.columns(0, p).into_owned()).collect();
        let model = Phmm::assemble(
            true,
            jmax,
            prm.end_mode,
            prm.covariance,
            start,
            trans,
            exit,
            mean_bias,
            weights,
            centre,
            scale,
            covs,
        )?;
        Ok(model.with_training_thetas(set.thetas.clone()))
    }

    /// Diagonal restriction, eigenvalue floor, then a Cholesky check with jitter retries.
    fn regularise(
        &self,
        mut c: DMatrix<f64>,
        kind: CovarianceKind,
        global_scale: f64,
        state: usize,
    ) -> Result<DMatrix<f64>, PhmmError> {
        symmetrise(&mut c);
        if kind == CovarianceKind::Diagonal {
            let dg = c.diagonal();
            c = DMatrix::from_diagonal(&dg);
        }
        let floor = self.0.cov_floor * self.0.cov_floor;
        if floor > 0.0 {
            c = eigen_floor(&c, floor);
        }
        let eps = 1e-3 * global_scale.max(floor);
        cholesky_with_jitter(&c, eps)
            .map(|(cj, _)| cj)
            .ok_or(PhmmError::NotPositiveDefinite {
                state,
                retries: crate::linalg::CHOLESKY_RETRIES,
            })
    }

    /// E-step over all sequences (parallel), statistics in sequence order.
    fn e_step(model: &Phmm, set: &TrainingSet) -> Result<Vec<SeqStats>, PhmmError> {
        let results: Vec<Result<SeqStats, PhmmError>> = (0..set.rows.len())
            .into_par_iter()
            .map_init(Workspace::default, |ws, m| seq_stats(model, set, m, ws))
            .collect();
        results.into_iter().collect()
    }

    /// Σ_m log P(X^m) by forward passes (parallel, summed in sequence order).
    fn total_log_likelihood(model: &Phmm, set: &TrainingSet) -> Result<f64, PhmmError> {
        let lps: Vec<f64> = (0..set.rows.len())
            .into_par_iter()
            .map_init(Workspace::default, |ws, m| {
                ws.xcols.clear();
                ws.xcols.extend_from_slice(&set.cols[m]);
                ws.set_means(model, &set.thetas[m]);
                ws.emissions(model, set.lens[m]);
                ws.forward_only(model, set.lens[m])
            })
            .collect();
        let mut total = 0.0;
        for (index, lp) in lps.into_iter().enumerate() {
            if !lp.is_finite() {
                return Err(PhmmError::ZeroLikelihood { index });
            }
            total += lp;
        }
        Ok(total)
    }

    fn baum_welch(
        &self,
        mut model: Phmm,
        set: &TrainingSet,
    ) -> Result<(Phmm, FitReport), PhmmError> {
        let prm = &self.0;
        let mut lls = Vec::new();
        let mut converged = false;
        let mut iterations = 0;
        let global_scale =
            model.covariances.iter().map(DMatrix::trace).sum::<f64>() / (model.n * model.d) as f64;
        loop {
            // After the last M-step only the likelihood is needed: forward passes only.
            let (ll, stats) = if iterations >= prm.max_iterations {
                (Self::total_log_likelihood(&model, set)?, None)
            } else {
                let stats = Self::e_step(&model, set)?;
                (stats.iter().map(|s| s.log_p).sum(), Some(stats))
            };
            if let Some(&prev) = lls.last() {
                let change: f64 = (ll - prev) / set.total_frames as f64;
                if change.abs() < prm.tolerance {
                    lls.push(ll);
                    converged = true;
                    break;
                }
            }
            lls.push(ll);
            let Some(stats) = stats else {
                break;
            };
            model = self.m_step(&model, set, &stats, global_scale)?;
            iterations += 1;
        }
        Ok((
            model,
            FitReport {
                iterations,
                log_likelihoods: lls,
                converged,
            },
        ))
    }

    fn m_step(
        &self,
        old: &Phmm,
        set: &TrainingSet,
        stats: &[SeqStats],
        global_scale: f64,
    ) -> Result<Phmm, PhmmError> {
        let prm = &self.0;
        let (n, d, p, w) = (old.n, old.d, old.p, old.j + 1);
        let q = p + 1;
        let tri = d * (d + 1) / 2;
        // Ordered reduction.
        let mut occ = vec![0.0; n];
        let mut first = vec![0.0; n];
        let mut last = vec![0.0; n];
        let mut xi = vec![0.0; n * w];
        let mut outer = vec![0.0; n * tri];
        for s in stats {
            add_into(&mut occ, &s.occ);
            add_into(&mut first, &s.first);
            add_into(&mut last, &s.last);
            add_into(&mut xi, &s.xi);
            add_into(&mut outer, &s.outer);
        }
        // π
        let start = if prm.learn_start {
            let tot: f64 = first.iter().sum();
            first.iter().map(|v| v / tot).collect()
        } else {
            old.start.clone()
        };
        // A, a_E
        let mut trans = old.trans.clone();
        let mut exit = old.exit.clone();
        for i in 0..n {
            let row = &xi[i * w..(i + 1) * w];
            let e = if old.end_mode == EndMode::None {
                0.0
            } else {
                last[i]
            };
            let denom: f64 = row.iter().sum::<f64>() + e;
            if denom > 0.0 && denom.is_finite() {
                for k in 0..w {
                    trans[i * w + k] = row[k] / denom;
                }
                exit[i] = e / denom;
            }
            if prm.transition_floor > 0.0 {
                let kmax = w.min(n - i);
                let row = &mut trans[i * w..i * w + kmax];
                for v in row.iter_mut() {
                    *v = v.max(prm.transition_floor);
                }
                let tot: f64 = row.iter().sum::<f64>() + exit[i];
                for v in row.iter_mut() {
                    *v /= tot;
                }
                exit[i] /= tot;
            }
            if old.end_mode == EndMode::MustEnd && i + 1 < n {
                exit[i] = 0.0;
            }
        }
        // Means / Z and covariances.
        let min_occ = self.min_occ(d);
        let mut mean_bias = old.mean_bias.clone();
        let mut weights = old.weights.clone();
        let mut covs = old.covariances.clone();
        let mut mu_old = vec![0.0; d];
        let mut delta = vec![0.0; d];
        for i in 0..n {
            if !(occ[i] >= min_occ && occ[i] > 0.0) {
                continue;
            }
            // Normal equations in terms of s^m_i = sum_y + Γ^m_i μ_old,m.
            let mut g = DMatrix::<f64>::zeros(q, q);
            let mut b = DMatrix::<f64>::zeros(d, q);
            for (m, s) in stats.iter().enumerate() {
                let gm = s.occ[i];
                if gm == 0.0 {
                    continue;
                }
                let omega = omega_of(&set.thetas[m]);
                old.mean_internal_into(i, &set.thetas[m], &mut mu_old);
                let sy = &s.sum_y[i * d..(i + 1) * d];
                for r in 0..q {
                    for c in 0..q {
                        g[(r, c)] += gm * omega[r] * omega[c];
                    }
                    for k in 0..d {
                        b[(k, r)] += (sy[k] + gm * mu_old[k]) * omega[r];
                    }
                }
            }
            let Some(z) = solve_normal_equations(&g, &b) else {
                continue;
            };
            // Γ_i Σ_i = Σ_m [S_m − s'_m δ_mᵀ − δ_m s'_mᵀ + Γ^m δ_m δ_mᵀ], with S pooled.
            let mut c = DMatrix::<f64>::zeros(d, d);
            let packed = &outer[i * tri..(i + 1) * tri];
            let mut off = 0;
            for r in 0..d {
                for cc in 0..=r {
                    c[(r, cc)] = packed[off];
                    off += 1;
                }
            }
            for (m, s) in stats.iter().enumerate() {
                let gm = s.occ[i];
                if gm == 0.0 {
                    continue;
                }
                let omega = omega_of(&set.thetas[m]);
                old.mean_internal_into(i, &set.thetas[m], &mut mu_old);
                for k in 0..d {
                    delta[k] = (0..q).map(|cc| z[(k, cc)] * omega[cc]).sum::<f64>() - mu_old[k];
                }
                let sy = &s.sum_y[i * d..(i + 1) * d];
                for r in 0..d {
                    for cc in 0..=r {
                        c[(r, cc)] +=
                            gm * delta[r] * delta[cc] - sy[r] * delta[cc] - delta[r] * sy[cc];
                    }
                }
            }
            fill_upper(&mut c);
            c /= occ[i];
            let Ok(c) = self.regularise(c, old.covariance_kind, global_scale, i) else {
                // Keep the previous state parameters rather than produce a broken model.
                continue;
            };
            mean_bias[i] = z.column(p).into_owned();
            weights[i] = z.columns(0, p).into_owned();
            covs[i] = c;
        }
        let model = Phmm::assemble(
            false,
            old.j,
            old.end_mode,
            old.covariance_kind,
            start,
            trans,
            exit,
            mean_bias,
            weights,
            old.theta_center.clone(),
            old.theta_scale.clone(),
            covs,
        )
        .map_err(|e| PhmmError::Numerical(format!("M-step produced an invalid model: {e}")))?;
        Ok(model.with_training_thetas(old.training_thetas.clone()))
    }
}

/// E-step statistics of one sequence.
fn seq_stats(
    model: &Phmm,
    set: &TrainingSet,
    m: usize,
    ws: &mut Workspace,
) -> Result<SeqStats, PhmmError> {
    let (n, d) = (model.n, model.d);
    let tri = d * (d + 1) / 2;
    let t_len = set.lens[m];
    ws.xrows.clear();
    ws.xrows.extend_from_slice(&set.rows[m]);
    ws.xcols.clear();
    ws.xcols.extend_from_slice(&set.cols[m]);
    ws.set_means(model, &set.thetas[m]);
    ws.emissions(model, t_len);
    let log_p = ws.forward_backward(model, t_len, true);
    if !log_p.is_finite() {
        return Err(PhmmError::ZeroLikelihood { index: m });
    }
    let mut st = SeqStats {
        log_p,
        occ: vec![0.0; n],
        first: ws.gamma[..n].to_vec(),
        last: ws.gamma[(t_len - 1) * n..t_len * n].to_vec(),
        xi: ws.xi.clone(),
        sum_y: vec![0.0; n * d],
        outer: vec![0.0; n * tri],
    };
    accumulate(ws, &mut st, n, d, t_len);
    Ok(st)
}

/// Σ_t γ_t(i) y and Σ_t γ_t(i) y yᵀ with y = x_t − μ_i (packed lower triangle).
#[inline(never)]
fn accumulate(ws: &Workspace, st: &mut SeqStats, n: usize, d: usize, t_len: usize) {
    let tri = d * (d + 1) / 2;
    let mut y = vec![0.0; d];
    for t in 0..t_len {
        let x = &ws.xrows[t * d..(t + 1) * d];
        for i in 0..n {
            let g = ws.gamma[t * n + i];
            st.occ[i] += g;
            if g < GAMMA_SKIP {
                continue;
            }
            let mu = &ws.means[i * d..(i + 1) * d];
            for k in 0..d {
                y[k] = x[k] - mu[k];
            }
            let sy = &mut st.sum_y[i * d..(i + 1) * d];
            for k in 0..d {
                sy[k] += g * y[k];
            }
            let o = &mut st.outer[i * tri..(i + 1) * tri];
            let mut off = 0;
            for r in 0..d {
                let gy = g * y[r];
                let row = &mut o[off..=off + r];
                for (c, v) in row.iter_mut().enumerate() {
                    *v += gy * y[c];
                }
                off += r + 1;
            }
        }
    }
}

fn add_into(acc: &mut [f64], v: &[f64]) {
    for (a, b) in acc.iter_mut().zip(v) {
        *a += b;
    }
}

fn fill_upper(m: &mut DMatrix<f64>) {
    let d = m.nrows();
    for r in 0..d {
        for c in 0..r {
            m[(c, r)] = m[(r, c)];
        }
    }
}

/// Ω(θ) = [θ; 1].
fn omega_of(theta: &[f64]) -> Vec<f64> {
    let mut o = theta.to_vec();
    o.push(1.0);
    o
}

/// Solve `Z (G + R) = B` with the ridge R = diag(λ_W, …, λ_W, 0) on W only (SPEC §2.4), by
/// Cholesky; R = 0 when G is well conditioned. `None` if the system is singular even with the ridge.
pub(crate) fn solve_normal_equations(g: &DMatrix<f64>, b: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let q = g.nrows();
    // λ_W = 0 when G is well conditioned (the pivot ratio of its Cholesky factor is a cheap
    // proxy), else λ_W = 1e-6·tr(G)/(p+1) on the W block only.
    let well_conditioned = cholesky_lower(g).filter(|l| {
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for k in 0..q {
            lo = lo.min(l[(k, k)]);
            hi = hi.max(l[(k, k)]);
        }
        lo * lo >= 1e-8 * hi * hi
    });
    // (G+R) Zᵀ = Bᵀ, G symmetric.
    let l = if let Some(l) = well_conditioned {
        l
    } else {
        let mut gr = g.clone();
        let lam = 1e-6 * g.trace() / q as f64;
        for k in 0..q - 1 {
            gr[(k, k)] += lam;
        }
        cholesky_lower(&gr)?
    };
    let mut zt = b.transpose();
    for c in 0..zt.ncols() {
        let mut col: Vec<f64> = zt.column(c).iter().copied().collect();
        crate::linalg::solve_lower_in_place(&l, &mut col);
        crate::linalg::solve_upper_t_in_place(&l, &mut col);
        for r in 0..q {
            zt[(r, c)] = col[r];
        }
    }
    Some(zt.transpose())
}

/// Centre = mean of the training θ, scale = their standard deviation per component.
fn theta_normalisation(
    thetas: &[DVector<f64>],
    p: usize,
) -> Result<(Vec<f64>, Vec<f64>), PhmmError> {
    if p == 0 {
        return Ok((Vec::new(), Vec::new()));
    }
    let s = thetas.len() as f64;
    let mut centre = vec![0.0; p];
    for t in thetas {
        for k in 0..p {
            centre[k] += t[k] / s;
        }
    }
    let mut scale = vec![0.0; p];
    for t in thetas {
        for k in 0..p {
            scale[k] += (t[k] - centre[k]).powi(2) / s;
        }
    }
    for (k, v) in scale.iter_mut().enumerate() {
        *v = v.sqrt();
        if !(*v > 0.0) {
            return Err(PhmmError::ThetaRankDeficient {
                rank: k.min(p - 1),
                theta_dim: p,
                needed: p + 1,
            });
        }
    }
    Ok((centre, scale))
}

/// The training θ must span a p-dimensional affine space (p + 1 affinely independent values).
fn check_theta_rank(thetas: &[DVector<f64>], p: usize, centre: &[f64]) -> Result<(), PhmmError> {
    let mut c = DMatrix::<f64>::zeros(p, p);
    let mut scale = vec![0.0f64; p];
    for t in thetas {
        for k in 0..p {
            scale[k] = scale[k].max((t[k] - centre[k]).abs());
        }
    }
    for t in thetas {
        for r in 0..p {
            for cc in 0..p {
                let a = (t[r] - centre[r]) / scale[r].max(f64::MIN_POSITIVE);
                let b = (t[cc] - centre[cc]) / scale[cc].max(f64::MIN_POSITIVE);
                c[(r, cc)] += a * b;
            }
        }
    }
    let eig = SymmetricEigen::new(c);
    let lmax = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let rank = eig
        .eigenvalues
        .iter()
        .filter(|&&l| lmax > 0.0 && l > 1e-10 * lmax)
        .count();
    if rank < p {
        return Err(PhmmError::ThetaRankDeficient {
            rank,
            theta_dim: p,
            needed: p + 1,
        });
    }
    Ok(())
}
