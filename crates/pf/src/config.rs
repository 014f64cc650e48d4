//! Tracker configuration: a builder whose [`TrackerConfigBuilder::build`] validates every value
//! once, so the filter only ever sees a valid [`TrackerConfig`].

use serde::{Deserialize, Serialize};

use crate::PfError;

/// The table region R in the actor frame (metres): the θ prior is uniform over it, and θ is
/// normalised internally by its half-extents (SPEC §3.1), so its corners are (±1, ±1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TableRegion {
    /// Centre (x, y) of the region in the actor frame, metres.
    pub centre: [f64; 2],
    /// Half-extents along the actor frame's x and y, metres (SPEC default 0.40 × 0.15).
    pub half_extents: [f64; 2],
}

impl TableRegion {
    /// A region from its centre and half-extents (metres, actor frame).
    pub fn new(centre: [f64; 2], half_extents: [f64; 2]) -> Self {
        Self {
            centre,
            half_extents,
        }
    }

    /// Normalised θ (half-extent units, corners at ±1) → metres in the actor frame.
    #[inline]
    pub fn to_metres(&self, u: [f64; 2]) -> [f64; 2] {
        [
            self.centre[0] + self.half_extents[0] * u[0],
            self.centre[1] + self.half_extents[1] * u[1],
        ]
    }

    /// Metres in the actor frame → normalised θ.
    #[inline]
    pub fn to_normalised(&self, m: [f64; 2]) -> [f64; 2] {
        [
            (m[0] - self.centre[0]) / self.half_extents[0],
            (m[1] - self.centre[1]) / self.half_extents[1],
        ]
    }
}

/// Boundary handling of the θ random walk (SPEC §3.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Boundary {
    /// Reflect θ at the border of the region enlarged by this factor (default 1.25·R).
    Reflect(f64),
    /// No boundary: θ may drift anywhere.
    None,
}

/// The action grammar G(a' | a), applied when a particle leaves its action through the exit
/// state (SPEC §3.3 step 2, erratum E5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Grammar {
    /// G = I: the same action repeats (the paper's literal "a kept constant").
    Loop,
    /// G(a'|a) = 1/|𝒜|: loop with uniform switching (default).
    Uniform,
    /// A general row-stochastic |𝒜|×|𝒜| matrix, `rows[a][a']` = G(a'|a). Its shape is checked
    /// against the number of models when the tracker is built.
    Matrix(Vec<Vec<f64>>),
}

/// How k is initialised on the first frame (SPEC §3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum KInit {
    /// k ~ π_a, the model's start distribution (k = 1 for π = e₁). Default.
    First,
    /// k uniform over the action's states, for videos that start mid-action.
    Uniform,
}

/// The resampling scheme (SPEC §3.6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Resampling {
    /// One uniform offset, M evenly spaced points (default).
    Systematic,
    /// One uniform draw in each of the M strata [n/M, (n+1)/M).
    Stratified,
    /// ⌊M·w_i⌋ deterministic copies, the remainder drawn multinomially from the residuals.
    Residual,
    /// M independent draws (the literal CONDENSATION method).
    Multinomial,
}

/// When to resample (SPEC §3.6).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum ResampleWhen {
    /// Every frame, before propagation (CONDENSATION; default). Weights are then `log w_i = ℓ_i`.
    EveryFrame,
    /// Only when N_eff = 1/Σw² falls below this fraction of M (SPEC: 0.5). Weights accumulate
    /// (`log w_i += ℓ_i`) between resamplings.
    EssBelow(f64),
}

