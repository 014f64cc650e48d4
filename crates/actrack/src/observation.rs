//! The observation models a [`crate::Session`] scores particles with (SPEC §4 and the
//! configuration's extensions), as [`ObservationModel`]s of the filter.
//!
//! Every model corrects generated poses with the arm lengths (SPEC §3.4; lengths are invariant
//! under the rigid actor → world map, so correcting in the actor frame is the same), maps them to
//! the world with the scene's actor placement and scores them against every view's edge image.
//!
//! * [`SceneObservation`]: SPEC's ε̄ (Eq. 3/4), on the CPU or the GPU ([`Scorer`]).
//! * [`ShortContourPenalty`]: short contours count their missing points as unmatched.
//! * [`FingertipFloor`]: wraps either with a soft floor under the fingertip.
//! * [`Timed`]: wraps any model with the marks that split a step into its stages.

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use actrack_pf::ObservationModel;
use actrack_render::{ArmGeometry, EdgeImage, LikelihoodModel, RenderScratch, correct_arm};
use rayon::prelude::*;

use crate::config::Device;
use crate::error::{Error, Result};
use crate::scene::Scene;

/// The batch likelihood of SPEC Eq. 3/4, on the CPU or on the GPU.
pub enum Scorer {
    /// `actrack-render`'s CPU likelihood (rayon over poses).
    Cpu(LikelihoodModel),
    /// The wgpu likelihood (analytic contours).
    #[cfg(feature = "gpu")]
    Gpu(Box<actrack_render::gpu::GpuLikelihood>),
}

impl Scorer {
    /// The scorer for `device`, and a note when `Auto` fell back to the CPU.
    ///
    /// # Errors
    /// [`Error::Config`] when `Gpu` is asked for and there is no usable adapter (or no `gpu`
    /// feature in this build).
    pub fn new(device: Device, likelihood: LikelihoodModel) -> Result<(Self, Option<String>)> {
        match device {
            Device::Cpu => Ok((Self::Cpu(likelihood), None)),
            #[cfg(feature = "gpu")]
            Device::Gpu | Device::Auto => {
                match actrack_render::gpu::GpuLikelihood::new(
                    likelihood.cameras().to_vec(),
                    likelihood.geometry().clone(),
                    likelihood.gamma(),
                ) {
                    // A software adapter (lavapipe) is slower than the CPU likelihood.
                    Ok(g) if device == Device::Auto && g.is_software() => Ok((
                        Self::Cpu(likelihood),
                        Some(format!(
                            "only a software GPU ({}); using the CPU",
                            g.adapter_name()
                        )),
                    )),
                    Ok(g) => Ok((Self::Gpu(Box::new(g)), None)),
                    Err(e) if device == Device::Auto => Ok((
                        Self::Cpu(likelihood),
                        Some(format!("no usable GPU ({e}); using the CPU")),
                    )),
                    Err(e) => Err(Error::Config(format!("observation.device = gpu: {e}"))),
                }
            }
            #[cfg(not(feature = "gpu"))]
            Device::Gpu => Err(Error::Config(
                "observation.device = gpu: this build has no GPU support (build with \
                 `--features gpu`)"
                    .into(),
            )),
            #[cfg(not(feature = "gpu"))]
            Device::Auto => Ok((
                Self::Cpu(likelihood),
                Some("this build has no GPU support (feature `gpu`); using the CPU".into()),
            )),
        }
    }

    /// `cpu` or `gpu`.
    pub fn device(&self) -> &'static str {
        match self {
            Self::Cpu(_) => "cpu",
            #[cfg(feature = "gpu")]
            Self::Gpu(_) => "gpu",
        }
    }

    /// Scores world poses into `out`; NaN on error.
    pub fn score(&self, edges: &[EdgeImage], world: &[[f64; 9]], out: &mut [f64]) {
        let ok = match self {
            Self::Cpu(m) => m.log_likelihood_batch(edges, world, out).is_ok(),
            #[cfg(feature = "gpu")]
            Self::Gpu(g) => g.log_likelihood_batch(edges, world, out).is_ok(),
        };
        if !ok {
            out.fill(f64::NAN);
        }
    }
}

