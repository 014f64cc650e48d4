//! The particle filter itself (SPEC §3.2–§3.8).

use actrack_phmm::Phmm;
use rand::Rng;
use rayon::prelude::*;

use crate::config::check_grammar_matrix;
use crate::estimate::{self, MedianFilter, Scratch, WeightedSet};
use crate::model::{ActionCache, D, Next};
use crate::resample::{
    Resampler, allocate_actions, effective_sample_size, log_sum_exp, normalise_log_weights,
};
use crate::rng::{DOMAIN_PARTICLE, DOMAIN_RESAMPLE, stream};
use crate::{
    ActionBalance, ActionState, Boundary, CloudParticle, Estimate, Grammar, KInit,
    ObservationModel, PfError, PoseSampling, ResampleWhen, TrackerConfig,
};

/// Particles per rayon task: enough work per task to amortise scheduling.
const MIN_PARTICLES_PER_TASK: usize = 64;

/// The grammar in sampling form.
#[derive(Debug, Clone)]
enum GrammarCache {
    Loop,
    Uniform,
    /// Cumulative rows, |𝒜|×|𝒜| row-major.
    Matrix(Vec<f64>),
}

/// Everything the per-particle kernels read (shared across worker threads).
struct Kernel<'a> {
    models: &'a [ActionCache],
    grammar: &'a GrammarCache,
    config: &'a TrackerConfig,
    /// Per-action θ supports in normalised units of R (centre, half-extents), if configured.
    boxes: Option<&'a [ThetaBox]>,
    frame: u64,
}

/// A per-action θ support in normalised units of R.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ThetaBox {
    centre: [f64; 2],
    half: [f64; 2],
}

impl Kernel<'_> {
    #[inline]
    fn uniform_theta<R: Rng + ?Sized>(rng: &mut R) -> [f64; 2] {
        [
            rng.random::<f64>().mul_add(2.0, -1.0),
            rng.random::<f64>().mul_add(2.0, -1.0),
        ]
    }

    /// θ ~ U(R), or U(the action's support) when per-action regions are configured.
    #[inline]
    fn draw_theta<R: Rng + ?Sized>(&self, action: usize, rng: &mut R) -> [f64; 2] {
        let u = Self::uniform_theta(rng);
        match self.boxes {
            None => u,
            Some(b) => {
                let b = &b[action];
                [
                    b.half[0].mul_add(u[0], b.centre[0]),
                    b.half[1].mul_add(u[1], b.centre[1]),
                ]
            }
        }
    }

    /// A speed for a new action instance: log-uniform over the configured range (1 without).
    #[inline]
    fn draw_speed<R: Rng + ?Sized>(&self, rng: &mut R) -> f64 {
        match self.config.speed_range {
            None => 1.0,
            Some([lo, hi]) => (lo.ln() + (hi / lo).ln() * rng.random::<f64>()).exp(),
        }
    }

    /// SPEC §3.2: a ~ U(𝒜), θ ~ U(R), k ~ π_a (or uniform).
    fn init<R: Rng + ?Sized>(&self, rng: &mut R) -> ActionState {
        let action = rng.random_range(0..self.models.len());
        let theta = self.draw_theta(action, rng);
        let m = &self.models[action];
        let k = match self.config.k_init {
            KInit::First => m.draw_start(rng),
            KInit::Uniform => rng.random_range(0..m.n),
        };
        ActionState { action, theta, k }
    }

    /// SPEC §3.3: timing, grammar on exit, θ diffusion with the cooling schedule at k'.
    fn propagate<R: Rng + ?Sized>(&self, s: &mut ActionState, speed: &mut f64, rng: &mut R) {
        // A phase jump replaces the frame's transitions (no draw at all without the option, so
        // the default streams are unchanged).
        if let Some(rate) = self.config.phase_jump
            && rng.random::<f64>() < rate
        {
            s.k = rng.random_range(0..self.models[s.action].n);
        } else if self.config.speed_range.is_none() {
            self.transition(s, rng);
        } else {
            let whole = speed.floor();
            let mut n = whole as usize;
            if rng.random::<f64>() < *speed - whole {
                n += 1;
            }
            for _ in 0..n {
                if self.transition(s, rng) {
                    *speed = self.draw_speed(rng);
                    break;
                }
            }
        }
        let sigma = self.models[s.action].sigma(s.k);
        self.diffuse_theta(s, sigma, rng);
    }

    /// One draw from the transition row (SPEC §3.3 steps 1–2); true when the particle left its
    /// action and started a new instance.
    fn transition<R: Rng + ?Sized>(&self, s: &mut ActionState, rng: &mut R) -> bool {
        match self.models[s.action].next(s.k, rng) {
            Next::State(k) => {
                s.k = k;
                false
            }
            Next::Exit => {
                let n_actions = self.models.len();
                s.action = match self.grammar {
                    GrammarCache::Loop => s.action,
                    GrammarCache::Uniform => rng.random_range(0..n_actions),
                    GrammarCache::Matrix(cum) => {
                        let row = &cum[s.action * n_actions..(s.action + 1) * n_actions];
                        let u: f64 = rng.random();
                        row.partition_point(|&c| c <= u).min(n_actions - 1)
                    }
                };
                s.k = self.models[s.action].draw_start(rng);
                s.theta = self.draw_theta(s.action, rng);
                true
            }
        }
    }

    /// θ' = θ + σ ε with the boundary handling of SPEC §3.3 (per-action support if set).
    #[inline]
    fn diffuse_theta<R: Rng + ?Sized>(&self, s: &mut ActionState, sigma: f64, rng: &mut R) {
        let c = self.config;
        let support = self.boxes.map(|b| b[s.action]);
        for (i, t) in s.theta.iter_mut().enumerate() {
            let e: f64 = rng.sample(rand_distr::StandardNormal);
            *t = sigma.mul_add(e, *t);
            if let Boundary::Reflect(b) = c.boundary {
                *t = match support {
                    None => reflect(*t, b),
                    Some(sb) => {
                        let (m, h) = (sb.centre[i], sb.half[i]);
                        h.mul_add(reflect((*t - m) / h, b), m)
                    }
                };
            }
        }
    }

    /// SPEC §3.4: draw the particle's poses and correct them.
    fn generate<R: Rng + ?Sized, O: ObservationModel + ?Sized>(
        &self,
        s: &ActionState,
        rng: &mut R,
        obs: &O,
        out: &mut [[f64; D]],
    ) {
        let m = &self.models[s.action];
        let theta_m = self.config.table.to_metres(s.theta);
        for x in out {
            match self.config.pose_sampling {
                PoseSampling::Gaussian { .. } => m.sample(s.k, theta_m, rng, x),
                PoseSampling::Mean => m.mean(s.k, theta_m, x),
            }
            obs.correct(x);
        }
    }
}

