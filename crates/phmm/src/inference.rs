//! Inference kernels (SPEC §1.2, §1.5): emission log-densities, the max-shift scaled
//! forward–backward with a log-space fallback, and Viterbi.
//!
//! All kernels work on flat, frame-major buffers held in a reusable [`Workspace`], so a
//! Baum–Welch iteration allocates per sequence at most once (when a buffer grows), never per
//! frame. Only the `J + 1` band entries of each transition row are ever touched.

use nalgebra::{DMatrix, DVector};

use crate::PhmmError;
use crate::linalg::mahalanobis_packed;
use crate::model::{EndMode, Phmm};

/// Scaled recursions give up (and the log-space version takes over) below this normaliser.
const TINY: f64 = 1e-280;
/// … or above this backward value.
const HUGE: f64 = 1e280;

/// Reusable scratch buffers for one sequence at a time.
#[derive(Default, Debug)]
pub(crate) struct Workspace {
    /// The sequence, frame-major (T × d).
    pub xrows: Vec<f64>,
    /// The sequence, coordinate-major (d × T; nalgebra's storage of a T × d matrix).
    pub xcols: Vec<f64>,
    /// Whitened residuals of one state, coordinate-major (d × T), and their squared norms (T).
    zcols: Vec<f64>,
    acc: Vec<f64>,
    /// State means for the current θ (N × d).
    pub means: Vec<f64>,
    /// Log emission densities ℓ_t(j) (T × N).
    pub ll: Vec<f64>,
    /// Shifted emission densities b̃_j(x_t) = exp(ℓ_t(j) − m_t) (T × N).
    bt: Vec<f64>,
    /// Scaled forward variables α̂ (T × N); in log-space mode, log α.
    alpha: Vec<f64>,
    /// Scaled backward variables β̂ (T × N); in log-space mode, log β.
    beta: Vec<f64>,
    /// Forward normalisers c_t.
    scale: Vec<f64>,
    /// Predicted mass per state (N).
    pred: Vec<f64>,
    /// Per-frame backward helper (N).
    u: Vec<f64>,
    /// Log transitions, N × (J+1).
    log_trans: Vec<f64>,
    /// Posteriors γ (T × N).
    pub gamma: Vec<f64>,
    /// Σ_t ξ_t(i, i+k), N × (J+1).
    pub xi: Vec<f64>,
    /// The same by band diagonal, (J+1) × N, while accumulating.
    xi_diag: Vec<f64>,
}