/// How the action dimension is treated when resampling (not in the SPEC; see the crate docs).
///
/// The literal CONDENSATION step ([`ActionBalance::Joint`]) resamples the whole set at once. At
/// the start of an action (the rest pose) every action generates nearly the same pose, so the
/// likelihood carries no action information, and resampling every frame lets genetic drift
/// remove whole actions from the set before the movement starts to discriminate them; a lost
/// action can only come back through the exit state. [`ActionBalance::Mixture`] resamples
/// **within each action** instead (a mixture particle filter, Vermaak, Doucet & Pérez 2003):
/// action a gets `n_a` particles, at least a floor, and the action posterior is carried in
/// the post-resampling weights `w_i = P(a_i)/n_{a_i}`, so it is updated exactly by the
/// likelihoods (`P(a | I_1:t) ∝ P(a | I_1:t−1) · mean likelihood of a's particles`) and never by
/// resampling noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum ActionBalance {
    /// Resample the joint set (SPEC §3.6 literally); weights are uniform afterwards.
    Joint,
    /// Resample within each action. The `f64` is the fraction ε ∈ (0, 1) of M split evenly
    /// over the actions as a floor: every action that still has particles of non-zero weight
    /// keeps at least ⌈ε·M/|𝒜|⌉ of them; the other (1 − ε)·M follow the action posterior.
    /// Default `Mixture(0.25)`.
    Mixture(f64),
}

/// How a particle turns its state into a pose (SPEC §3.4, erratum E14).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PoseSampling {
    /// `samples` Gaussian draws x ~ N(μ_{a,k}(θ), Σ_{a,k}) per particle and frame; their
    /// likelihoods are averaged (log-mean-exp) and the best-scoring draw is kept as x̃. Default 1.
    Gaussian {
        /// Draws per particle per frame, S ≥ 1.
        samples: usize,
    },
    /// The mean pose μ_{a,k}(θ) only (deterministic).
    Mean,
}

/// Default floor fraction of [`ActionBalance::Mixture`].
pub const DEFAULT_ACTION_FLOOR: f64 = 0.25;

/// The validated configuration of a [`crate::Tracker`]. Build it with [`TrackerConfig::builder`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackerConfig {
    pub(crate) particles: usize,
    pub(crate) table: TableRegion,
    pub(crate) sigma0: f64,
    pub(crate) sigma_end_ratio: f64,
    pub(crate) boundary: Boundary,
    pub(crate) grammar: Grammar,
    pub(crate) k_init: KInit,
    pub(crate) resampling: Resampling,
    pub(crate) resample_when: ResampleWhen,
    pub(crate) action_balance: ActionBalance,
    pub(crate) pose_sampling: PoseSampling,
    pub(crate) action_regions: Option<Vec<TableRegion>>,
    #[serde(default)]
    pub(crate) speed_range: Option<[f64; 2]>,
    #[serde(default)]
    pub(crate) phase_jump: Option<f64>,
    #[serde(default)]
    pub(crate) action_switch: f64,
    pub(crate) median_window: usize,
    pub(crate) seed: u64,
}

impl TrackerConfig {
    /// A builder with the SPEC defaults for the given table region: M = 400, σ₀ = 0.4,
    /// σ(N)/σ(0) = 1/16, reflection at 1.25·R, uniform switching grammar, k ~ π_a, systematic
    /// resampling every frame, one pose sample per particle, causal median filter of 5 frames,
    /// seed 0.
    pub fn builder(table: TableRegion) -> TrackerConfigBuilder {
        TrackerConfigBuilder {
            config: TrackerConfig {
                particles: 400,
                table,
                sigma0: 0.4,
                sigma_end_ratio: 1.0 / 16.0,
                boundary: Boundary::Reflect(1.25),
                grammar: Grammar::Uniform,
                k_init: KInit::First,
                resampling: Resampling::Systematic,
                resample_when: ResampleWhen::EveryFrame,
                action_balance: ActionBalance::Mixture(DEFAULT_ACTION_FLOOR),
                pose_sampling: PoseSampling::Gaussian { samples: 1 },
                action_regions: None,
                speed_range: None,
                phase_jump: None,
                action_switch: 0.0,
                median_window: 5,
                seed: 0,
            },
        }
    }

    /// A builder starting from this configuration (to change a few values and re-validate).
    pub fn to_builder(&self) -> TrackerConfigBuilder {
        TrackerConfigBuilder {
            config: self.clone(),
        }
    }

