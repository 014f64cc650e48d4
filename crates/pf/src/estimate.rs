//! Per-frame estimates from the weighted particle set (SPEC §3.7).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::{ActionState, TableRegion};

/// Bins per axis of the θ histogram (SPEC §3.7: a 16×16 grid over R).
pub const HISTOGRAM_BINS: usize = 16;

/// Floor of det C_θ (m⁴) in the Gaussian entropy: θ known to within about a micrometre per axis.
/// Keeps H_θ finite (≈ −24.8 nats) when every particle has the same θ.
pub const DET_FLOOR: f64 = 1e-24;

/// What the filter believes at one frame, computed from the weighted particle set before
/// resampling (SPEC §3.7–§3.8).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// 0-based index of the frame (the number of earlier [`crate::Tracker::step`] calls).
    pub frame: usize,
    /// True when no particle had a usable likelihood this frame (all −∞/NaN): the weights were
    /// kept from the prior and every estimate below describes the prediction only.
    pub degenerate: bool,
    /// P(a | I_{1:t}) per action, summing to 1.
    pub action_posterior: Vec<f64>,
    /// The most probable action (ties: the smaller index).
    pub map_action: usize,
    /// H_a = −Σ_a P(a) log P(a), nats.
    pub action_entropy: f64,
    /// θ̄ = Σ w_i θ_i over all particles (marginalising a and k; E18), metres, actor frame.
    pub theta_mean: [f64; 2],
    /// Per-component weighted standard deviation of θ, metres.
    pub theta_std: [f64; 2],
    /// Weighted covariance C_θ, m².
    pub theta_cov: [[f64; 2]; 2],
    /// θ̄ conditioned on the MAP action (option of SPEC §3.7), metres.
    pub theta_mean_map_action: [f64; 2],
    /// Gaussian entropy H_θ = ½ log((2πe)² det C_θ) in nats (θ in metres; det floored at
    /// [`DET_FLOOR`]).
    pub theta_entropy: f64,
    /// Entropy of the weighted θ histogram on a 16×16 grid over R (particles outside R count in
    /// the border bins), divided by log 256: 0 = one cell, 1 = uniform over R.
    pub theta_histogram_entropy: f64,
    /// Effective sample size 1/Σw² of this frame's weights.
    pub ess: f64,
    /// Weighted mean of SPEC's 1-based k over all particles.
    pub mean_k: f64,
    /// Weighted mean progress k/N over all particles, in (0, 1].
    pub progress: f64,
    /// Weighted mean progress k/N of the MAP action's particles.
    pub map_action_progress: f64,
    /// Index of the particle with the largest likelihood ℓ_i (the largest weight on a
    /// degenerate frame).
    pub best_particle: usize,
    /// Its log-likelihood ℓ_i (−∞ on a degenerate frame).
    pub best_log_likelihood: f64,
    /// Its action.
    pub best_action: usize,
    /// Its corrected pose x̃ (p, q, r), metres, actor frame (SPEC §3.7, Fig. 3).
    pub best_pose: [f64; 9],
    /// The best pose median-filtered per coordinate over a causal window (default 5 frames;
    /// Fig. 4).
    pub smoothed_pose: [f64; 9],
    /// The weighted mean of the corrected poses x̃ of the MAP action's particles (metres, actor
    /// frame; all particles when that action has no weight): the posterior-mean pose given the
    /// action, the minimum-mean-square alternative to the best particle (not in the paper).
    /// Being a mean of corrected poses, its segment lengths can be slightly shorter than the
    /// arm's.
    pub mean_pose: [f64; 9],
}

/// Causal per-coordinate median filter of poses over the last `window` frames.
#[derive(Debug, Clone)]
pub struct MedianFilter {
    window: usize,
    history: VecDeque<[f64; 9]>,
    scratch: Vec<f64>,
}

impl MedianFilter {
    /// A filter over `window` ≥ 1 frames.
    pub fn new(window: usize) -> Self {
        let window = window.max(1);
        Self {
            window,
            history: VecDeque::with_capacity(window),
            scratch: Vec::with_capacity(window),
        }
    }

    /// Forget the history.
    pub fn reset(&mut self) {
        self.history.clear();
    }

