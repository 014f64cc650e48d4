//! `actrack-cli`: the command-line interface of actrack.
//!
//! `main` returns an exit code: 0 success, 1 runtime failure, 2 bad usage or invalid input (an
//! [`actrack::Error`] that [`actrack::Error::is_input_error`] calls the user's input). Errors are
//! printed once, with their causes (`{:#}`). One module per command in `cmd/`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cmd;

/// Track a human arm in video by tracking the action it performs.
#[derive(Debug, Parser)]
#[command(name = "actrack-cli", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The commands.
#[derive(Debug, Subcommand)]
enum Command {
    /// Train action models (one parametric HMM per action) from mocap trials listed in a manifest.
    Train(cmd::train::Args),
    /// Recognise the action and its θ of mocap trials with a model (no video).
    Classify(cmd::classify::Args),
    /// Summarise a model file.
    Inspect(cmd::inspect::Args),
    /// The embedded demo: generate, train, render, track, evaluate (no arguments needed).
    Demo(cmd::demo::Args),
    /// Render a synthetic video (frames + ground-truth CSV) of actions in a row.
    Synth(cmd::synth::Args),
    /// Track the action and the arm in a video: MCAP (Foxglove) and/or CSV, overlays.
    Track(cmd::track::Args),
    /// Compare a track with ground truth (SPEC §5.4 metrics, plots).
    Eval(cmd::eval::Args),
    /// Calibrate a scene from one frame: the table's corners in pixels, its size, the camera's
    /// intrinsics and the acting shoulder → scene.toml, reprojection error, preview image.
    Calibrate(cmd::calibrate::Args),
    /// Time the tracker on a synthetic sequence: per-frame median/p95, stages, peak memory.
    Bench(cmd::bench::Args),
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Train(a) => cmd::train::run(&a),
        Command::Classify(a) => cmd::classify::run(&a),
        Command::Inspect(a) => cmd::inspect::run(&a),
        Command::Demo(a) => cmd::demo::run(&a),
        Command::Synth(a) => cmd::synth::run(&a),
        Command::Track(a) => cmd::track::run(&a),
        Command::Eval(a) => cmd::eval::run(&a),
        Command::Bench(a) => cmd::bench::run(&a),
        Command::Calibrate(a) => cmd::calibrate::run(&a),
    }
}

/// 2 when the error chain holds an input error of the library, else 1.
fn exit_code_of(e: &anyhow::Error) -> u8 {
    let input = e.chain().any(|c| {
        c.downcast_ref::<actrack::Error>()
            .is_some_and(actrack::Error::is_input_error)
            || c.downcast_ref::<cmd::UsageError>().is_some()
    });
    if input { 2 } else { 1 }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(exit_code_of(&e))
        }
    }
}