/// `exp(x)` for `x ≤ 0` (the shifted emission densities), inlined and branch-free so the
/// per-frame loop over states vectorises and needs no libm call. Range reduction
/// `x = k ln 2 + r`, `|r| ≤ ln 2 / 2` (k rounded with the 1.5·2^52 trick, a two-part ln 2),
/// the degree-13 Taylor polynomial (truncation error < 1e-17 relative) and an exact scaling by
/// `2^k`. Agrees with `f64::exp` to a few ulp above `e^−707`; below, where `exp` would be
/// subnormal (< 1e-307 of the frame's largest density), it returns 0, as it does for NaN.
#[inline]
pub(crate) fn exp_nonpositive(x: f64) -> f64 {
    const LN2_HI: f64 = 0.693_147_180_369_123_8;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    const INV_LN2: f64 = std::f64::consts::LOG2_E;
    const MAGIC: f64 = 6_755_399_441_055_744.0; // 1.5·2^52
    const LOWEST: f64 = -707.0;
    let xc = x.max(LOWEST);
    let kd = xc * INV_LN2 + MAGIC;
    let k = kd - MAGIC;
    let r = (xc - k * LN2_HI) - k * LN2_LO;
    // Horner on 1 + r + r²/2! + … + r¹³/13!.
    let mut p = 1.0 / 6_227_020_800.0;
    for c in [
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    // kd's low bits hold k (two's complement offset from MAGIC); 2^k has exponent field k+1023.
    let kbits = kd
        .to_bits()
        .wrapping_sub(MAGIC.to_bits())
        .wrapping_add(1023);
    let scaled = p * f64::from_bits(kbits << 52);
    if x > LOWEST { scaled } else { 0.0 }
}

/// Set the length to `len`, all zeros.
fn resize(v: &mut Vec<f64>, len: usize) {
    v.clear();
    v.resize(len, 0.0);
}

/// Set the length to `len` without clearing (for buffers that are fully overwritten).
fn grow(v: &mut Vec<f64>, len: usize) {
    v.resize(len, 0.0);
}

/// Copy a T × d nalgebra matrix (column-major) into frame-major order.
pub(crate) fn rows_into(x: &DMatrix<f64>, out: &mut Vec<f64>) {
    let (t, d) = x.shape();
    resize(out, t * d);
    for c in 0..d {
        let col = x.column(c);
        for r in 0..t {
            out[r * d + c] = col[r];
        }
    }
}

/// Validate one observation sequence against a model.
pub(crate) fn check_sequence(
    model: &Phmm,
    x: &DMatrix<f64>,
    index: usize,
) -> Result<(), PhmmError> {
    check_sequence_shape(
        x,
        index,
        model.d,
        model.min_sequence_len(),
        model.n,
        model.j,
    )
}

/// Checks one observation sequence: non-empty, `d` columns (d > 0), finite, at least `min_len`
/// frames (the shortest path to the last state of an `n_states` model with jumps ≤ `max_jump`).
pub(crate) fn check_sequence_shape(
    x: &DMatrix<f64>,
    index: usize,
    d: usize,
    min_len: usize,
    n_states: usize,
    max_jump: usize,
) -> Result<(), PhmmError> {
    if x.nrows() == 0 {
        return Err(PhmmError::EmptySequence { index });
    }
    if x.ncols() != d || d == 0 {
        return Err(PhmmError::ObservationDimension {
            index,
            expected: d,
            got: x.ncols(),
        });
    }
    check_finite_seq(x, index)?;
    if x.nrows() < min_len {
        return Err(PhmmError::SequenceTooShort {
            index,
            len: x.nrows(),
            min_len,
            n_states,
            max_jump,
        });
    }
    Ok(())
}

pub(crate) fn check_finite_seq(x: &DMatrix<f64>, index: usize) -> Result<(), PhmmError> {
    for c in 0..x.ncols() {
        for r in 0..x.nrows() {
            let v = x[(r, c)];
            if !v.is_finite() {
                return Err(PhmmError::NonFinite {
                    what: format!("sequence {index}"),
                    row: r,
                    col: c,
                    value: v,
                });
            }
        }
    }
    Ok(())
}

/// Validate θ (caller units) against a model.
pub(crate) fn check_theta(model: &Phmm, theta: &[f64], what: &str) -> Result<(), PhmmError> {
    if theta.len() != model.p {
        return Err(PhmmError::ThetaDimension {
            what: what.to_string(),
            expected: model.p,
            got: theta.len(),
        });
    }
    if let Some((k, &v)) = theta.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(PhmmError::NonFinite {
            what: what.to_string(),
            row: 0,
            col: k,
            value: v,
        });
    }
    Ok(())
}

impl Workspace {
    /// Load a sequence and the means for an internal θ, and compute the log emissions.
    pub(crate) fn prepare(&mut self, model: &Phmm, x: &DMatrix<f64>, theta_int: &[f64]) {
        self.load_sequence(x);
        self.set_means(model, theta_int);
        self.emissions(model, x.nrows());
    }

    /// Copy a T × d sequence into both layouts.
    pub(crate) fn load_sequence(&mut self, x: &DMatrix<f64>) {
        rows_into(x, &mut self.xrows);
        self.xcols.clear();
        self.xcols.extend_from_slice(x.as_slice());
    }

    /// Means μ_i(θ) for an internal θ.
    pub(crate) fn set_means(&mut self, model: &Phmm, theta_int: &[f64]) {
        let (n, d) = (model.n, model.d);
        grow(&mut self.means, n * d);
        for i in 0..n {
            model.mean_internal_into(i, theta_int, &mut self.means[i * d..(i + 1) * d]);
        }
    }

