//! Estimating θ of an unseen sequence by EM (SPEC §2.6), its MAP variant, and recognition by
//! comparing actions' likelihoods at their estimated θ.

use nalgebra::{DMatrix, DVector};

use crate::PhmmError;
use crate::inference::{Workspace, check_sequence, check_theta};
use crate::linalg::{cholesky_lower, solve_lower_in_place, solve_upper_t_in_place};
use crate::model::Phmm;

/// Options of θ estimation. `Default`: start at the training mean, 50 iterations, tolerance 1e-6,
/// no prior, single start.
#[derive(Clone, Debug, PartialEq)]
pub struct ThetaEmOptions {
    /// Starting value θ^(0) in caller units; `None` = mean of the training θ.
    pub init: Option<DVector<f64>>,
    /// Maximum number of EM iterations.
    pub max_iterations: usize,
    /// Stop when ‖Δθ‖ (internal, normalised units) or the per-frame log-likelihood change falls
    /// below this.
    pub tolerance: f64,
    /// Gaussian prior `θ ~ N(θ_0, Λ_0)` in caller units for the MAP variant (partial sequences).
    pub prior: Option<(DVector<f64>, DMatrix<f64>)>,
    /// Also start from every distinct training θ and keep the best final objective.
    pub multi_start: bool,
    /// A box `(lower, upper)` in caller units that θ is confined to: each M-step maximises
    /// the EM objective over the box (exactly, by projected coordinate ascent on its concave
    /// quadratic), so the estimate stays in the region a model supports even when the
    /// sequence (a movement seen only in part) pulls it outside. `None`: unconstrained.
    pub bounds: Option<(DVector<f64>, DVector<f64>)>,
}

impl Default for ThetaEmOptions {
    fn default() -> Self {
        ThetaEmOptions {
            init: None,
            max_iterations: 50,
            tolerance: 1e-6,
            prior: None,
            multi_start: false,
            bounds: None,
        }
    }
}

/// Result of θ estimation.
#[derive(Clone, Debug, PartialEq)]
pub struct ThetaEstimate {
    /// The estimate, caller units.
    pub theta: DVector<f64>,
    /// log P(X | θ̂) (the likelihood, also under the MAP variant).
    pub log_likelihood: f64,
    /// EM iterations (M-steps) of the run that produced the estimate.
    pub iterations: usize,
    /// log P(X | θ^(n)) at every E-step of that run (non-decreasing for the ML variant).
    pub history: Vec<f64>,
}

/// Per-model precomputation: `V_i = L_i⁻¹ W_i` (d × p, column-major in a flat Vec).
/// One θ-EM run: (θ internal, log-likelihood, objective, iterations, history).
type RunResult = (Vec<f64>, f64, f64, usize, Vec<f64>);
/// A Gaussian prior on the internal θ: its mean and covariance.
type InternalPrior = (DVector<f64>, DMatrix<f64>);
/// A box on the internal θ: lower and upper bounds per component.
type InternalBox = (Vec<f64>, Vec<f64>);

struct ThetaKernel {
    v: Vec<f64>,
}

impl ThetaKernel {
    fn new(model: &Phmm) -> Self {
        let (d, p) = (model.d, model.p);
        let mut v = vec![0.0; model.n * d * p];
        let mut col = vec![0.0; d];
        for i in 0..model.n {
            for k in 0..p {
                for r in 0..d {
                    col[r] = model.weights[i][(r, k)];
                }
                solve_lower_in_place(&model.cholesky[i], &mut col);
                v[(i * p + k) * d..(i * p + k + 1) * d].copy_from_slice(&col);
            }
        }
        ThetaKernel { v }
    }
}

