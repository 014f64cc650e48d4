//! Left-right Gaussian HMMs and linear parametric HMMs (Wilson & Bobick, PAMI 1999).
//!
//! This crate is the action model of actrack (SPEC.md §1–§2). It does no I/O.
//!
//! # Architecture
//!
//! * [`Phmm`] (`model.rs`) holds the parameters of a left-right HMM with a banded forward
//!   topology (state i moves to i … i+J), an exit probability per [`EndMode`], and Gaussian
//!   emissions whose means depend linearly on a parameter θ: `μ_i(θ) = μ̄_i + W_i θ`. With θ of
//!   dimension 0 it is a plain HMM ([`Hmm`] wraps that case). Transitions are stored banded
//!   (N × (J+1)), so zeros outside the band cannot become non-zero. Cholesky factors and
//!   log-normalisers of the covariances are computed once when a model is built.
//!   θ is centred and scaled internally (the transform is part of the model); every public
//!   method takes θ in the caller's units.
//! * Inference (`inference.rs`): emission log-densities by forward substitution with the
//!   Cholesky factor (never an inverse), the max-shift scaled forward–backward of SPEC §1.2
//!   (shift taken over reachable states) with an automatic fall-back to the log-space
//!   recursions if a normaliser would under- or overflow, and log-space Viterbi (ties to the
//!   smaller state). Kernels run on flat frame-major buffers in a reusable workspace: nothing
//!   is allocated per frame, and only the J + 1 band entries of a row are visited.
//! * Training (`train.rs`): [`PhmmParams`] → [`PhmmParams::check`] → [`ValidPhmmParams::fit`].
//!   Uniform segmentation initialises the means (normal equations for W, SPEC §2.5 I1),
//!   covariances and transitions (§1.4). Baum–Welch (§1.3) runs the E-step in parallel over
//!   sequences with rayon; per-sequence sufficient statistics are reduced in sequence order, so
//!   results do not depend on the thread count. The PHMM M-step solves the weighted normal
//!   equations by Cholesky with a ridge on W only (§2.4). Safeguards of §1.7: eigenvalue-clamp
//!   covariance floor, low-occupancy states keep their parameters, Cholesky retries with jitter.
//! * θ estimation and recognition (`theta.rs`): EM on θ with the model fixed (§2.6), the MAP
//!   variant with a Gaussian prior, optional multi-start from the training θ, and [`recognise`].
//! * Generation (`generate.rs`): sampling (§1.6, §2.7 G1) with an injectable RNG (and a fixed
//!   default seed) and the expected trajectory (G2).
//!
//! Dependencies: nalgebra (Cholesky, symmetric eigen-decomposition, small solves), rayon
//! (parallel E-step), rand / rand_distr / rand_pcg (sampling), serde (models are saved by the
//! `actrack` crate), thiserror (the error type).
//!
//! # Example
//!
//! Fit a parametric HMM to a few synthetic sequences whose path depends on θ, then estimate θ
//! of a new sequence:
//!
//! ```
//! use actrack_phmm::{EndMode, PhmmParams, ThetaEmOptions};
//! use nalgebra::{DMatrix, DVector};
//!
//! // A 2-D "reach": the end point is θ, the path is a straight line from the origin.
//! let make = |theta: [f64; 2], len: usize, wobble: f64| {
//!     DMatrix::from_fn(len, 2, |t, k| {
//!         let s = t as f64 / (len - 1) as f64;
//!         s * theta[k] + wobble * ((t * 7 + k * 3) as f64).sin()
//!     })
//! };
//! let corners = [[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0], [0.0, 0.0]];
//! let mut seqs = Vec::new();
//! let mut thetas = Vec::new();
//! for (m, c) in corners.iter().cycle().take(10).enumerate() {
//!     seqs.push(make(*c, 30 + m, 0.02));
//!     thetas.push(DVector::from_row_slice(c));
//! }
//! let params = PhmmParams::new(6)
//!     .end_mode(EndMode::MustEnd)
//!     .cov_floor(0.01)
//!     .max_iterations(30)
//!     .check()?;
//! let (model, report) = params.fit(&seqs, &thetas)?;
//! assert!(report.log_likelihoods.windows(2).all(|w| w[1] >= w[0] - 1e-6 * w[0].abs()));
//!
//! let est = model.estimate_theta(&make([0.5, -0.3], 33, 0.02), &ThetaEmOptions::default())?;
//! assert!((est.theta[0] - 0.5).abs() < 0.1 && (est.theta[1] + 0.3).abs() < 0.1);
//! # Ok::<(), actrack_phmm::PhmmError>(())
//! ```
#![deny(missing_docs)]
// `!(x > 0.0)` is used on purpose: it is also true for NaN, which must take the same branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod error;
mod generate;
mod hmm;
mod inference;
mod linalg;
mod model;
mod theta;
mod train;

pub use error::PhmmError;
pub use generate::MAX_GENERATED_LEN;
pub use hmm::Hmm;
pub use model::{CovarianceKind, EndMode, Phmm};
pub use theta::{ThetaEmOptions, ThetaEstimate, recognise};
pub use train::{DEFAULT_SEED, FitReport, PhmmParams, ValidPhmmParams};

#[doc(hidden)]
pub mod __private {
    //! Reference implementations exposed for the crate's integration tests and benches only.
    use crate::{Phmm, PhmmError};
    use nalgebra::DMatrix;

    /// log P(X | θ) by the log-space recursions only (no scaled fast path).
    pub fn log_likelihood_log_space(
        model: &Phmm,
        x: &DMatrix<f64>,
        theta: &[f64],
    ) -> Result<f64, PhmmError> {
        crate::inference::check_sequence(model, x, 0)?;
        crate::inference::check_theta(model, theta, "theta")?;
        let mut ti = vec![0.0; model.theta_dim()];
        model.theta_internal(theta, &mut ti);
        let mut ws = crate::inference::Workspace::default();
        ws.prepare(model, x, &ti);
        Ok(ws.forward_backward_log(model, x.nrows(), false))
    }
}
