//! The embedded demo: generator → demonstrations → one parametric HMM per action → a synthetic
//! test video of several actions in a row with known truth → track → MCAP, CSV, plots → the
//! accuracy and speed summary. Everything it makes stays in one folder, so the result can be
//! reproduced by hand with `actrack-cli track` and `actrack-cli eval`.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use actrack_phmm::{EndMode, PhmmParams};
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use crate::config::TrackConfig;
use crate::error::{Error, Result};
use crate::eval::{EvalReport, evaluate};
use crate::frames::{FrameOptions, FrameSource};
use crate::model::{Action, ActionModel, ArmLengths, Provenance, THETA_FRAME};
use crate::motion::{ACTIONS, demonstrations};
use crate::pipeline::{TrackOutputs, TrackSummary, track};
use crate::scene::{Scene, SceneCamera, default_scene, look_at};
use crate::synth::{
    MotionSource, motion_params, random_targets, render_frames, save_frames, sequence,
};

/// Options of the demo.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Output folder.
    pub dir: PathBuf,
    /// The tracking configuration (default: the `default` preset; its filter seed is replaced by
    /// `seed`).
    pub config: TrackConfig,
    /// Seed of everything.
    pub seed: u64,
    /// Frame size.
    pub size: (u32, u32),
    /// The test video's actions in order.
    pub actions: Vec<String>,
    /// Demonstrations per table corner and action.
    pub reps: usize,
    /// PHMM states per action.
    pub states: usize,
}

impl Default for DemoOptions {
    fn default() -> Self {
        Self {
            dir: PathBuf::from("actrack-demo"),
            config: TrackConfig::default(),
            seed: 1,
            size: (320, 240),
            actions: ["point", "push", "reach", "point"]
                .map(String::from)
                .to_vec(),
            reps: 4,
            states: 20,
        }
    }
}

/// What the demo did.
#[derive(Clone, Debug)]
pub struct DemoReport {
    /// Accuracy.
    pub eval: EvalReport,
    /// The tracking run.
    pub track: TrackSummary,
    /// Seconds generating and training.
    pub train_seconds: f64,
    /// Seconds rendering the test video.
    pub synth_seconds: f64,
    /// Number of training demonstrations.
    pub demonstrations: usize,
    /// Particles used.
    pub particles: usize,
    /// Seed used.
    pub seed: u64,
    /// Paths: model, scene, frames, truth, mcap, csv, plots.
    pub model: PathBuf,
    /// Scene file.
    pub scene: PathBuf,
    /// The tracking configuration used (TOML).
    pub config: PathBuf,
    /// Frame directory.
    pub frames: PathBuf,
    /// Ground truth CSV.
    pub truth: PathBuf,
    /// Track MCAP.
    pub mcap: PathBuf,
    /// Track CSV.
    pub csv: PathBuf,
    /// Plot directory.
    pub plots: PathBuf,
}

/// Trains one parametric HMM per action on generator demonstrations in `scene`.
pub fn train_generator_model(
    scene: &Scene,
    actions: &[&str],
    reps: usize,
    states: usize,
    seed: u64,
) -> Result<(ActionModel, usize)> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let params = motion_params(scene, 30.0);
    let (centre, half) = scene.theta_region();
    let demos = demonstrations(actions, centre, half, reps, &params, &mut rng);
    let phmm = PhmmParams::new(states)
        .max_jump(3)
        .end_mode(EndMode::MustEnd)
        .max_iterations(25)
        .cov_floor(0.01)
        .seed(seed)
        .check()
        .map_err(|e| Error::Config(e.to_string()))?;
    let fitted: Vec<Result<Action>> = actions
        .par_iter()
        .map(|name| {
            let mine: Vec<_> = demos.iter().filter(|m| m.action == *name).collect();
            let seqs: Vec<DMatrix<f64>> = mine.iter().map(|m| m.poses.clone()).collect();
            let thetas: Vec<DVector<f64>> = mine
                .iter()
                .map(|m| DVector::from_row_slice(&m.theta))
                .collect();
            let (p, report) = phmm.fit(&seqs, &thetas).map_err(|e| Error::Model {
                context: format!("training `{name}`"),
                message: e.to_string(),
            })?;
            let n = thetas.len() as f64;
            let mut mean = [0.0; 2];
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for t in &thetas {
                for c in 0..2 {
                    mean[c] += t[c] / n;
                    lo[c] = lo[c].min(t[c]);
                    hi[c] = hi[c].max(t[c]);
                }
            }
            let mut cov = [[0.0; 2]; 2];
            for t in &thetas {
                for a in 0..2 {
                    for b in 0..2 {
                        cov[a][b] += (t[a] - mean[a]) * (t[b] - mean[b]) / (n - 1.0).max(1.0);
                    }
                }
            }
            let mut lens: Vec<f64> = seqs.iter().map(|s| s.nrows() as f64).collect();
            lens.sort_by(f64::total_cmp);
            Ok(Action {
                name: (*name).to_string(),
                phmm: p,
                theta_mean: mean,
                theta_cov: cov,
                theta_min: lo,
                theta_max: hi,
                n_trials: seqs.len(),
                iterations: report.iterations,
                converged: report.converged,
                final_log_likelihood: report.log_likelihoods.last().copied().unwrap_or(f64::NAN),
                median_frames: lens[lens.len() / 2],
            })
        })
        .collect();
    let actions_fitted = fitted.into_iter().collect::<Result<Vec<_>>>()?;
    let model = ActionModel {
        actions: actions_fitted,
        arm_lengths: ArmLengths {
            upper_arm: params.upper_arm,
            forearm_hand: params.forearm_hand,
        },
        theta_frame: THETA_FRAME.to_string(),
        preprocessing: crate::mocap::trial::Preprocessing::default(),
        provenance: Provenance {
            tool: format!(
                "actrack {} (built-in motion generator)",
                env!("CARGO_PKG_VERSION")
            ),
            created: crate::model::now_iso8601(),
            manifest: None,
            files: vec![format!(
                "generator: {} demonstrations, seed {seed}",
                demos.len()
            )],
            states,
            max_jump: 3,
            max_iterations: 25,
            cov_floor: 0.01,
        },
    };
    Ok((model, demos.len()))
}

