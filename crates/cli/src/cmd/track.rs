//! `actrack-cli track [--model M] --scene S --input IN -o track.mcap [--csv track.csv] …`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use actrack::frames::{FrameOptions, FrameSource};
use actrack::model::ActionModel;
use actrack::pipeline::{TrackOutputs, track};
use actrack::scene::Scene;

/// Set by Ctrl-C / SIGTERM; the pipeline finishes the outputs with the frames done so far.
pub static STOP: std::sync::LazyLock<Arc<AtomicBool>> =
    std::sync::LazyLock::new(|| Arc::new(AtomicBool::new(false)));

/// Set by SIGTERM (exit code 143 = 128 + 15 instead of 130 for Ctrl-C).
static TERMINATED: std::sync::LazyLock<Arc<AtomicBool>> =
    std::sync::LazyLock::new(|| Arc::new(AtomicBool::new(false)));

/// Installs the Ctrl-C / SIGTERM handlers (a second signal exits at once).
#[cfg(unix)]
pub fn install_stop_handler() {
    use signal_hook::consts::{SIGINT, SIGTERM};
    use signal_hook::flag;
    // The conditional exits first: they fire only once STOP is already set (a second signal).
    let _ = flag::register_conditional_shutdown(SIGINT, 130, Arc::clone(&STOP));
    let _ = flag::register_conditional_shutdown(SIGTERM, 143, Arc::clone(&STOP));
    let _ = flag::register(SIGTERM, Arc::clone(&TERMINATED));
    let _ = flag::register(SIGINT, Arc::clone(&STOP));
    let _ = flag::register(SIGTERM, Arc::clone(&STOP));
}

/// Installs the Ctrl-C handler (a second Ctrl-C exits at once).
#[cfg(windows)]
pub fn install_stop_handler() {
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
    });
}

/// The exit code of an interrupted run: 143 after SIGTERM, 130 after Ctrl-C.
pub fn interrupted_code() -> ExitCode {
    ExitCode::from(if TERMINATED.load(Ordering::SeqCst) {
        143
    } else {
        130
    })
}

/// Options of `track`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The action model file (`*.actrack.json`; default: the shipped reach-and-drink model,
    /// `models/reach-drink.v1.actrack.json`, built in).
    #[arg(long, short = 'm')]
    pub model: Option<PathBuf>,
    /// The scene file (TOML: cameras, table, actor). The video is from its first camera.
    #[arg(long, short = 's')]
    pub scene: PathBuf,
    /// The frames: a directory of PNG/JPEG images, a `.y4m` file, `-` for y4m on stdin, or any
    /// video ffmpeg can decode.
    #[arg(long, short = 'i')]
    pub input: PathBuf,
    /// The MCAP track to write (Foxglove schemas).
    #[arg(long, short = 'o')]
    pub output: Option<PathBuf>,
    /// The trajectory CSV to write.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// A directory for overlay images (best contour, θ dot coloured by entropy).
    #[arg(long)]
    pub overlay: Option<PathBuf>,
    /// Also put the camera image, calibration and contour topics in the MCAP.
    #[arg(long)]
    pub images: bool,
    /// The tracking configuration.
    #[command(flatten)]
    pub config: super::config::ConfigArgs,
    /// Seed of every random draw (the key `filter.seed`; the result does not depend on
    /// --threads).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Frame rate (default: the source's, or 30 for image directories).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Skip corrupt frames and frames of another size instead of stopping.
    #[arg(long)]
    pub skip_bad_frames: bool,
    /// Read the input live, as a camera device always is: the newest frame wins, frames the
    /// tracker has no time for are dropped, and the frame rates in and out are shown.
    #[arg(long)]
    pub live: bool,
}

