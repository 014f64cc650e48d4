//! `actrack-cli demo`: the embedded default (no arguments needed).

use std::path::PathBuf;
use std::process::ExitCode;

use actrack::demo::{DemoOptions, run_demo, shown};

/// Options of `demo` (all optional).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The folder for everything the demo makes.
    #[arg(long, default_value = "actrack-demo")]
    pub dir: PathBuf,
    /// The tracking configuration (default: the `default` preset, as `track` uses).
    #[command(flatten)]
    pub config: super::config::ConfigArgs,
    /// Seed of everything.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs `demo`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    super::track::install_stop_handler();
    let start = std::time::Instant::now();
    let config = args.config.build(&[], Some(args.seed))?;
    let opts = DemoOptions {
        dir: args.dir.clone(),
        config,
        seed: args.seed,
        ..DemoOptions::default()
    };
    let bar = std::cell::RefCell::new(None::<indicatif::ProgressBar>);
    let mut say = |s: &str| eprintln!("{s}");
    let mut progress = |done: usize, total: Option<usize>| {
        let mut b = bar.borrow_mut();
        if b.is_none() {
            *b = super::frame_bar(total);
        }
        if let Some(b) = b.as_ref() {
            b.set_position(done as u64);
        }
    };
    let r = run_demo(&opts, &super::track::STOP, &mut say, &mut progress)?;
    if let Some(b) = bar.borrow().as_ref() {
        b.finish_and_clear();
    }
    let total = start.elapsed().as_secs_f64();
    let frames = r.track.frames;
    let threads = std::thread::available_parallelism().map_or(1, usize::from);
    println!();
    println!(
        "actrack demo — {} actions in a row, {frames} frames 320×240, {} particles, {threads} threads",
        opts.actions.len(),
        r.particles
    );
    println!();
    println!("{:<34} {:>10}", "stage", "seconds");
    println!(
        "{:<34} {:>10.2}",
        format!("generate + train ({} demos)", r.demonstrations),
        r.train_seconds
    );
    println!("{:<34} {:>10.2}", "render test video", r.synth_seconds);
    println!(
        "{:<34} {:>10.2}   ({:.1} frames/s, {:.2} ms/frame in the tracker)",
        "track",
        r.track.seconds,
        frames as f64 / r.track.seconds.max(1e-9),
        1000.0 * r.track.filter_seconds / frames.max(1) as f64
    );
    println!("{:<34} {:>10.2}", "total", total);
    println!();
    print!("{}", r.eval);
    println!();
    println!(
        "everything is in {}/ (model, scene, frames, truth, demo.mcap, track.csv, plots/)",
        args.dir.display()
    );
    println!("reproduce the result by hand:");
    println!(
        "  actrack-cli track --model {} --scene {} --input {} -o {} --csv {} --config {}",
        shown(&r.model),
        shown(&r.scene),
        shown(&r.frames),
        shown(&r.mcap),
        shown(&r.csv),
        shown(&r.config),
    );
    println!(
        "  actrack-cli eval --track {} --truth {} --plots {}",
        shown(&r.csv),
        shown(&r.truth),
        shown(&r.plots)
    );
    println!("(from a checkout: `cargo run --release -p actrack-cli -- track …`)");
    if r.track.interrupted {
        return Ok(super::track::interrupted_code());
    }
    Ok(ExitCode::SUCCESS)
}