impl Phmm {
    /// Estimate θ of a sequence by EM with the model held fixed (SPEC §2.6), in caller units.
    /// With `opts.prior`, the MAP variant. With `opts.multi_start`, also starts from each distinct
    /// training θ and keeps the best (log-likelihood, or log-posterior with a prior).
    pub fn estimate_theta(
        &self,
        x: &DMatrix<f64>,
        opts: &ThetaEmOptions,
    ) -> Result<ThetaEstimate, PhmmError> {
        check_sequence(self, x, 0)?;
        let p = self.p;
        if let Some(init) = &opts.init {
            check_theta(self, init.as_slice(), "initial theta")?;
        }
        if !(opts.tolerance.is_finite() && opts.tolerance >= 0.0) {
            return Err(PhmmError::InvalidParameter {
                name: "tolerance",
                reason: format!("{} is not a finite non-negative number", opts.tolerance),
            });
        }
        // Prior in internal units: θ_int = D⁻¹(θ − c) ⇒ mean D⁻¹(θ0 − c), cov D⁻¹ Λ D⁻¹.
        let prior = match &opts.prior {
            None => None,
            Some((m0, l0)) => {
                check_theta(self, m0.as_slice(), "prior mean")?;
                if l0.nrows() != p || l0.ncols() != p {
                    return Err(PhmmError::ThetaDimension {
                        what: "prior covariance (rows/columns)".into(),
                        expected: p,
                        got: l0.nrows(),
                    });
                }
                let mut mi = vec![0.0; p];
                self.theta_internal(m0.as_slice(), &mut mi);
                let mut li = l0.clone();
                for r in 0..p {
                    for c in 0..p {
                        li[(r, c)] /= self.theta_scale[r] * self.theta_scale[c];
                    }
                }
                if li.iter().any(|v| !v.is_finite()) || cholesky_lower(&li).is_none() {
                    return Err(PhmmError::InvalidParameter {
                        name: "prior",
                        reason: "the prior covariance must be finite, symmetric positive definite"
                            .into(),
                    });
                }
                Some((DVector::from_vec(mi), li))
            }
        };
        let bounds = match &opts.bounds {
            None => None,
            Some((lo, hi)) => {
                check_theta(self, lo.as_slice(), "lower θ bound")?;
                check_theta(self, hi.as_slice(), "upper θ bound")?;
                if let Some(k) = (0..p).find(|&k| lo[k] > hi[k]) {
                    return Err(PhmmError::InvalidParameter {
                        name: "bounds",
                        reason: format!(
                            "lower bound {} exceeds upper bound {} in θ component {k}",
                            lo[k], hi[k]
                        ),
                    });
                }
                let (mut li, mut hi_i) = (vec![0.0; p], vec![0.0; p]);
                self.theta_internal(lo.as_slice(), &mut li);
                self.theta_internal(hi.as_slice(), &mut hi_i);
                // A negative scale would swap the ends.
                let (l, h): (Vec<f64>, Vec<f64>) = li
                    .iter()
                    .zip(&hi_i)
                    .map(|(a, b)| (a.min(*b), a.max(*b)))
                    .unzip();
                Some((l, h))
            }
        };
        let mut starts: Vec<Vec<f64>> = Vec::new();
        match &opts.init {
            Some(t) => {
                let mut ti = vec![0.0; p];
                self.theta_internal(t.as_slice(), &mut ti);
                starts.push(ti);
            }
            None => starts.push(vec![0.0; p]),
        }
        if opts.multi_start && p > 0 {
            for t in &self.training_thetas {
                if !starts.contains(t) {
                    starts.push(t.clone());
                }
            }
        }
        if let Some((lo, hi)) = &bounds {
            for s in &mut starts {
                for k in 0..p {
                    s[k] = s[k].clamp(lo[k], hi[k]);
                }
            }
        }
        let kernel = ThetaKernel::new(self);
        let mut ws = Workspace::default();
        ws.load_sequence(x);
        let mut best: Option<(f64, RunResult)> = None;
        for s in starts {
            let run = self.theta_em_run(
                &mut ws,
                x.nrows(),
                &kernel,
                s,
                (prior.as_ref(), bounds.as_ref()),
                opts,
            )?;
            if best.as_ref().is_none_or(|b| run.2 > b.0) {
                best = Some((run.2, run));
            }
        }
        let Some((_, (th, ll, _, iterations, history))) = best else {
            return Err(PhmmError::Numerical("no θ start".into()));
        };
        let theta = DVector::from_iterator(
            p,
            (0..p).map(|k| th[k] * self.theta_scale[k] + self.theta_center[k]),
        );
        Ok(ThetaEstimate {
            theta,
            log_likelihood: ll,
            iterations,
            history,
        })
    }

