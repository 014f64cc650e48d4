//! Leave-one-subject-out cross-validation of the mocap action models on UE-ADL training
//! subjects (ADL001–ADL007 by default), and per-trial diagnostics of the θ-EM of whole reach
//! trials: the error, the log-likelihood at θ̂ and at the true θ (EM started at the true θ),
//! so a local optimum (the true θ's basin scores higher) can be told from a biased optimum.
//!
//! ```sh
//! cargo run --release -p actrack --example mocap_cv -- \
//!     [--manifest manifests/ue-adl3-train.toml] [--floor 0.0005,0.001] [--states 20] \
//!     [--multi-start] [--trials] [--heldout manifests/ue-adl3-test.toml]
//! ```
//!
//! `--heldout M`: instead of cross-validation, train on the whole manifest and evaluate the
//! trials of `M` once (the held-out measurement).

use std::path::{Path, PathBuf};

use actrack::manifest::{Manifest, TrainOptions};
use actrack::mocap::trial::Importer;
use actrack::train::{
    Classifier, FractionOf, LabelledTrial, ThetaFrom, TrialResult, evaluate, fit_actions,
    import_trials, quantile,
};
use actrack_phmm::ThetaEmOptions;
use nalgebra::DVector;
use rayon::prelude::*;

fn subject(t: &LabelledTrial) -> u32 {
    let name = t
        .trial
        .source
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    name.get(3..6).and_then(|s| s.parse().ok()).unwrap_or(0)
}