/// One particle's slots in the per-frame loop: index, (state, speed), poses.
type ParticleItem<'x> = (
    usize,
    ((&'x mut ActionState, &'x mut f64), &'x mut [[f64; D]]),
);

/// Buffers of the mixture resampler (reused every frame).
#[derive(Debug, Clone, Default)]
struct MixtureScratch {
    /// log P(a) of every action.
    log_mass: Vec<f64>,
    /// P(a) of every action.
    posterior: Vec<f64>,
    /// Particles allocated to every action.
    counts: Vec<usize>,
    /// Global indices of the current action's particles.
    members: Vec<usize>,
    /// Their weights, normalised within the action.
    member_w: Vec<f64>,
    /// Their log weights (for the group LSE).
    member_log_w: Vec<f64>,
    /// Ancestors drawn within the action (indices into `members`).
    draws: Vec<usize>,
}

/// Fold `x` into [−b, b] by reflection at the borders (any distance).
#[inline]
pub(crate) fn reflect(x: f64, b: f64) -> f64 {
    if (-b..=b).contains(&x) {
        return x;
    }
    if !x.is_finite() {
        return 0.0;
    }
    let period = 4.0 * b;
    let y = (x + b).rem_euclid(period);
    let y = if y > 2.0 * b { period - y } else { y };
    y - b
}

