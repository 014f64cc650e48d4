//! `actrack-cli synth -o DIR [--scene S] [--model M] --action point@-0.1,0.45 --action push …`.

use std::path::PathBuf;
use std::process::ExitCode;

use actrack::model::ActionModel;
use actrack::scene::{Scene, default_scene};
use actrack::style::{Style, render_styled};
use actrack::synth::{MotionSource, random_targets, render_frames, save_frames, sequence};

/// Options of `synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output directory: `frames/frame_00000.png …`, `truth.csv` (and `scene.toml` when the
    /// built-in scene is used, `video.y4m` with --y4m).
    #[arg(long, short = 'o')]
    pub output: PathBuf,
    /// The scene file (default: a built-in one-camera table scene, written to the output).
    #[arg(long, short = 's')]
    pub scene: Option<PathBuf>,
    /// Sample the movements from this action model (default: the built-in minimum-jerk
    /// generator, which knows point, reach and push).
    #[arg(long, short = 'm')]
    pub model: Option<PathBuf>,
    /// An action, optionally with its θ in the actor frame in metres: `point` or
    /// `point@-0.1,0.45`; repeat for several actions in a row. Without θ, a random target in the
    /// table region.
    #[arg(long = "action", short = 'a', required = true)]
    pub actions: Vec<String>,
    /// Seed of the movements, targets and rendering.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Frame rate of the truth's time column.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Frame size WxH of the built-in scene.
    #[arg(long, default_value = "320x240")]
    pub size: String,
    /// Also write the frames as `video.y4m`.
    #[arg(long)]
    pub y4m: bool,
    /// The look of the video: `classic` (the scene's camera, fixed colours), `random` (camera
    /// placement, field of view, resolution, lens distortion, colours, lighting, textures,
    /// cups, the other arm, blur, noise, JPEG compression and dropped frames drawn from
    /// --seed; the scene's camera is replaced and the scene written to the output with
    /// `style.toml`) or a `style.toml` written by an earlier run.
    #[arg(long, default_value = "classic")]
    pub style: String,
}

fn parse_action(s: &str) -> Result<(String, Option<[f64; 2]>), String> {
    let Some((name, theta)) = s.split_once('@') else {
        return Ok((s.to_string(), None));
    };
    let v: Vec<f64> = theta
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            format!("--action {s}: θ must be two numbers in metres, e.g. {name}@-0.1,0.45")
        })?;
    if v.len() != 2 || !v.iter().all(|x| x.is_finite()) {
        return Err(format!(
            "--action {s}: θ must be two numbers in metres, e.g. {name}@-0.1,0.45"
        ));
    }
    Ok((name.to_string(), Some([v[0], v[1]])))
}

/// Largest frame `--size` renders (pixels): 8K UHD; larger frames exhaust memory before the
/// first one is drawn.
pub const MAX_PIXELS: u64 = 7680 * 4320;

/// How far (metres) beyond the scene's table region a `--action` θ may lie.
pub const MAX_THETA_OUTSIDE_TABLE: f64 = 0.3;

/// Runs `synth`.
pub fn run(args: &Args) -> anyhow::Result<ExitCode> {
    if !(args.fps.is_finite() && args.fps > 0.0) {
        return Err(super::UsageError("--fps must be positive".into()).into());
    }
    let scene = if let Some(p) = &args.scene {
        Scene::load(p)?
    } else {
        {
            let (w, h) = args
                .size
                .split_once('x')
                .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
                .filter(|(w, h)| *w >= 32 && *h >= 32)
                .ok_or_else(|| {
                    super::UsageError(format!("--size {}: expected WxH, e.g. 320x240", args.size))
                })?;
            if u64::from(w) * u64::from(h) > MAX_PIXELS {
                return Err(super::UsageError(format!(
                    "--size {}: {} megapixels per frame is more than the {} the renderer \
                     allows (e.g. 3840x2160)",
                    args.size,
                    u64::from(w) * u64::from(h) / 1_000_000,
                    MAX_PIXELS / 1_000_000
                ))
                .into());
            }
            default_scene(w, h)
        }
    };
    let style = match args.style.as_str() {
        "classic" => None,
        "random" => Some(Style::random(args.seed)),
        path => {
            let p = std::path::Path::new(path);
            if !p.is_file() {
                return Err(super::UsageError(format!(
                    "--style {path}: expected classic, random or a style.toml file"
                ))
                .into());
            }
            let text = std::fs::read_to_string(p)?;
            Some(Style::parse(&text, p).map_err(|e| super::UsageError(e.to_string()))?)
        }
    };
    // A style brings its own camera: the scene is seen through it.
    let scene = match &style {
        Some(s) => s.scene(&scene)?,
        None => scene,
    };
    let model = args
        .model
        .as_ref()
        .map(|p| ActionModel::load(p))
        .transpose()?;
    let mut actions = Vec::new();
    for (i, a) in args.actions.iter().enumerate() {
        let (name, theta) = parse_action(a).map_err(super::UsageError)?;
        let theta = theta.unwrap_or_else(|| {
            random_targets(&scene, &[name.as_str()], args.seed.wrapping_add(i as u64))[0].1
        });
        let (c, h) = scene.theta_region();
        let (lo, hi) = ([c[0] - h[0], c[1] - h[1]], [c[0] + h[0], c[1] + h[1]]);
        let off = (0..2)
            .map(|k| (lo[k] - theta[k]).max(theta[k] - hi[k]).max(0.0))
            .fold(0.0f64, f64::max);
        if off > MAX_THETA_OUTSIDE_TABLE {
            return Err(super::UsageError(format!(
                "--action {a}: θ is {off:.2} m outside the scene's table region (u in \
                 [{:.2}, {:.2}], v in [{:.2}, {:.2}] m, actor frame); at most \
                 {MAX_THETA_OUTSIDE_TABLE} m beyond it is within an arm's reach",
                lo[0], hi[0], lo[1], hi[1]
            ))
            .into());
        }
        actions.push((name, theta));
    }
    let source = model
        .as_ref()
        .map_or(MotionSource::Generator, MotionSource::Model);
    let seq = sequence(&scene, source, &actions, args.fps, args.seed)
        .map_err(|e| super::UsageError(e.to_string()))?;
    let world: Vec<[f64; 9]> = seq.truth.rows.iter().map(|r| r.pose).collect();
    let frames = match &style {
        None => render_frames(&scene, &world, seq.lengths, args.seed)?,
        Some(style) => render_styled(style, &scene, &seq.truth, seq.lengths)?,
    };
    std::fs::create_dir_all(&args.output)?;
    save_frames(&frames, &args.output.join("frames"))?;
    seq.truth.save(&args.output.join("truth.csv"))?;
    if args.scene.is_none() || style.is_some() {
        std::fs::write(args.output.join("scene.toml"), scene.to_toml_string())?;
    }
    if let Some(style) = &style {
        std::fs::write(args.output.join("style.toml"), style.to_toml())?;
    }
    if args.y4m {
        let f = std::io::BufWriter::new(std::fs::File::create(args.output.join("video.y4m"))?);
        actrack::frames::write_y4m(f, &frames, args.fps)?;
    }
    eprintln!(
        "wrote {} frames of {} to {}",
        frames.len(),
        actions
            .iter()
            .map(|(a, t)| format!("{a}@{:.3},{:.3}", t[0], t[1]))
            .collect::<Vec<_>>()
            .join(" "),
        args.output.display()
    );
    Ok(ExitCode::SUCCESS)
}
