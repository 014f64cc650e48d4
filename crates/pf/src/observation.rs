//! The observation side of the filter: how a generated pose is made admissible and scored.

/// An observation model for one frame: poses in, log-likelihoods out.
///
/// The filter never depends on how a pose is scored (DESIGN.md): the `actrack` crate implements
/// this with the silhouette/edge likelihood of `actrack-render`, tests use synthetic oracles.
/// Poses are `[p, q, r]` (shoulder, elbow, fingertip; 9 numbers, metres) in the **actor frame**,
/// the frame the parametric HMMs generate in.
///
/// Implementations must be deterministic for the filter to be reproducible across thread counts.
pub trait ObservationModel: Sync {
    /// Correct a generated pose in place (the arm-length correction of SPEC §3.4; the
    /// observation side owns arm geometry). Called once per generated pose, from worker
    /// threads. The default keeps the pose as generated.
    fn correct(&self, pose: &mut [f64; 9]) {
        let _ = pose;
    }

    /// Write log P(I_t | x̃) of every pose into `out` (same length) for the current frame.
    /// NaN, −∞ (and +∞) mean "no information" for that pose and are treated as −∞; a frame where
    /// every pose has no information leaves the weights unchanged and is flagged degenerate.
    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]);
}

impl<T: ObservationModel + ?Sized> ObservationModel for &T {
    fn correct(&self, pose: &mut [f64; 9]) {
        (**self).correct(pose);
    }
    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        (**self).log_likelihoods(poses, out);
    }
}

/// An observation model that carries no information: every pose gets the same log-likelihood
/// and is left uncorrected. Useful to run the prior dynamics alone (benches, tests).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ConstantObservation(pub f64);

impl ObservationModel for ConstantObservation {
    fn log_likelihoods(&self, _poses: &[[f64; 9]], out: &mut [f64]) {
        out.fill(self.0);
    }
}