    /// ℓ_t(j) = log N(x_t; μ_j, Σ_j) for the loaded sequence and means.
    ///
    /// For each state, the forward substitution `z = L⁻¹(x_t − μ_j)` runs for all frames at
    /// once, coordinate by coordinate, so the inner loops run over contiguous frames (they
    /// vectorise and have no loop-carried dependency). Per element the arithmetic is exactly the
    /// frame-by-frame substitution.
    #[inline(never)]
    pub(crate) fn emissions(&mut self, model: &Phmm, t_len: usize) {
        let (n, d) = (model.n, model.d);
        grow(&mut self.ll, t_len * n);
        grow(&mut self.zcols, d * t_len);
        grow(&mut self.acc, t_len);
        for j in 0..n {
            let lp = &model.chol_packed[j];
            let inv_diag = &model.chol_inv_diag[j];
            let mu = &self.means[j * d..(j + 1) * d];
            self.acc.fill(0.0);
            let mut off = 0;
            for k in 0..d {
                let (done, rest) = self.zcols.split_at_mut(k * t_len);
                let zk = &mut rest[..t_len];
                let xk = &self.xcols[k * t_len..(k + 1) * t_len];
                let m = mu[k];
                for (z, x) in zk.iter_mut().zip(xk) {
                    *z = x - m;
                }
                for c in 0..k {
                    let l = lp[off + c];
                    let zc = &done[c * t_len..(c + 1) * t_len];
                    for (z, y) in zk.iter_mut().zip(zc) {
                        *z -= l * y;
                    }
                }
                let inv = inv_diag[k];
                for (z, a) in zk.iter_mut().zip(self.acc.iter_mut()) {
                    *z *= inv;
                    *a += *z * *z;
                }
                off += k + 1;
            }
            let ln = model.log_norm[j];
            for (t, a) in self.acc.iter().enumerate() {
                self.ll[t * n + j] = ln - 0.5 * a;
            }
        }
    }

    /// Forward–backward on the loaded emissions: fills `gamma` (and `xi` if asked) and returns
    /// log P(X). Uses the scaled recursions and falls back to log space when they would under- or
    /// overflow. Returns −∞ when the sequence has zero probability.
    pub(crate) fn forward_backward(&mut self, model: &Phmm, t_len: usize, want_xi: bool) -> f64 {
        match self.forward_backward_scaled(model, t_len, want_xi) {
            Some(lp) => lp,
            None => self.forward_backward_log(model, t_len, want_xi),
        }
    }

    /// Forward pass only: log P(X).
    pub(crate) fn forward_only(&mut self, model: &Phmm, t_len: usize) -> f64 {
        match self.forward_scaled(model, t_len) {
            Some(lp) => lp,
            None => self.forward_backward_log(model, t_len, false),
        }
    }