    /// Number of particles M.
    pub fn particles(&self) -> usize {
        self.particles
    }
    /// The table region R (actor frame, metres).
    pub fn table(&self) -> &TableRegion {
        &self.table
    }
    /// σ₀ of the cooling schedule (normalised units).
    pub fn sigma0(&self) -> f64 {
        self.sigma0
    }
    /// σ(N)/σ(0) of the cooling schedule.
    pub fn sigma_end_ratio(&self) -> f64 {
        self.sigma_end_ratio
    }
    /// θ boundary handling.
    pub fn boundary(&self) -> Boundary {
        self.boundary
    }
    /// The action grammar.
    pub fn grammar(&self) -> &Grammar {
        &self.grammar
    }
    /// The k initialisation.
    pub fn k_init(&self) -> KInit {
        self.k_init
    }
    /// The resampling scheme.
    pub fn resampling(&self) -> Resampling {
        self.resampling
    }
    /// When to resample.
    pub fn resample_when(&self) -> ResampleWhen {
        self.resample_when
    }
    /// How the action dimension is resampled.
    pub fn action_balance(&self) -> ActionBalance {
        self.action_balance
    }
    /// How poses are generated.
    pub fn pose_sampling(&self) -> PoseSampling {
        self.pose_sampling
    }
    /// Pose draws per particle per frame (1 in [`PoseSampling::Mean`] mode).
    pub fn samples_per_particle(&self) -> usize {
        match self.pose_sampling {
            PoseSampling::Gaussian { samples } => samples,
            PoseSampling::Mean => 1,
        }
    }
    /// Per-action θ supports (metres, actor frame), if set.
    pub fn action_regions(&self) -> Option<&[TableRegion]> {
        self.action_regions.as_deref()
    }
    /// The range of per-particle speeds, if set.
    pub fn speed_range(&self) -> Option<[f64; 2]> {
        self.speed_range
    }
    /// The phase-jump rate ρ, if set.
    pub fn phase_jump(&self) -> Option<f64> {
        self.phase_jump
    }
    /// The per-frame action-switch probability ε of mixture resampling (0 = none).
    pub fn action_switch(&self) -> f64 {
        self.action_switch
    }
    /// Window of the causal median filter of the best pose, frames.
    pub fn median_window(&self) -> usize {
        self.median_window
    }
    /// The seed of every random stream.
    pub fn seed(&self) -> u64 {
        self.seed
    }
}

/// Builder of a [`TrackerConfig`]; see [`TrackerConfig::builder`] for the defaults.
#[derive(Debug, Clone)]
pub struct TrackerConfigBuilder {
    config: TrackerConfig,
}

