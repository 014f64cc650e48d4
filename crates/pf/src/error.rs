//! The crate's one error type.

use thiserror::Error;

/// Everything that can go wrong when configuring or building a [`crate::Tracker`].
///
/// Filtering itself never fails: a frame without usable likelihoods is flagged in the
/// [`crate::Estimate`] instead (see [`crate::Estimate::degenerate`]).
#[derive(Debug, Error, Clone, PartialEq)]
pub enum PfError {
    /// A configuration value is out of its valid range; the message says which and what to change.
    #[error("invalid tracker configuration: {0}")]
    InvalidConfig(String),
    /// The tracker needs at least one action model.
    #[error("the tracker needs at least one action model (got none)")]
    NoModels,
    /// The number of action names differs from the number of models.
    #[error("{names} action names given for {models} action models; give one name per model")]
    NameCount {
        /// Number of names.
        names: usize,
        /// Number of models.
        models: usize,
    },
    /// A model does not generate 9-D arm poses from a 2-D θ.
    #[error(
        "action model {action} generates {dim}-D observations from a {theta_dim}-D θ; \
         the tracker needs 9-D arm poses (p, q, r) and a 2-D table target θ"
    )]
    ModelShape {
        /// Index of the offending action.
        action: usize,
        /// Its observation dimension.
        dim: usize,
        /// Its θ dimension.
        theta_dim: usize,
    },
    /// A model's parameters are unusable (empty, non-finite, or a transition row without mass).
    #[error("action model {action}: {reason}")]
    BadModel {
        /// Index of the offending action.
        action: usize,
        /// What is wrong.
        reason: String,
    },
    /// The grammar matrix does not match the number of actions or is not row-stochastic.
    #[error("action grammar: {0}")]
    Grammar(String),
}