    /// Add this frame's pose and return the median of the last `window` poses (fewer at the
    /// start); an even count gives the mean of the two middle values.
    pub fn push(&mut self, pose: [f64; 9]) -> [f64; 9] {
        if self.history.len() == self.window {
            self.history.pop_front();
        }
        self.history.push_back(pose);
        let mut out = [0.0; 9];
        for (c, o) in out.iter_mut().enumerate() {
            self.scratch.clear();
            self.scratch.extend(self.history.iter().map(|p| p[c]));
            *o = median_of(&mut self.scratch);
        }
        out
    }
}

/// The median of `v` (sorted in place; an even count gives the mean of the two middle values).
fn median_of(v: &mut [f64]) -> f64 {
    v.sort_unstable_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Centred per-coordinate median filter of poses (SPEC §3.7's option): frame t's output is the
/// median of frames t − h … t + h, h = (window − 1)/2, truncated at both ends of the sequence.
/// Streaming: frame t's output is known once frame t + h has been pushed, so the outputs lag
/// the inputs by h frames, and [`CentredMedian::finish`] returns the last h. For offline
/// tracking (a file, not a live camera); [`MedianFilter`] is the causal filter of the tracker.
#[derive(Debug, Clone)]
pub struct CentredMedian {
    half: usize,
    /// The inputs still needed: frames `first` … `pushed − 1`.
    history: VecDeque<[f64; 9]>,
    first: usize,
    pushed: usize,
    emitted: usize,
    scratch: Vec<f64>,
}

impl CentredMedian {
    /// A filter over an odd `window` ≥ 1 of frames (1: the input unchanged).
    ///
    /// # Errors
    /// [`PfError::InvalidConfig`](crate::PfError::InvalidConfig) when `window` is even or 0: an even window has
    /// no centre.
    pub fn new(window: usize) -> Result<Self, crate::PfError> {
        if window.is_multiple_of(2) {
            return Err(crate::PfError::InvalidConfig(format!(
                "a centred median needs an odd window ≥ 1 (frames t − h … t + h), got {window}"
            )));
        }
        Ok(Self {
            half: window / 2,
            history: VecDeque::with_capacity(window),
            first: 0,
            pushed: 0,
            emitted: 0,
            scratch: Vec::with_capacity(window),
        })
    }

    /// Frames by which the outputs lag the inputs, (window − 1)/2.
    pub fn lag(&self) -> usize {
        self.half
    }

    /// Forget every frame (the next push is frame 0 of a new sequence).
    pub fn reset(&mut self) {
        self.history.clear();
        (self.first, self.pushed, self.emitted) = (0, 0, 0);
    }

    /// Add the next frame's pose; returns the output of frame `pushed − 1 − lag` once it is
    /// known (`None` for the first `lag` frames).
    pub fn push(&mut self, pose: [f64; 9]) -> Option<[f64; 9]> {
        self.history.push_back(pose);
        self.pushed += 1;
        (self.pushed > self.emitted + self.half).then(|| self.emit())
    }

    /// The outputs of the frames not yet returned (the last `lag`, or fewer when fewer were
    /// pushed), in order; the filter is then empty.
    pub fn finish(&mut self) -> Vec<[f64; 9]> {
        let mut out = Vec::with_capacity(self.pushed - self.emitted);
        while self.emitted < self.pushed {
            out.push(self.emit());
        }
        self.reset();
        out
    }

    /// The output of frame `emitted` from the frames pushed so far.
    fn emit(&mut self) -> [f64; 9] {
        let t = self.emitted;
        let lo = t.saturating_sub(self.half);
        let hi = (t + self.half + 1).min(self.pushed);
        let mut out = [0.0; 9];
        for (c, o) in out.iter_mut().enumerate() {
            self.scratch.clear();
            self.scratch.extend(
                self.history
                    .range(lo - self.first..hi - self.first)
                    .map(|p| p[c]),
            );
            *o = median_of(&mut self.scratch);
        }
        self.emitted += 1;
        // Frame t + 1 needs frames from t + 1 − h on.
        while self.first < self.emitted.saturating_sub(self.half) {
            self.history.pop_front();
            self.first += 1;
        }
        out
    }
}

/// The centred median ([`CentredMedian`]) of a whole sequence of poses.
///
/// # Errors
/// When `window` is even or 0.
pub fn centred_median(poses: &[[f64; 9]], window: usize) -> Result<Vec<[f64; 9]>, crate::PfError> {
    let mut f = CentredMedian::new(window)?;
    let mut out: Vec<[f64; 9]> = poses.iter().filter_map(|p| f.push(*p)).collect();
    out.extend(f.finish());
    Ok(out)
}

/// Everything [`compute`] reads about the current weighted set.
pub(crate) struct WeightedSet<'a> {
    pub states: &'a [ActionState],
    pub weights: &'a [f64],
    pub log_likelihoods: &'a [f64],
    /// Poses, `pose_stride` per particle; particle i's x̃ is `poses[i * pose_stride]`.
    pub poses: &'a [[f64; 9]],
    pub pose_stride: usize,
    pub region: &'a TableRegion,
    /// Number of states N_a of every action.
    pub n_states: &'a [usize],
}

/// Reusable buffers of the estimator (one allocation per tracker, not per frame).
#[derive(Debug, Clone)]
pub(crate) struct Scratch {
    posterior: Vec<f64>,
    /// Σ_{i∈a} w_i k_i per action (1-based k).
    k_sum: Vec<f64>,
    histogram: Vec<f64>,
}

impl Scratch {
    pub(crate) fn new(n_actions: usize) -> Self {
        Self {
            posterior: vec![0.0; n_actions],
            k_sum: vec![0.0; n_actions],
            histogram: vec![0.0; HISTOGRAM_BINS * HISTOGRAM_BINS],
        }
    }
}

#[inline]
fn bin(u: f64) -> usize {
    let b = (u + 1.0) * 0.5 * HISTOGRAM_BINS as f64;
    // Truncation is floor for b ≥ 0; NaN and negatives go to the first bin.
    if b >= 0.0 {
        (b as usize).min(HISTOGRAM_BINS - 1)
    } else {
        0
    }
}

/// The estimates of SPEC §3.7 (all sums sequential, in particle order, for bit-reproducibility).
pub(crate) fn compute(
    set: &WeightedSet<'_>,
    scratch: &mut Scratch,
    frame: usize,
    degenerate: bool,
    median: &mut MedianFilter,
) -> Estimate {
    let n_actions = set.n_states.len();
    let post = &mut scratch.posterior;
    post.clear();
    post.resize(n_actions, 0.0);
    scratch.histogram.fill(0.0);

    // Moments relative to the first particle's θ: exact zeros when every θ is the same.
    let r0 = set.states.first().map_or([0.0; 2], |s| s.theta);
    let (mut su, mut sv) = (0.0, 0.0);
    let k_sum = &mut scratch.k_sum;
    k_sum.clear();
    k_sum.resize(n_actions, 0.0);
    let mut sum_w2 = 0.0;
    for (s, &w) in set.states.iter().zip(set.weights) {
        post[s.action] += w;
        su += w * (s.theta[0] - r0[0]);
        sv += w * (s.theta[1] - r0[1]);
        k_sum[s.action] += w * (s.k + 1) as f64;
        sum_w2 += w * w;
        scratch.histogram[bin(s.theta[1]) * HISTOGRAM_BINS + bin(s.theta[0])] += w;
    }
    // The weights are normalised; dividing by their float sum keeps Σ_a P(a) = 1 to rounding.
    let total: f64 = post.iter().sum();
    let total = if total > 0.0 { total } else { 1.0 };
    for p in post.iter_mut() {
        *p /= total;
    }
    let mut map_action = 0;
    for a in 0..n_actions {
        if post[a] > post[map_action] {
            map_action = a;
        }
    }
    let action_entropy = -post
        .iter()
        .filter(|p| **p > 0.0)
        .map(|p| p * p.ln())
        .sum::<f64>();

    // Second moments in normalised units, then to metres.
    let (du_mean, dv_mean) = (su / total, sv / total);
    let (mu_u, mu_v) = (r0[0] + du_mean, r0[1] + dv_mean);
    let (mut cuu, mut cuv, mut cvv) = (0.0, 0.0, 0.0);
    let (mut mu_a, mut mv_a, mut wa) = (0.0, 0.0, 0.0);
    let mut pose_a = [0.0; 9];
    for (i, (s, &w)) in set.states.iter().zip(set.weights).enumerate() {
        let du = (s.theta[0] - r0[0]) - du_mean;
        let dv = (s.theta[1] - r0[1]) - dv_mean;
        cuu += w * du * du;
        cuv += w * du * dv;
        cvv += w * dv * dv;
        if s.action == map_action {
            wa += w;
            mu_a += w * s.theta[0];
            mv_a += w * s.theta[1];
            for (m, x) in pose_a.iter_mut().zip(&set.poses[i * set.pose_stride]) {
                *m += w * x;
            }
        }
    }
    let [hx, hy] = set.region.half_extents;
    let cov = [
        [hx * hx * cuu / total, hx * hy * cuv / total],
        [hx * hy * cuv / total, hy * hy * cvv / total],
    ];
    let det = cov[0][0] * cov[1][1] - cov[0][1] * cov[1][0];
    let two_pi_e = 2.0 * std::f64::consts::PI * std::f64::consts::E;
    let theta_entropy = 0.5 * (two_pi_e * two_pi_e * det.max(DET_FLOOR)).ln();
    let hist_entropy = -scratch
        .histogram
        .iter()
        .filter(|p| **p > 0.0)
        .map(|p| {
            let p = p / total;
            p * p.ln()
        })
        .sum::<f64>()
        / ((HISTOGRAM_BINS * HISTOGRAM_BINS) as f64).ln();
    let theta_mean_map_action = if wa > 0.0 {
        set.region.to_metres([mu_a / wa, mv_a / wa])
    } else {
        set.region.to_metres([mu_u, mu_v])
    };

    // Best particle: largest ℓ_i, or the largest weight when no ℓ_i is usable.
    let mut best = 0;
    if degenerate {
        for (i, w) in set.weights.iter().enumerate() {
            if *w > set.weights[best] {
                best = i;
            }
        }
    } else {
        for (i, l) in set.log_likelihoods.iter().enumerate() {
            if *l > set.log_likelihoods[best] {
                best = i;
            }
        }
    }
    let best_pose = set.poses[best * set.pose_stride];
    let smoothed_pose = median.push(best_pose);
    let mean_pose = if wa > 0.0 {
        pose_a.map(|m| m / wa)
    } else {
        // No weight on the MAP action (all weights zero): the unweighted mean of every particle.
        let n = set.states.len().max(1) as f64;
        let mut m = [0.0; 9];
        for i in 0..set.states.len() {
            for (mc, x) in m.iter_mut().zip(&set.poses[i * set.pose_stride]) {
                *mc += x / n;
            }
        }
        m
    };

    Estimate {
        frame,
        degenerate,
        action_posterior: post.clone(),
        map_action,
        action_entropy: action_entropy.max(0.0),
        theta_mean: set.region.to_metres([mu_u, mu_v]),
        theta_std: [cov[0][0].max(0.0).sqrt(), cov[1][1].max(0.0).sqrt()],
        theta_cov: cov,
        theta_mean_map_action,
        theta_entropy,
        theta_histogram_entropy: hist_entropy.clamp(0.0, 1.0),
        ess: if sum_w2 > 0.0 {
            total * total / sum_w2
        } else {
            0.0
        },
        mean_k: k_sum.iter().sum::<f64>() / total,
        progress: k_sum
            .iter()
            .zip(set.n_states)
            .map(|(k, n)| k / *n as f64)
            .sum::<f64>()
            / total,
        map_action_progress: if wa > 0.0 {
            k_sum[map_action] / set.n_states[map_action] as f64 / wa
        } else {
            0.0
        },
        best_particle: best,
        best_log_likelihood: set.log_likelihoods[best],
        best_action: set.states[best].action,
        best_pose,
        smoothed_pose,
        mean_pose,
    }
}

#[cfg(test)]
// Exact float comparisons are the point of these tests (zeros, unchanged buffers, −∞).
#[allow(clippy::float_cmp)]
mod tests {
    use super::*;

    fn region() -> TableRegion {
        TableRegion::new([0.1, 0.5], [0.4, 0.15])
    }

    fn run(states: &[ActionState], weights: &[f64], n_states: &[usize]) -> Estimate {
        let m = states.len();
        let ll: Vec<f64> = (0..m).map(|i| -(i as f64)).collect();
        let poses: Vec<[f64; 9]> = (0..m).map(|i| [i as f64; 9]).collect();
        let set = WeightedSet {
            states,
            weights,
            log_likelihoods: &ll,
            poses: &poses,
            pose_stride: 1,
            region: &region(),
            n_states,
        };
        compute(
            &set,
            &mut Scratch::new(n_states.len()),
            3,
            false,
            &mut MedianFilter::new(5),
        )
    }

    /// SPEC §7 test 12: Σ_a P(a) = 1; identical θ → std 0 and histogram entropy 0.
    #[test]
    fn identical_theta_has_zero_spread() {
        let m = 37;
        let states: Vec<ActionState> = (0..m)
            .map(|i| ActionState {
                action: i % 3,
                theta: [0.3, -0.7],
                k: i % 5,
            })
            .collect();
        let w: Vec<f64> = (0..m).map(|i| (i + 1) as f64).collect();
        let s: f64 = w.iter().sum();
        let w: Vec<f64> = w.iter().map(|v| v / s).collect();
        let e = run(&states, &w, &[5, 6, 7]);
        assert!((e.action_posterior.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert_eq!(e.theta_std, [0.0, 0.0]);
        assert_eq!(e.theta_histogram_entropy, 0.0);
        assert!(e.theta_entropy.is_finite());
        let t = region().to_metres([0.3, -0.7]);
        assert!((e.theta_mean[0] - t[0]).abs() < 1e-12 && (e.theta_mean[1] - t[1]).abs() < 1e-12);
        assert_eq!(e.best_particle, 0);
        assert_eq!(e.frame, 3);
    }

    /// Uniform over a 16×16 grid of cell centres → histogram entropy 1; Gaussian entropy and
    /// moments match closed forms.
    #[test]
    fn moments_and_entropies_match_closed_forms() {
        let mut states = Vec::new();
        for j in 0..HISTOGRAM_BINS {
            for i in 0..HISTOGRAM_BINS {
                let c = |n: usize| -1.0 + (2 * n + 1) as f64 / HISTOGRAM_BINS as f64;
                states.push(ActionState {
                    action: usize::from(i >= 8),
                    theta: [c(i), c(j)],
                    k: 0,
                });
            }
        }
        let m = states.len();
        let w = vec![1.0 / m as f64; m];
        let e = run(&states, &w, &[4, 4]);
        assert!((e.theta_histogram_entropy - 1.0).abs() < 1e-12);
        assert!((e.action_posterior[0] - 0.5).abs() < 1e-12);
        assert!((e.action_entropy - 2f64.ln()).abs() < 1e-12);
        assert!((e.ess - m as f64).abs() < 1e-9);
        assert!((e.mean_k - 1.0).abs() < 1e-12 && (e.progress - 0.25).abs() < 1e-12);
        // Discrete uniform on 16 cell centres: variance ((2/16)²·(16²−1)/12) per unit.
        let var_u = (2.0 / 16.0_f64).powi(2) * (256.0 - 1.0) / 12.0;
        let (hx, hy) = (0.4, 0.15);
        assert!((e.theta_cov[0][0] - hx * hx * var_u).abs() < 1e-12);
        assert!((e.theta_cov[1][1] - hy * hy * var_u).abs() < 1e-12);
        assert!(e.theta_cov[0][1].abs() < 1e-12);
        let det = hx * hx * var_u * hy * hy * var_u;
        let h = 0.5 * ((2.0 * std::f64::consts::PI * std::f64::consts::E).powi(2) * det).ln();
        assert!((e.theta_entropy - h).abs() < 1e-9);
        // The MAP action is 0 on a tie; its θ mean is the mean of the left half.
        assert_eq!(e.map_action, 0);
        assert!(e.theta_mean_map_action[0] < 0.1);
    }

    /// The mean pose is Σ_{i∈a*} w_i x̃_i / Σ_{i∈a*} w_i over the MAP action a* (brute force),
    /// and ignores the other actions' particles.
    #[test]
    fn mean_pose_is_the_map_actions_weighted_mean() {
        let m = 11;
        let states: Vec<ActionState> = (0..m)
            .map(|i| ActionState {
                action: usize::from(i % 3 == 0),
                theta: [0.0, 0.0],
                k: 0,
            })
            .collect();
        let raw: Vec<f64> = (0..m).map(|i| 1.0 + (i * i % 7) as f64).collect();
        let s: f64 = raw.iter().sum();
        let w: Vec<f64> = raw.iter().map(|v| v / s).collect();
        let e = run(&states, &w, &[3, 3]);
        let a = e.map_action;
        let (mut num, mut den) = (0.0, 0.0);
        for i in (0..m).filter(|&i| states[i].action == a) {
            num += w[i] * i as f64;
            den += w[i];
        }
        assert!(den > 0.0 && den < 1.0);
        for c in e.mean_pose {
            assert!((c - num / den).abs() < 1e-12, "{c} vs {}", num / den);
        }
    }

    #[test]
    fn causal_median_filter() {
        let mut f = MedianFilter::new(5);
        let seq = [1.0, 10.0, 2.0, 3.0, 100.0, 4.0, 5.0];
        let expect = [1.0, 5.5, 2.0, 2.5, 3.0, 4.0, 4.0];
        for (x, e) in seq.iter().zip(expect) {
            let out = f.push([*x; 9]);
            assert!(
                out.iter().all(|v| (*v - e).abs() < 1e-15),
                "{x}: {out:?} vs {e}"
            );
        }
    }

    /// Brute force: frame t's window [t − h, t + h] clipped to the sequence, sorted per coordinate.
    fn centred_brute(poses: &[[f64; 9]], window: usize) -> Vec<[f64; 9]> {
        let h = window / 2;
        (0..poses.len())
            .map(|t| {
                let w = &poses[t.saturating_sub(h)..(t + h + 1).min(poses.len())];
                std::array::from_fn(|c| {
                    let mut v: Vec<f64> = w.iter().map(|p| p[c]).collect();
                    v.sort_by(f64::total_cmp);
                    let n = v.len();
                    if n % 2 == 1 {
                        v[n / 2]
                    } else {
                        f64::midpoint(v[n / 2 - 1], v[n / 2])
                    }
                })
            })
            .collect()
    }

    #[test]
    #[allow(clippy::float_cmp)] // the same values selected: exact
    fn centred_median_matches_brute_force() {
        // A deterministic pseudo-random sequence with repeated values and outliers.
        let mut x: u64 = 12345;
        let mut next = || {
            x = x
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((x >> 33) % 1000) as f64 / 100.0 - 5.0
        };
        let poses: Vec<[f64; 9]> = (0..40).map(|_| std::array::from_fn(|_| next())).collect();
        for window in [1, 3, 5, 7, 9, 61] {
            for n in [0, 1, 2, 3, 4, 7, 40] {
                let seq = &poses[..n];
                let got = centred_median(seq, window).unwrap();
                assert_eq!(
                    got,
                    centred_brute(seq, window),
                    "window {window}, {n} frames"
                );
            }
        }
        assert_eq!(centred_median(&poses, 1).unwrap(), poses);
    }

    #[test]
    #[allow(clippy::float_cmp)]
    fn centred_median_streams_with_a_lag_and_truncates_the_ends() {
        let seq = [1.0, 10.0, 2.0, 3.0, 100.0, 4.0, 5.0];
        // Windows: [1,10] [1,10,2] [10,2,3] [2,3,100] [3,100,4] [100,4,5] [4,5].
        let expect = [5.5, 2.0, 3.0, 3.0, 4.0, 5.0, 4.5];
        let mut f = CentredMedian::new(3).unwrap();
        assert_eq!(f.lag(), 1);
        let mut out = Vec::new();
        for (t, x) in seq.iter().enumerate() {
            let o = f.push([*x; 9]);
            // Nothing for the first frame, then frame t − 1's output.
            assert_eq!(o.is_some(), t >= 1, "frame {t}");
            out.extend(o);
        }
        out.extend(f.finish());
        let got: Vec<f64> = out.iter().map(|p| p[0]).collect();
        assert_eq!(got, expect);
        assert!(out.iter().all(|p| p.iter().all(|v| *v == p[0])));
        // finish() leaves an empty filter: a new sequence starts at frame 0.
        assert!(f.finish().is_empty());
        assert_eq!(f.push([7.0; 9]), None);
        assert_eq!(f.finish(), vec![[7.0; 9]]);
        // The history stays bounded by the window.
        let mut g = CentredMedian::new(5).unwrap();
        for t in 0..100 {
            g.push([f64::from(t); 9]);
            assert!(g.history.len() <= 5, "{} frames kept", g.history.len());
        }
    }

    #[test]
    fn centred_median_rejects_even_windows() {
        for w in [0, 2, 4] {
            let e = CentredMedian::new(w).unwrap_err().to_string();
            assert!(
                e.contains("odd window") && e.contains(&w.to_string()),
                "{e}"
            );
            assert!(centred_median(&[[0.0; 9]], w).is_err());
        }
    }
}