impl TrackerConfigBuilder {
    /// Number of particles M (≥ 1; default 400).
    #[must_use]
    pub fn particles(mut self, m: usize) -> Self {
        self.config.particles = m;
        self
    }
    /// The table region R.
    #[must_use]
    pub fn table(mut self, table: TableRegion) -> Self {
        self.config.table = table;
        self
    }
    /// σ₀ of the cooling schedule, normalised units (> 0; default 0.4).
    #[must_use]
    pub fn sigma0(mut self, sigma0: f64) -> Self {
        self.config.sigma0 = sigma0;
        self
    }
    /// σ(N)/σ(0) (in (0, 1] for a cooling schedule; default 1/16, E1's alternative is 1/4).
    #[must_use]
    pub fn sigma_end_ratio(mut self, ratio: f64) -> Self {
        self.config.sigma_end_ratio = ratio;
        self
    }
    /// θ boundary handling (default `Reflect(1.25)`).
    #[must_use]
    pub fn boundary(mut self, boundary: Boundary) -> Self {
        self.config.boundary = boundary;
        self
    }
    /// The action grammar (default [`Grammar::Uniform`]).
    #[must_use]
    pub fn grammar(mut self, grammar: Grammar) -> Self {
        self.config.grammar = grammar;
        self
    }
    /// The k initialisation (default [`KInit::First`]).
    #[must_use]
    pub fn k_init(mut self, k_init: KInit) -> Self {
        self.config.k_init = k_init;
        self
    }
    /// The resampling scheme (default [`Resampling::Systematic`]).
    #[must_use]
    pub fn resampling(mut self, scheme: Resampling) -> Self {
        self.config.resampling = scheme;
        self
    }
    /// When to resample (default [`ResampleWhen::EveryFrame`]).
    #[must_use]
    pub fn resample_when(mut self, when: ResampleWhen) -> Self {
        self.config.resample_when = when;
        self
    }
    /// Shorthand for `resample_when(ResampleWhen::EssBelow(0.5))`, the SPEC's ESS option.
    #[must_use]
    pub fn ess_threshold(self) -> Self {
        self.resample_when(ResampleWhen::EssBelow(0.5))
    }
    /// How the action dimension is resampled (default
    /// [`ActionBalance::Mixture`]`(0.25)`; [`ActionBalance::Joint`] is the SPEC's literal
    /// CONDENSATION step).
    #[must_use]
    pub fn action_balance(mut self, balance: ActionBalance) -> Self {
        self.config.action_balance = balance;
        self
    }
    /// Per-frame action-switch probability ε (not in the SPEC; default 0). With
    /// [`ActionBalance::Mixture`], the carried action posterior becomes
    /// `(1 − ε)·P(a) + ε/|𝒜_live|` at each resampling: a Markov chain on the action label that
    /// lets the label change at any frame with probability ε. Without it, frames that carry
    /// almost no action information (the rest pose, where every action's model differs only
    /// slightly) multiply up until the posterior of the true action underflows, and the
    /// movement that follows cannot bring it back; with it, no action's posterior falls below
    /// about ε/|𝒜| times its likelihood ratio of one frame. No effect with
    /// [`ActionBalance::Joint`].
    #[must_use]
    pub fn action_switch(mut self, epsilon: f64) -> Self {
        self.config.action_switch = epsilon;
        self
    }
    /// How poses are generated (default one Gaussian draw).
    #[must_use]
    pub fn pose_sampling(mut self, mode: PoseSampling) -> Self {
        self.config.pose_sampling = mode;
        self
    }
    /// Shorthand for `pose_sampling(PoseSampling::Gaussian { samples })`.
    #[must_use]
    pub fn samples_per_particle(self, samples: usize) -> Self {
        self.pose_sampling(PoseSampling::Gaussian { samples })
    }
    /// Per-action θ supports, one region per action in model order (metres, actor frame; not in
    /// the SPEC). A particle of action a draws θ uniformly from its region at the start and on
    /// re-entry, and θ is reflected at that region enlarged by the [`Boundary`] factor. Use the
    /// box of each action's training targets (padded): a linear PHMM extrapolated far outside
    /// the θ range it was trained on generates implausible poses. θ stays normalised by the
    /// table region R (σ of the cooling schedule is in R's units). Default: every action uses R.
    #[must_use]
    pub fn action_regions(mut self, regions: Vec<TableRegion>) -> Self {
        self.config.action_regions = Some(regions);
        self
    }
    /// Per-particle speeds (not in the SPEC; default none, i.e. every particle follows the
    /// model's timing). With `Some([lo, hi])` every particle draws a speed s log-uniformly from
    /// [lo, hi] when it starts an action instance (at initialisation and on re-entry through the
    /// grammar) and keeps it for the instance; each frame it then takes ⌊s⌋ transition draws
    /// from its state's row, plus one more with probability s − ⌊s⌋. People move at different
    /// speeds, and the HMM's geometric dwell times alone let particles keep a persistent
    /// faster or slower pace only by chance.
    #[must_use]
    pub fn speed_range(mut self, range: Option<[f64; 2]>) -> Self {
        self.config.speed_range = range;
        self
    }
    /// Phase jumps (not in the SPEC; default none). With `Some(ρ)`, each frame each particle,
    /// with probability ρ, draws its state k uniformly over its action's states instead of
    /// taking the transition row (action and θ are kept; θ then diffuses with σ at the new k).
    /// The motion model then allows, rarely, a jump to any phase of the action: a filter whose
    /// particles all run ahead of or behind the person (a hand held at the mouth longer than
    /// any training demonstration, a pause the model did not see) can recover in a frame
    /// instead of waiting for the slow geometric dwell times, because the jumped particles that
    /// match the image win the next resampling. ρ ∈ (0, 1).
    #[must_use]
    pub fn phase_jump(mut self, rate: Option<f64>) -> Self {
        self.config.phase_jump = rate;
        self
    }
    /// Window of the causal median filter, frames (≥ 1; default 5; 1 disables smoothing).
    #[must_use]
    pub fn median_window(mut self, window: usize) -> Self {
        self.config.median_window = window;
        self
    }
    /// Seed of every random draw (default 0).
    #[must_use]
    pub fn seed(mut self, seed: u64) -> Self {
        self.config.seed = seed;
        self
    }

