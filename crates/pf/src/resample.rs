//! Log-space weighting and resampling (SPEC §3.5–§3.6).
//!
//! The schemes return, for M draws, the ancestor index of every new particle in ascending order.
//! All four are unbiased: the expected number of copies of particle i is M·w_i.

use rand::Rng;

use crate::Resampling;

/// log Σ exp(x_i), subtracting the maximum first. Returns −∞ when every term is −∞ (or the
/// slice is empty). NaN terms must have been removed by the caller.
pub fn log_sum_exp(x: &[f64]) -> f64 {
    let m = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return f64::NEG_INFINITY;
    }
    if m == f64::INFINITY {
        return f64::INFINITY;
    }
    let s: f64 = x.iter().map(|v| (v - m).exp()).sum();
    m + s.ln()
}

/// Normalise log weights into weights: `w_i = exp(log_w_i − LSE(log_w))`. Returns the LSE, or
/// `None` (leaving `w` untouched) when it is not finite, i.e. when no particle has a usable
/// weight.
pub fn normalise_log_weights(log_w: &[f64], w: &mut [f64]) -> Option<f64> {
    debug_assert_eq!(log_w.len(), w.len());
    let lse = log_sum_exp(log_w);
    if !lse.is_finite() {
        return None;
    }
    for (wi, lw) in w.iter_mut().zip(log_w) {
        *wi = (lw - lse).exp();
    }
    Some(lse)
}

/// The effective sample size N_eff = (Σw)² / Σw² (= 1/Σw² for normalised weights).
pub fn effective_sample_size(w: &[f64]) -> f64 {
    let s: f64 = w.iter().sum();
    let s2: f64 = w.iter().map(|v| v * v).sum();
    if s2 > 0.0 { s * s / s2 } else { 0.0 }
}

/// A resampler with its scratch buffers (allocated once, reused every frame).
#[derive(Debug, Clone)]
pub struct Resampler {
    scheme: Resampling,
    cumulative: Vec<f64>,
}

impl Resampler {
    /// A resampler for the given scheme.
    pub fn new(scheme: Resampling) -> Self {
        Self {
            scheme,
            cumulative: Vec::new(),
        }
    }

    /// The scheme in use.
    pub fn scheme(&self) -> Resampling {
        self.scheme
    }

    /// Draw `weights.len()` ancestors from the (non-negative, not necessarily normalised)
    /// `weights` into `out` (cleared first), in ascending order. All-zero or non-finite total
    /// weight falls back to the identity (every particle kept once).
    pub fn resample<R: Rng + ?Sized>(
        &mut self,
        weights: &[f64],
        rng: &mut R,
        out: &mut Vec<usize>,
    ) {
        out.clear();
        self.resample_n(weights, weights.len(), rng, out);
    }

    /// Append `m` ancestors drawn from `weights` (indices into `weights`, ascending) to `out`.
    /// The expected number of copies of particle i is `m·w_i/Σw`. All-zero or non-finite total
    /// weight spreads the `m` draws evenly over the particles (cyclically).
    pub fn resample_n<R: Rng + ?Sized>(
        &mut self,
        weights: &[f64],
        m: usize,
        rng: &mut R,
        out: &mut Vec<usize>,
    ) {
        let n_w = weights.len();
        if m == 0 || n_w == 0 {
            return;
        }
        let base = out.len();
        self.cumulative.clear();
        let mut acc = 0.0;
        for &w in weights {
            acc += if w > 0.0 { w } else { 0.0 };
            self.cumulative.push(acc);
        }
        let total = acc;
        if !(total.is_finite() && total > 0.0) {
            let start = out.len();
            out.extend((0..m).map(|n| n % n_w));
            out[start..].sort_unstable();
            return;
        }
        match self.scheme {
            Resampling::Systematic => {
                let u0: f64 = rng.random::<f64>();
                walk(&self.cumulative, total, m, out, |n| {
                    (n as f64 + u0) / m as f64
                });
            }
            Resampling::Stratified => {
                walk(&self.cumulative, total, m, out, |n| {
                    (n as f64 + rng.random::<f64>()) / m as f64
                });
            }
            Resampling::Multinomial => multinomial(&self.cumulative, total, m, rng, out),
            Resampling::Residual => {
                // Deterministic copies ⌊M·w_i⌋, then the remainder from the residual weights.
                let mf = m as f64;
                let mut prev = 0.0;
                let mut residual_total = 0.0;
                for i in 0..n_w {
                    let wi = (self.cumulative[i] - prev) / total;
                    prev = self.cumulative[i];
                    let copies = (mf * wi).floor();
                    out.extend(std::iter::repeat_n(i, copies as usize));
                    residual_total += mf * wi - copies;
                    // Reuse `cumulative` for the residuals' cumulative sum.
                    self.cumulative[i] = residual_total;
                }
                out.truncate(base + m);
                let rest = base + m - out.len();
                if rest > 0 {
                    if residual_total > 0.0 {
                        let start = out.len();
                        multinomial(&self.cumulative, residual_total, rest, rng, out);
                        // Both parts are ascending; merge them in place.
                        out[base..].sort_unstable();
                        debug_assert!(out.len() == start + rest);
                    } else {
                        // Rounding left no residual mass: pad with the heaviest particle.
                        let heaviest = argmax(weights);
                        out.resize(base + m, heaviest);
                        out[base..].sort_unstable();
                    }
                }
            }
        }
        debug_assert_eq!(out.len(), base + m);
    }
}