    /// One EM run from an internal θ. Returns (θ, log-lik, objective, iterations, history).
    fn theta_em_run(
        &self,
        ws: &mut Workspace,
        t_len: usize,
        kernel: &ThetaKernel,
        mut theta: Vec<f64>,
        (prior, bounds): (Option<&InternalPrior>, Option<&InternalBox>),
        opts: &ThetaEmOptions,
    ) -> Result<RunResult, PhmmError> {
        let (n, d, p) = (self.n, self.d, self.p);
        let mut history = Vec::new();
        let mut iterations = 0;
        let mut r = vec![0.0; d];
        let log_prior = |th: &[f64]| -> f64 {
            prior.map_or(0.0, |(m0, l0)| {
                let mut diff: Vec<f64> = (0..p).map(|k| th[k] - m0[k]).collect();
                cholesky_lower(l0).map_or(0.0, |l| {
                    solve_lower_in_place(&l, &mut diff);
                    -0.5 * diff.iter().map(|v| v * v).sum::<f64>()
                })
            })
        };
        loop {
            ws.set_means(self, &theta);
            ws.emissions(self, t_len);
            let ll = ws.forward_backward(self, t_len, false);
            if !ll.is_finite() {
                return Err(PhmmError::ZeroLikelihood { index: 0 });
            }
            let obj = ll + log_prior(&theta);
            if let Some(&prev) = history.last() {
                let prev: f64 = prev;
                if ((ll - prev) / t_len as f64).abs() < opts.tolerance {
                    history.push(ll);
                    return Ok((theta, ll, obj, iterations, history));
                }
            }
            history.push(ll);
            if iterations >= opts.max_iterations || p == 0 {
                return Ok((theta, ll, obj, iterations, history));
            }
            // H = Σ_i Γ_i V_iᵀ V_i, g = Σ_i V_iᵀ L_i⁻¹ (Σ_t γ_t(i) x_t − Γ_i μ̄_i).
            let mut h = DMatrix::<f64>::zeros(p, p);
            let mut g = DVector::<f64>::zeros(p);
            for i in 0..n {
                let mut occ = 0.0;
                r.fill(0.0);
                for t in 0..t_len {
                    let gm = ws.gamma[t * n + i];
                    if gm == 0.0 {
                        continue;
                    }
                    occ += gm;
                    let xt = &ws.xrows[t * d..(t + 1) * d];
                    for k in 0..d {
                        r[k] += gm * xt[k];
                    }
                }
                if occ == 0.0 {
                    continue;
                }
                let mb = &self.mean_bias[i];
                for k in 0..d {
                    r[k] -= occ * mb[k];
                }
                solve_lower_in_place(&self.cholesky[i], &mut r);
                let v = &kernel.v[i * p * d..(i + 1) * p * d];
                for a in 0..p {
                    let va = &v[a * d..(a + 1) * d];
                    g[a] += va.iter().zip(&r).map(|(x, y)| x * y).sum::<f64>();
                    for b in 0..=a {
                        let vb = &v[b * d..(b + 1) * d];
                        let s = occ * va.iter().zip(vb).map(|(x, y)| x * y).sum::<f64>();
                        h[(a, b)] += s;
                        if a != b {
                            h[(b, a)] += s;
                        }
                    }
                }
            }
            let new_theta = match (prior, bounds) {
                (None, None) => solve_spd_or_ridge(&h, &g, &theta),
                (Some((m0, l0)), None) => {
                    // (Λ H + I) θ = Λ g + θ0  ⇔  θ = (H + Λ⁻¹)⁻¹ (g + Λ⁻¹ θ0), no inverse formed.
                    let a = l0 * &h + DMatrix::identity(p, p);
                    let rhs = l0 * &g + m0;
                    a.lu().solve(&rhs).map(|v| v.as_slice().to_vec())
                }
                (prior, Some((lo, hi))) => {
                    // Maximise gᵀθ − ½ θᵀHθ (plus the log prior) over the box.
                    let (mut hq, mut gq) = (h.clone(), g.clone());
                    if let Some((m0, l0)) = prior {
                        let Some(li) = l0.clone().try_inverse() else {
                            return Ok((theta, ll, obj, iterations, history));
                        };
                        gq += &li * m0;
                        hq += li;
                    }
                    Some(box_qp(&hq, &gq, &theta, lo, hi))
                }
            };
            let Some(new_theta) = new_theta.filter(|t| t.iter().all(|v| v.is_finite())) else {
                return Ok((theta, ll, obj, iterations, history));
            };
            let step: f64 = new_theta
                .iter()
                .zip(&theta)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            theta = new_theta;
            iterations += 1;
            if step < opts.tolerance {
                // Evaluate the final θ so the returned likelihood belongs to it.
                ws.set_means(self, &theta);
                ws.emissions(self, t_len);
                let ll = ws.forward_only(self, t_len);
                if !ll.is_finite() {
                    return Err(PhmmError::ZeroLikelihood { index: 0 });
                }
                history.push(ll);
                let obj = ll + log_prior(&theta);
                return Ok((theta, ll, obj, iterations, history));
            }
        }
    }
}