    /// Validate and return the configuration.
    pub fn build(self) -> Result<TrackerConfig, PfError> {
        let c = self.config;
        let bad = |msg: String| Err(PfError::InvalidConfig(msg));
        if c.particles == 0 {
            return bad("particles must be at least 1 (SPEC default 400)".into());
        }
        if c.particles > u32::MAX as usize {
            return bad(format!("particles = {} is too many", c.particles));
        }
        let t = &c.table;
        if !(t.centre.iter().all(|v| v.is_finite())
            && t.half_extents.iter().all(|v| v.is_finite() && *v > 0.0))
        {
            return bad(format!(
                "table region needs a finite centre and positive half-extents (metres), got \
                 centre {:?}, half-extents {:?}",
                t.centre, t.half_extents
            ));
        }
        if !(c.sigma0.is_finite() && c.sigma0 > 0.0) {
            return bad(format!(
                "sigma0 must be positive and finite (default 0.4), got {}",
                c.sigma0
            ));
        }
        if !(c.sigma_end_ratio.is_finite() && c.sigma_end_ratio > 0.0) {
            return bad(format!(
                "sigma_end_ratio must be positive and finite (default 1/16), got {}",
                c.sigma_end_ratio
            ));
        }
        if let Boundary::Reflect(s) = c.boundary
            && !(s.is_finite() && s >= 1.0)
        {
            return bad(format!(
                "the reflection region scale must be ≥ 1 (default 1.25), got {s}"
            ));
        }
        if let Grammar::Matrix(rows) = &c.grammar {
            check_grammar_matrix(rows, None)?;
        }
        if let ResampleWhen::EssBelow(f) = c.resample_when
            && !(f.is_finite() && f > 0.0 && f <= 1.0)
        {
            return bad(format!(
                "the ESS threshold is a fraction of M in (0, 1] (SPEC 0.5), got {f}"
            ));
        }
        if let ActionBalance::Mixture(f) = c.action_balance
            && !(f.is_finite() && f > 0.0 && f < 1.0)
        {
            return bad(format!(
                "the per-action particle floor is a fraction of M in (0, 1) (default 0.25), got {f}"
            ));
        }
        if !(c.action_switch.is_finite() && (0.0..0.5).contains(&c.action_switch)) {
            return bad(format!(
                "the action-switch probability is per frame in [0, 0.5) (default 0), got {}",
                c.action_switch
            ));
        }
        if let PoseSampling::Gaussian { samples } = c.pose_sampling
            && samples == 0
        {
            return bad("samples per particle must be at least 1".into());
        }
        if let Some([lo, hi]) = c.speed_range
            && !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi && hi <= 4.0)
        {
            return bad(format!(
                "the speed range needs 0 < lo ≤ hi ≤ 4 (1 = the model's timing), got [{lo}, {hi}]"
            ));
        }
        if let Some(r) = c.phase_jump
            && !(r.is_finite() && r > 0.0 && r < 1.0)
        {
            return bad(format!(
                "the phase-jump rate is a probability per particle and frame in (0, 1), got {r}"
            ));
        }
        if c.median_window == 0 {
            return bad("the median-filter window must be at least 1 frame (default 5)".into());
        }
        if let Some(regions) = &c.action_regions {
            if regions.is_empty() {
                return bad("action regions: the list is empty (one region per action)".into());
            }
            for (a, t) in regions.iter().enumerate() {
                if !(t.centre.iter().all(|v| v.is_finite())
                    && t.half_extents.iter().all(|v| v.is_finite() && *v > 0.0))
                {
                    return bad(format!(
                        "action region {a} needs a finite centre and positive half-extents \
                         (metres), got centre {:?}, half-extents {:?}",
                        t.centre, t.half_extents
                    ));
                }
            }
        }
        Ok(c)
    }
}