    /// Scaled forward pass (SPEC §1.2 "scaled variant", with the shift taken over reachable states).
    /// Returns `None` if a normaliser under/overflows.
    #[inline(never)]
    fn forward_scaled(&mut self, model: &Phmm, t_len: usize) -> Option<f64> {
        let (n, jmax) = (model.n, model.j);
        grow(&mut self.bt, t_len * n);
        grow(&mut self.alpha, t_len * n);
        grow(&mut self.scale, t_len);
        grow(&mut self.pred, n);
        let mut log_p = 0.0;
        self.pred.copy_from_slice(&model.start);
        for t in 0..t_len {
            if t > 0 {
                // pred(j) = Σ_{i ∈ pred(j)} α̂_{t−1}(i) a_ij, summed over ascending i.
                // pred(j) = Σ_{i ∈ pred(j)} α̂_{t−1}(i) a_ij, one band diagonal at a time; the
                // far diagonal first, so each pred(j) adds its terms in ascending i.
                let prev = &self.alpha[(t - 1) * n..t * n];
                self.pred.fill(0.0);
                for k in (0..=jmax.min(n - 1)).rev() {
                    let diag = &model.band_in[k * n + k..(k + 1) * n];
                    for ((p, a), d) in self.pred[k..].iter_mut().zip(prev).zip(diag) {
                        *p += a * d;
                    }
                }
            }
            let ll = &self.ll[t * n..(t + 1) * n];
            let mut m = f64::NEG_INFINITY;
            for (&p, &l) in self.pred.iter().zip(ll) {
                if p > 0.0 && l > m {
                    m = l;
                }
            }
            if !m.is_finite() {
                return None;
            }
            let bt = &mut self.bt[t * n..(t + 1) * n];
            for ((b, &p), &l) in bt.iter_mut().zip(&self.pred).zip(ll) {
                let e = exp_nonpositive(l - m);
                *b = if p > 0.0 { e } else { 0.0 };
            }
            let al = &mut self.alpha[t * n..(t + 1) * n];
            let mut c = 0.0;
            for ((a, &b), &p) in al.iter_mut().zip(bt.iter()).zip(&self.pred) {
                *a = b * p;
                c += *a;
            }
            if !(c > TINY && c.is_finite()) {
                return None;
            }
            let inv = 1.0 / c;
            for a in al.iter_mut() {
                *a *= inv;
            }
            self.scale[t] = c;
            log_p += c.ln() + m;
        }
        let last = &self.alpha[(t_len - 1) * n..t_len * n];
        let s_e = match model.end_mode {
            EndMode::None => 1.0,
            _ => last
                .iter()
                .zip(&model.exit)
                .map(|(a, e)| a * e)
                .sum::<f64>(),
        };
        if !(s_e > TINY) {
            return None;
        }
        Some(log_p + s_e.ln())
    }

    #[inline(never)]
    fn forward_backward_scaled(
        &mut self,
        model: &Phmm,
        t_len: usize,
        want_xi: bool,
    ) -> Option<f64> {
        let log_p = self.forward_scaled(model, t_len)?;
        let (n, w) = (model.n, model.j + 1);
        grow(&mut self.beta, t_len * n);
        grow(&mut self.u, n);
        grow(&mut self.gamma, t_len * n);
        if want_xi {
            resize(&mut self.xi, n * w);
        }
        // β̂_T(i) = a_iE / s_E (or 1 without exit modelling).
        {
            let last = (t_len - 1) * n;
            if model.end_mode == EndMode::None {
                self.beta[last..].fill(1.0);
            } else {
                let s_e: f64 = self.alpha[last..]
                    .iter()
                    .zip(&model.exit)
                    .map(|(a, e)| a * e)
                    .sum();
                let inv = 1.0 / s_e;
                for i in 0..n {
                    self.beta[last + i] = model.exit[i] * inv;
                }
            }
        }
        if want_xi {
            resize(&mut self.xi_diag, n * w);
        }
        for t in (0..t_len - 1).rev() {
            let inv_c = 1.0 / self.scale[t + 1];
            let nb = (t + 1) * n;
            for ((u, b), bt) in self
                .u
                .iter_mut()
                .zip(&self.beta[nb..nb + n])
                .zip(&self.bt[nb..nb + n])
            {
                *u = bt * b * inv_c;
            }
            let cur = t * n;
            // β̂_t(i) = Σ_k a_{i,i+k} u(i+k), one band diagonal at a time (contiguous, vectorises;
            // per element the terms are still added in ascending k).
            let beta_t = &mut self.beta[cur..cur + n];
            beta_t.fill(0.0);
            for k in 0..w.min(n) {
                let diag = &model.band_out[k * n..k * n + (n - k)];
                for ((b, a), u) in beta_t[..n - k].iter_mut().zip(diag).zip(&self.u[k..]) {
                    *b += a * u;
                }
            }
            if beta_t.iter().any(|b| !(*b < HUGE)) {
                return None;
            }
            if want_xi {
                let alpha_t = &self.alpha[cur..cur + n];
                for k in 0..w.min(n) {
                    let diag = &model.band_out[k * n..k * n + (n - k)];
                    let xi = &mut self.xi_diag[k * n..k * n + (n - k)];
                    for (((x, al), a), u) in xi.iter_mut().zip(alpha_t).zip(diag).zip(&self.u[k..])
                    {
                        *x += al * a * u;
                    }
                }
            }
        }
        if want_xi {
            for i in 0..n {
                for k in 0..w {
                    self.xi[i * w + k] = self.xi_diag[k * n + i];
                }
            }
        }
        for k in 0..t_len * n {
            self.gamma[k] = self.alpha[k] * self.beta[k];
        }
        Some(log_p)
    }