/// The demo's scene: [`default_scene`]'s table and actor, filmed as a user would set a camera
/// up — across the table, out to the acting arm's side and above the shoulder, with a 65°
/// horizontal field of view — so that the actions' paths differ across the image and not only
/// along the line of sight.
pub fn demo_scene(width: u32, height: u32) -> Scene {
    let mut scene = default_scene(width, height);
    let shoulder = scene.actor.origin;
    let eye = shoulder + nalgebra::Vector3::new(0.6, 1.3, 0.6);
    let target = shoulder + nalgebra::Vector3::new(-0.1, 0.3, -0.1);
    let f = 0.5 * f64::from(width) / (0.5 * 65f64.to_radians()).tan();
    if let Some(pose) = look_at(eye, target, nalgebra::Vector3::z()) {
        scene.cameras = vec![SceneCamera::centred("camera0", (width, height), f, pose)];
    }
    scene
}

/// Runs the demo; `say` receives one line per stage.
pub fn run_demo(
    opts: &DemoOptions,
    stop: &AtomicBool,
    say: &mut dyn FnMut(&str),
    progress: &mut dyn FnMut(usize, Option<usize>),
) -> Result<DemoReport> {
    let dir = &opts.dir;
    std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
    let p = |n: &str| dir.join(n);
    let scene = demo_scene(opts.size.0, opts.size.1);
    let scene_path = p("scene.toml");
    std::fs::write(&scene_path, scene.to_toml_string())
        .map_err(|e| Error::write(&scene_path, e))?;

    let t0 = Instant::now();
    say(&format!(
        "training point/reach/push models on generated demonstrations ({} per action)…",
        4 * opts.reps
    ));
    let (model, n_demos) =
        train_generator_model(&scene, &ACTIONS, opts.reps, opts.states, opts.seed)?;
    let model_path = p("model.actrack.json");
    model.save(&model_path)?;
    let train_seconds = t0.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let names: Vec<&str> = opts.actions.iter().map(String::as_str).collect();
    let targets = random_targets(&scene, &names, opts.seed);
    let seq = sequence(
        &scene,
        MotionSource::Generator,
        &targets,
        30.0,
        opts.seed.wrapping_add(1),
    )?;
    say(&format!(
        "rendering a {}-frame test video of {} actions ({})…",
        seq.poses_actor.len(),
        names.len(),
        names.join(", ")
    ));
    let world: Vec<[f64; 9]> = seq.truth.rows.iter().map(|r| r.pose).collect();
    let frames = render_frames(&scene, &world, seq.lengths, opts.seed)?;
    let frames_dir = p("frames");
    if frames_dir.exists() {
        for f in std::fs::read_dir(&frames_dir)
            .map_err(|e| Error::read(&frames_dir, e))?
            .flatten()
        {
            if f.path().extension().is_some_and(|e| e == "png") {
                let _ = std::fs::remove_file(f.path());
            }
        }
    }
    save_frames(&frames, &frames_dir)?;
    let truth_path = p("truth.csv");
    seq.truth.save(&truth_path)?;
    let synth_seconds = t1.elapsed().as_secs_f64();

    let mut config = opts.config.clone();
    config.filter.seed = opts.seed;
    config.check()?;
    let config_path = p("config.toml");
    std::fs::write(&config_path, config.to_toml()).map_err(|e| Error::write(&config_path, e))?;
    say(&format!(
        "tracking with {} particles…",
        config.filter.particles
    ));
    let mcap = p("demo.mcap");
    let csv = p("track.csv");
    let mut source = FrameSource::open(&frames_dir, &FrameOptions::default())?;
    let outputs = TrackOutputs {
        mcap: Some(mcap.clone()),
        mcap_images: false,
        csv: Some(csv.clone()),
        overlay: None,
        keep_trajectory: true,
    };
    let summary = track(
        &model,
        &scene,
        &mut source,
        &config,
        &outputs,
        stop,
        progress,
    )?;
    let eval = evaluate(&summary.trajectory, &seq.truth)?;
    let plots = p("plots");
    crate::plots::write_all(&summary.trajectory, &seq.truth, &plots)?;
    Ok(DemoReport {
        eval,
        track: summary,
        train_seconds,
        synth_seconds,
        demonstrations: n_demos,
        particles: config.filter.particles,
        seed: opts.seed,
        model: model_path,
        scene: scene_path,
        config: config_path,
        frames: frames_dir,
        truth: truth_path,
        mcap,
        csv,
        plots,
    })
}

/// `path` relative to the current directory where possible, for printed commands.
pub fn shown(path: &Path) -> String {
    let s = path.display().to_string();
    if s.contains(' ') { format!("'{s}'") } else { s }
}
