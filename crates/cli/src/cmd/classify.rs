//! `actrack-cli classify --model M (--trial FILE [--static S --arm R|L] | --manifest M.toml)`:
//! per action the log-likelihood at its EM-estimated θ, the recognised action and its θ; with a
//! manifest (labels known) also the confusion matrix and the θ error distribution.

use std::path::PathBuf;
use std::process::ExitCode;

use actrack::manifest::{Manifest, ManifestTrial};
use actrack::mocap::ArmSide;
use actrack::mocap::trial::Importer;
use actrack::model::ActionModel;
use actrack::train::{
    Classifier, FractionOf, ThetaFrom, TrialResult, confusion, evaluate, format_confusion,
    import_trials, quantile,
};

/// Options of `classify`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (`*.actrack.json`).
    #[arg(long)]
    pub model: PathBuf,
    /// A movement trial (Vicon CSV, C3D or joint-trajectory CSV).
    #[arg(
        long,
        conflicts_with = "manifest",
        required_unless_present = "manifest"
    )]
    pub trial: Option<PathBuf>,
    /// The subject's static trial (needed for marker files).
    #[arg(long = "static", requires = "trial")]
    pub static_trial: Option<PathBuf>,
    /// The acting arm: R or L (L is mirrored onto the right).
    #[arg(long, default_value = "R", requires = "trial")]
    pub arm: ArmSide,
    /// A manifest listing many labelled trials (its preprocessing is ignored: the model's applies).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
    /// Classify only the first fraction of each trial (0 < f ≤ 1; partial sequences are scored
    /// without the models' exit, with inflated covariances, θ by EM from several starts).
    #[arg(long, default_value_t = 1.0)]
    pub fraction: f64,
    /// What `--fraction` is a fraction of: the movement (rest phases trimmed) or the whole
    /// recording.
    #[arg(long, value_enum, default_value = "movement")]
    pub fraction_of: Of,
    /// Partial sequences: σ in metres of the isotropic noise added to every state's covariance
    /// (0 = the trained covariances).
    #[arg(long, default_value_t = actrack::train::PARTIAL_COV_INFLATION)]
    pub partial_sigma: f64,
    /// Partial sequences: the θ prior (`training`: each action's training θ mean and
    /// covariance, MAP; `none`: maximum likelihood).
    #[arg(long, value_enum, default_value = "training")]
    pub partial_prior: PartialPrior,
    /// Whole sequences: also start θ-EM from every distinct training θ of the action and keep
    /// the best log-likelihood (slower; partial sequences always use several starts).
    #[arg(long)]
    pub multi_start: bool,
    /// Whole sequences: which coordinates θ-EM uses (`fingertip`: the fingertip's marginal
    /// model, the default; `pose`: shoulder, elbow and fingertip, SPEC §2.6 as written). The
    /// action is scored by the whole pose either way; partial sequences always use the pose.
    #[arg(long, value_enum, default_value = "fingertip")]
    pub theta_from: ThetaSource,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// The coordinates θ-EM uses for whole sequences.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ThetaSource {
    /// The fingertip only (its marginal model).
    Fingertip,
    /// The whole pose (SPEC §2.6).
    Pose,
}

/// The θ prior for partial sequences.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum PartialPrior {
    /// The action's training θ mean and covariance (MAP).
    Training,
    /// None (maximum likelihood).
    None,
}

/// What a fraction of a trial is a fraction of.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Of {
    /// The movement (the trimmed trial).
    Movement,
    /// The whole recording, rest phases included.
    Recording,
}

