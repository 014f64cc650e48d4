//! Training action models from mocap trials, and recognising actions of whole or partial trials
//! without video (Wilson & Bobick: per action, the likelihood at its EM-estimated θ).

use std::fmt::Write as _;
use std::path::Path;

use actrack_phmm::{EndMode, Phmm, PhmmParams, ThetaEmOptions};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::manifest::{Manifest, ManifestTrial, TrainOptions};
use crate::mocap::trial::{Importer, Preprocessing, Trial, median};
use crate::model::{Action, ActionModel, ArmLengths, Provenance, THETA_FRAME, now_iso8601};

/// Progress of a long operation, reported to a callback (the CLI draws a bar from it).
#[derive(Clone, Debug)]
pub enum Progress {
    /// `done` of `total` trials imported.
    Imported {
        /// Trials done.
        done: usize,
        /// Trials in all.
        total: usize,
    },
    /// Fitting action `action` (index `index` of `total`).
    Fitting {
        /// The action.
        action: String,
        /// Its index.
        index: usize,
        /// Number of actions.
        total: usize,
    },
}

/// A trial with its label, as trained on or classified.
#[derive(Clone, Debug)]
pub struct LabelledTrial {
    /// Action label.
    pub action: String,
    /// The prepared trial.
    pub trial: Trial,
}