/// Runs `track`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    if args.output.is_none() && args.csv.is_none() && args.overlay.is_none() {
        return Err(super::UsageError(
            "nothing to write: give -o track.mcap, --csv track.csv and/or --overlay DIR".into(),
        )
        .into());
    }
    let config = args.config.build(&[], args.seed)?;
    if let Some(n) = args.threads {
        actrack::pipeline::set_threads(n)?;
    }
    let model = if let Some(p) = &args.model {
        ActionModel::load(p)?
    } else {
        let m = actrack::model::default_model()?;
        eprintln!(
            "model: the built-in {} (actions {})",
            actrack::model::DEFAULT_MODEL_NAME,
            m.action_names().join(", ")
        );
        m
    };
    let scene = Scene::load(&args.scene)?;
    if scene.cameras.len() != 1 {
        return Err(actrack::Error::invalid(
            &args.scene,
            format!(
                "has {} [[camera]]s but track reads one video ({}): give a scene with only the \
                 camera that filmed it",
                scene.cameras.len(),
                args.input.display()
            ),
        )
        .into());
    }
    let mut source = FrameSource::open(
        &args.input,
        &FrameOptions {
            fps: args.fps,
            skip_bad_frames: args.skip_bad_frames,
            live: args.live,
        },
    )?;
    let live = source.live_stats();
    install_stop_handler();
    let outputs = TrackOutputs {
        mcap: args.output.clone(),
        mcap_images: args.images,
        csv: args.csv.clone(),
        overlay: args.overlay.clone(),
        keep_trajectory: false,
    };
    let bar = super::frame_bar(source.len_hint());
    let started = std::time::Instant::now();
    let mut readout = LiveReadout::default();
    let mut progress = |done: usize, _total: Option<usize>| {
        if let Some(b) = &bar {
            b.set_position(done as u64);
        }
        if let Some(stats) = &live
            && let Some(line) = readout.update(started.elapsed().as_secs_f64(), done, stats)
        {
            match &bar {
                Some(b) => b.set_message(line),
                None => eprintln!("{line}"),
            }
        }
    };
    let summary = track(
        &model,
        &scene,
        &mut source,
        &config,
        &outputs,
        &STOP,
        &mut progress,
    )?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    for (i, why) in &summary.skipped {
        eprintln!("skipped frame {i}: {why}");
    }
    let fps = summary.frames as f64 / summary.seconds.max(1e-9);
    eprintln!(
        "tracked {} frames in {:.1} s ({fps:.1} frames/s, {:.2} ms/frame in the tracker), {} particles",
        summary.frames,
        summary.seconds,
        1000.0 * summary.filter_seconds / summary.frames.max(1) as f64,
        config.filter.particles
    );
    if let Some(stats) = &live {
        eprintln!(
            "live: {} frames arrived, {} tracked, {} dropped (the tracker had no time for them)",
            stats.received(),
            summary.frames,
            stats.dropped()
        );
    }
    for (what, p) in [
        ("MCAP", &args.output),
        ("CSV", &args.csv),
        ("overlays", &args.overlay),
    ] {
        if let Some(p) = p {
            eprintln!("{what}: {}", p.display());
        }
    }
    if let Some(why) = &summary.stopped {
        eprintln!(
            "warning: the input broke off after {} frames: {why}; the outputs hold the {} frames \
             tracked before",
            summary.frames, summary.frames
        );
        if !args.skip_bad_frames {
            return Err(super::UsageError(format!(
                "{}: stopped after {} frames (outputs finished with them): {why}",
                args.input.display(),
                summary.frames
            ))
            .into());
        }
    }
    if summary.interrupted {
        eprintln!(
            "interrupted after {} frames: the outputs hold the frames done so far",
            summary.frames
        );
        return Ok(interrupted_code());
    }
    Ok(ExitCode::SUCCESS)
}

/// The frame-rate readout of a live source: once a second, the rates in (from the source) and out
/// (tracked) over the last second and the frames dropped so far.
#[derive(Default)]
struct LiveReadout {
    last: Option<(f64, usize, usize)>,
}

impl LiveReadout {
    fn update(
        &mut self,
        now: f64,
        tracked: usize,
        stats: &actrack::frames::LiveStats,
    ) -> Option<String> {
        let received = stats.received();
        let (t0, r0, k0) = *self.last.get_or_insert((0.0, 0, 0));
        let dt = now - t0;
        if dt < 1.0 {
            return None;
        }
        self.last = Some((now, received, tracked));
        Some(format!(
            "live: {:.1} frames/s in, {:.1} tracked/s, {} dropped",
            (received - r0) as f64 / dt,
            (tracked - k0) as f64 / dt,
            stats.dropped()
        ))
    }
}