/// SPEC's observation model of one frame: `edges` holds one edge image per camera of `scene`.
pub struct SceneObservation<'a> {
    scene: &'a Scene,
    geometry: &'a ArmGeometry,
    scorer: &'a Scorer,
    edges: &'a [EdgeImage],
    world: &'a Mutex<Vec<[f64; 9]>>,
}

impl<'a> SceneObservation<'a> {
    /// The model of one frame; `world` is a reused buffer for the poses in world coordinates.
    pub fn new(
        scene: &'a Scene,
        geometry: &'a ArmGeometry,
        scorer: &'a Scorer,
        edges: &'a [EdgeImage],
        world: &'a Mutex<Vec<[f64; 9]>>,
    ) -> Self {
        Self {
            scene,
            geometry,
            scorer,
            edges,
            world,
        }
    }
}

impl ObservationModel for SceneObservation<'_> {
    fn correct(&self, pose: &mut [f64; 9]) {
        correct_arm(self.geometry, pose, None);
    }

    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        let mut world = match self.world.lock() {
            Ok(w) => w,
            Err(p) => p.into_inner(),
        };
        world.clear();
        world.extend(poses.iter().map(|p| self.scene.pose_to_world(p)));
        self.scorer.score(self.edges, &world, out);
    }
}

/// The arm-length correction alone (SPEC §3.4), for [`actrack_pf::Tracker::predict`], which
/// generates poses without scoring them; it scores nothing (every pose −∞).
pub struct Correction<'a> {
    geometry: &'a ArmGeometry,
}

impl<'a> Correction<'a> {
    /// The correction with `geometry`'s arm lengths.
    pub fn new(geometry: &'a ArmGeometry) -> Self {
        Self { geometry }
    }
}

impl ObservationModel for Correction<'_> {
    fn correct(&self, pose: &mut [f64; 9]) {
        correct_arm(self.geometry, pose, None);
    }

    fn log_likelihoods(&self, _poses: &[[f64; 9]], out: &mut [f64]) {
        out.fill(f64::NEG_INFINITY);
    }
}

/// The short-contour penalty (not SPEC §4.3): SPEC's ε̄ is a mean over the contour's points, so
/// a pose whose contour is short (a forearm foreshortened towards the camera, a hand at the mouth
/// seen end-on) can lie on a few strong edges of the torso or head and beat the true pose, whose
/// long contour crosses weak edges. Here a pose's contour shorter than the q-quantile n̄ of the
/// contour lengths of the frame's particle set (per view) counts each missing point with error
/// λ: ε = (Σ (1 − G)² + λ·max(0, n̄ − n)) / max(n, n̄). Poses with n ≥ n̄ get SPEC's ε̄.
/// Deterministic for any thread count (n̄ is taken after the parallel part).
pub struct ShortContourPenalty<'a> {
    geometry: &'a ArmGeometry,
    likelihood: &'a LikelihoodModel,
    scene: &'a Scene,
    edges: &'a [EdgeImage],
    /// λ and q.
    settings: [f64; 2],
}

impl<'a> ShortContourPenalty<'a> {
    /// The model of one frame with weight λ and quantile q.
    pub fn new(
        scene: &'a Scene,
        likelihood: &'a LikelihoodModel,
        edges: &'a [EdgeImage],
        weight: f64,
        quantile: f64,
    ) -> Self {
        Self {
            geometry: likelihood.geometry(),
            likelihood,
            scene,
            edges,
            settings: [weight, quantile],
        }
    }
}