/// Runs `classify`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    if !(args.fraction > 0.0 && args.fraction <= 1.0) {
        return Err(super::UsageError(format!(
            "--fraction must be in (0, 1], not {}",
            args.fraction
        ))
        .into());
    }
    let model = ActionModel::load(&args.model)?;
    let importer = Importer::new(model.preprocessing.clone())?;
    let (trials, labelled) = match (&args.manifest, &args.trial) {
        (Some(m), _) => (Manifest::load(m)?.trials, true),
        (None, Some(t)) => (
            vec![ManifestTrial {
                file: t.clone(),
                static_path: args.static_trial.clone(),
                action: String::new(),
                arm: args.arm,
                theta: None,
                theta_rule: None,
                line: 0,
                manifest: None,
            }],
            false,
        ),
        (None, None) => return Err(super::UsageError("give --trial or --manifest".into()).into()),
    };
    let bar = super::progress_bar(trials.len() as u64, "importing");
    let lt = import_trials(&importer, &trials, &|p| {
        if let (Some(b), actrack::train::Progress::Imported { done, .. }) = (&bar, p) {
            b.set_position(done as u64);
        }
    })?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    if !(args.partial_sigma.is_finite() && args.partial_sigma >= 0.0) {
        return Err(super::UsageError(format!(
            "--partial-sigma must be a finite number ≥ 0, not {}",
            args.partial_sigma
        ))
        .into());
    }
    let mut classifier = Classifier::with_partial_inflation(&model, args.partial_sigma)?;
    classifier.partial_prior = matches!(args.partial_prior, PartialPrior::Training);
    classifier.multi_start = args.multi_start;
    classifier.theta_from = match args.theta_from {
        ThetaSource::Fingertip => ThetaFrom::Fingertip,
        ThetaSource::Pose => ThetaFrom::Pose,
    };
    let of = match args.fraction_of {
        Of::Movement => FractionOf::Movement,
        Of::Recording => FractionOf::Recording,
    };
    let results = evaluate(&classifier, &lt, args.fraction, of)?;
    let names = model.action_names();
    if args.json {
        let mut v = serde_json::json!({ "model": args.model.display().to_string(), "fraction": args.fraction });
        let rows: Vec<serde_json::Value> = results
            .iter()
            .map(|r| {
                let mut o = serde_json::json!({
                    "file": r.file, "recognised": r.result.action, "theta": r.result.theta,
                    "theta_std": r.result.theta_std, "theta_at_bound": r.result.theta_at_bound,
                    "scores": r.result.scores,
                });
                if labelled {
                    o["action"] = serde_json::json!(r.action);
                    o["theta_true"] = serde_json::json!(r.theta_true);
                    o["theta_error"] = serde_json::json!(r.theta_error);
                }
                o
            })
            .collect();
        v["trials"] = serde_json::json!(rows);
        if labelled {
            v["summary"] = summary_json(&results, &names);
        }
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    for r in &results {
        println!("{}", r.file);
        for s in &r.result.scores {
            println!(
                "  {:<16} log-likelihood {:>12.2}  θ = ({:+.3}, {:+.3}) m",
                s.action, s.log_likelihood, s.theta[0], s.theta[1]
            );
        }
        print!(
            "  recognised: {}  θ = ({:+.3}, {:+.3}) m ± ({:.3}, {:.3}) m",
            r.result.action,
            r.result.theta[0],
            r.result.theta[1],
            r.result.theta_std[0],
            r.result.theta_std[1]
        );
        if r.result.theta_at_bound {
            print!("  [θ at the border of the model's θ support]");
        }
        if labelled {
            print!(
                "  (true: {}, θ error {:.1} cm)",
                r.action,
                100.0 * r.theta_error
            );
        }
        println!();
    }
    if labelled {
        print_summary(&results, &names);
    }
    Ok(ExitCode::SUCCESS)
}

fn summary_json(results: &[TrialResult], names: &[&str]) -> serde_json::Value {
    let correct = results
        .iter()
        .filter(|r| r.result.action == r.action)
        .count();
    let errs: Vec<f64> = results.iter().map(|r| r.theta_error).collect();
    serde_json::json!({
        "actions": names,
        "confusion": confusion(results, names),
        "recognition_rate": correct as f64 / results.len().max(1) as f64,
        "theta_error_median": quantile(&errs, 0.5),
        "theta_error_p90": quantile(&errs, 0.9),
    })
}

fn print_summary(results: &[TrialResult], names: &[&str]) {
    let correct = results
        .iter()
        .filter(|r| r.result.action == r.action)
        .count();
    println!();
    println!(
        "recognition: {correct}/{} = {:.1} %",
        results.len(),
        100.0 * correct as f64 / results.len().max(1) as f64
    );
    print!("{}", format_confusion(&confusion(results, names), names));
    println!("θ error (own action's estimate), cm:");
    for a in names {
        let errs: Vec<f64> = results
            .iter()
            .filter(|r| r.action == *a)
            .map(|r| r.theta_error)
            .collect();
        if errs.is_empty() {
            continue;
        }
        println!(
            "  {:<16} n = {:>3}  median {:.2}  p90 {:.2}  max {:.2}",
            a,
            errs.len(),
            100.0 * quantile(&errs, 0.5),
            100.0 * quantile(&errs, 0.9),
            100.0 * quantile(&errs, 1.0)
        );
    }
}