/// The action-space particle filter (SPEC §3): M particles ω = (a, θ, k), each generating an arm
/// pose from its action's parametric HMM; an [`ObservationModel`] scores the poses.
///
/// Each [`Tracker::step`] processes one frame in the normative order of SPEC §3.8 and returns the
/// frame's [`Estimate`]. After a step the tracker holds that frame's *weighted* set (the one the
/// estimate describes: [`Tracker::states`], [`Tracker::weights`], [`Tracker::cloud`]); resampling
/// happens at the start of the next step.
///
/// Actions switch only through the exit state E of their model (the loop grammar): a model
/// built with `EndMode::None` has a_iE = 0 everywhere, so its particles never leave the action
/// and the grammar never fires for them (they stay in the last state once they reach it).
///
/// Reproducibility: every random draw comes from a stream derived from (seed, frame, particle)
/// or (seed, frame) for resampling, never from the thread, so a given seed gives bit-identical
/// estimates whatever the number of rayon threads (provided the observation model is
/// deterministic).
#[derive(Debug, Clone)]
pub struct Tracker {
    config: TrackerConfig,
    names: Vec<String>,
    models: Vec<ActionCache>,
    n_states: Vec<usize>,
    grammar: GrammarCache,
    /// Frames processed so far.
    frame: usize,
    states: Vec<ActionState>,
    next_states: Vec<ActionState>,
    /// Per-particle speeds (all 1 without [`TrackerConfig::speed_range`]).
    speeds: Vec<f64>,
    next_speeds: Vec<f64>,
    /// Generated, corrected poses: S per particle, particle-major.
    samples: Vec<[f64; D]>,
    /// Per-action θ supports (normalised units of R), if configured.
    boxes: Option<Vec<ThetaBox>>,
    /// Raw log-likelihoods of every sample.
    sample_ll: Vec<f64>,
    /// Index (within the particle's S samples) of its best-scoring sample: its x̃.
    best_sample: Vec<usize>,
    /// ℓ_i per particle (sanitised: NaN/±∞ → −∞; S > 1: log-mean-exp over the samples).
    ll: Vec<f64>,
    /// Normalised log weights and weights of the current set.
    log_w: Vec<f64>,
    log_w_new: Vec<f64>,
    w: Vec<f64>,
    resampler: Resampler,
    ancestors: Vec<usize>,
    mixture: MixtureScratch,
    scratch: Scratch,
    median: MedianFilter,
    /// Whether `samples` holds the poses of the frame being processed ([`Tracker::predict`]
    /// ran, [`Tracker::update`] not yet).
    predicted: bool,
}

