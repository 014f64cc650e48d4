//! The particle state ω = (a, θ, k) (SPEC §3.1).

use serde::{Deserialize, Serialize};

/// One particle's position in action space.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActionState {
    /// The action a: index of its parametric HMM in the tracker's model list.
    pub action: usize,
    /// The target θ in **normalised** table units (corners at ±1, SPEC §3.1); convert with
    /// [`crate::TableRegion::to_metres`].
    pub theta: [f64; 2],
    /// The progress k as a **0-based** state index of the action's HMM (SPEC's k − 1).
    pub k: usize,
}

/// A particle of the cloud for visualisation: θ in metres (actor frame), action, 0-based state,
/// normalised weight.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CloudParticle {
    /// The action index.
    pub action: usize,
    /// θ in metres, actor frame.
    pub theta: [f64; 2],
    /// 0-based HMM state.
    pub k: usize,
    /// Normalised weight (the weights of a frame sum to 1).
    pub weight: f64,
}
