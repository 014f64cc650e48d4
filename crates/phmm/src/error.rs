//! The crate's one error type.

use thiserror::Error;

/// Everything that can go wrong in this crate. Every message says what is wrong and, where there
/// is one, what to change.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum PhmmError {
    /// `fit` or `recognise` was given no sequences (or no models).
    #[error("no {what} given: pass at least one")]
    Empty {
        /// What was missing ("sequences", "models").
        what: &'static str,
    },
    /// A sequence has no frames.
    #[error("sequence {index} is empty (0 frames): remove it or pass at least one frame")]
    EmptySequence {
        /// Index of the sequence in the input slice.
        index: usize,
    },
    /// A sequence is too short to reach the last state, which the model must end in.
    #[error(
        "sequence {index} has {len} frames but the model needs at least {min_len} to reach its last \
         state (EndMode::MustEnd with {n_states} states, max jump {max_jump}): use fewer states, a \
         larger max_jump, EndMode::Free/None, or drop the sequence"
    )]
    SequenceTooShort {
        /// Index of the sequence in the input slice.
        index: usize,
        /// Its length in frames.
        len: usize,
        /// The shortest admissible length.
        min_len: usize,
        /// Number of states of the model.
        n_states: usize,
        /// Maximum forward jump of the model.
        max_jump: usize,
    },
    /// An observation has the wrong number of columns.
    #[error(
        "sequence {index} has {got} columns but the model's observations are {expected}-D \
         (one row per frame, one column per coordinate)"
    )]
    ObservationDimension {
        /// Index of the sequence in the input slice.
        index: usize,
        /// Expected dimension d.
        expected: usize,
        /// Number of columns found.
        got: usize,
    },
    /// A NaN or infinite value in the input.
    #[error("non-finite value {value} in {what} at row {row}, column {col}: clean or drop it")]
    NonFinite {
        /// What held the value (e.g. "sequence 3", "theta 2", "covariance of state 5").
        what: String,
        /// Row (frame) of the value.
        row: usize,
        /// Column of the value.
        col: usize,
        /// The value itself.
        value: f64,
    },
    /// θ has the wrong length.
    #[error("{what} has {got} components but the model's θ is {expected}-D")]
    ThetaDimension {
        /// Which θ ("theta of sequence 4", "theta", "prior mean").
        what: String,
        /// Expected length.
        expected: usize,
        /// Length found.
        got: usize,
    },
    /// Number of θ values does not match the number of sequences.
    #[error(
        "{sequences} sequences but {thetas} θ values: pass one θ per sequence (or none for a plain HMM)"
    )]
    ThetaCount {
        /// Number of sequences.
        sequences: usize,
        /// Number of θ vectors.
        thetas: usize,
    },
    /// The training θ values do not determine W: fewer than dim θ + 1 affinely independent values.
    #[error(
        "the training θ values span an affine space of dimension {rank} but θ is {theta_dim}-D: \
         W needs at least {needed} affinely independent θ values (e.g. the four table corners for 2-D θ); \
         add demonstrations with other θ or reduce the θ dimension"
    )]
    ThetaRankDeficient {
        /// Affine dimension spanned by the θ values.
        rank: usize,
        /// Dimension of θ.
        theta_dim: usize,
        /// Number of affinely independent values needed (dim θ + 1).
        needed: usize,
    },
    /// A builder parameter is out of range.
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParameter {
        /// Name of the builder method / field.
        name: &'static str,
        /// What is wrong and what to change.
        reason: String,
    },
    /// Explicit model parameters (or a deserialised model) are inconsistent.
    #[error("invalid model: {0}")]
    InvalidModel(String),
    /// A covariance matrix is not positive definite even after regularisation.
    #[error(
        "covariance of state {state} is not positive definite even after {retries} jitter retries: \
         raise cov_floor or check the data for duplicated/constant coordinates"
    )]
    NotPositiveDefinite {
        /// The state.
        state: usize,
        /// How many jitter retries were tried.
        retries: usize,
    },
    /// The model assigns probability zero to a sequence.
    #[error(
        "sequence {index} has zero probability under the model (log P = −∞): it cannot be generated \
         with this topology/end mode; check its length and EndMode"
    )]
    ZeroLikelihood {
        /// Index of the sequence.
        index: usize,
    },
    /// A numerical failure that should not happen with valid input (reported, never a NaN model).
    #[error("numerical failure: {0}")]
    Numerical(String),
}
