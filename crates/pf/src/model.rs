//! Per-action caches of the parametric HMM parameters the hot loop needs, in flat fixed-size
//! arrays: cumulative transition rows (band + exit), cumulative π, mean bias b and weights A
//! (μ_k(θ) = b_k + A_k θ, θ in metres) and the packed lower Cholesky factor L_k of Σ_k.

use actrack_phmm::Phmm;
use rand::Rng;

use crate::PfError;

/// Pose dimension (p, q, r).
pub(crate) const D: usize = 9;
/// θ dimension.
pub(crate) const P: usize = 2;
/// Entries of a packed 9×9 lower triangle.
pub(crate) const TRI: usize = D * (D + 1) / 2;

/// Outcome of a transition draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Next {
    /// Move to this 0-based state.
    State(usize),
    /// Leave the action through the end state E.
    Exit,
}

/// One action's parameters, laid out for sampling.
#[derive(Debug, Clone)]
pub(crate) struct ActionCache {
    pub(crate) n: usize,
    /// Row stride of `trans_cum`: J + 2 (offsets 0..=J, then exit).
    stride: usize,
    /// Cumulative, normalised transition rows: `trans_cum[i*stride + o]` = Σ_{o' ≤ o} a_{i,i+o'},
    /// the last entry of a row includes a_iE (and is 1).
    trans_cum: Vec<f64>,
    /// Cumulative, normalised π.
    start_cum: Vec<f64>,
    bias: Vec<[f64; D]>,
    /// Row-major 9×2.
    weights: Vec<[f64; D * P]>,
    /// Row-major packed lower triangle.
    chol: Vec<[f64; TRI]>,
    /// σ(k) of the cooling schedule at each 0-based state (SPEC's k = index + 1).
    sigma: Vec<f64>,
}

fn finite(action: usize, what: &str, v: f64) -> Result<f64, PfError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(PfError::BadModel {
            action,
            reason: format!("{what} is not finite ({v})"),
        })
    }
}

impl ActionCache {
    /// The cache of action `action`'s model, with the cooling schedule σ₀·ratio^(k/N) tabulated.
    pub(crate) fn from_phmm(
        action: usize,
        m: &Phmm,
        sigma0: f64,
        end_ratio: f64,
    ) -> Result<Self, PfError> {
        if m.dim() != D || m.theta_dim() != P {
            return Err(PfError::ModelShape {
                action,
                dim: m.dim(),
                theta_dim: m.theta_dim(),
            });
        }
        let n = m.n_states();
        if n == 0 {
            return Err(PfError::BadModel {
                action,
                reason: "the model has no states".into(),
            });
        }
        let j = m.max_jump();
        let stride = j + 2;
        let mut trans_cum = vec![0.0; n * stride];
        for i in 0..n {
            let row = &mut trans_cum[i * stride..(i + 1) * stride];
            let mut acc = 0.0;
            for o in 0..=j {
                if i + o < n {
                    acc += finite(action, "a transition probability", m.transition(i, i + o))?
                        .max(0.0);
                }
                row[o] = acc;
            }
            acc += finite(action, "an exit probability", m.exit_prob(i))?.max(0.0);
            row[j + 1] = acc;
            if acc <= 0.0 {
                return Err(PfError::BadModel {
                    action,
                    reason: format!("transition row {i} has no probability mass"),
                });
            }
            for c in row.iter_mut() {
                *c /= acc;
            }
        }
        let mut start_cum = vec![0.0; n];
        let mut acc = 0.0;
        for i in 0..n {
            acc += finite(action, "a start probability", m.start_prob(i))?.max(0.0);
            start_cum[i] = acc;
        }
        if acc <= 0.0 {
            return Err(PfError::BadModel {
                action,
                reason: "the start distribution π has no mass".into(),
            });
        }
        for c in &mut start_cum {
            *c /= acc;
        }

        let mut bias = Vec::with_capacity(n);
        let mut weights = Vec::with_capacity(n);
        let mut chol = Vec::with_capacity(n);
        for i in 0..n {
            let (b, a) = m.mean_affine(i);
            let l = m.cov_cholesky(i);
            let mut bb = [0.0; D];
            let mut aa = [0.0; D * P];
            let mut ll = [0.0; TRI];
            for r in 0..D {
                bb[r] = finite(action, "a mean", b[r])?;
                for c in 0..P {
                    aa[r * P + c] = finite(action, "a mean weight", a[(r, c)])?;
                }
                for c in 0..=r {
                    ll[r * (r + 1) / 2 + c] = finite(action, "a Cholesky factor", l[(r, c)])?;
                }
            }
            bias.push(bb);
            weights.push(aa);
            chol.push(ll);
        }
        let mut cache = Self {
            n,
            stride,
            trans_cum,
            start_cum,
            bias,
            weights,
            chol,
            sigma: vec![0.0; n],
        };
        for (i, s) in cache.sigma.iter_mut().enumerate() {
            *s = crate::cooling_sigma((i + 1) as f64, n, sigma0, end_ratio);
        }
        Ok(cache)
    }

    /// σ at 0-based state `k`.
    #[inline]
    pub(crate) fn sigma(&self, k: usize) -> f64 {
        self.sigma[k]
    }

    /// Draw the successor of 0-based state `k` from its banded row and exit probability.
    #[inline]
    pub(crate) fn next<R: Rng + ?Sized>(&self, k: usize, rng: &mut R) -> Next {
        let row = &self.trans_cum[k * self.stride..(k + 1) * self.stride];
        let u: f64 = rng.random();
        let last = self.stride - 1;
        let mut o = 0;
        while o < last && row[o] <= u {
            o += 1;
        }
        if o == last {
            Next::Exit
        } else {
            Next::State((k + o).min(self.n - 1))
        }
    }

    /// Draw a state from π.
    #[inline]
    pub(crate) fn draw_start<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        let u: f64 = rng.random();
        self.start_cum.partition_point(|&c| c <= u).min(self.n - 1)
    }

    /// μ_k(θ) into `out`, θ in metres.
    #[inline]
    pub(crate) fn mean(&self, k: usize, theta_m: [f64; 2], out: &mut [f64; D]) {
        let b = &self.bias[k];
        let a = &self.weights[k];
        for r in 0..D {
            out[r] = b[r] + a[r * P] * theta_m[0] + a[r * P + 1] * theta_m[1];
        }
    }

    /// x ~ N(μ_k(θ), Σ_k) into `out`: x = μ + L z with z ~ N(0, I).
    #[inline]
    pub(crate) fn sample<R: Rng + ?Sized>(
        &self,
        k: usize,
        theta_m: [f64; 2],
        rng: &mut R,
        out: &mut [f64; D],
    ) {
        self.mean(k, theta_m, out);
        let mut z = [0.0; D];
        for v in &mut z {
            *v = rng.sample(rand_distr::StandardNormal);
        }
        let l = &self.chol[k];
        let mut off = 0;
        for r in 0..D {
            let mut s = 0.0;
            for c in 0..=r {
                s += l[off + c] * z[c];
            }
            out[r] += s;
            off += r + 1;
        }
    }
}