impl Tracker {
    /// A tracker over one parametric HMM per action (9-D poses in the actor frame, 2-D θ in
    /// metres), with one name per action. The models are read into sampling caches; the tracker
    /// keeps no reference to them.
    pub fn new<'a>(
        models: impl IntoIterator<Item = &'a Phmm>,
        action_names: Vec<String>,
        config: TrackerConfig,
    ) -> Result<Self, PfError> {
        let models = models
            .into_iter()
            .enumerate()
            .map(|(a, m)| ActionCache::from_phmm(a, m, config.sigma0, config.sigma_end_ratio))
            .collect::<Result<Vec<_>, _>>()?;
        if models.is_empty() {
            return Err(PfError::NoModels);
        }
        if action_names.len() != models.len() {
            return Err(PfError::NameCount {
                names: action_names.len(),
                models: models.len(),
            });
        }
        let n_actions = models.len();
        let grammar = match &config.grammar {
            Grammar::Loop => GrammarCache::Loop,
            Grammar::Uniform => GrammarCache::Uniform,
            Grammar::Matrix(rows) => {
                check_grammar_matrix(rows, Some(n_actions))?;
                let mut cum = Vec::with_capacity(n_actions * n_actions);
                for row in rows {
                    let total: f64 = row.iter().sum();
                    let mut acc = 0.0;
                    for g in row {
                        acc += g;
                        cum.push(acc / total);
                    }
                }
                GrammarCache::Matrix(cum)
            }
        };
        let boxes = match &config.action_regions {
            None => None,
            Some(regions) => {
                if regions.len() != n_actions {
                    return Err(PfError::InvalidConfig(format!(
                        "{} action regions for {n_actions} actions (one per action, in model \
                         order)",
                        regions.len()
                    )));
                }
                let t = &config.table;
                Some(
                    regions
                        .iter()
                        .map(|r| ThetaBox {
                            centre: t.to_normalised(r.centre),
                            half: [
                                r.half_extents[0] / t.half_extents[0],
                                r.half_extents[1] / t.half_extents[1],
                            ],
                        })
                        .collect(),
                )
            }
        };
        let m = config.particles;
        let s = config.samples_per_particle();
        let init_state = ActionState {
            action: 0,
            theta: [0.0; 2],
            k: 0,
        };
        let n_states = models.iter().map(|c| c.n).collect();
        Ok(Self {
            names: action_names,
            n_states,
            grammar,
            frame: 0,
            states: vec![init_state; m],
            next_states: vec![init_state; m],
            speeds: vec![1.0; m],
            next_speeds: vec![1.0; m],
            samples: vec![[0.0; D]; m * s],
            boxes,
            sample_ll: vec![0.0; m * s],
            best_sample: vec![0; m],
            ll: vec![0.0; m],
            log_w: vec![-(m as f64).ln(); m],
            log_w_new: vec![0.0; m],
            w: vec![1.0 / m as f64; m],
            resampler: Resampler::new(config.resampling),
            ancestors: Vec::with_capacity(m),
            mixture: MixtureScratch::default(),
            scratch: Scratch::new(n_actions),
            median: MedianFilter::new(config.median_window),
            predicted: false,
            models,
            config,
        })
    }

    /// Forget everything: the next [`Tracker::step`] is frame 0 again (same seed, same draws).
    pub fn reset(&mut self) {
        self.frame = 0;
        self.predicted = false;
        self.median.reset();
        let m = self.config.particles;
        self.log_w.fill(-(m as f64).ln());
        self.w.fill(1.0 / m as f64);
    }

    /// Process one frame (SPEC §3.8) and return its estimate.
    ///
    /// Frame 0: initialise (§3.2), generate poses (§3.4), weight (§3.5). Later frames: resample
    /// (§3.6; every frame or on the ESS threshold), propagate (§3.3), generate, weight. The
    /// estimate (§3.7) describes the weighted set before the next resampling.
    ///
    /// If no particle gets a usable log-likelihood (all −∞/NaN), the prior weights are kept,
    /// the estimate is flagged [`Estimate::degenerate`] and filtering carries on.
    pub fn step<O: ObservationModel + ?Sized>(&mut self, obs: &O) -> Estimate {
        self.predict(obs);
        self.update(obs)
    }

    /// The first half of [`Tracker::step`]: resample, propagate and generate the poses of the
    /// frame (corrected by `obs`), without scoring them. [`Tracker::samples`] then holds every
    /// pose that [`Tracker::update`] will score, so that a caller can prepare its observation for
    /// exactly those poses (the region of the image they project into). Calling it again before
    /// `update` changes nothing.
    pub fn predict<O: ObservationModel + ?Sized>(&mut self, obs: &O) {
        if self.predicted {
            return;
        }
        let m = self.config.particles;
        let s = self.config.samples_per_particle();
        let seed = self.config.seed;
        let frame = self.frame as u64;

        if self.frame > 0 {
            self.maybe_resample(frame);
        }

        let kernel = Kernel {
            models: &self.models,
            grammar: &self.grammar,
            config: &self.config,
            boxes: self.boxes.as_deref(),
            frame,
        };
        let first = self.frame == 0;
        let particle = |(i, ((state, speed), poses)): ParticleItem<'_>| {
            let mut rng = stream(seed, DOMAIN_PARTICLE, kernel.frame, i as u64);
            if first {
                *state = kernel.init(&mut rng);
                *speed = kernel.draw_speed(&mut rng);
            } else {
                kernel.propagate(state, speed, &mut rng);
            }
            kernel.generate(state, &mut rng, obs, poses);
        };
        // Same per-particle streams either way, so the result does not depend on this choice.
        if m < 2 * MIN_PARTICLES_PER_TASK || rayon::current_num_threads() == 1 {
            self.states
                .iter_mut()
                .zip(self.speeds.iter_mut())
                .zip(self.samples.chunks_mut(s))
                .enumerate()
                .for_each(particle);
        } else {
            self.states
                .par_iter_mut()
                .zip(self.speeds.par_iter_mut())
                .zip(self.samples.par_chunks_mut(s))
                .enumerate()
                .with_min_len(MIN_PARTICLES_PER_TASK)
                .for_each(particle);
        }
        self.predicted = true;
    }

    /// The second half of [`Tracker::step`]: scores the poses of [`Tracker::predict`] with `obs`,
    /// weights the particles and returns the frame's estimate (predicting first if `predict`
    /// was not called for this frame).
    pub fn update<O: ObservationModel + ?Sized>(&mut self, obs: &O) -> Estimate {
        self.predict(obs);
        self.predicted = false;
        let m = self.config.particles;
        let s = self.config.samples_per_particle();

        // §3.5 weighting.
        obs.log_likelihoods(&self.samples, &mut self.sample_ll);
        let ln_s = (s as f64).ln();
        for i in 0..m {
            let lls = &self.sample_ll[i * s..(i + 1) * s];
            let mut best = 0;
            let mut mx = f64::NEG_INFINITY;
            for (j, &l) in lls.iter().enumerate() {
                let l = sanitise(l);
                if l > mx {
                    mx = l;
                    best = j;
                }
            }
            self.best_sample[i] = best;
            self.ll[i] = if s == 1 || mx == f64::NEG_INFINITY {
                mx
            } else {
                let sum: f64 = lls.iter().map(|&l| (sanitise(l) - mx).exp()).sum();
                mx + sum.ln() - ln_s
            };
        }
        for i in 0..m {
            self.log_w_new[i] = self.log_w[i] + self.ll[i];
        }
        let degenerate = if let Some(lse) = normalise_log_weights(&self.log_w_new, &mut self.w) {
            for i in 0..m {
                self.log_w[i] = self.log_w_new[i] - lse;
            }
            false
        } else {
            // Keep the prior weights (already normalised in log space).
            for i in 0..m {
                self.w[i] = self.log_w[i].exp();
            }
            true
        };

        // The chosen x̃ of every particle sits first in its sample block.
        if s > 1 {
            for i in 0..m {
                let b = self.best_sample[i];
                if b != 0 {
                    self.samples.swap(i * s, i * s + b);
                    self.sample_ll.swap(i * s, i * s + b);
                    self.best_sample[i] = 0;
                }
            }
        }

        let est = {
            let set = WeightedSet {
                states: &self.states,
                weights: &self.w,
                log_likelihoods: &self.ll,
                poses: &self.samples,
                pose_stride: s,
                region: &self.config.table,
                n_states: &self.n_states,
            };
            estimate::compute(
                &set,
                &mut self.scratch,
                self.frame,
                degenerate,
                &mut self.median,
            )
        };
        self.frame += 1;
        est
    }

    fn maybe_resample(&mut self, frame: u64) {
        let m = self.config.particles;
        let resample = match self.config.resample_when {
            ResampleWhen::EveryFrame => true,
            ResampleWhen::EssBelow(f) => effective_sample_size(&self.w) < f * m as f64,
        };
        if !resample {
            return;
        }
        let mut rng = stream(self.config.seed, DOMAIN_RESAMPLE, frame, 0);
        match self.config.action_balance {
            ActionBalance::Joint => {
                self.resampler
                    .resample(&self.w, &mut rng, &mut self.ancestors);
                self.log_w.fill(-(m as f64).ln());
                self.w.fill(1.0 / m as f64);
            }
            ActionBalance::Mixture(floor) => {
                if !self.resample_mixture(floor, &mut rng) {
                    self.resampler
                        .resample(&self.w, &mut rng, &mut self.ancestors);
                    self.log_w.fill(-(m as f64).ln());
                    self.w.fill(1.0 / m as f64);
                }
            }
        }
        for (dst, &a) in self.next_states.iter_mut().zip(&self.ancestors) {
            *dst = self.states[a];
        }
        std::mem::swap(&mut self.states, &mut self.next_states);
        if self.config.speed_range.is_some() {
            for (dst, &a) in self.next_speeds.iter_mut().zip(&self.ancestors) {
                *dst = self.speeds[a];
            }
            std::mem::swap(&mut self.speeds, &mut self.next_speeds);
        }
    }

    /// Mixture resampling ([`ActionBalance::Mixture`]): resample within each action, n_a
    /// particles for action a (at least a floor), and carry P(a) in the new weights
    /// `w_i = P(a_i)/n_{a_i}`. Fills `ancestors` (grouped by action, ascending within each)
    /// and the new `log_w`/`w`. Returns false (changing nothing) if the weights have no finite
    /// total, for the caller to fall back to joint resampling.
    fn resample_mixture<R: Rng + ?Sized>(&mut self, floor: f64, rng: &mut R) -> bool {
        let n_actions = self.models.len();
        let mx = &mut self.mixture;
        mx.log_mass.clear();
        for a in 0..n_actions {
            mx.member_log_w.clear();
            mx.member_log_w.extend(
                self.states
                    .iter()
                    .zip(&self.log_w)
                    .filter(|(s, _)| s.action == a)
                    .map(|(_, &lw)| lw),
            );
            mx.log_mass.push(log_sum_exp(&mx.member_log_w));
        }
        // log_w is normalised, but renormalise the masses against rounding.
        let lse = log_sum_exp(&mx.log_mass);
        if !lse.is_finite() {
            return false;
        }
        mx.posterior.clear();
        mx.posterior
            .extend(mx.log_mass.iter().map(|&l| (l - lse).exp()));
        let eps = self.config.action_switch;
        if eps > 0.0 {
            // Switching only among actions with particles of non-zero weight: an action
            // without any has nothing to resample from.
            let live = mx.log_mass.iter().filter(|l| l.is_finite()).count() as f64;
            for (p, l) in mx.posterior.iter_mut().zip(&mx.log_mass) {
                if l.is_finite() {
                    *p = (1.0 - eps) * *p + eps / live;
                }
            }
        }
        allocate_actions(&mx.posterior, self.config.particles, floor, &mut mx.counts);
        self.ancestors.clear();
        self.log_w_new.clear();
        for a in 0..n_actions {
            let n_a = mx.counts[a];
            if n_a == 0 {
                continue;
            }
            mx.members.clear();
            mx.member_w.clear();
            for (i, (s, &lw)) in self.states.iter().zip(&self.log_w).enumerate() {
                if s.action == a {
                    mx.members.push(i);
                    mx.member_w.push((lw - mx.log_mass[a]).exp());
                }
            }
            mx.draws.clear();
            self.resampler
                .resample_n(&mx.member_w, n_a, rng, &mut mx.draws);
            self.ancestors
                .extend(mx.draws.iter().map(|&j| mx.members[j]));
            let log_p = if eps > 0.0 {
                mx.posterior[a].ln()
            } else {
                mx.log_mass[a] - lse
            };
            let lw = log_p - (n_a as f64).ln();
            self.log_w_new.extend(std::iter::repeat_n(lw, n_a));
        }
        debug_assert_eq!(self.ancestors.len(), self.config.particles);
        std::mem::swap(&mut self.log_w, &mut self.log_w_new);
        self.log_w_new.resize(self.config.particles, 0.0);
        for (w, &lw) in self.w.iter_mut().zip(&self.log_w) {
            *w = lw.exp();
        }
        true
    }

    /// The configuration.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }
    /// The action names, in model order.
    pub fn action_names(&self) -> &[String] {
        &self.names
    }
    /// Number of actions |𝒜|.
    pub fn n_actions(&self) -> usize {
        self.models.len()
    }
    /// Number of HMM states N_a of every action.
    pub fn n_states(&self) -> &[usize] {
        &self.n_states
    }
    /// Number of frames processed so far (the index of the next frame).
    pub fn frame(&self) -> usize {
        self.frame
    }
    /// The particles' states after the last step (θ normalised, k 0-based).
    pub fn states(&self) -> &[ActionState] {
        &self.states
    }
    /// The normalised weights after the last step (uniform before the first).
    pub fn weights(&self) -> &[f64] {
        &self.w
    }
    /// The particles' log-likelihoods ℓ_i of the last step (NaN/+∞ reported as −∞).
    pub fn log_likelihoods(&self) -> &[f64] {
        &self.ll
    }
    /// Every generated pose of the frame (S per particle, particle-major; actor frame): after
    /// [`Tracker::predict`] the poses `update` will score, after a step the scored ones with
    /// each particle's x̃ first in its block.
    pub fn samples(&self) -> &[[f64; D]] {
        &self.samples
    }
    /// The corrected pose x̃ of particle `i` (p, q, r; metres, actor frame) after the last step
    /// (its best-scoring sample when S > 1).
    pub fn particle_pose(&self, i: usize) -> [f64; 9] {
        self.samples[i * self.config.samples_per_particle()]
    }
    /// Iterator over x̃ of every particle.
    pub fn particle_poses(&self) -> impl ExactSizeIterator<Item = &[f64; 9]> + '_ {
        self.samples
            .iter()
            .step_by(self.config.samples_per_particle())
    }
    /// The weighted particle cloud (θ in metres, actor frame) for visualisation.
    pub fn cloud(&self) -> Vec<CloudParticle> {
        let mut out = Vec::with_capacity(self.states.len());
        self.cloud_into(&mut out);
        out
    }
    /// [`Tracker::cloud`] into a reused buffer.
    pub fn cloud_into(&self, out: &mut Vec<CloudParticle>) {
        out.clear();
        out.extend(
            self.states
                .iter()
                .zip(&self.w)
                .map(|(s, &weight)| CloudParticle {
                    action: s.action,
                    theta: self.config.table.to_metres(s.theta),
                    k: s.k,
                    weight,
                }),
        );
    }
}

/// NaN and ±∞ carry no information: −∞.
#[inline]
fn sanitise(l: f64) -> f64 {
    if l.is_finite() { l } else { f64::NEG_INFINITY }
}

#[cfg(test)]
// Exact float comparisons are the point of these tests (zeros, unchanged buffers, −∞).
#[allow(clippy::float_cmp)]
mod tests;