/// Imports every trial a manifest lists (in parallel where cores allow), with the manifest's
/// preprocessing or `preprocessing` when given.
pub fn import_manifest(
    manifest: &Manifest,
    preprocessing: Option<&Preprocessing>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Vec<LabelledTrial>> {
    let importer = Importer::new(preprocessing.unwrap_or(&manifest.preprocessing).clone())?;
    import_trials(&importer, &manifest.trials, progress)
}

/// Imports trials with an importer (in parallel where cores allow).
pub fn import_trials(
    importer: &Importer,
    trials: &[ManifestTrial],
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Vec<LabelledTrial>> {
    let done = std::sync::atomic::AtomicUsize::new(0);
    let total = trials.len();
    trials
        .par_iter()
        .map(|t| {
            let trial = importer
                .load(
                    &t.file,
                    t.static_path.as_deref(),
                    t.arm,
                    t.theta,
                    t.theta_rule,
                )
                .map_err(|e| entry_error(t, e))?;
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            progress(Progress::Imported { done: k, total });
            Ok(LabelledTrial {
                action: t.action.clone(),
                trial,
            })
        })
        .collect()
}

/// A marker trial listed without `static` is the manifest entry's fault: name the manifest and
/// the entry's line rather than only the trial.
fn entry_error(t: &ManifestTrial, e: Error) -> Error {
    match (&e, &t.manifest, &t.static_path) {
        (Error::Invalid { path, message }, Some(manifest), None)
            if path == &t.file && message == crate::mocap::trial::NEEDS_STATIC =>
        {
            Error::parse(
                manifest,
                t.line.max(1),
                format!(
                    "{} is a marker trial and needs its subject's static trial: add \
                     `static = \"…\"` to this [[trials]] entry",
                    t.file.display()
                ),
            )
        }
        _ => e,
    }
}

/// Fits one parametric HMM per action (in order of first appearance) to labelled trials.
pub fn fit_actions(
    trials: &[LabelledTrial],
    options: &TrainOptions,
    preprocessing: &Preprocessing,
    manifest: Option<&Path>,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<ActionModel> {
    if trials.is_empty() {
        return Err(Error::Config("no training trials".into()));
    }
    let mut names: Vec<String> = Vec::new();
    for t in trials {
        if !names.contains(&t.action) {
            names.push(t.action.clone());
        }
    }
    let params = PhmmParams::new(options.states)
        .max_jump(options.max_jump)
        .max_iterations(options.iterations)
        .cov_floor(options.cov_floor)
        .tolerance(options.tolerance)
        .end_mode(EndMode::MustEnd)
        .check()
        .map_err(|e| Error::Config(e.to_string()))?;
    check_trial_lengths(trials, params.min_sequence_len(), options, preprocessing)?;
    let mut actions = Vec::new();
    for (index, name) in names.iter().enumerate() {
        progress(Progress::Fitting {
            action: name.clone(),
            index,
            total: names.len(),
        });
        let mine: Vec<&LabelledTrial> = trials.iter().filter(|t| &t.action == name).collect();
        let seqs: Vec<DMatrix<f64>> = mine
            .iter()
            .map(|t| t.trial.arm_trajectory.to_matrix())
            .collect();
        let thetas: Vec<DVector<f64>> = mine
            .iter()
            .map(|t| DVector::from_row_slice(&t.trial.theta))
            .collect();
        if mine.len() < 3 {
            return Err(Error::Config(format!(
                "action `{name}` has {} training trial(s); a parametric HMM over a 2-D θ needs at \
                 least 3 with different θ",
                mine.len()
            )));
        }
        let (phmm, report) = params.fit(&seqs, &thetas).map_err(|e| Error::Model {
            context: format!("training action `{name}` ({} trials)", mine.len()),
            message: e.to_string(),
        })?;
        let (mean, cov, lo, hi) = theta_stats(&thetas);
        actions.push(Action {
            name: name.clone(),
            phmm,
            theta_mean: mean,
            theta_cov: cov,
            theta_min: lo,
            theta_max: hi,
            n_trials: mine.len(),
            iterations: report.iterations,
            converged: report.converged,
            final_log_likelihood: report.log_likelihoods.last().copied().unwrap_or(f64::NAN),
            median_frames: median(seqs.iter().map(|s| s.nrows() as f64).collect()),
        });
    }
    let arm_lengths = ArmLengths {
        upper_arm: median(trials.iter().map(|t| t.trial.arm_lengths[0]).collect()),
        forearm_hand: median(trials.iter().map(|t| t.trial.arm_lengths[1]).collect()),
    };
    Ok(ActionModel {
        actions,
        arm_lengths,
        theta_frame: THETA_FRAME.to_string(),
        preprocessing: preprocessing.clone(),
        provenance: Provenance {
            tool: format!("actrack {}", env!("CARGO_PKG_VERSION")),
            created: now_iso8601(),
            manifest: manifest.map(|m| m.display().to_string()),
            files: trials
                .iter()
                .map(|t| t.trial.source.display().to_string())
                .collect(),
            states: options.states,
            max_jump: options.max_jump,
            max_iterations: options.iterations,
            cov_floor: options.cov_floor,
        },
    })
}

/// Refuses, before any fitting and naming its file, the first trial with fewer frames than
/// the models' topology needs (`min_frames`, [`actrack_phmm::ValidPhmmParams::min_sequence_len`]):
/// a training trial passes through every state from the first to the last, jumping at most
/// `max_jump` states a frame, so `states = 20`, `max_jump = 3` need 8 frames.
fn check_trial_lengths(
    trials: &[LabelledTrial],
    min_frames: usize,
    options: &TrainOptions,
    preprocessing: &Preprocessing,
) -> Result<()> {
    let Some(t) = trials
        .iter()
        .find(|t| t.trial.arm_trajectory.len() < min_frames)
    else {
        return Ok(());
    };
    let after = match (preprocessing.trim.is_some(), preprocessing.frame_rate) {
        (true, Some(f)) => format!(" after trimming the rest phases and resampling to {f} Hz"),
        (true, None) => " after trimming the rest phases".to_string(),
        (false, Some(f)) => format!(" after resampling to {f} Hz"),
        (false, None) => String::new(),
    };
    let len = t.trial.arm_trajectory.len();
    Err(Error::invalid(
        &t.trial.source,
        format!(
            "this `{}` trial has {len} frame{}{after}, but training needs at least {min_frames} \
             frames per trial ({} states, max_jump {}: a trial passes from the first state to the \
             last, at most {} states a frame): give a longer trial, leave this one out of the \
             manifest, or train with fewer states or a larger max_jump",
            t.action,
            if len == 1 { "" } else { "s" },
            options.states,
            options.max_jump,
            options.max_jump,
        ),
    ))
}

fn theta_stats(thetas: &[DVector<f64>]) -> ([f64; 2], [[f64; 2]; 2], [f64; 2], [f64; 2]) {
    let n = thetas.len().max(1) as f64;
    let mut mean = [0.0; 2];
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for t in thetas {
        for k in 0..2 {
            mean[k] += t[k] / n;
            lo[k] = lo[k].min(t[k]);
            hi[k] = hi[k].max(t[k]);
        }
    }
    let mut cov = [[0.0; 2]; 2];
    for t in thetas {
        for a in 0..2 {
            for b in 0..2 {
                cov[a][b] += (t[a] - mean[a]) * (t[b] - mean[b]) / (n - 1.0).max(1.0);
            }
        }
    }
    (mean, cov, lo, hi)
}

/// Score of one action for one sequence.
#[derive(Clone, Debug, Serialize)]
pub struct ActionScore {
    /// The action.
    pub action: String,
    /// log P(X | λ_a, θ̂_a).
    pub log_likelihood: f64,
    /// θ̂_a (actor frame, metres).
    pub theta: [f64; 2],
    /// Standard deviation of θ̂_a per axis (metres): the Laplace approximation of its
    /// posterior, from the curvature of the log-likelihood (plus the prior, for partial
    /// sequences) at θ̂_a.
    pub theta_std: [f64; 2],
    /// θ̂_a lies on the border of the action's θ support (the training θ box widened by
    /// [`THETA_SUPPORT_MARGIN`]), where partial sequences confine it: the sequence points
    /// further out than the model was trained for.
    pub theta_at_bound: bool,
}

/// Recognition result for one sequence.
#[derive(Clone, Debug, Serialize)]
pub struct Classification {
    /// Per action, in model order.
    pub scores: Vec<ActionScore>,
    /// The recognised action (largest log-likelihood).
    pub action: String,
    /// Its θ̂.
    pub theta: [f64; 2],
    /// Its θ̂'s standard deviation per axis (metres, see [`ActionScore::theta_std`]).
    pub theta_std: [f64; 2],
    /// Its θ̂ lies on the border of the action's θ support (see
    /// [`ActionScore::theta_at_bound`]).
    pub theta_at_bound: bool,
}

/// Standard deviation (metres) of the isotropic noise added to every state's covariance when a
/// partial sequence is scored ([`Classifier::classify`] with `partial`), the default of
/// [`Classifier::new`].
///
/// Why: without its end the alignment of a prefix is free, and on a held-out subject the
/// tight late states (σ_min = 1 mm) fit the subject's own posture so badly that a path parking
/// the last, nearly arrived frames in one broad mid-movement state wins by ~100 nats, with a θ
/// extrapolated 5–10 cm too far (ADL008 reach-across). The inflation bounds that mismatch.
/// Chosen on training subjects only (model trained on ADL001–005, validated on ADL006–007,
/// first 75 % of the movement: reach θ median / p90 5.6 / 14.4 and 3.6 / 25.5 cm without,
/// 3.2 / 5.8 and 3.8 / 4.6 cm with 1 cm; 0.5 and 2 cm gave similar figures).
pub const PARTIAL_COV_INFLATION: f64 = 0.01;

/// Margin (metres) by which an action's θ support extends beyond the box of its training θ.
/// θ of a partial sequence is estimated within that support: a movement seen in part carries
/// little information on where it ends, and an unconstrained estimate can leave the table
/// entirely (tens of centimetres outside every training target).
pub const THETA_SUPPORT_MARGIN: f64 = 0.05;

/// The θ support of an action (lower and upper corner, actor frame, metres): its training θ
/// box widened by [`THETA_SUPPORT_MARGIN`].
pub fn theta_support(a: &Action) -> ([f64; 2], [f64; 2]) {
    let m = THETA_SUPPORT_MARGIN;
    (
        [a.theta_min[0] - m, a.theta_min[1] - m],
        [a.theta_max[0] + m, a.theta_max[1] + m],
    )
}

/// Standard deviation per axis of θ̂ by the Laplace approximation: the inverse of the negative
/// Hessian of `objective` at `theta` (central differences, 5 mm steps). Where the curvature is
/// not positive definite the sequence does not pin θ down, and `fallback` (the spread of the
/// support) is returned.
fn laplace_std(
    objective: &dyn Fn(&[f64; 2]) -> Option<f64>,
    theta: [f64; 2],
    fallback: [f64; 2],
) -> [f64; 2] {
    let h = 0.005;
    let f = |du: f64, dv: f64| objective(&[theta[0] + du, theta[1] + dv]);
    let (Some(f0), Some(fpu), Some(fmu), Some(fpv), Some(fmv)) =
        (f(0.0, 0.0), f(h, 0.0), f(-h, 0.0), f(0.0, h), f(0.0, -h))
    else {
        return fallback;
    };
    let (Some(fpp), Some(fpm), Some(fmp), Some(fmm)) = (f(h, h), f(h, -h), f(-h, h), f(-h, -h))
    else {
        return fallback;
    };
    let huu = (fpu - 2.0 * f0 + fmu) / (h * h);
    let hvv = (fpv - 2.0 * f0 + fmv) / (h * h);
    let huv = (fpp - fpm - fmp + fmm) / (4.0 * h * h);
    // Negative Hessian = information matrix [[a, b], [b, c]].
    let (a, b, c) = (-huu, -huv, -hvv);
    let det = a * c - b * b;
    if !(a > 0.0 && c > 0.0 && det > 0.0 && det.is_finite()) {
        return fallback;
    }
    let (su, sv) = ((c / det).sqrt(), (a / det).sqrt());
    [su.min(fallback[0]), sv.min(fallback[1])]
}

/// The observation coordinates of the fingertip r in the PHMM observation (p, q, r).
pub const FINGERTIP_COORDINATES: [usize; 3] = [6, 7, 8];

/// Which coordinates of the observation (p, q, r) θ is estimated from
/// ([`Classifier::theta_from`], [`Classifier::theta_from_partial`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ThetaFrom {
    /// The fingertip r only (the default for whole sequences): θ-EM (SPEC §2.6) under the exact
    /// marginal model of r ([`Phmm::marginal`]); the action is still scored by the likelihood
    /// of the whole observation at that θ̂.
    ///
    /// Why: θ is the fingertip's table position, but a linear PHMM also predicts the shoulder
    /// and elbow from θ, and those carry the demonstrator's build and seat (arm lengths,
    /// posture), which the model cannot separate from θ. On a held-out subject the tight
    /// shoulder/elbow states then pull θ̂ by several cm (UE-ADL ADL006 reach-across: 3.5–5.8 cm,
    /// the same optimum from every start, while its fingertip alone gives 1.0–1.7 cm).
    /// Leave-one-subject-out on ADL001–007 (three actions, whole trials): reach θ median / p90
    /// 1.44 / 3.52 cm from the whole pose, 0.54 / 1.13 cm from the fingertip; 209 and 210 of
    /// 210 recognised (docs/mocap.md). For partial sequences the pose does better (see
    /// [`Classifier::theta_from_partial`]).
    Fingertip,
    /// The whole observation (p, q, r): SPEC §2.6 as written.
    Pose,
}

/// Recognises the action of whole or partial sequences with a model.
#[derive(Debug)]
pub struct Classifier<'a> {
    model: &'a ActionModel,
    /// Models without exit modelling and with inflated covariances, for sequences cut before
    /// their end.
    truncated: Vec<Phmm>,
    /// The fingertip marginals of the models and of `truncated` (for [`ThetaFrom::Fingertip`]).
    fingertip: Vec<Phmm>,
    truncated_fingertip: Vec<Phmm>,
    /// Also start θ-EM from every distinct training θ of whole sequences (slower).
    pub multi_start: bool,
    /// Partial sequences: θ by the MAP variant with each action's training θ distribution as
    /// the prior (`true`, the default) or by maximum likelihood.
    pub partial_prior: bool,
    /// The coordinates θ of a whole sequence is estimated from (default
    /// [`ThetaFrom::Fingertip`]).
    pub theta_from: ThetaFrom,
    /// The coordinates θ of a partial sequence is estimated from (default [`ThetaFrom::Pose`]:
    /// before the fingertip arrives, the shoulder and elbow help to extrapolate where it is
    /// heading; leave-one-subject-out on ADL001–007, three actions, first 75 % of the
    /// movement: reach θ median / p90 3.86 / 6.15 cm from the pose, 4.07 / 8.74 cm from the
    /// fingertip).
    pub theta_from_partial: ThetaFrom,
}

impl<'a> Classifier<'a> {
    /// A classifier for `model`; partial sequences are scored with
    /// [`PARTIAL_COV_INFLATION`].
    pub fn new(model: &'a ActionModel) -> Result<Classifier<'a>> {
        Self::with_partial_inflation(model, PARTIAL_COV_INFLATION)
    }

    /// A classifier whose partial-sequence models add `sigma²·I` (metres²) to every state's
    /// covariance (0: the trained covariances).
    pub fn with_partial_inflation(model: &'a ActionModel, sigma: f64) -> Result<Classifier<'a>> {
        if !(sigma.is_finite() && sigma >= 0.0) {
            return Err(Error::Config(format!(
                "the partial-sequence covariance inflation must be a finite σ ≥ 0, not {sigma}"
            )));
        }
        let model_err = |a: &Action| {
            let name = a.name.clone();
            move |e: actrack_phmm::PhmmError| Error::Model {
                context: format!("action `{name}`"),
                message: e.to_string(),
            }
        };
        let truncated: Vec<Phmm> = model
            .actions
            .iter()
            .map(|a| partial_model(&a.phmm, sigma).map_err(model_err(a)))
            .collect::<Result<_>>()?;
        let fingertip = model
            .actions
            .iter()
            .map(|a| {
                a.phmm
                    .marginal(&FINGERTIP_COORDINATES)
                    .map_err(model_err(a))
            })
            .collect::<Result<_>>()?;
        let truncated_fingertip = model
            .actions
            .iter()
            .zip(&truncated)
            .map(|(a, t)| t.marginal(&FINGERTIP_COORDINATES).map_err(model_err(a)))
            .collect::<Result<_>>()?;
        Ok(Classifier {
            model,
            truncated,
            fingertip,
            truncated_fingertip,
            multi_start: false,
            partial_prior: true,
            theta_from: ThetaFrom::Fingertip,
            theta_from_partial: ThetaFrom::Pose,
        })
    }

    /// Classifies a sequence (T × 9, actor frame). `partial`: the sequence is the beginning of
    /// an action only: it is scored by a forward pass that may end in any state (the models'
    /// exit ignored), with the covariances inflated (see [`PARTIAL_COV_INFLATION`]), and θ is
    /// estimated by EM from the training θ mean and a 3 × 3 grid spanning the training θ
    /// (corners included), keeping the best objective (see [`Classifier::partial_prior`]).
    /// θ is estimated from the coordinates [`Classifier::theta_from`] (whole sequences) or
    /// [`Classifier::theta_from_partial`] names; each action's score is the log-likelihood of
    /// the whole observation at its θ̂.
    pub fn classify(&self, x: &DMatrix<f64>, partial: bool) -> Result<Classification> {
        let d = self.model.actions.first().map_or(9, |a| a.phmm.dim());
        if x.ncols() != d {
            return Err(Error::Config(format!(
                "the sequence has {} columns but the model's observations are {d}-D (p, q, r)",
                x.ncols()
            )));
        }
        let x_tip = DMatrix::from_fn(x.nrows(), FINGERTIP_COORDINATES.len(), |t, k| {
            x[(t, FINGERTIP_COORDINATES[k])]
        });
        let mut scores = Vec::new();
        for (k, (a, trunc)) in self.model.actions.iter().zip(&self.truncated).enumerate() {
            let err = |e: actrack_phmm::PhmmError| Error::Model {
                context: format!("estimating θ for action `{}`", a.name),
                message: e.to_string(),
            };
            // The model scoring the sequence, and the model and observations θ comes from.
            let scoring = if partial { trunc } else { &a.phmm };
            let from = if partial {
                self.theta_from_partial
            } else {
                self.theta_from
            };
            let (em_model, em_x) = match (from, partial) {
                (ThetaFrom::Pose, _) => (scoring, x),
                (ThetaFrom::Fingertip, false) => (&self.fingertip[k], &x_tip),
                (ThetaFrom::Fingertip, true) => (&self.truncated_fingertip[k], &x_tip),
            };
            let est = if partial {
                // Early frames leave the likelihood over θ multi-modal: several starts.
                let mut starts = vec![DVector::from_row_slice(&a.theta_mean)];
                for fx in [0.0, 0.5, 1.0] {
                    for fy in [0.0, 0.5, 1.0] {
                        starts.push(DVector::from_row_slice(&[
                            a.theta_min[0] + fx * (a.theta_max[0] - a.theta_min[0]),
                            a.theta_min[1] + fy * (a.theta_max[1] - a.theta_min[1]),
                        ]));
                    }
                }
                // MAP: prior = the action's training θ mean and covariance (at least 1 cm² per
                // axis against a degenerate spread); it keeps early cuts, where W ≈ 0 leaves the
                // likelihood flat, on the table. The objective is the log-posterior.
                let mean = DVector::from_row_slice(&a.theta_mean);
                let c = a.theta_cov;
                let prior_cov = DMatrix::from_row_slice(
                    2,
                    2,
                    &[c[0][0].max(1e-4), c[0][1], c[1][0], c[1][1].max(1e-4)],
                );
                let inv = prior_cov
                    .clone()
                    .try_inverse()
                    .unwrap_or_else(|| DMatrix::identity(2, 2));
                let (lo, hi) = theta_support(a);
                let bounds = (DVector::from_row_slice(&lo), DVector::from_row_slice(&hi));
                let mut best: Option<(f64, actrack_phmm::ThetaEstimate)> = None;
                for init in starts {
                    let opts = ThetaEmOptions {
                        init: Some(init),
                        prior: self
                            .partial_prior
                            .then(|| (mean.clone(), prior_cov.clone())),
                        bounds: Some(bounds.clone()),
                        ..ThetaEmOptions::default()
                    };
                    let est = em_model.estimate_theta(em_x, &opts).map_err(err)?;
                    let d = &est.theta - &mean;
                    let objective = if self.partial_prior {
                        est.log_likelihood - 0.5 * (d.transpose() * &inv * &d)[(0, 0)]
                    } else {
                        est.log_likelihood
                    };
                    if best.as_ref().is_none_or(|(o, _)| objective > *o) {
                        best = Some((objective, est));
                    }
                }
                best.map(|(_, e)| e)
                    .ok_or_else(|| Error::Config("no θ start".into()))?
            } else {
                let opts = ThetaEmOptions {
                    multi_start: self.multi_start,
                    ..ThetaEmOptions::default()
                };
                em_model.estimate_theta(em_x, &opts).map_err(err)?
            };
            let log_likelihood = match from {
                ThetaFrom::Pose => est.log_likelihood,
                ThetaFrom::Fingertip => scoring
                    .log_likelihood(x, est.theta.as_slice())
                    .map_err(err)?,
            };
            let theta = [est.theta[0], est.theta[1]];
            let (lo, hi) = theta_support(a);
            // The uniform distribution over the support: what is known without the sequence.
            let fallback = [
                (hi[0] - lo[0]) / 12f64.sqrt(),
                (hi[1] - lo[1]) / 12f64.sqrt(),
            ];
            let prior_inv = if partial && self.partial_prior {
                let c = a.theta_cov;
                let (p, q, r) = (c[0][0].max(1e-4), c[0][1], c[1][1].max(1e-4));
                let det = p * r - q * q;
                (det > 0.0).then(|| [r / det, -q / det, p / det])
            } else {
                None
            };
            let objective = |t: &[f64; 2]| {
                let ll = em_model.log_likelihood(em_x, t).ok()?;
                let lp = prior_inv.map_or(0.0, |[iuu, iuv, ivv]| {
                    let (du, dv) = (t[0] - a.theta_mean[0], t[1] - a.theta_mean[1]);
                    -0.5 * (iuu * du * du + 2.0 * iuv * du * dv + ivv * dv * dv)
                });
                Some(ll + lp).filter(|v| v.is_finite())
            };
            let theta_std = laplace_std(&objective, theta, fallback);
            let tol = 1e-6;
            let theta_at_bound =
                partial && (0..2).any(|k| theta[k] <= lo[k] + tol || theta[k] >= hi[k] - tol);
            scores.push(ActionScore {
                action: a.name.clone(),
                log_likelihood,
                theta,
                theta_std,
                theta_at_bound,
            });
        }
        let best = scores
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.log_likelihood.total_cmp(&b.1.log_likelihood))
            .map_or(0, |(k, _)| k);
        Ok(Classification {
            action: scores[best].action.clone(),
            theta: scores[best].theta,
            theta_std: scores[best].theta_std,
            theta_at_bound: scores[best].theta_at_bound,
            scores,
        })
    }
}

/// The same parametric HMM without exit modelling (`EndMode::None`, `a_NN = 1`), for sequences
/// that stop before the action ends.
pub fn truncate(phmm: &Phmm) -> Result<Phmm, actrack_phmm::PhmmError> {
    partial_model(phmm, 0.0)
}

/// [`truncate`], with `sigma²·I` added to every state's covariance (see
/// [`PARTIAL_COV_INFLATION`]).
pub fn partial_model(phmm: &Phmm, sigma: f64) -> Result<Phmm, actrack_phmm::PhmmError> {
    let n = phmm.n_states();
    let start: Vec<f64> = (0..n).map(|i| phmm.start_prob(i)).collect();
    let mut a = DMatrix::from_fn(n, n, |i, j| phmm.transition(i, j));
    for i in 0..n {
        let s: f64 = a.row(i).sum();
        if s > 0.0 {
            for j in 0..n {
                a[(i, j)] /= s;
            }
        } else {
            a[(i, i)] = 1.0;
        }
    }
    let mut bias = Vec::with_capacity(n);
    let mut weights = Vec::with_capacity(n);
    let mut covs = Vec::with_capacity(n);
    for i in 0..n {
        let (b, w) = phmm.mean_affine(i);
        bias.push(b);
        weights.push(w);
        let mut c = phmm.covariance(i).clone();
        for k in 0..c.nrows() {
            c[(k, k)] += sigma * sigma;
        }
        covs.push(c);
    }
    Phmm::from_params(
        &start,
        &a,
        &vec![0.0; n],
        &bias,
        &weights,
        &covs,
        phmm.max_jump(),
        EndMode::None,
    )
}

/// Result for one evaluated trial.
#[derive(Clone, Debug, Serialize)]
pub struct TrialResult {
    /// The movement file.
    pub file: String,
    /// True label.
    pub action: String,
    /// True θ (rule or explicit).
    pub theta_true: [f64; 2],
    /// Fraction of the trial seen (1 = whole).
    pub fraction: f64,
    /// The classification.
    pub result: Classification,
    /// ‖θ̂ − θ‖ in metres for the true action's θ̂.
    pub theta_error: f64,
}

/// What a fraction of a trial is a fraction of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FractionOf {
    /// Of the movement (the trimmed trial the models see).
    Movement,
    /// Of the whole recording, rest phases included (what a tracker started with the recording
    /// sees).
    Recording,
}

/// Classifies the first `fraction` of each labelled trial. A sequence cut before the end of
/// the movement is classified as partial (see [`Classifier::classify`]).
pub fn evaluate(
    classifier: &Classifier<'_>,
    trials: &[LabelledTrial],
    fraction: f64,
    of: FractionOf,
) -> Result<Vec<TrialResult>> {
    trials
        .par_iter()
        .map(|t| {
            let x = t.trial.arm_trajectory.to_matrix();
            let n = match of {
                FractionOf::Movement => ((x.nrows() as f64 * fraction).ceil() as usize)
                    .clamp(2.min(x.nrows()), x.nrows()),
                FractionOf::Recording => t.trial.frames_within_recording(fraction),
            };
            let partial = n < x.nrows();
            let x = x.rows(0, n).into_owned();
            let result = classifier.classify(&x, partial)?;
            let own = result.scores.iter().find(|s| s.action == t.action);
            let theta_error = own.map_or(f64::NAN, |s| {
                (s.theta[0] - t.trial.theta[0]).hypot(s.theta[1] - t.trial.theta[1])
            });
            Ok(TrialResult {
                file: t.trial.source.display().to_string(),
                action: t.action.clone(),
                theta_true: t.trial.theta,
                fraction,
                result,
                theta_error,
            })
        })
        .collect()
}

/// Confusion matrix `[true][predicted]` over `actions` (labels outside it are ignored).
pub fn confusion(results: &[TrialResult], actions: &[&str]) -> Vec<Vec<usize>> {
    let mut m = vec![vec![0; actions.len()]; actions.len()];
    for r in results {
        let t = actions.iter().position(|a| *a == r.action);
        let p = actions.iter().position(|a| *a == r.result.action);
        if let (Some(t), Some(p)) = (t, p) {
            m[t][p] += 1;
        }
    }
    m
}

/// The `q`-quantile (0…1, linear interpolation) of finite values; NaN when none.
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let pos = q.clamp(0.0, 1.0) * (v.len() - 1) as f64;
    let i = pos.floor() as usize;
    let j = (i + 1).min(v.len() - 1);
    v[i] + (pos - i as f64) * (v[j] - v[i])
}

/// Formats a confusion matrix as an aligned text table.
pub fn format_confusion(m: &[Vec<usize>], actions: &[&str]) -> String {
    let w = actions.iter().map(|a| a.len()).max().unwrap_or(4).max(6);
    let mut s = format!("{:w$}", "true \\ pred");
    for a in actions {
        let _ = write!(s, "  {a:>w$}");
    }
    s.push('\n');
    for (k, row) in m.iter().enumerate() {
        let _ = write!(s, "{:w$}", actions[k]);
        for c in row {
            let _ = write!(s, "  {c:>w$}");
        }
        s.push('\n');
    }
    s
}
