//! The action-space particle filter of "Tracking in Action Space" (SPEC.md §3).
//!
//! Instead of searching joint angles, the filter searches the action space ω = (a, θ, k): the
//! action a (one linear parametric HMM per action), its target θ on the table, and its progress
//! k (the HMM state). Each particle generates an arm pose x ~ N(μ_{a,k}(θ), Σ_{a,k}) from its
//! action's model; an [`ObservationModel`] corrects it (arm lengths) and scores it against the
//! frame. The crate is generic over that model, so it never depends on rendering, and does no I/O.
//!
//! # Architecture
//!
//! * [`TrackerConfig`] — validated configuration (builder with the SPEC defaults).
//! * [`Tracker`] — particles, the per-frame cycle of SPEC §3.8: resample → propagate (timing
//!   from the banded transition row, the action grammar on exit, θ Brownian motion with the
//!   *decreasing* cooling schedule [`cooling_sigma`] of erratum E1, reflection at 1.25·R) →
//!   generate poses (cached Cholesky factors) → weight in log space → [`Estimate`].
//! * [`resample`] — log-sum-exp weighting and the systematic, stratified, residual and
//!   multinomial schemes.
//! * [`synthetic`] — hand-written action models and an oracle observation model for tests,
//!   benches and demos.
//! * θ conventions (DESIGN.md): θ is in metres in the actor frame at every public boundary;
//!   inside, particles store it normalised by the table region's half-extents (corners at ±1),
//!   the units of σ(k).
//!
//! ```no_run
//! # use actrack_pf::*;
//! # fn demo(models: &[actrack_phmm::Phmm], frames: &[ConstantObservation]) -> Result<(), PfError> {
//! let config = TrackerConfig::builder(TableRegion::new([0.0, 0.45], [0.40, 0.15]))
//!     .particles(400)
//!     .seed(7)
//!     .build()?;
//! let mut tracker = Tracker::new(models, vec!["point".into(), "push".into()], config)?;
//! for obs in frames {
//!     let est = tracker.step(obs);
//!     println!("P(a) = {:?}, θ = {:?} m", est.action_posterior, est.theta_mean);
//! }
//! # Ok(()) }
//! ```
//!
//! # Dependencies
//!
//! `actrack-phmm` (the action models), `rayon` (propagation and pose sampling in parallel over
//! particles), `rand`/`rand_distr`/`rand_pcg` (seeded per-particle streams), `serde` (configs
//! and estimates are serialisable), `thiserror` (the error enum). `nalgebra` comes in through
//! the model accessors only.

mod config;
mod cooling;
mod error;
mod estimate;
mod model;
mod observation;
pub mod resample;
mod rng;
mod state;
pub mod synthetic;
mod tracker;

pub use config::{
    ActionBalance, Boundary, DEFAULT_ACTION_FLOOR, Grammar, KInit, PoseSampling, ResampleWhen,
    Resampling, TableRegion, TrackerConfig, TrackerConfigBuilder,
};
pub use cooling::cooling_sigma;
pub use error::PfError;
pub use estimate::{
    CentredMedian, DET_FLOOR, Estimate, HISTOGRAM_BINS, MedianFilter, centred_median,
};
pub use observation::{ConstantObservation, ObservationModel};
pub use state::{ActionState, CloudParticle};
pub use tracker::Tracker;
