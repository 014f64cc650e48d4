//! `actrack-cli bench [--config FILE | --preset NAME] [--set KEY=VALUE …] [--particles N]
//! [--contour raster|analytic] [--device cpu|gpu|auto] [--width W --height H] [--views V]
//! [--threads N] [--frames F] [--json]`:
//! tracks a synthetic sequence with the session and configuration `track` uses and prints the
//! time per frame (median, p95), frames/s, the share of each stage and the peak memory, so users
//! can check the real-time budget on their machine.

use std::process::ExitCode;

use actrack::bench::{BenchOptions, BenchReport, run_bench};

/// The real-time budget at 30 frames/s, ms.
const BUDGET_MS: f64 = 1000.0 / 30.0;

/// Contour method names.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Contour {
    /// tiny-skia silhouette, inner 4-neighbour boundary.
    Raster,
    /// Points every 2 px along the parts' outlines.
    Analytic,
}

/// Likelihood devices.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum DeviceArg {
    /// The CPU.
    Cpu,
    /// The GPU (build with `--features gpu`); an error when no adapter exists.
    Gpu,
    /// The GPU when one exists, else the CPU (with a message).
    Auto,
}

/// Options of `bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The tracking configuration timed (default: what `track` runs).
    #[command(flatten)]
    pub config: super::config::ConfigArgs,
    /// Frame width in pixels.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Synchronised views (cameras around the table).
    #[arg(long, default_value_t = 1)]
    pub views: usize,
    /// Contour method (the key `observation.contour`).
    #[arg(long, value_enum)]
    pub contour: Option<Contour>,
    /// Where the likelihood runs (the key `observation.device`; the GPU scores SPEC's ε̄, so
    /// `gpu` also sets `observation.short_contour_penalty.enabled=false`).
    #[arg(long, value_enum)]
    pub device: Option<DeviceArg>,
    /// Worker threads.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Timed frames.
    #[arg(long, default_value_t = 100)]
    pub frames: usize,
    /// Untimed warm-up frames.
    #[arg(long, default_value_t = 5)]
    pub warmup: usize,
    /// PHMM states per action of the generator-trained models.
    #[arg(long, default_value_t = 20)]
    pub states: usize,
    /// Seed of the sequence, the models and the filter.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

fn print_report(r: &BenchReport) {
    println!(
        "{} particles, {}×{}, {} view(s), {} contours, {} thread(s), device {}",
        r.particles, r.width, r.height, r.views, r.contour, r.threads, r.device,
    );
    println!(
        "per frame: median {:.3} ms, p95 {:.3} ms, mean {:.3} ms over {} frames → {:.1} frames/s",
        r.median_ms, r.p95_ms, r.mean_ms, r.frames, r.fps
    );
    let verdict = if r.median_ms <= BUDGET_MS {
        "within"
    } else {
        "over"
    };
    println!(
        "real-time budget (30 frames/s = {BUDGET_MS:.1} ms): {verdict}, median at {:.0} % of it",
        100.0 * r.median_ms / BUDGET_MS
    );
    println!("stage medians:");
    for (name, ms, share) in r.shares() {
        println!("  {name:<30} {ms:>9.3} ms  {share:>5.1} %");
    }
    println!(
        "edge region: {:.1} % of the pixels (median)",
        100.0 * r.edge_region_share
    );
    if let Some(hwm) = r.peak_rss_kib {
        print!("peak memory (VmHWM): {:.1} MiB", hwm as f64 / 1024.0);
        if let (Some(a), Some(b)) = (r.rss_kib_after_warmup, r.rss_kib_end) {
            print!(
                "; resident after warm-up {:.1} MiB, at the end {:.1} MiB",
                a as f64 / 1024.0,
                b as f64 / 1024.0
            );
        }
        println!();
    }
    println!(
        "setup (training, rendering the frames): {:.1} s",
        r.setup_seconds
    );
}

/// Runs `bench`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    if args.frames == 0 || args.threads == 0 || args.views == 0 || args.states < 2 {
        return Err(super::UsageError(
            "--frames, --threads and --views must be ≥ 1, --states ≥ 2".into(),
        )
        .into());
    }
    if args.width < 16 || args.height < 16 {
        return Err(super::UsageError("--width and --height must be ≥ 16".into()).into());
    }
    let mut set = Vec::new();
    if let Some(c) = args.contour {
        set.push(format!(
            "observation.contour={}",
            match c {
                Contour::Raster => "raster",
                Contour::Analytic => "analytic",
            }
        ));
    }
    if let Some(d) = args.device {
        let name = match d {
            DeviceArg::Cpu => "cpu",
            DeviceArg::Gpu => "gpu",
            DeviceArg::Auto => "auto",
        };
        if name != "cpu" {
            set.push("observation.short_contour_penalty.enabled=false".into());
        }
        set.push(format!("observation.device={name}"));
    }
    let config = args.config.build(&set, Some(args.seed))?;
    let opts = BenchOptions {
        config,
        width: args.width,
        height: args.height,
        views: args.views,
        frames: args.frames,
        warmup: args.warmup,
        threads: args.threads,
        seed: args.seed,
        states: args.states,
    };
    let report = run_bench(&opts)?;
    if let Some(note) = &report.device_note {
        eprintln!("note: {note}");
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_report(&report);
    }
    Ok(ExitCode::SUCCESS)
}
