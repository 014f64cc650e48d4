//! A plain left-right Gaussian HMM: a [`Phmm`] with θ of dimension 0, without θ arguments.

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::PhmmError;
use crate::model::Phmm;
use crate::train::{FitReport, ValidPhmmParams};

/// A plain left-right Gaussian HMM (SPEC §1). Wraps a [`Phmm`] whose θ has dimension 0.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(try_from = "Phmm", into = "Phmm")]
pub struct Hmm(Phmm);

impl TryFrom<Phmm> for Hmm {
    type Error = PhmmError;
    fn try_from(m: Phmm) -> Result<Self, PhmmError> {
        if m.theta_dim() != 0 {
            return Err(PhmmError::InvalidModel(format!(
                "a plain HMM has no θ, but this model's θ is {}-D: use Phmm",
                m.theta_dim()
            )));
        }
        Ok(Hmm(m))
    }
}

impl From<Hmm> for Phmm {
    fn from(h: Hmm) -> Phmm {
        h.0
    }
}

impl Hmm {
    /// Train on sequences (each T_m × d, one row per frame) by uniform segmentation and
    /// Baum–Welch (SPEC §1.3–§1.4).
    pub fn fit(
        params: &ValidPhmmParams,
        seqs: &[DMatrix<f64>],
    ) -> Result<(Hmm, FitReport), PhmmError> {
        let (m, r) = params.fit(seqs, &[])?;
        Ok((Hmm(m), r))
    }

    /// The underlying model (θ of dimension 0).
    pub fn as_phmm(&self) -> &Phmm {
        &self.0
    }

    /// log P(X).
    pub fn log_likelihood(&self, x: &DMatrix<f64>) -> Result<f64, PhmmError> {
        self.0.log_likelihood(x, &[])
    }

    /// State posteriors γ (T × N).
    pub fn posteriors(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>, PhmmError> {
        self.0.posteriors(x, &[])
    }

    /// Most likely state path and its log-probability.
    pub fn viterbi(&self, x: &DMatrix<f64>) -> Result<(Vec<usize>, f64), PhmmError> {
        self.0.viterbi(x, &[])
    }

    /// Sample a sequence with the given RNG (see [`Phmm::sample`]).
    pub fn sample<R: Rng>(&self, len: Option<usize>, rng: &mut R) -> (DMatrix<f64>, Vec<usize>) {
        self.0.sample(&[], len, rng)
    }

    /// Sample with a seeded generator (`Pcg64Mcg`).
    pub fn sample_seeded(&self, len: Option<usize>, seed: u64) -> (DMatrix<f64>, Vec<usize>) {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        self.0.sample(&[], len, &mut rng)
    }
}
