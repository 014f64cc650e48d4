//! `actrack-cli track --model M --scene S --input IN -o track.mcap [--csv track.csv] …`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

use actrack::frames::{FrameOptions, FrameSource};
use actrack::model::{ActionModel, DwellCap};
use actrack::pipeline::{ContourMethod, ThetaPrior, TrackOptions, TrackOutputs, track};
use actrack::scene::Scene;

/// Set by Ctrl-C / SIGTERM; the pipeline finishes the outputs with the frames done so far.
pub static STOP: AtomicBool = AtomicBool::new(false);

/// Installs the Ctrl-C / SIGTERM handler (once).
pub fn install_stop_handler() {
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            // Second signal: give up at once.
            std::process::exit(130);
        }
        eprintln!(
            "\ninterrupted: finishing the outputs with the frames done so far (Ctrl-C again to abort)"
        );
    });
}

/// Options of `track`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The action model file (`*.actrack.json`).
    #[arg(long, short = 'm')]
    pub model: PathBuf,
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
    /// Number of particles.
    #[arg(long, default_value_t = 400)]
    pub particles: usize,
    /// Seed of every random draw (the result does not depend on --threads).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Frame rate (default: the source's, or 30 for image directories).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Skip corrupt frames and frames of another size instead of stopping.
    #[arg(long)]
    pub skip_bad_frames: bool,
    /// Contour of the likelihood: `raster` (SPEC §4.2) or `analytic` (cheaper).
    #[arg(long, value_enum, default_value_t = ContourArg::Raster)]
    pub contour: ContourArg,
    /// θ prior of each action: `training` (the box of the action's training targets, padded by
    /// 5 cm) or `scene` (the scene's table region for every action, SPEC §3.2 literally).
    #[arg(long, value_enum, default_value_t = ThetaPriorArg::Training)]
    pub theta_prior: ThetaPriorArg,
    /// Per-particle speeds `LO,HI` (e.g. `0.8,2.0`): each particle draws a speed log-uniformly
    /// from [LO, HI] per action instance and takes that many transitions per frame on average,
    /// for people who move faster or slower than the demonstrations. Default: the models'
    /// timing.
    #[arg(long, value_name = "LO,HI", value_parser = parse_speed_range)]
    pub speed_range: Option<[f64; 2]>,
    /// Cap every model state's self-transition probability at P (0 < P ≤ 1, e.g. 0.8: no state
    /// is expected to last more than 1/(1 − P) frames), for people who pause for less time than
    /// the demonstrations did (a drink held at the mouth). Default: the models' dwell times.
    #[arg(long, value_name = "P", value_parser = parse_max_stay)]
    pub max_stay: Option<f64>,
    /// With `--max-stay`: leave each model's last state uncapped, so that the action holds while
    /// the arm rests after it (the demonstrations end at rest; capping that state makes a
    /// finished drink look like the start of a reach).
    #[arg(long, requires = "max_stay")]
    pub keep_last_dwell: bool,
    /// Multiply the models' heights (actor-frame z of shoulder, elbow and fingertip) by S > 0,
    /// for an actor whose table lies nearer to (S < 1) or farther from the shoulder than the
    /// demonstrators': S = the actor's fingertip height below the shoulder with the hand at
    /// rest on the table over the models' (`inspect` prints the models' rest height). Default:
    /// the models' heights.
    #[arg(long, value_name = "S", value_parser = parse_height_scale)]
    pub height_scale: Option<f64>,
    /// A soft floor under the fingertip at height Z (metres, actor frame: negative, below the
    /// shoulder; the actor's fingertip height with the hand at rest on the table, e.g.
    /// `--fingertip-floor=-0.30`), or `table` for the scene's table surface: poses whose
    /// fingertip lies d below it lose ½(d/1 cm)² of log-likelihood, since the hand cannot go
    /// through the table. Default: no floor.
    #[arg(long, value_name = "Z|table", allow_hyphen_values = true, value_parser = parse_floor)]
    pub fingertip_floor: Option<FloorArg>,
    /// The fraction F ∈ (0, 1) of the particles split evenly over the actions as a floor: the
    /// filter resamples within each action and every action keeps at least F·M/|actions|
    /// particles, however improbable it has become (default 0.25). A larger floor keeps the
    /// less probable actions tracked, so that when the evidence turns they are in phase.
    #[arg(long, value_name = "F", value_parser = parse_action_floor)]
    pub action_floor: Option<f64>,
}

/// `--action-floor F`: 0 < F < 1.
fn parse_action_floor(s: &str) -> Result<f64, String> {
    let f: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number (expected 0 < F < 1, e.g. 0.9)"))?;
    if !(f > 0.0 && f < 1.0) {
        return Err(format!("needs 0 < F < 1, got {f}"));
    }
    Ok(f)
}

/// `--fingertip-floor`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FloorArg {
    /// The scene's table surface.
    Table,
    /// A height in metres, actor frame.
    Height(f64),
}