/// Sweep ascending points `point(n)` ∈ [0,1) (n = 0..count) through the cumulative weights.
fn walk(
    cumulative: &[f64],
    total: f64,
    count: usize,
    out: &mut Vec<usize>,
    mut point: impl FnMut(usize) -> f64,
) {
    let last = cumulative.len() - 1;
    let mut i = 0;
    for n in 0..count {
        let u = point(n) * total;
        while i < last && cumulative[i] <= u {
            i += 1;
        }
        out.push(i);
    }
}

/// `count` independent draws, sorted: binary search of each U[0,1) draw in the cumulative
/// weights (SPEC §3.6, CONDENSATION), then one sort.
fn multinomial<R: Rng + ?Sized>(
    cumulative: &[f64],
    total: f64,
    count: usize,
    rng: &mut R,
    out: &mut Vec<usize>,
) {
    let last = cumulative.len() - 1;
    let start = out.len();
    for _ in 0..count {
        let u = rng.random::<f64>() * total;
        // First index with cumulative > u.
        let i = cumulative.partition_point(|&c| c <= u).min(last);
        out.push(i);
    }
    out[start..].sort_unstable();
}

/// Particle counts per action for mixture resampling ([`crate::ActionBalance::Mixture`]).
///
/// `posterior[a]` is P(a) (a ∈ 𝒜, summing to 1; actions with P(a) = 0 have no particle left to
/// resample from and get none). Every other action gets a floor of ⌈ε·M/|𝒜|⌉ particles (less if
/// the floors alone would exceed M), and the remaining particles are shared in proportion to
/// P(a), rounded by largest remainder (ties to the lower index), so the counts sum to M exactly.
/// Deterministic: no random draws.
pub fn allocate_actions(posterior: &[f64], m: usize, floor_fraction: f64, out: &mut Vec<usize>) {
    out.clear();
    out.resize(posterior.len(), 0);
    let live = posterior.iter().filter(|&&p| p > 0.0).count();
    if live == 0 || m == 0 {
        return;
    }
    let n_actions = posterior.len() as f64;
    // ⌈ε·M/|𝒜|⌉, capped so that the live actions' floors fit into M.
    let floor = ((floor_fraction * m as f64 / n_actions).ceil() as usize).min(m / live);
    let free = m - floor * live;
    let total: f64 = posterior.iter().filter(|&&p| p > 0.0).sum();
    let mut assigned = 0;
    // (remainder, index) of every live action, for the largest-remainder rounding.
    let mut rem: Vec<(f64, usize)> = Vec::with_capacity(live);
    for (a, &p) in posterior.iter().enumerate() {
        if p > 0.0 {
            let share = free as f64 * p / total;
            let whole = (share.floor() as usize).min(free - assigned);
            out[a] = floor + whole;
            assigned += whole;
            rem.push((share - whole as f64, a));
        }
    }
    rem.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
    for &(_, a) in rem.iter().cycle().take(free - assigned) {
        out[a] += 1;
    }
    debug_assert_eq!(out.iter().sum::<usize>(), m);
}

fn argmax(x: &[f64]) -> usize {
    let mut best = 0;
    for (i, v) in x.iter().enumerate() {
        if *v > x[best] {
            best = i;
        }
    }
    best
}