impl ObservationModel for ShortContourPenalty<'_> {
    fn correct(&self, pose: &mut [f64; 9]) {
        correct_arm(self.geometry, pose, None);
    }

    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        let gamma = self.likelihood.gamma();
        let factor = 1.0 / (2.0 * gamma * gamma);
        out.fill(0.0);
        for (view, edge) in self.edges.iter().enumerate() {
            // Per pose: the contour's Σ (1 − G)² and length.
            let sums: Vec<(f64, usize)> = poses
                .par_iter()
                .map_init(RenderScratch::new, |scratch, p| {
                    let world = self.scene.pose_to_world(p);
                    if world.iter().all(|x| x.is_finite()) {
                        self.likelihood.view_sum(view, edge, &world, scratch)
                    } else {
                        (0.0, 0)
                    }
                })
                .collect();
            let mut lens: Vec<usize> = sums.iter().map(|x| x.1).filter(|&n| n > 0).collect();
            lens.sort_unstable();
            let [weight, q] = self.settings;
            let at = ((lens.len() as f64 * q.clamp(0.0, 1.0)) as usize).min(lens.len().max(1) - 1);
            let reference = lens.get(at).copied().unwrap_or(0) as f64;
            for (o, &(s, n)) in out.iter_mut().zip(&sums) {
                let n = n as f64;
                let eps = if n == 0.0 {
                    1.0
                } else {
                    ((s + weight * (reference - n).max(0.0)) / n.max(reference)).clamp(0.0, 1.0)
                };
                *o -= eps * factor;
            }
        }
        // Views without an image count as "no contour" (SPEC's missing view).
        let missing = self
            .likelihood
            .cameras()
            .len()
            .saturating_sub(self.edges.len()) as f64;
        if missing > 0.0 {
            for o in out.iter_mut() {
                *o -= missing * factor;
            }
        }
    }
}

/// The floor of a [`FingertipFloor`]: its height z₀ (metres, actor frame) and softness σ
/// (metres), validated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    z: f64,
    sigma: f64,
}

impl Floor {
    /// The floor at z₀ = `z` with softness `sigma` (> 0).
    ///
    /// # Errors
    /// When `z` is not finite or `sigma` is not positive and finite.
    pub fn new(z: f64, sigma: f64) -> Result<Self> {
        if !(z.is_finite() && sigma.is_finite() && sigma > 0.0) {
            return Err(Error::Config(format!(
                "fingertip floor: needs a finite height (metres, actor frame) and a positive \
                 σ, got {z} and {sigma}"
            )));
        }
        Ok(Self { z, sigma })
    }

    /// The floor's height z₀ (metres, actor frame).
    pub fn height(&self) -> f64 {
        self.z
    }

    /// The log-likelihood a pose loses to the floor (0 when its fingertip is on or above it).
    pub fn penalty(&self, pose: &[f64; 9]) -> f64 {
        let below = (self.z - pose[8]).max(0.0) / self.sigma;
        0.5 * below * below
    }
}

/// A soft floor under the fingertip (not in the paper): the hand rests on the table before and
/// after a movement and cannot go through it, so a pose whose fingertip r lies below the floor
/// z₀ (actor frame) loses ½((z₀ − r_z)/σ)² of log-likelihood; poses above it are scored by the
/// inner model alone. In a monocular view a hand lower and nearer the body can lie on the same
/// viewing ray as the true one; the floor rules out the part of the ray under the table.
#[derive(Clone, Copy, Debug)]
pub struct FingertipFloor<O> {
    inner: O,
    floor: Floor,
}

impl<O> FingertipFloor<O> {
    /// `inner` under `floor`.
    pub fn new(inner: O, floor: Floor) -> Self {
        Self { inner, floor }
    }
}

impl<O: ObservationModel> ObservationModel for FingertipFloor<O> {
    fn correct(&self, pose: &mut [f64; 9]) {
        self.inner.correct(pose);
    }

    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        self.inner.log_likelihoods(poses, out);
        for (o, p) in out.iter_mut().zip(poses) {
            *o -= self.floor.penalty(p);
        }
    }
}