/// Check that `rows` is a square row-stochastic matrix (of size `n` when given).
pub(crate) fn check_grammar_matrix(rows: &[Vec<f64>], n: Option<usize>) -> Result<(), PfError> {
    let m = rows.len();
    if m == 0 {
        return Err(PfError::Grammar("the grammar matrix is empty".into()));
    }
    if let Some(n) = n
        && m != n
    {
        return Err(PfError::Grammar(format!(
            "the grammar matrix has {m} rows but there are {n} actions"
        )));
    }
    for (a, row) in rows.iter().enumerate() {
        if row.len() != m {
            return Err(PfError::Grammar(format!(
                "row {a} has {} entries, expected {m} (a square matrix)",
                row.len()
            )));
        }
        if row.iter().any(|g| !g.is_finite() || *g < 0.0) {
            return Err(PfError::Grammar(format!(
                "row {a} has a negative or non-finite entry: {row:?}"
            )));
        }
        let s: f64 = row.iter().sum();
        if (s - 1.0).abs() > 1e-9 {
            return Err(PfError::Grammar(format!(
                "row {a} sums to {s}, not 1 (G(·|a) must be a distribution)"
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region() -> TableRegion {
        TableRegion::new([0.0, 0.45], [0.40, 0.15])
    }

    #[test]
    fn defaults_are_the_spec_defaults() {
        let c = TrackerConfig::builder(region()).build().unwrap();
        assert_eq!(c.particles(), 400);
        assert!((c.sigma0() - 0.4).abs() < 1e-15);
        assert!((c.sigma_end_ratio() - 1.0 / 16.0).abs() < 1e-15);
        assert_eq!(c.boundary(), Boundary::Reflect(1.25));
        assert_eq!(c.grammar(), &Grammar::Uniform);
        assert_eq!(c.resampling(), Resampling::Systematic);
        assert_eq!(c.resample_when(), ResampleWhen::EveryFrame);
        assert_eq!(c.action_balance(), ActionBalance::Mixture(0.25));
        assert_eq!(c.samples_per_particle(), 1);
        assert_eq!(c.median_window(), 5);
        let c2 = c.to_builder().ess_threshold().build().unwrap();
        assert_eq!(c2.resample_when(), ResampleWhen::EssBelow(0.5));
    }

    #[test]
    fn invalid_values_are_rejected() {
        let b = || TrackerConfig::builder(region());
        assert!(b().particles(0).build().is_err());
        assert!(b().sigma0(-1.0).build().is_err());
        assert!(b().sigma0(f64::NAN).build().is_err());
        assert!(b().sigma_end_ratio(0.0).build().is_err());
        assert!(b().boundary(Boundary::Reflect(0.5)).build().is_err());
        assert!(b().samples_per_particle(0).build().is_err());
        assert!(b().median_window(0).build().is_err());
        assert!(b().action_regions(vec![]).build().is_err());
        assert!(
            b().action_regions(vec![TableRegion::new([0.0, 0.4], [0.0, 0.1])])
                .build()
                .is_err()
        );
        assert!(
            b().resample_when(ResampleWhen::EssBelow(1.5))
                .build()
                .is_err()
        );
        assert!(
            b().table(TableRegion::new([0.0, 0.0], [0.0, 0.1]))
                .build()
                .is_err()
        );
        assert!(
            b().grammar(Grammar::Matrix(vec![vec![0.5, 0.6], vec![0.5, 0.5]]))
                .build()
                .is_err()
        );
        assert!(
            b().grammar(Grammar::Matrix(vec![vec![1.0], vec![0.5, 0.5]]))
                .build()
                .is_err()
        );
        assert!(
            b().grammar(Grammar::Matrix(vec![vec![0.2, 0.8], vec![1.0, 0.0]]))
                .build()
                .is_ok()
        );
    }

    #[test]
    fn region_round_trip() {
        let r = region();
        let m = r.to_metres([1.0, -1.0]);
        assert!((m[0] - 0.4).abs() < 1e-15 && (m[1] - 0.30).abs() < 1e-15);
        let u = r.to_normalised(m);
        assert!((u[0] - 1.0).abs() < 1e-12 && (u[1] + 1.0).abs() < 1e-12);
    }
}