/// `--fingertip-floor Z|table`: `table` or a finite height in metres.
fn parse_floor(s: &str) -> Result<FloorArg, String> {
    if s.trim() == "table" {
        return Ok(FloorArg::Table);
    }
    let v: f64 = s.trim().parse().map_err(|_| {
        format!(
            "`{s}` is neither `table` nor a number (expected a height in metres, actor frame, \
             e.g. -0.30)"
        )
    })?;
    if !v.is_finite() {
        return Err(format!("needs a finite height in metres, got {v}"));
    }
    Ok(FloorArg::Height(v))
}

/// `--height-scale S`: finite, S > 0.
fn parse_height_scale(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number (expected S > 0, e.g. 0.9)"))?;
    if !(v.is_finite() && v > 0.0) {
        return Err(format!("needs a finite S > 0, got {v}"));
    }
    Ok(v)
}

/// `--max-stay P`: 0 < P ≤ 1.
fn parse_max_stay(s: &str) -> Result<f64, String> {
    let p: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number (expected 0 < P ≤ 1, e.g. 0.8)"))?;
    if !(p > 0.0 && p <= 1.0) {
        return Err(format!("needs 0 < P ≤ 1, got {p}"));
    }
    Ok(p)
}

/// `--speed-range LO,HI`: two numbers, 0 < LO ≤ HI ≤ 4.
fn parse_speed_range(s: &str) -> Result<[f64; 2], String> {
    let v: Vec<&str> = s.split(',').map(str::trim).collect();
    let [lo, hi] = v[..] else {
        return Err(format!("expected LO,HI (e.g. 0.8,2.0), got `{s}`"));
    };
    let num = |x: &str| {
        x.parse::<f64>()
            .map_err(|_| format!("`{x}` is not a number (expected LO,HI, e.g. 0.8,2.0)"))
    };
    let (lo, hi) = (num(lo)?, num(hi)?);
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi && hi <= 4.0) {
        return Err(format!(
            "needs 0 < LO ≤ HI ≤ 4 (1 = the models' timing), got {lo},{hi}"
        ));
    }
    Ok([lo, hi])
}

/// `--theta-prior`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum ThetaPriorArg {
    /// Each action's own training targets.
    Training,
    /// The scene's table region.
    Scene,
}

/// `--contour`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum ContourArg {
    /// Rasterised silhouette boundary.
    Raster,
    /// Points along the projected outlines.
    Analytic,
}

/// Runs `track`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    if args.output.is_none() && args.csv.is_none() && args.overlay.is_none() {
        return Err(super::UsageError(
            "nothing to write: give -o track.mcap, --csv track.csv and/or --overlay DIR".into(),
        )
        .into());
    }
    if args.particles == 0 {
        return Err(super::UsageError("--particles must be ≥ 1".into()).into());
    }
    if let Some(n) = args.threads {
        actrack::pipeline::set_threads(n)?;
    }
    let model = ActionModel::load(&args.model)?;
    let scene = Scene::load(&args.scene)?;
    let mut source = FrameSource::open(
        &args.input,
        &FrameOptions {
            fps: args.fps,
            skip_bad_frames: args.skip_bad_frames,
        },
    )?;
    install_stop_handler();
    let opts = TrackOptions {
        particles: args.particles,
        seed: args.seed,
        contour: match args.contour {
            ContourArg::Raster => ContourMethod::Raster,
            ContourArg::Analytic => ContourMethod::Analytic,
        },
        theta_prior: match args.theta_prior {
            ThetaPriorArg::Training => ThetaPrior::Training,
            ThetaPriorArg::Scene => ThetaPrior::Scene,
        },
        speed_range: args.speed_range,
        dwell_cap: args.max_stay.map(|max_stay| DwellCap {
            max_stay,
            keep_last: args.keep_last_dwell,
        }),
        height_scale: args.height_scale,
        fingertip_floor: args.fingertip_floor.map(|f| match f {
            FloorArg::Table => scene.table_height(),
            FloorArg::Height(z) => z,
        }),
        action_floor: args.action_floor,
    };
    let outputs = TrackOutputs {
        mcap: args.output.clone(),
        mcap_images: args.images,
        csv: args.csv.clone(),
        overlay: args.overlay.clone(),
    };
    let bar = super::frame_bar(source.len_hint());
    let mut progress = |done: usize, _total: Option<usize>| {
        if let Some(b) = &bar {
            b.set_position(done as u64);
        }
    };
    let summary = track(
        &model,
        &scene,
        &mut source,
        &opts,
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
        "tracked {} frames in {:.1} s ({fps:.1} frames/s, {:.1} ms/frame in the filter), {} particles",
        summary.frames,
        summary.seconds,
        1000.0 * summary.filter_seconds / summary.frames.max(1) as f64,
        args.particles
    );
    for (what, p) in [
        ("MCAP", &args.output),
        ("CSV", &args.csv),
        ("overlays", &args.overlay),
    ] {
        if let Some(p) = p {
            eprintln!("{what}: {}", p.display());
        }
    }
    if summary.interrupted {
        eprintln!(
            "interrupted after {} frames: the outputs hold the frames done so far",
            summary.frames
        );
        return Ok(ExitCode::from(130));
    }
    Ok(ExitCode::SUCCESS)
}
