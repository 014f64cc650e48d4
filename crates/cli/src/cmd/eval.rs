//! `actrack-cli eval --track T --truth GT [--json] [--plots DIR]`.

use std::path::PathBuf;
use std::process::ExitCode;

use actrack::eval::evaluate;
use actrack::track_csv::Trajectory;

/// Options of `eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The tracker's CSV (`track --csv`).
    #[arg(long, short = 't')]
    pub track: PathBuf,
    /// The ground-truth CSV (same columns).
    #[arg(long, short = 'g')]
    pub truth: PathBuf,
    /// Print the metrics as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write the plots (posterior, θ, fingertip) as PNG into this directory.
    #[arg(long)]
    pub plots: Option<PathBuf>,
}

/// Runs `eval`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    let track = Trajectory::load(&args.track)?;
    let truth = Trajectory::load(&args.truth)?;
    if !track.is_track() {
        return Err(super::UsageError(format!(
            "{}: not a tracker output (no theta_u_std/theta_v_std columns); give it as --truth?",
            args.track.display()
        ))
        .into());
    }
    let report = evaluate(&track, &truth)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{report}");
    }
    if let Some(dir) = &args.plots {
        let paths = actrack::plots::write_all(&track, &truth, dir)?;
        for p in paths {
            eprintln!("plot: {}", p.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}
