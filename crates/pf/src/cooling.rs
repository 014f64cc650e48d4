//! The cooling schedule of the θ diffusion (SPEC §3.3, erratum E1).

/// σ(k) = σ₀ · ratio^(k/N): the standard deviation of the θ random walk at progress k of an
/// N-state action, in normalised table units (half-extents).
///
/// With the defaults σ₀ = 0.4 and ratio = 1/16 this is the *decreasing* schedule
/// 0.4·16^(−k/N) of erratum E1: σ(0) = 0.4, σ(N/2) = 0.1, σ(N) = 0.025. The paper's printed
/// formula increases instead; SPEC §3.3 makes the decreasing form normative. `k` is SPEC's
/// 1-based state number (the filter passes the post-transition state k', erratum E10); real
/// values are accepted so the schedule can be plotted or tested at k = N/2.
#[inline]
pub fn cooling_sigma(k: f64, n_states: usize, sigma0: f64, end_ratio: f64) -> f64 {
    let n = n_states.max(1) as f64;
    sigma0 * end_ratio.powf(k / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SPEC §7 test 7.
    #[test]
    fn cooling_endpoints_and_monotone() {
        for n in [10_usize, 40, 50, 64] {
            let s = |k: f64| cooling_sigma(k, n, 0.4, 1.0 / 16.0);
            assert!((s(0.0) - 0.4).abs() < 1e-15);
            assert!((s(n as f64 / 2.0) - 0.1).abs() < 1e-15);
            assert!((s(n as f64) - 0.025).abs() < 1e-15);
            for k in 0..n {
                assert!(s(k as f64 + 1.0) < s(k as f64), "σ must decrease (E1)");
            }
            assert!(s(n as f64) < s(1.0));
        }
        // The alternative reading of E1 (ratio 1/4).
        assert!((cooling_sigma(10.0, 10, 0.4, 0.25) - 0.1).abs() < 1e-15);
    }
}