#[cfg(test)]
// Exact float comparisons are the point of these tests (zeros, unchanged buffers, −∞).
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_pcg::Pcg64Mcg;

    fn random_weights(m: usize, seed: u64) -> Vec<f64> {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let mut w: Vec<f64> = (0..m)
            .map(|_| {
                let x: f64 = rng.random();
                x * x * x
            })
            .collect();
        if m >= 3 {
            w[m / 3] = 0.0;
        }
        let s: f64 = w.iter().sum();
        for v in &mut w {
            *v /= s;
        }
        w
    }

    fn counts(idx: &[usize], m: usize) -> Vec<usize> {
        let mut c = vec![0; m];
        for &i in idx {
            c[i] += 1;
        }
        c
    }

    /// SPEC §7 test 11: systematic copy counts are within ±1 of M·w_i.
    #[test]
    fn systematic_copy_counts_within_one() {
        let mut rng = Pcg64Mcg::seed_from_u64(5);
        for m in [1_usize, 7, 100, 400, 1000] {
            for trial in 0..20 {
                let w = random_weights(m, trial + 100 * m as u64);
                let w = &w[..];
                let mut r = Resampler::new(Resampling::Systematic);
                let mut out = Vec::new();
                r.resample(w, &mut rng, &mut out);
                assert_eq!(out.len(), w.len());
                assert!(out.windows(2).all(|p| p[0] <= p[1]));
                let s: f64 = w.iter().sum();
                let c = counts(&out, w.len());
                for i in 0..w.len() {
                    let expect = w.len() as f64 * w[i] / s;
                    assert!(
                        (c[i] as f64 - expect).abs() < 1.0 + 1e-9,
                        "particle {i}: {} copies, M·w = {expect}",
                        c[i]
                    );
                    if w[i] == 0.0 {
                        assert_eq!(c[i], 0);
                    }
                }
            }
        }
    }

    /// SPEC §7 test 11: N_eff = M for uniform weights.
    #[test]
    fn ess_of_uniform_weights_is_m() {
        for m in [1_usize, 10, 400] {
            let w = vec![1.0 / m as f64; m];
            assert!((effective_sample_size(&w) - m as f64).abs() < 1e-9 * m as f64);
        }
        let mut one_hot = vec![0.0; 10];
        one_hot[3] = 1.0;
        assert!((effective_sample_size(&one_hot) - 1.0).abs() < 1e-15);
    }

    /// Every scheme is unbiased: the mean copy count over many draws ≈ M·w_i.
    #[test]
    fn all_schemes_are_unbiased() {
        let m = 50;
        let w = random_weights(m, 42);
        let draws = 20_000;
        for scheme in [
            Resampling::Systematic,
            Resampling::Stratified,
            Resampling::Residual,
            Resampling::Multinomial,
        ] {
            let mut rng = Pcg64Mcg::seed_from_u64(7);
            let mut r = Resampler::new(scheme);
            let mut out = Vec::new();
            let mut total = vec![0.0_f64; m];
            for _ in 0..draws {
                r.resample(&w, &mut rng, &mut out);
                assert_eq!(out.len(), m, "{scheme:?}");
                assert!(
                    out.windows(2).all(|p| p[0] <= p[1]),
                    "{scheme:?} not sorted"
                );
                for &i in &out {
                    total[i] += 1.0;
                }
            }
            for i in 0..m {
                let mean = total[i] / f64::from(draws);
                let expect = m as f64 * w[i];
                // Binomial std of the mean count is at most sqrt(M·w(1−w)/draws).
                let tol = 5.0 * (expect.max(1e-3) / f64::from(draws)).sqrt() + 1e-9;
                assert!(
                    (mean - expect).abs() < tol,
                    "{scheme:?} particle {i}: mean {mean}, expected {expect}"
                );
                if w[i] == 0.0 {
                    assert!(total[i] == 0.0, "{scheme:?} copied a zero-weight particle");
                }
            }
        }
    }

    #[test]
    fn residual_keeps_deterministic_copies() {
        let w = [0.5, 0.25, 0.125, 0.125];
        let mut r = Resampler::new(Resampling::Residual);
        let mut out = Vec::new();
        r.resample(&w, &mut Pcg64Mcg::seed_from_u64(1), &mut out);
        // 4·w = (2, 1, 0.5, 0.5): two copies of 0, one of 1, one of 2 or 3.
        assert_eq!(&out[..3], &[0, 0, 1]);
        assert!(out[3] == 2 || out[3] == 3);
    }

    #[test]
    fn degenerate_weights_fall_back_to_identity() {
        let mut out = Vec::new();
        let mut rng = Pcg64Mcg::seed_from_u64(1);
        for scheme in [Resampling::Systematic, Resampling::Residual] {
            let mut r = Resampler::new(scheme);
            r.resample(&[0.0, 0.0, 0.0], &mut rng, &mut out);
            assert_eq!(out, vec![0, 1, 2]);
        }
    }

    #[test]
    fn lse_and_normalisation() {
        assert_eq!(log_sum_exp(&[f64::NEG_INFINITY; 3]), f64::NEG_INFINITY);
        assert_eq!(log_sum_exp(&[]), f64::NEG_INFINITY);
        let x = [-1000.0, -1000.0];
        assert!((log_sum_exp(&x) - (-1000.0 + 2f64.ln())).abs() < 1e-12);
        let mut w = [0.0; 3];
        let lse = normalise_log_weights(&[-2000.0, f64::NEG_INFINITY, -2000.0], &mut w).unwrap();
        assert!((lse - (-2000.0 + 2f64.ln())).abs() < 1e-9);
        assert!((w[0] - 0.5).abs() < 1e-12 && w[1] == 0.0 && w[0] == w[2]);
        let before = w;
        assert!(normalise_log_weights(&[f64::NEG_INFINITY; 3], &mut w).is_none());
        assert_eq!(w, before);
    }
}