    fn fill_log_trans(&mut self, model: &Phmm) {
        resize(&mut self.log_trans, model.trans.len());
        for (l, &a) in self.log_trans.iter_mut().zip(&model.trans) {
            *l = a.ln();
        }
    }

    /// Log-space forward–backward (SPEC §1.2, normative form). Slower; used as the fallback and
    /// as the reference in tests.
    pub(crate) fn forward_backward_log(
        &mut self,
        model: &Phmm,
        t_len: usize,
        want_xi: bool,
    ) -> f64 {
        let (n, w) = (model.n, model.j + 1);
        self.fill_log_trans(model);
        resize(&mut self.alpha, t_len * n);
        resize(&mut self.beta, t_len * n);
        resize(&mut self.gamma, t_len * n);
        if want_xi {
            resize(&mut self.xi, n * w);
        }
        let lt = &self.log_trans;
        for j in 0..n {
            self.alpha[j] = model.start[j].ln() + self.ll[j];
        }
        let mut terms = Vec::with_capacity(w.max(n));
        for t in 1..t_len {
            for j in 0..n {
                terms.clear();
                for i in j.saturating_sub(model.j)..=j {
                    terms.push(self.alpha[(t - 1) * n + i] + lt[i * w + (j - i)]);
                }
                self.alpha[t * n + j] = self.ll[t * n + j] + lse(&terms);
            }
        }
        let last = (t_len - 1) * n;
        terms.clear();
        for i in 0..n {
            let le = match model.end_mode {
                EndMode::None => 0.0,
                _ => model.exit[i].ln(),
            };
            self.beta[last + i] = le;
            terms.push(self.alpha[last + i] + le);
        }
        let log_p = lse(&terms);
        for t in (0..t_len - 1).rev() {
            for i in 0..n {
                terms.clear();
                for k in 0..w.min(n - i) {
                    let j = i + k;
                    terms.push(
                        lt[i * w + k] + self.ll[(t + 1) * n + j] + self.beta[(t + 1) * n + j],
                    );
                }
                self.beta[t * n + i] = lse(&terms);
            }
        }
        if log_p == f64::NEG_INFINITY {
            self.gamma.fill(0.0);
            return log_p;
        }
        for t in 0..t_len {
            let row = &mut self.gamma[t * n..(t + 1) * n];
            let mut tot = 0.0;
            for i in 0..n {
                let g = (self.alpha[t * n + i] + self.beta[t * n + i] - log_p).exp();
                row[i] = if g.is_nan() { 0.0 } else { g };
                tot += row[i];
            }
            // Σ_i γ_t(i) = 1 exactly in theory; with |log P| ~ 1e9 the subtraction above carries
            // an absolute error of ~ulp(log P), so renormalise each frame.
            if tot > 0.0 {
                for v in row.iter_mut() {
                    *v /= tot;
                }
            }
        }
        if want_xi {
            for t in 0..t_len - 1 {
                for i in 0..n {
                    let la = self.alpha[t * n + i];
                    if la == f64::NEG_INFINITY {
                        continue;
                    }
                    for k in 0..w.min(n - i) {
                        let j = i + k;
                        let v = la
                            + lt[i * w + k]
                            + self.ll[(t + 1) * n + j]
                            + self.beta[(t + 1) * n + j]
                            - log_p;
                        let e = v.exp();
                        if e.is_finite() {
                            self.xi[i * w + k] += e;
                        }
                    }
                }
            }
        }
        log_p
    }

