//! `actrack-cli train --manifest M.toml -o model.actrack.json`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Mutex;

use actrack::manifest::Manifest;
use actrack::train::{Progress, fit_actions, import_manifest};
use anyhow::Context;

/// Options of `train`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The training manifest (TOML): trials, actions, arms, static trials, options.
    #[arg(long, short = 'm')]
    pub manifest: PathBuf,
    /// The model file to write (`*.actrack.json`).
    #[arg(long, short = 'o')]
    pub output: PathBuf,
    /// States per action (overrides the manifest).
    #[arg(long)]
    pub states: Option<usize>,
    /// Maximum forward jump (overrides the manifest).
    #[arg(long)]
    pub max_jump: Option<usize>,
    /// Maximum Baum–Welch iterations (overrides the manifest).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Covariance floor σ_min in metres (overrides the manifest).
    #[arg(long)]
    pub cov_floor: Option<f64>,
}

/// Runs `train`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let manifest = Manifest::load(&args.manifest)?;
    let mut options = manifest.options.clone();
    if let Some(n) = args.states {
        options.states = n;
    }
    if let Some(j) = args.max_jump {
        options.max_jump = j;
    }
    if let Some(i) = args.iterations {
        options.iterations = i;
    }
    if let Some(f) = args.cov_floor {
        options.cov_floor = f;
    }
    if options.states == 0
        || options.max_jump == 0
        || options.cov_floor.is_nan()
        || options.cov_floor <= 0.0
    {
        return Err(super::UsageError(
            "--states and --max-jump must be ≥ 1 and --cov-floor > 0".into(),
        )
        .into());
    }
    let start = std::time::Instant::now();
    let bar = Mutex::new(super::progress_bar(
        manifest.trials.len() as u64,
        "importing",
    ));
    let progress = |p: Progress| {
        if let Ok(b) = bar.lock()
            && let Some(b) = b.as_ref()
        {
            match p {
                Progress::Imported { done, .. } => b.set_position(done as u64),
                Progress::Fitting { action, .. } => {
                    b.set_message(format!("fitting {action}"));
                    b.tick();
                }
            }
        }
    };
    let trials = import_manifest(&manifest, None, &progress)?;
    let model = fit_actions(
        &trials,
        &options,
        &manifest.preprocessing,
        Some(&args.manifest),
        &progress,
    )?;
    if let Ok(b) = bar.lock()
        && let Some(b) = b.as_ref()
    {
        b.finish_and_clear();
    }
    model
        .save(&args.output)
        .with_context(|| format!("saving the model to {}", args.output.display()))?;
    eprintln!(
        "trained {} action(s) on {} trials ({} states, J = {}) in {:.1} s → {}",
        model.actions.len(),
        trials.len(),
        options.states,
        options.max_jump,
        start.elapsed().as_secs_f64(),
        args.output.display()
    );
    for a in &model.actions {
        eprintln!(
            "  {:<16} {:>3} trials, {:>3} iterations{}, final log-likelihood {:.1}",
            a.name,
            a.n_trials,
            a.iterations,
            if a.converged { "" } else { " (not converged)" },
            a.final_log_likelihood
        );
    }
    Ok(ExitCode::SUCCESS)
}
