//! `actrack-cli bench [--particles N] [--width W --height H] [--views V]
//! [--contour raster|analytic] [--device cpu|gpu|auto] [--threads N] [--frames F] [--overlap]
//! [--json]`:
//! tracks a synthetic sequence and prints the time per frame (median, p95), frames/s, the share
//! of each stage and the peak memory, so users can check the real-time budget on their machine.

use std::process::ExitCode;

use actrack::bench::{BenchOptions, BenchReport, Device, run_bench};
use actrack::pipeline::ContourMethod;

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
    /// Particles.
    #[arg(long, default_value_t = 400)]
    pub particles: usize,
    /// Frame width in pixels.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Synchronised views (cameras around the table).
    #[arg(long, default_value_t = 1)]
    pub views: usize,
    /// Contour method.
    #[arg(long, value_enum, default_value_t = Contour::Analytic)]
    pub contour: Contour,
    /// Where the likelihood runs.
    #[arg(long, value_enum, default_value_t = DeviceArg::Cpu)]
    pub device: DeviceArg,
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
    /// Seed.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Overlap each tracker step with the next frame's edge image, as `track` does (there the
    /// next frame's decoding joins it); default: the serial order, whose stages add up.
    #[arg(long)]
    pub overlap: bool,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

fn print_report(r: &BenchReport) {
    println!(
        "{} particles, {}×{}, {} view(s), {} contours, {} thread(s), device {}, {}",
        r.particles,
        r.width,
        r.height,
        r.views,
        r.contour,
        r.threads,
        r.device,
        if r.overlap {
            "step overlapped with the next edge image"
        } else {
            "serial"
        }
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
    if r.overlap && r.threads > 1 {
        println!("stage medians (the edge image runs alongside the other four):");
    } else {
        println!("stage medians:");
    }
    for (name, ms, share) in r.shares() {
        println!("  {name:<30} {ms:>9.3} ms  {share:>5.1} %");
    }
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
    if args.particles == 0 || args.frames == 0 || args.threads == 0 || args.views == 0 {
        return Err(super::UsageError(
            "--particles, --frames, --threads and --views must be ≥ 1".into(),
        )
        .into());
    }
    if args.width < 16 || args.height < 16 {
        return Err(super::UsageError("--width and --height must be ≥ 16".into()).into());
    }
    let opts = BenchOptions {
        particles: args.particles,
        width: args.width,
        height: args.height,
        views: args.views,
        contour: match args.contour {
            Contour::Raster => ContourMethod::Raster,
            Contour::Analytic => ContourMethod::Analytic,
        },
        frames: args.frames,
        warmup: args.warmup,
        threads: args.threads,
        seed: args.seed,
        states: args.states,
        device: match args.device {
            DeviceArg::Cpu => Device::Cpu,
            DeviceArg::Gpu => Device::Gpu,
            DeviceArg::Auto => Device::Auto,
        },
        overlap: args.overlap,
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