/// Maximises `gᵀθ − ½ θᵀHθ` (H symmetric positive semi-definite) over the box `[lo, hi]` by
/// projected coordinate ascent from `start` (inside the box): every coordinate step maximises
/// exactly along its axis, so the objective never decreases (a generalised EM step) and the
/// sweeps converge to the box optimum.
fn box_qp(h: &DMatrix<f64>, g: &DVector<f64>, start: &[f64], lo: &[f64], hi: &[f64]) -> Vec<f64> {
    let p = h.nrows();
    let mut t: Vec<f64> = (0..p).map(|k| start[k].clamp(lo[k], hi[k])).collect();
    for _ in 0..200 {
        let mut moved = 0.0f64;
        for k in 0..p {
            if h[(k, k)] <= 0.0 {
                continue;
            }
            let rest: f64 = (0..p).filter(|&j| j != k).map(|j| h[(k, j)] * t[j]).sum();
            let v = ((g[k] - rest) / h[(k, k)]).clamp(lo[k], hi[k]);
            moved = moved.max((v - t[k]).abs());
            t[k] = v;
        }
        if moved < 1e-12 {
            break;
        }
    }
    t
}

/// Solve `H θ = g` by Cholesky; if H is singular (W ≈ 0 for every visited state), add a tiny
/// ridge pulling towards the current θ; `None` if even that fails.
fn solve_spd_or_ridge(h: &DMatrix<f64>, g: &DVector<f64>, current: &[f64]) -> Option<Vec<f64>> {
    let p = h.nrows();
    let solve = |m: &DMatrix<f64>, rhs: &mut [f64]| -> bool {
        match cholesky_lower(m) {
            Some(l) => {
                solve_lower_in_place(&l, rhs);
                solve_upper_t_in_place(&l, rhs);
                true
            }
            None => false,
        }
    };
    let mut rhs = g.as_slice().to_vec();
    if solve(h, &mut rhs) {
        return Some(rhs);
    }
    let lam = 1e-9 * (h.trace() / p as f64).max(1e-12);
    let mut hr = h.clone();
    let mut rhs: Vec<f64> = (0..p).map(|k| g[k] + lam * current[k]).collect();
    for k in 0..p {
        hr[(k, k)] += lam;
    }
    solve(&hr, &mut rhs).then_some(rhs)
}

/// Recognition (SPEC §2.6): estimate θ under every model and return each estimate, in model
/// order; the recognised action is the one with the largest `log_likelihood` (add a log prior
/// if you have one). `opts.init` and `opts.prior` are used for models whose θ dimension matches
/// and ignored for plain HMMs (θ dimension 0).
pub fn recognise(
    models: &[&Phmm],
    x: &DMatrix<f64>,
    opts: &ThetaEmOptions,
) -> Result<Vec<ThetaEstimate>, PhmmError> {
    if models.is_empty() {
        return Err(PhmmError::Empty { what: "models" });
    }
    models
        .iter()
        .map(|m| {
            if m.theta_dim() == 0 {
                let o = ThetaEmOptions {
                    init: None,
                    prior: None,
                    bounds: None,
                    ..opts.clone()
                };
                m.estimate_theta(x, &o)
            } else {
                m.estimate_theta(x, opts)
            }
        })
        .collect()
}