    /// Viterbi on the loaded emissions (SPEC §1.5). Ties break to the smaller state index.
    /// Returns the 0-based path and its log-probability, or `None` if no path has positive
    /// probability.
    pub(crate) fn viterbi(&mut self, model: &Phmm, t_len: usize) -> Option<(Vec<usize>, f64)> {
        let (n, w) = (model.n, model.j + 1);
        self.fill_log_trans(model);
        resize(&mut self.alpha, t_len * n);
        let mut psi = vec![0usize; t_len * n];
        for j in 0..n {
            self.alpha[j] = model.start[j].ln() + self.ll[j];
        }
        for t in 1..t_len {
            for j in 0..n {
                let mut best = f64::NEG_INFINITY;
                let mut arg = j;
                for i in j.saturating_sub(model.j)..=j {
                    let v = self.alpha[(t - 1) * n + i] + self.log_trans[i * w + (j - i)];
                    if v > best {
                        best = v;
                        arg = i;
                    }
                }
                self.alpha[t * n + j] = self.ll[t * n + j] + best;
                psi[t * n + j] = arg;
            }
        }
        let last = (t_len - 1) * n;
        let mut best = f64::NEG_INFINITY;
        let mut arg = 0;
        for i in 0..n {
            let le = match model.end_mode {
                EndMode::None => 0.0,
                _ => model.exit[i].ln(),
            };
            let v = self.alpha[last + i] + le;
            if v > best {
                best = v;
                arg = i;
            }
        }
        if best == f64::NEG_INFINITY || best.is_nan() {
            return None;
        }
        let mut path = vec![0usize; t_len];
        path[t_len - 1] = arg;
        for t in (1..t_len).rev() {
            path[t - 1] = psi[t * n + path[t]];
        }
        Some((path, best))
    }
}

/// Log-sum-exp; −∞ when every term is −∞.
pub(crate) fn lse(v: &[f64]) -> f64 {
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + v.iter().map(|&x| (x - m).exp()).sum::<f64>().ln()
}

impl Phmm {
    fn load(&self, x: &DMatrix<f64>, theta: &[f64]) -> Result<Workspace, PhmmError> {
        check_sequence(self, x, 0)?;
        check_theta(self, theta, "theta")?;
        let mut ti = vec![0.0; self.p];
        self.theta_internal(theta, &mut ti);
        let mut ws = Workspace::default();
        ws.prepare(self, x, &ti);
        Ok(ws)
    }

    /// log P(X | θ) by the forward algorithm (SPEC §1.2). `x` is T × d, one row per frame.
    pub fn log_likelihood(&self, x: &DMatrix<f64>, theta: &[f64]) -> Result<f64, PhmmError> {
        let mut ws = self.load(x, theta)?;
        let lp = ws.forward_only(self, x.nrows());
        finite_or_zero(lp)
    }

    /// State posteriors γ_t(i) (T × N), rows sum to 1.
    pub fn posteriors(&self, x: &DMatrix<f64>, theta: &[f64]) -> Result<DMatrix<f64>, PhmmError> {
        let mut ws = self.load(x, theta)?;
        let t_len = x.nrows();
        let lp = ws.forward_backward(self, t_len, false);
        finite_or_zero(lp)?;
        Ok(DMatrix::from_row_slice(t_len, self.n, &ws.gamma))
    }

    /// Posteriors γ (T × N), the expected transition counts Σ_t ξ_t(i, j) (N × N, zero outside
    /// the band) and log P(X | θ).
    pub fn posteriors_with_transitions(
        &self,
        x: &DMatrix<f64>,
        theta: &[f64],
    ) -> Result<(DMatrix<f64>, DMatrix<f64>, f64), PhmmError> {
        let mut ws = self.load(x, theta)?;
        let t_len = x.nrows();
        let lp = finite_or_zero(ws.forward_backward(self, t_len, true))?;
        Ok((
            DMatrix::from_row_slice(t_len, self.n, &ws.gamma),
            self.banded_to_dense(&ws.xi),
            lp,
        ))
    }