fn file_name(t: &LabelledTrial) -> String {
    t.trial
        .source
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

struct Row {
    file: String,
    action: String,
    recognised: bool,
    err: f64,
    ll_hat: f64,
    ll_true_start: f64,
    err_true_start: f64,
    /// θ̂ − θ (metres).
    delta: [f64; 2],
    /// Error of the fingertip-only (marginal) model's θ̂, and of the model without the shoulder.
    err_tip: f64,
    err_no_shoulder: f64,
    /// Fingertip (x, y) of the last frame minus θ.
    last_minus_theta: [f64; 2],
    /// Recognised when every action is scored by the full likelihood at its fingertip-only θ̂.
    recognised_tip: bool,
}

fn evaluate_fold(
    train: &[LabelledTrial],
    test: &[LabelledTrial],
    opts: &TrainOptions,
    man: &Manifest,
    multi_start: bool,
    fractions: &[f64],
    partial: &mut Vec<(ThetaFrom, usize, TrialResult)>,
) -> Vec<Row> {
    let model = fit_actions(train, opts, &man.preprocessing, None, &|_| {}).expect("fit");
    let mut c = Classifier::new(&model).expect("classifier");
    c.multi_start = multi_start;
    for from in [ThetaFrom::Pose, ThetaFrom::Fingertip] {
        c.theta_from = from;
        c.theta_from_partial = from;
        for (k, &f) in fractions.iter().enumerate() {
            for r in evaluate(&c, test, f, FractionOf::Movement).expect("evaluate") {
                partial.push((from, k, r));
            }
        }
    }
    c.theta_from = ThetaFrom::Pose;
    c.theta_from_partial = ThetaFrom::Pose;
    test.par_iter()
        .map(|t| {
            let x = t.trial.arm_trajectory.to_matrix();
            let r = c.classify(&x, false).expect("classify");
            let own = r.scores.iter().find(|s| s.action == t.action).expect("own");
            let err = (own.theta[0] - t.trial.theta[0]).hypot(own.theta[1] - t.trial.theta[1]);
            let a = model
                .actions
                .iter()
                .find(|a| a.name == t.action)
                .expect("action");
            let o = ThetaEmOptions {
                init: Some(DVector::from_row_slice(&t.trial.theta)),
                ..ThetaEmOptions::default()
            };
            let e = a.phmm.estimate_theta(&x, &o).expect("em");
            let sub = |dims: &[usize]| {
                let mm = a.phmm.marginal(dims).expect("marginal");
                let xs = nalgebra::DMatrix::from_fn(x.nrows(), dims.len(), |t, k| x[(t, dims[k])]);
                let o = ThetaEmOptions {
                    init: Some(DVector::from_row_slice(&a.theta_mean)),
                    multi_start,
                    ..ThetaEmOptions::default()
                };
                let e = mm.estimate_theta(&xs, &o).expect("marginal em");
                (e.theta[0] - t.trial.theta[0]).hypot(e.theta[1] - t.trial.theta[1])
            };
            let last = x.nrows() - 1;
            let tip_dims = [6usize, 7, 8];
            let xs = nalgebra::DMatrix::from_fn(x.nrows(), 3, |t, k| x[(t, tip_dims[k])]);
            let mut best = (f64::NEG_INFINITY, String::new());
            for act in &model.actions {
                let mm = act.phmm.marginal(&tip_dims).expect("marginal");
                let o = ThetaEmOptions {
                    init: Some(DVector::from_row_slice(&act.theta_mean)),
                    multi_start,
                    ..ThetaEmOptions::default()
                };
                let e = mm.estimate_theta(&xs, &o).expect("marginal em");
                let ll = act.phmm.log_likelihood(&x, e.theta.as_slice()).expect("ll");
                if ll > best.0 {
                    best = (ll, act.name.clone());
                }
            }
            Row {
                file: file_name(t),
                action: t.action.clone(),
                recognised: r.action == t.action,
                recognised_tip: best.1 == t.action,
                err,
                ll_hat: own.log_likelihood,
                ll_true_start: e.log_likelihood,
                err_true_start: (e.theta[0] - t.trial.theta[0])
                    .hypot(e.theta[1] - t.trial.theta[1]),
                delta: [
                    own.theta[0] - t.trial.theta[0],
                    own.theta[1] - t.trial.theta[1],
                ],
                err_tip: sub(&[6, 7, 8]),
                err_no_shoulder: sub(&[3, 4, 5, 6, 7, 8]),
                last_minus_theta: [
                    x[(last, 6)] - t.trial.theta[0],
                    x[(last, 7)] - t.trial.theta[1],
                ],
            }
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|k| args.get(k + 1).cloned())
    };
    let flag = |name: &str| args.iter().any(|a| a == name);
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let man_path =
        arg("--manifest").map_or_else(|| root.join("manifests/ue-adl3-train.toml"), PathBuf::from);
    let man = Manifest::load(&man_path).expect("manifest");
    let mut pre = man.preprocessing.clone();
    if let Some(s) = arg("--trim")
        && let Some(t) = pre.trim.as_mut()
    {
        t.speed = s.parse().expect("--trim speed");
    }
    let importer = Importer::new(pre).expect("importer");
    let t0 = std::time::Instant::now();
    let all = import_trials(&importer, &man.trials, &|_| {}).expect("import");
    eprintln!("imported {} trials in {:.1?}", all.len(), t0.elapsed());
    let floors: Vec<f64> = arg("--floor").map_or_else(
        || vec![man.options.cov_floor],
        |s| s.split(',').map(|v| v.parse().expect("floor")).collect(),
    );
    let states: Vec<usize> = arg("--states").map_or_else(
        || vec![man.options.states],
        |s| s.split(',').map(|v| v.parse().expect("states")).collect(),
    );
    let multi = flag("--multi-start");
    let fractions: Vec<f64> = arg("--fractions").map_or_else(
        || vec![1.0],
        |s| s.split(',').map(|v| v.parse().expect("fraction")).collect(),
    );
    let heldout: Option<Vec<LabelledTrial>> = arg("--heldout").map(|p| {
        let m = Manifest::load(Path::new(&p)).expect("held-out manifest");
        import_trials(&importer, &m.trials, &|_| {}).expect("import held-out")
    });
    for &n in &states {
        for &floor in &floors {
            let opts = TrainOptions {
                states: n,
                cov_floor: floor,
                ..man.options.clone()
            };
            let mut partial = Vec::new();
            let rows: Vec<Row> = if let Some(test) = &heldout {
                evaluate_fold(&all, test, &opts, &man, multi, &fractions, &mut partial)
            } else {
                let mut subjects: Vec<u32> = all.iter().map(subject).collect();
                subjects.sort_unstable();
                subjects.dedup();
                subjects
                    .iter()
                    .flat_map(|&s| {
                        let train: Vec<LabelledTrial> =
                            all.iter().filter(|t| subject(t) != s).cloned().collect();
                        let test: Vec<LabelledTrial> =
                            all.iter().filter(|t| subject(t) == s).cloned().collect();
                        evaluate_fold(&train, &test, &opts, &man, multi, &fractions, &mut partial)
                    })
                    .collect()
            };
            for from in [ThetaFrom::Pose, ThetaFrom::Fingertip] {
                for (k, &f) in fractions.iter().enumerate() {
                    let res: Vec<&TrialResult> = partial
                        .iter()
                        .filter(|(a, b, _)| *a == from && *b == k)
                        .map(|(_, _, r)| r)
                        .collect();
                    let errs: Vec<f64> = res
                        .iter()
                        .filter(|r| r.action.starts_with("reach"))
                        .map(|r| r.theta_error)
                        .collect();
                    println!(
                        "  classifier, θ from {from:?}, first {:.0} % of the movement: recognition {}/{}; reach θ median {:.2} p90 {:.2} max {:.2} cm",
                        100.0 * f,
                        res.iter().filter(|r| r.result.action == r.action).count(),
                        res.len(),
                        100.0 * quantile(&errs, 0.5),
                        100.0 * quantile(&errs, 0.9),
                        100.0 * quantile(&errs, 1.0)
                    );
                }
            }
            let reach: Vec<&Row> = rows
                .iter()
                .filter(|r| r.action.starts_with("reach"))
                .collect();
            let errs: Vec<f64> = reach.iter().map(|r| r.err).collect();
            let tip: Vec<f64> = reach.iter().map(|r| r.err_tip).collect();
            let nos: Vec<f64> = reach.iter().map(|r| r.err_no_shoulder).collect();
            println!(
                "  recognition by the full likelihood at the fingertip θ̂: {}/{}",
                rows.iter().filter(|r| r.recognised_tip).count(),
                rows.len()
            );
            println!(
                "  marginal models: fingertip only median {:.2} p90 {:.2}; without shoulder median {:.2} p90 {:.2} cm",
                100.0 * quantile(&tip, 0.5),
                100.0 * quantile(&tip, 0.9),
                100.0 * quantile(&nos, 0.5),
                100.0 * quantile(&nos, 0.9)
            );
            let local = reach
                .iter()
                .filter(|r| r.ll_true_start > r.ll_hat + 1e-6)
                .count();
            println!(
                "states {n} floor {floor}{}: recognition {}/{}; reach θ median {:.2} p90 {:.2} max {:.2} cm (n = {}); true-θ start scores higher in {local}",
                if multi { " multi-start" } else { "" },
                rows.iter().filter(|r| r.recognised).count(),
                rows.len(),
                100.0 * quantile(&errs, 0.5),
                100.0 * quantile(&errs, 0.9),
                100.0 * quantile(&errs, 1.0),
                errs.len()
            );
            for a in ["reach-forward", "reach-across", "reach"] {
                let e: Vec<f64> = reach
                    .iter()
                    .filter(|r| r.action == a)
                    .map(|r| r.err)
                    .collect();
                if !e.is_empty() {
                    println!(
                        "  {a}: median {:.2} p90 {:.2} cm (n = {})",
                        100.0 * quantile(&e, 0.5),
                        100.0 * quantile(&e, 0.9),
                        e.len()
                    );
                }
            }
            if flag("--trials") {
                let mut sorted = reach.clone();
                sorted.sort_by(|a, b| b.err.total_cmp(&a.err));
                for r in sorted.iter().take(25) {
                    println!(
                        "  {:<18} {:<14} err {:.2} cm ({:+.1}, {:+.1})  ll {:.1}  true-start ll {:.1} err {:.2}  tip-only {:.2}  no-shoulder {:.2}  last-θ ({:+.1}, {:+.1}){}",
                        r.file,
                        r.action,
                        100.0 * r.err,
                        100.0 * r.delta[0],
                        100.0 * r.delta[1],
                        r.ll_hat,
                        r.ll_true_start,
                        100.0 * r.err_true_start,
                        100.0 * r.err_tip,
                        100.0 * r.err_no_shoulder,
                        100.0 * r.last_minus_theta[0],
                        100.0 * r.last_minus_theta[1],
                        if r.recognised { "" } else { "  MISRECOGNISED" }
                    );
                }
            }
        }
    }
}
