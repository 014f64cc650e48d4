//! Generation for a given θ (SPEC §1.6, §2.7): stochastic sampling (G1) and the deterministic
//! expected trajectory (G2).

use nalgebra::DMatrix;
use rand::Rng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;

use crate::model::{EndMode, Phmm};
use crate::train::DEFAULT_SEED;

/// Safety cap on generated lengths when no length is requested (a tiny exit probability could
/// otherwise run for a very long time).
pub const MAX_GENERATED_LEN: usize = 100_000;

impl Phmm {
    /// Sample a sequence at θ (caller units) with the given RNG (SPEC §1.6 / §2.7 G1). Returns the
    /// T × d observations and the 0-based state path.
    ///
    /// * `len = Some(T)`: exactly T frames; the exit is ignored (each row renormalised without
    ///   `a_iE`).
    /// * `len = None`: run until the exit state is drawn, so the length includes the final
    ///   state's dwell. With [`EndMode::None`] (no exit) sampling stops after the first frame in
    ///   the last state. At most [`MAX_GENERATED_LEN`] frames.
    ///
    /// Panics if `theta.len() != theta_dim()`.
    pub fn sample<R: Rng>(
        &self,
        theta: &[f64],
        len: Option<usize>,
        rng: &mut R,
    ) -> (DMatrix<f64>, Vec<usize>) {
        assert_eq!(theta.len(), self.p, "θ has the wrong dimension");
        let (n, d, w) = (self.n, self.d, self.j + 1);
        let mut ti = vec![0.0; self.p];
        self.theta_internal(theta, &mut ti);
        let mut mu = vec![0.0; d];
        let mut z = vec![0.0; d];
        let mut data: Vec<f64> = Vec::new();
        let mut states = Vec::new();
        let cap = len.unwrap_or(MAX_GENERATED_LEN);
        if cap == 0 {
            return (DMatrix::zeros(0, d), states);
        }
        let mut q = draw(rng, self.start.iter().copied()).unwrap_or(0);
        loop {
            self.mean_internal_into(q, &ti, &mut mu);
            for v in &mut z {
                *v = StandardNormal.sample(rng);
            }
            let l = &self.cholesky[q];
            for r in 0..d {
                let mut s = mu[r];
                for c in 0..=r {
                    s += l[(r, c)] * z[c];
                }
                data.push(s);
            }
            states.push(q);
            if states.len() >= cap {
                break;
            }
            let row = &self.trans[q * w..q * w + w.min(n - q)];
            if len.is_none() {
                if self.end_mode == EndMode::None {
                    if q + 1 == n {
                        break;
                    }
                } else {
                    // Draw among (a_q,q..q+J, a_qE): the index past the band means exit.
                    match draw(
                        rng,
                        row.iter().copied().chain(std::iter::once(self.exit[q])),
                    ) {
                        Some(k) if k < row.len() => {
                            q += k;
                            continue;
                        }
                        _ => break,
                    }
                }
            }
            q += draw(rng, row.iter().copied()).unwrap_or(0);
        }
        let t = states.len();
        (DMatrix::from_row_slice(t, d, &data), states)
    }

    /// [`Phmm::sample`] with the crate's fixed default seed ([`DEFAULT_SEED`]).
    pub fn sample_default(&self, theta: &[f64], len: Option<usize>) -> (DMatrix<f64>, Vec<usize>) {
        let mut rng = Pcg64Mcg::seed_from_u64(DEFAULT_SEED);
        self.sample(theta, len, &mut rng)
    }

    /// The deterministic expected trajectory at θ (SPEC §2.7 G2): propagate the state
    /// distribution `s_{t+1}(j) = Σ_i s_t(i) a_ij` from π, emit `Σ_i s_t(i) μ_i(θ) / Σ_i s_t(i)`.
    /// With `len = None` it stops before the first frame whose remaining mass is below ½ (the
    /// median length); with [`EndMode::None`] (no exit) it stops once at least half the mass is
    /// in the last state. At most [`MAX_GENERATED_LEN`] frames.
    ///
    /// Panics if `theta.len() != theta_dim()`.
    pub fn expected_trajectory(&self, theta: &[f64], len: Option<usize>) -> DMatrix<f64> {
        assert_eq!(theta.len(), self.p, "θ has the wrong dimension");
        let (n, d, w) = (self.n, self.d, self.j + 1);
        let mut ti = vec![0.0; self.p];
        self.theta_internal(theta, &mut ti);
        let mut means = vec![0.0; n * d];
        for i in 0..n {
            self.mean_internal_into(i, &ti, &mut means[i * d..(i + 1) * d]);
        }
        let mut s = self.start.clone();
        let mut next = vec![0.0; n];
        let mut data = Vec::new();
        let cap = len.unwrap_or(MAX_GENERATED_LEN);
        let mut t = 0;
        while t < cap {
            let mass: f64 = s.iter().sum();
            if len.is_none() && self.end_mode != EndMode::None && mass < 0.5 {
                break;
            }
            if !(mass > 0.0) {
                break;
            }
            for k in 0..d {
                data.push((0..n).map(|i| s[i] * means[i * d + k]).sum::<f64>() / mass);
            }
            t += 1;
            if len.is_none() && self.end_mode == EndMode::None && s[n - 1] >= 0.5 * mass {
                break;
            }
            next.fill(0.0);
            for i in 0..n {
                for k in 0..w.min(n - i) {
                    next[i + k] += s[i] * self.trans[i * w + k];
                }
            }
            std::mem::swap(&mut s, &mut next);
        }
        DMatrix::from_row_slice(t, d, &data)
    }
}

/// Draw an index with probability proportional to the weights; `None` if they sum to zero.
fn draw<R: Rng, I: Iterator<Item = f64> + Clone>(rng: &mut R, weights: I) -> Option<usize> {
    let total: f64 = weights.clone().sum();
    if !(total > 0.0) {
        return None;
    }
    let u = rng.random::<f64>() * total;
    let mut acc = 0.0;
    let mut last_pos = None;
    for (k, wgt) in weights.enumerate() {
        if wgt > 0.0 {
            last_pos = Some(k);
        }
        acc += wgt;
        if u < acc {
            return Some(k);
        }
    }
    last_pos
}
