//! `actrack-cli inspect model.actrack.json`: actions, states, θ range, arm lengths, provenance.

use std::path::PathBuf;
use std::process::ExitCode;

use actrack::model::ActionModel;

/// Options of `inspect`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The file to summarise (a model file `*.actrack.json`).
    pub file: PathBuf,
    /// Print JSON instead of text (the model's summary fields).
    #[arg(long)]
    pub json: bool,
}

/// Runs `inspect`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let m = ActionModel::load(&args.file)?;
    if args.json {
        let actions: Vec<serde_json::Value> = m
            .actions
            .iter()
            .map(|a| {
                serde_json::json!({
                    "name": a.name, "states": a.phmm.n_states(), "max_jump": a.phmm.max_jump(),
                    "n_trials": a.n_trials, "theta_min": a.theta_min, "theta_max": a.theta_max,
                    "theta_mean": a.theta_mean, "iterations": a.iterations,
                    "final_log_likelihood": a.final_log_likelihood,
                })
            })
            .collect();
        let v = serde_json::json!({
            "file": args.file.display().to_string(),
            "actions": actions,
            "arm_lengths": m.arm_lengths,
            "rest_height": m.rest_height(),
            "theta_frame": m.theta_frame,
            "preprocessing": m.preprocessing,
            "provenance": m.provenance,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!("model file   {}", args.file.display());
    println!("actions      {}", m.action_names().join(", "));
    for a in &m.actions {
        println!(
            "  {:<16} {} states, J = {}, {} trials, θ x ∈ [{:.3}, {:.3}] m, y ∈ [{:.3}, {:.3}] m, {} iterations, final log-likelihood {:.1}",
            a.name,
            a.phmm.n_states(),
            a.phmm.max_jump(),
            a.n_trials,
            a.theta_min[0],
            a.theta_max[0],
            a.theta_min[1],
            a.theta_max[1],
            a.iterations,
            a.final_log_likelihood
        );
    }
    println!(
        "arm lengths  L1 (shoulder→elbow) {:.3} m, L2 (elbow→fingertip) {:.3} m",
        m.arm_lengths.upper_arm, m.arm_lengths.forearm_hand
    );
    println!(
        "rest height  fingertip {:.3} m below the shoulder (first states; `track --height-scale`'s reference)",
        -m.rest_height()
    );
    println!("θ frame      {}", m.theta_frame);
    let p = &m.preprocessing;
    println!(
        "prepared     frame rate {}, trim {}, max gap {} frames, θ rule {:?}, marker set {}",
        p.frame_rate.map_or("capture".into(), |f| format!("{f} Hz")),
        p.trim.map_or("off".into(), |t| format!("{} m/s", t.speed)),
        p.max_gap,
        p.theta,
        p.marker_set.name
    );
    let v = &m.provenance;
    println!("created      {} by {}", v.created, v.tool);
    if let Some(man) = &v.manifest {
        println!("manifest     {man}");
    }
    println!(
        "training     {} files, {} states, J = {}, ≤ {} iterations, covariance floor {} m",
        v.files.len(),
        v.states,
        v.max_jump,
        v.max_iterations,
        v.cov_floor
    );
    Ok(ExitCode::SUCCESS)
}