/// Nanoseconds since `base`, saturating.
fn since(base: Instant) -> u64 {
    u64::try_from(base.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// An observation model with timing marks: the first arm correction (the end of resampling),
/// the start and the end of the batch likelihood.
pub struct Timed<O> {
    inner: O,
    base: Instant,
    first_correct: AtomicU64,
    ll_start: AtomicU64,
    ll_end: AtomicU64,
}

impl<O> Timed<O> {
    /// `inner`, with the clock started now.
    pub fn new(inner: O) -> Self {
        Self {
            inner,
            base: Instant::now(),
            first_correct: AtomicU64::new(u64::MAX),
            ll_start: AtomicU64::new(0),
            ll_end: AtomicU64::new(0),
        }
    }

    /// The stages of a [`actrack_pf::Tracker::predict`] that ended now, milliseconds: resample,
    /// propagate + sample (split at the first arm correction).
    pub fn predict_stages(&self) -> [f64; 2] {
        let end = since(self.base);
        let fc = self.first_correct.load(Ordering::Relaxed).min(end);
        [fc as f64 * 1e-6, end.saturating_sub(fc) as f64 * 1e-6]
    }

    /// The stages of a step that ended now, milliseconds: resample, propagate + sample,
    /// likelihood, weights + estimates.
    pub fn stages(&self) -> [f64; 4] {
        let end = since(self.base);
        let ms = |ns: u64| ns as f64 * 1e-6;
        let (ls, le) = (
            self.ll_start.load(Ordering::Relaxed),
            self.ll_end.load(Ordering::Relaxed),
        );
        let fc = self.first_correct.load(Ordering::Relaxed);
        let fc = if fc == u64::MAX { ls } else { fc.min(ls) };
        [
            ms(fc),
            ms(ls.saturating_sub(fc)),
            ms(le.saturating_sub(ls)),
            ms(end.saturating_sub(le)),
        ]
    }
}

impl<O: ObservationModel> ObservationModel for Timed<O> {
    fn correct(&self, pose: &mut [f64; 9]) {
        if self.first_correct.load(Ordering::Relaxed) == u64::MAX {
            self.first_correct
                .fetch_min(since(self.base), Ordering::Relaxed);
        }
        self.inner.correct(pose);
    }

    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        self.ll_start.store(since(self.base), Ordering::Relaxed);
        self.inner.log_likelihoods(poses, out);
        self.ll_end.store(since(self.base), Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Linear;

    impl ObservationModel for Linear {
        fn correct(&self, _: &mut [f64; 9]) {}

        fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
            for (o, p) in out.iter_mut().zip(poses) {
                *o = p[0];
            }
        }
    }

    #[test]
    fn fingertip_floor_penalises_only_below_the_floor() {
        let floor = Floor::new(-0.3, 0.01).unwrap();
        let obs = FingertipFloor::new(Linear, floor);
        let mut above = [0.0; 9];
        above[0] = 2.0;
        above[8] = -0.2;
        let mut below = above;
        below[8] = -0.32; // 2 cm under: ½·2² = 2
        let mut out = [0.0; 2];
        obs.log_likelihoods(&[above, below], &mut out);
        assert!((out[0] - 2.0).abs() < 1e-12);
        assert!((out[1] - 0.0).abs() < 1e-9, "{}", out[1]);
        assert!(Floor::new(f64::NAN, 0.01).is_err());
        assert!(Floor::new(-0.3, 0.0).is_err());
    }

    #[test]
    fn timed_passes_scores_through() {
        let t = Timed::new(Linear);
        let mut p = [[0.0; 9]; 2];
        p[1][0] = 3.0;
        let mut out = [0.0; 2];
        t.correct(&mut p[0]);
        t.log_likelihoods(&p, &mut out);
        assert!(out[0].abs() < 1e-12 && (out[1] - 3.0).abs() < 1e-12);
        assert!(t.stages().iter().all(|s| *s >= 0.0));
    }
}