    /// The most likely state path (0-based states) and its log-probability (SPEC §1.5).
    pub fn viterbi(&self, x: &DMatrix<f64>, theta: &[f64]) -> Result<(Vec<usize>, f64), PhmmError> {
        let mut ws = self.load(x, theta)?;
        ws.viterbi(self, x.nrows())
            .ok_or(PhmmError::ZeroLikelihood { index: 0 })
    }

    /// Log emission densities ℓ_t(i) = log N(x_t; μ_i(θ), Σ_i) (T × N).
    pub fn log_emissions(
        &self,
        x: &DMatrix<f64>,
        theta: &[f64],
    ) -> Result<DMatrix<f64>, PhmmError> {
        let ws = self.load(x, theta)?;
        Ok(DMatrix::from_row_slice(x.nrows(), self.n, &ws.ll))
    }

    /// Log-density of one observation under state i at θ (caller units). Panics on bad indices or
    /// dimensions, like the accessors.
    pub fn log_emission(&self, i: usize, x: &[f64], theta: &[f64]) -> f64 {
        assert_eq!(x.len(), self.d, "observation has the wrong dimension");
        let mut mu = vec![0.0; self.d];
        self.mean_into(i, theta, &mut mu);
        let r: Vec<f64> = x.iter().zip(&mu).map(|(a, b)| a - b).collect();
        let mut z = vec![0.0; self.d];
        let m2 = mahalanobis_packed(&self.chol_packed[i], &self.chol_inv_diag[i], &r, &mut z);
        self.log_norm[i] - 0.5 * m2
    }

    pub(crate) fn banded_to_dense(&self, banded: &[f64]) -> DMatrix<f64> {
        let w = self.j + 1;
        let mut out = DMatrix::zeros(self.n, self.n);
        for i in 0..self.n {
            for k in 0..w.min(self.n - i) {
                out[(i, i + k)] = banded[i * w + k];
            }
        }
        out
    }

    /// The full transition matrix (N × N, zeros outside the band).
    pub fn transition_matrix(&self) -> DMatrix<f64> {
        self.banded_to_dense(&self.trans)
    }

    /// All exit probabilities a_iE.
    pub fn exit_probs(&self) -> DVector<f64> {
        DVector::from_row_slice(&self.exit)
    }
}

fn finite_or_zero(lp: f64) -> Result<f64, PhmmError> {
    if lp.is_finite() {
        Ok(lp)
    } else if lp == f64::NEG_INFINITY {
        Err(PhmmError::ZeroLikelihood { index: 0 })
    } else {
        Err(PhmmError::Numerical(format!("log-likelihood is {lp}")))
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp)] // exact values are the point of these checks
pub(crate) mod tests {
    //! Scaled vs log-space agreement; brute-force checks live in tests/conformance.rs.
    use super::*;

    #[test]
    fn fast_exp_matches_libm() {
        let mut worst = 0.0f64;
        let mut x = 0.0;
        while x > -760.0 {
            let (a, b) = (exp_nonpositive(x), x.exp());
            if x > -707.0 {
                worst = worst.max(((a - b) / b).abs());
            } else {
                assert!(a == 0.0 && b < 1e-307, "{x}: {a} vs {b}");
            }
            x -= 0.013_7;
        }
        assert!(worst < 1e-15, "max relative error {worst}");
        assert!(exp_nonpositive(0.0) == 1.0 && exp_nonpositive(-800.0) == 0.0);
        assert!(exp_nonpositive(f64::NAN) == 0.0);
    }

    #[test]
    fn lse_handles_all_neg_inf() {
        assert!(lse(&[f64::NEG_INFINITY, f64::NEG_INFINITY]).is_infinite());
        assert!((lse(&[0.0, 0.0]) - 2f64.ln()).abs() < 1e-15);
    }
}
