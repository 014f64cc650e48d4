//! The paper's experiment on real motion: held-out UE-ADL trials rendered into synthetic video,
//! tracked by [`actrack::Session`], evaluated with SPEC §5.4.
//!
//! * [`test_trials`] imports the held-out trials of a manifest (actor frame, trimmed, 30 fps).
//! * [`scene_for`] builds each subject's world: the actor's shoulder at [`SHOULDER`], the table
//!   surface at the subject's rest height (the fingertip on the table in its first frames,
//!   measured once per actor like the arm lengths: [`rest_heights`]), the θ prior region the box
//!   around the *training* targets of every action (padded by [`REGION_PAD`]), the camera(s) of
//!   the data README.
//! * A [`Condition`] is a [`TrackConfig`] plus the rendering conditions (views, clutter, noise,
//!   seed); [`load_conditions`] reads them from TOML ([`ConditionSpec`]).
//! * [`run_video`] renders a sequence of segments frame by frame in memory, tracks it with a
//!   [`Session`] and returns the track (as `actrack-cli track` writes it), the truth and the
//!   per-frame timings; [`run_condition`] does so for every trial of a condition in parallel and
//!   evaluates the whole.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use actrack::config::TrackConfig;
use actrack::eval::{ErrorStats, EvalReport, evaluate};
use actrack::manifest::Manifest;
use actrack::mocap::ArmSide;
use actrack::mocap::trial::{Importer, median};
use actrack::model::ActionModel;
use actrack::pipeline::{draw_overlay, track_row};
use actrack::scene::{
    ArmSettings, EdgeSettings, Placement, Scene, SceneCamera, SceneTable, Side, look_at, render_arm,
};
use actrack::session::{PoseReport, Session};
use actrack::style::{Style, StyledVideo, video_cups};
use actrack::synth::scene_synth;
use actrack::track_csv::{TrajRow, Trajectory};
use actrack::train::{Progress, fit_actions, import_manifest, import_trials};
use actrack::{Error, Result};
use actrack_render::contour_points;
use image::RgbImage;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// World position of the actor's shoulder (the actor frame's origin; heading 0).
pub const SHOULDER: [f64; 3] = [0.0, 0.0, 1.0];
/// Table surface below the shoulder when a subject's rest height is not known (UE-ADL README:
/// 0.33 m).
pub const TABLE_BELOW_SHOULDER: f64 = 0.33;
/// Padding of the scene's table region around the training targets (metres).
pub const REGION_PAD: f64 = 0.05;
/// First camera, actor frame (data README): eye and target.
pub const CAMERA0: ([f64; 3], [f64; 3]) = ([0.6, 1.3, 0.6], [-0.1, 0.3, -0.1]);
/// Second camera (two-view condition), actor frame: behind and to the right of the acting
/// shoulder, looking at the same point as the first (chosen on the training subjects).
pub const CAMERA1: ([f64; 3], [f64; 3]) = ([1.0, -0.3, 0.6], [-0.1, 0.3, -0.1]);
/// Horizontal field of view of both cameras (degrees).
pub const HFOV_DEG: f64 = 65.0;
/// Frame rate of the rendered video.
pub const FPS: f64 = 30.0;
/// Size of the rendered video's frames, pixels.
pub const FRAME_SIZE: (u32, u32) = (640, 480);

/// A held-out trial, ready to render.
#[derive(Clone, Debug)]
pub struct TestTrial {
    /// File stem, e.g. `ADL008FR1`.
    pub name: String,
    /// Subject, e.g. `ADL008`.
    pub subject: String,
    /// Ground-truth action label.
    pub action: String,
    /// θ of the trial (actor frame, metres).
    pub theta: [f64; 2],
    /// Joint trajectory (p, q, r) in the actor frame, 30 fps.
    pub poses: Vec<[f64; 9]>,
    /// The trial's arm lengths (upper arm, elbow → fingertip; medians).
    pub lengths: [f64; 2],
}

/// Imports the trials of `manifest` for one arm, sorted by name.
pub fn test_trials(manifest: &Manifest, arm: ArmSide) -> Result<Vec<TestTrial>> {
    let importer = Importer::new(manifest.preprocessing.clone())?;
    let wanted: Vec<_> = manifest
        .trials
        .iter()
        .filter(|t| t.arm == arm)
        .cloned()
        .collect();
    let quiet = |_: Progress| {};
    let imported = import_trials(&importer, &wanted, &quiet)?;
    let mut out: Vec<TestTrial> = imported
        .into_iter()
        .map(|lt| {
            let path = &lt.trial.source;
            let name = path
                .file_name()
                .and_then(|s| s.to_str())
                .map_or_else(String::new, |s| {
                    s.split('.').next().unwrap_or(s).to_string()
                });
            let subject = name.chars().take(6).collect();
            let arm = &lt.trial.arm_trajectory;
            TestTrial {
                name,
                subject,
                action: lt.action,
                theta: lt.trial.theta,
                poses: (0..arm.len()).map(|t| arm.pose(t)).collect(),
                lengths: lt.trial.arm_lengths,
            }
        })
        .collect();
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// Median arm lengths per subject (the scene's arm geometry: measured once per actor, like a
/// camera calibration).
pub fn subject_lengths(trials: &[TestTrial]) -> BTreeMap<String, [f64; 2]> {
    let mut by: BTreeMap<String, Vec<[f64; 2]>> = BTreeMap::new();
    for t in trials {
        by.entry(t.subject.clone()).or_default().push(t.lengths);
    }
    by.into_iter()
        .map(|(s, v)| {
            let l = [0, 1].map(|c| median(v.iter().map(|x| x[c]).collect()));
            (s, l)
        })
        .collect()
}

/// Each subject's rest height: the median over its trials of the fingertip's z (actor frame,
/// i.e. below the shoulder: negative) in the first frame, where the hand is still at rest on
/// the table. Measured once per actor, like [`subject_lengths`]; the frames of maximal
/// extension, where the table error is read, do not enter it.
pub fn rest_heights(trials: &[TestTrial]) -> BTreeMap<String, f64> {
    let mut by: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for t in trials {
        if let Some(p) = t.poses.first()
            && p[8].is_finite()
        {
            by.entry(t.subject.clone()).or_default().push(p[8]);
        }
    }
    by.into_iter().map(|(s, v)| (s, median(v))).collect()
}

/// The θ prior region (actor frame): the box around every action's training targets, padded.
pub fn theta_region(model: &ActionModel) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for a in &model.actions {
        for c in 0..2 {
            lo[c] = lo[c].min(a.theta_min[c]);
            hi[c] = hi[c].max(a.theta_max[c]);
        }
    }
    let centre = [0, 1].map(|c| 0.5 * (lo[c] + hi[c]));
    let half = [0, 1].map(|c| 0.5 * (hi[c] - lo[c]) + REGION_PAD);
    (centre, half)
}

fn camera(name: &str, eye: [f64; 3], target: [f64; 3]) -> Result<SceneCamera> {
    let o = Vector3::from(SHOULDER);
    let pose = look_at(
        Vector3::from(eye) + o,
        Vector3::from(target) + o,
        Vector3::z(),
    )
    .ok_or_else(|| Error::Config("camera: degenerate look-at".into()))?;
    let (w, h) = FRAME_SIZE;
    let f = f64::from(w) / 2.0 / (HFOV_DEG.to_radians() / 2.0).tan();
    Ok(SceneCamera::centred(name, (w, h), f, pose))
}

/// The scene of a subject: `views` cameras (1 or 2), the table around the model's θ region with
/// its surface at `table_z` (actor frame, negative: below the shoulder), the right arm with the
/// subject's arm lengths.
pub fn scene_for(
    model: &ActionModel,
    views: usize,
    lengths: [f64; 2],
    table_z: f64,
) -> Result<Scene> {
    let (c, h) = theta_region(model);
    let mut cameras = vec![camera("camera0", CAMERA0.0, CAMERA0.1)?];
    if views > 1 {
        cameras.push(camera("camera1", CAMERA1.0, CAMERA1.1)?);
    }
    let o = Vector3::from(SHOULDER);
    Ok(Scene {
        cameras,
        table: SceneTable {
            placement: Placement {
                origin: Vector3::new(o.x + c[0], o.y + c[1], o.z + table_z),
                yaw: 0.0,
            },
            half_extents: h,
        },
        actor: Placement {
            origin: o,
            yaw: 0.0,
        },
        side: Side::Right,
        arm: ArmSettings {
            upper_arm_length: Some(lengths[0]),
            lower_arm_length: Some(lengths[1]),
            ..ArmSettings::default()
        },
        edges: EdgeSettings::default(),
    })
}

/// Which model a condition tracks with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    /// reach / drink (`manifests/ue-adl-train.toml`).
    Two,
    /// reach-forward / reach-across / drink (`manifests/ue-adl3-train.toml`).
    Three,
}

/// Which trials a condition tracks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrialSet {
    /// Every held-out trial, each its own video.
    All,
    /// Repetitions 1 and 3 of every task (the ablations).
    Subset,
    /// One long video per subject: its trials back to back.
    Long,
}

/// How a condition adapts the models' heights to a test subject.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ActorHeight {
    /// The models' own heights.
    #[default]
    Models,
    /// Each subject's rest height over the models' ([`rest_heights`],
    /// [`ActionModel::rest_height`]) as `prior.height_scale`.
    Rest,
}

/// One experimental condition: the tracking configuration and how the video is rendered.
#[derive(Clone, Debug, Serialize)]
pub struct Condition {
    /// Short name (table row).
    pub name: String,
    /// Table group: `main`, `seeds`, `ablation`, `long`.
    pub group: String,
    /// The model.
    pub model: ModelKind,
    /// The trials.
    pub trials: TrialSet,
    /// Camera views (1 or 2).
    pub views: usize,
    /// Clutter shapes in the background.
    pub clutter: usize,
    /// Sensor noise σ (grey levels).
    pub noise: f64,
    /// Seed of the rendered backgrounds and of the filter (`filter.seed`).
    pub seed: u64,
    /// The models' heights per subject.
    pub actor_height: ActorHeight,
    /// The tracking configuration (its seed is replaced by `seed`).
    pub track: TrackConfig,
}

impl Condition {
    /// The tracking configuration of a video of `subject` ([`ActorHeight::Rest`] sets
    /// `prior.height_scale` from the rest heights).
    pub fn config_for(
        &self,
        subject: &str,
        rest: &BTreeMap<String, f64>,
        models: f64,
    ) -> TrackConfig {
        let mut c = self.track.clone();
        c.filter.seed = self.seed;
        if self.actor_height == ActorHeight::Rest
            && let Some(&h) = rest.get(subject)
            && h < 0.0
            && models < 0.0
        {
            c.prior.height_scale = h / models;
        }
        c
    }
}

/// A condition as written in the conditions file: a preset, overrides of its keys (a partial
/// `TrackConfig`), the rendering conditions and the seeds it runs at.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConditionSpec {
    /// Row name.
    pub name: String,
    /// Table group (`main`, `ablation`, `long`).
    #[serde(default = "main_group")]
    pub group: String,
    /// `two` or `three`.
    #[serde(default = "two")]
    pub model: ModelKind,
    /// `all`, `subset` or `long`.
    #[serde(default = "all")]
    pub trials: TrialSet,
    /// The preset the configuration starts from.
    #[serde(default = "default_preset")]
    pub preset: String,
    /// Keys of the preset changed (a partial `TrackConfig`).
    #[serde(default)]
    pub track: toml::Table,
    /// Camera views.
    #[serde(default = "one")]
    pub views: usize,
    /// Clutter shapes.
    #[serde(default = "clutter")]
    pub clutter: usize,
    /// Sensor noise σ.
    #[serde(default = "noise")]
    pub noise: f64,
    /// `models` or `rest`.
    #[serde(default)]
    pub actor_height: ActorHeight,
    /// Seeds: the first gives the row, the others the `seeds` group.
    #[serde(default = "seeds")]
    pub seeds: Vec<u64>,
}

fn main_group() -> String {
    "main".into()
}
fn two() -> ModelKind {
    ModelKind::Two
}
fn all() -> TrialSet {
    TrialSet::All
}
fn default_preset() -> String {
    "default".into()
}
fn one() -> usize {
    1
}
fn clutter() -> usize {
    40
}
fn noise() -> f64 {
    3.0
}
fn seeds() -> Vec<u64> {
    vec![9]
}

/// The conditions file: `[[condition]]` tables.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConditionsFile {
    condition: Vec<ConditionSpec>,
}

/// Merges `over` into `base` key by key (tables recursively).
fn merge_toml(base: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_toml(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

impl ConditionSpec {
    /// The tracking configuration: the preset with the overrides.
    pub fn config(&self) -> Result<TrackConfig> {
        let base = TrackConfig::preset(&self.preset)?;
        let mut table = toml::Table::try_from(&base)
            .map_err(|e| Error::Config(format!("condition `{}`: {e}", self.name)))?;
        merge_toml(&mut table, &self.track);
        let text = toml::to_string(&table)
            .map_err(|e| Error::Config(format!("condition `{}`: {e}", self.name)))?;
        TrackConfig::parse(&text, Path::new(&format!("condition `{}`", self.name)))
    }

    /// One condition per seed: the first keeps the name, the others get the seed appended
    /// (group `seeds`).
    pub fn expand(&self) -> Result<Vec<Condition>> {
        let track = self.config()?;
        Ok(self
            .seeds
            .iter()
            .enumerate()
            .map(|(i, &seed)| Condition {
                name: if i == 0 {
                    self.name.clone()
                } else {
                    format!("{}, seed {seed}", self.name)
                },
                group: if i == 0 {
                    self.group.clone()
                } else {
                    "seeds".into()
                },
                model: self.model,
                trials: self.trials,
                views: self.views,
                clutter: self.clutter,
                noise: self.noise,
                seed,
                actor_height: self.actor_height,
                track: track.clone(),
            })
            .collect())
    }
}

/// Reads a conditions file (`[[condition]]` tables of [`ConditionSpec`]).
pub fn load_conditions(path: &Path) -> Result<Vec<ConditionSpec>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::read(path, e))?;
    let f: ConditionsFile =
        toml::from_str(&text).map_err(|e| Error::invalid(path, e.message().to_string()))?;
    for c in &f.condition {
        c.config()?;
    }
    Ok(f.condition)
}

/// A piece of a video: an action instance (or, with an empty action, a transition not
/// evaluated), poses in the actor frame.
#[derive(Clone, Debug)]
pub struct Segment {
    /// Action label ("" for a transition).
    pub action: String,
    /// θ (actor frame).
    pub theta: [f64; 2],
    /// Poses (actor frame).
    pub poses: Vec<[f64; 9]>,
}

impl From<&TestTrial> for Segment {
    fn from(t: &TestTrial) -> Self {
        Self {
            action: t.action.clone(),
            theta: t.theta,
            poses: t.poses.clone(),
        }
    }
}

/// Joins trials back to back with `blend` interpolated transition frames between them.
pub fn back_to_back(trials: &[&TestTrial], blend: usize) -> Vec<Segment> {
    let mut out: Vec<Segment> = Vec::new();
    for t in trials {
        if let (Some(prev), Some(first)) =
            (out.last().and_then(|s| s.poses.last()), t.poses.first())
            && blend > 0
        {
            let (a, b) = (*prev, *first);
            let poses = (1..=blend)
                .map(|i| {
                    let s = i as f64 / (blend + 1) as f64;
                    std::array::from_fn(|c| a[c] + s * (b[c] - a[c]))
                })
                .collect();
            out.push(Segment {
                action: String::new(),
                theta: [f64::NAN; 2],
                poses,
            });
        }
        out.push(Segment::from(*t));
    }
    out
}

/// The result of one tracked video.
#[derive(Clone, Debug)]
pub struct VideoRun {
    /// The track (frames from 0), as `actrack-cli track` writes it.
    pub track: Trajectory,
    /// The truth.
    pub truth: Trajectory,
    /// The track with the best particle's pose instead of the median-filtered one (diagnostic).
    pub best: Trajectory,
    /// The track with the posterior-mean pose of the MAP action's particles
    /// ([`actrack_pf::Estimate::mean_pose`]) instead of the median-filtered best one.
    pub mean: Trajectory,
    /// Milliseconds per frame of the session's step (rendering excluded).
    pub step_ms: Vec<f64>,
    /// Milliseconds per frame of the scene synthesis (all views).
    pub render_ms: Vec<f64>,
    /// Overlays of the requested frames (first camera): frame index and image.
    pub overlays: Vec<(usize, RgbImage)>,
    /// Fraction of truth joints (p, q, r, all views) that project inside the image.
    pub in_view: f64,
    /// The first view's frames, when asked for ([`run_video`]'s `keep_frames`).
    pub frames: Vec<RgbImage>,
}

/// The model of `manifest`, loaded from `cache` when it exists, else trained (quietly) and saved
/// there; with the seconds training took (0 when loaded).
///
/// # Errors
/// Reading, training or writing errors, naming the file.
pub fn cached_model(manifest: &Path, cache: &Path) -> Result<(ActionModel, f64)> {
    if cache.exists() {
        eprintln!("model: reusing {}", cache.display());
        return Ok((ActionModel::load(cache)?, 0.0));
    }
    let t0 = Instant::now();
    let m = actrack::manifest::Manifest::load(manifest)?;
    let quiet = |_: Progress| {};
    let trials = import_manifest(&m, None, &quiet)?;
    eprintln!(
        "model: training on {} trials of {}…",
        trials.len(),
        manifest.display()
    );
    let model = fit_actions(
        &trials,
        &m.options,
        &m.preprocessing,
        Some(manifest),
        &quiet,
    )?;
    model.save(cache)?;
    Ok((model, t0.elapsed().as_secs_f64()))
}

/// The arm lengths a video of `scene` is rendered with: the scene's, else the model's.
pub fn render_lengths(model: &ActionModel, scene: &Scene) -> [f64; 2] {
    [
        scene
            .arm
            .upper_arm_length
            .unwrap_or(model.arm_lengths.upper_arm),
        scene
            .arm
            .lower_arm_length
            .unwrap_or(model.arm_lengths.forearm_hand),
    ]
}

/// The world poses of `segments`' frames, back to back.
pub fn world_poses(scene: &Scene, segments: &[Segment]) -> Vec<[f64; 9]> {
    segments
        .iter()
        .flat_map(|s| s.poses.iter().map(|p| scene.pose_to_world(p)))
        .collect()
}

/// Renders `segments` in `scene` frame by frame with `cond`'s clutter, noise and seed, and
/// tracks them with a [`Session`] of `config`; `overlay_frames` are kept as overlay images (best
/// pose's contour in yellow, θ̄ in red, the true fingertip in green), and every frame of the
/// first view with `keep_frames`.
pub fn run_video(
    model: &ActionModel,
    scene: &Scene,
    segments: &[Segment],
    cond: &Condition,
    config: &TrackConfig,
    overlay_frames: &[usize],
    keep_frames: bool,
) -> Result<VideoRun> {
    let mut synth = scene_synth(scene, render_lengths(model, scene));
    synth.clutter = cond.clutter;
    synth.noise_sigma = cond.noise;
    let cams: Vec<_> = scene.cameras.iter().map(|c| c.model.clone()).collect();
    let mut caches = vec![actrack_render::synth::SynthCache::default(); cams.len()];
    let worlds = world_poses(scene, segments);
    let mut render = |frame: usize| -> Result<Vec<RgbImage>> {
        cams.iter()
            .zip(&mut caches)
            .enumerate()
            .map(|(v, (cam, cache))| {
                let img = synth
                    .render_frame(
                        cache,
                        cam,
                        &worlds[frame],
                        cond.seed.wrapping_add(v as u64),
                        frame as u64,
                    )
                    .map_err(|e| Error::Config(format!("synth: frame {frame}: {e}")))?;
                RgbImage::from_raw(img.width, img.height, img.data)
                    .ok_or_else(|| Error::Config(format!("synth: frame {frame}: bad image buffer")))
            })
            .collect()
    };
    track_rendered(
        model,
        scene,
        segments,
        config,
        overlay_frames,
        keep_frames,
        &mut render,
    )
}

/// Renders `segments` in `style` through the first camera of `scene` (the style's scene,
/// [`Style::scene`]): its appearance, the cups on the table and a drink's cup carried by the
/// hand, motion blur, compression and dropped frames; and tracks them as [`run_video`] does,
/// with overlays of `overlay_frames`.
pub fn run_styled_video(
    model: &ActionModel,
    scene: &Scene,
    segments: &[Segment],
    style: &Style,
    config: &TrackConfig,
    overlay_frames: &[usize],
) -> Result<VideoRun> {
    let video = StyledVideo::new(style, scene, render_lengths(model, scene))?;
    let worlds = world_poses(scene, segments);
    let actions: Vec<(String, [f64; 2])> = segments
        .iter()
        .flat_map(|s| s.poses.iter().map(|_| (s.action.clone(), s.theta)))
        .collect();
    let cups = video_cups(&video, scene, &worlds, &actions);
    let mut cache = actrack_render::synth::SynthCache::default();
    let mut render = |frame: usize| -> Result<Vec<RgbImage>> {
        Ok(vec![video.frame(
            &mut cache,
            &worlds,
            frame,
            &cups[video.source(frame)],
        )?])
    };
    track_rendered(
        model,
        scene,
        segments,
        config,
        overlay_frames,
        false,
        &mut render,
    )
}

/// The one tracking loop of the experiment: `render(frame)` gives the views' images of each
/// frame of `segments`, a [`Session`] of `config` tracks them; see [`run_video`].
fn track_rendered(
    model: &ActionModel,
    scene: &Scene,
    segments: &[Segment],
    config: &TrackConfig,
    overlay_frames: &[usize],
    keep_frames: bool,
    render: &mut dyn FnMut(usize) -> Result<Vec<RgbImage>>,
) -> Result<VideoRun> {
    let geometry = render_arm(scene, render_lengths(model, scene));
    let first_cam = scene
        .cameras
        .first()
        .ok_or_else(|| Error::Config("the scene has no camera".into()))?
        .model
        .clone();
    let mut session = Session::new(model, scene, config)?;
    let names = session.action_names().to_vec();
    let mut report = PoseReport::new(&config.output)?;
    let mut track = Trajectory {
        actions: names.clone(),
        rows: Vec::new(),
    };
    let mut truth = Trajectory::default();
    let mut best = track.clone();
    let mut mean = track.clone();
    let (mut step_ms, mut render_ms, mut overlays, mut frames) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut inside, mut total) = (0usize, 0usize);
    let labels = segments
        .iter()
        .flat_map(|s| s.poses.iter().map(move |_| (&s.action, s.theta)));
    for (frame, (world, (action, theta))) in world_poses(scene, segments)
        .into_iter()
        .zip(labels)
        .enumerate()
    {
        let t = frame as f64 / FPS;
        truth
            .rows
            .push(TrajRow::truth(frame, t, action, theta, world));
        for cam in &scene.cameras {
            for j in 0..3 {
                total += 1;
                let x = Vector3::new(world[3 * j], world[3 * j + 1], world[3 * j + 2]);
                if let Some((u, w)) = cam.project(&x)
                    && cam.in_image(u, w)
                {
                    inside += 1;
                }
            }
        }
        let t0 = Instant::now();
        let images = render(frame)?;
        render_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        let r = session.step_rgb(frame, &images.iter().collect::<Vec<_>>())?;
        step_ms.push(session.last_times().total);
        let row = track_row(frame, t, &names, &r);
        let mut b = row.clone();
        b.pose = r.best_world;
        best.rows.push(b);
        let mut m = row.clone();
        m.pose = scene.pose_to_world(&r.estimate.mean_pose);
        mean.rows.push(m);
        let (best_pose, causal) = (r.estimate.best_pose, r.estimate.smoothed_pose);
        if let Some((mut row, pose)) = report.push(row, best_pose, causal) {
            row.pose = scene.pose_to_world(&pose);
            track.rows.push(row);
        }
        if let Some(first) = images.into_iter().next() {
            if overlay_frames.contains(&frame) {
                let mut img = first.clone();
                let contour = contour_points(
                    &first_cam,
                    &geometry,
                    &r.best_world,
                    config.observation.contour.into(),
                );
                let dot = scene.cameras[0]
                    .project(&r.theta_world)
                    .map(|(u, v)| ([u, v], [1.0, 0.1, 0.1]));
                draw_overlay(&mut img, &contour, dot);
                // The true fingertip, green: how far the estimate is from it in the image.
                let tip = Vector3::new(world[6], world[7], world[8]);
                let tip = scene.cameras[0]
                    .project(&tip)
                    .map(|(u, v)| ([u, v], [0.1, 0.9, 0.1]));
                draw_overlay(&mut img, &[], tip);
                overlays.push((frame, img));
            }
            if keep_frames {
                frames.push(first);
            }
        }
    }
    for (mut row, pose) in report.finish() {
        row.pose = scene.pose_to_world(&pose);
        track.rows.push(row);
    }
    Ok(VideoRun {
        track,
        truth,
        best,
        mean,
        step_ms,
        render_ms,
        overlays,
        in_view: inside as f64 / total.max(1) as f64,
        frames,
    })
}

/// A subject's scene and configuration under `cond`: its arm lengths, its table at its rest
/// height, its height factor.
pub fn subject_setup(
    model: &ActionModel,
    cond: &Condition,
    subject: &str,
    lengths: &BTreeMap<String, [f64; 2]>,
    rest: &BTreeMap<String, f64>,
    fallback_lengths: [f64; 2],
) -> Result<(Scene, TrackConfig)> {
    let l = lengths.get(subject).copied().unwrap_or(fallback_lengths);
    let table_z = rest.get(subject).copied().unwrap_or(-TABLE_BELOW_SHOULDER);
    let scene = scene_for(model, cond.views, l, table_z)?;
    Ok((scene, cond.config_for(subject, rest, model.rest_height())))
}

/// Tracks every trial of `trials` as its own video (in parallel over trials) and evaluates.
pub fn run_condition(
    model: &ActionModel,
    trials: &[TestTrial],
    cond: &Condition,
) -> Result<(ConditionResult, Vec<VideoRun>)> {
    let t0 = Instant::now();
    let lengths = subject_lengths(trials);
    let rest = rest_heights(trials);
    let runs: Vec<VideoRun> = trials
        .par_iter()
        .map(|t| {
            let (scene, config) =
                subject_setup(model, cond, &t.subject, &lengths, &rest, t.lengths)?;
            run_video(
                model,
                &scene,
                &[Segment::from(t)],
                cond,
                &config,
                &[],
                false,
            )
        })
        .collect::<Result<_>>()?;
    let res = summarise(cond, model, &runs, t0.elapsed().as_secs_f64())?;
    Ok((res, runs))
}

/// The evaluated result of a condition.
#[derive(Clone, Debug, Serialize)]
pub struct ConditionResult {
    /// The condition.
    pub condition: Condition,
    /// Videos tracked.
    pub videos: usize,
    /// SPEC §5.4 metrics over every video (instances of all videos).
    pub report: EvalReport,
    /// Joint errors of the unfiltered best particle (diagnostic: the median filter's lag).
    pub best_particle: ErrorStats,
    /// The metrics with the posterior-mean pose ([`VideoRun::mean`]) as the estimate.
    pub mean_pose: EvalReport,
    /// Action names (rows/columns of the confusion matrix).
    pub actions: Vec<String>,
    /// `confusion[true][predicted]`, counted over action instances.
    pub confusion: Vec<Vec<usize>>,
    /// Mean ms per frame of edge image + filter step (one thread per video).
    pub ms_per_frame: f64,
    /// Mean ms per frame of the scene synthesis.
    pub render_ms_per_frame: f64,
    /// Fraction of truth joints inside the image(s).
    pub in_view: f64,
    /// Wall-clock seconds of the condition.
    pub wall_seconds: f64,
}

/// Merges runs into one track and one truth (frame indices offset, one frame gap between runs so
/// instances never join).
pub fn merge(runs: &[VideoRun]) -> (Trajectory, Trajectory) {
    let mut track = Trajectory::default();
    let mut truth = Trajectory::default();
    let mut offset = 0usize;
    for r in runs {
        if track.actions.is_empty() {
            track.actions.clone_from(&r.track.actions);
        }
        let n = r.truth.rows.len();
        track.rows.extend(r.track.rows.iter().map(|x| {
            let mut x = x.clone();
            x.frame += offset;
            x
        }));
        truth.rows.extend(r.truth.rows.iter().map(|x| {
            let mut x = x.clone();
            x.frame += offset;
            x
        }));
        offset += n + 1;
    }
    (track, truth)
}

/// Evaluates runs of a condition.
pub fn summarise(
    cond: &Condition,
    model: &ActionModel,
    runs: &[VideoRun],
    wall_seconds: f64,
) -> Result<ConditionResult> {
    let (track, truth) = merge(runs);
    let report = evaluate(&track, &truth)?;
    let with_track = |pick: fn(&VideoRun) -> &Trajectory| -> Vec<VideoRun> {
        runs.iter()
            .map(|r| VideoRun {
                track: pick(r).clone(),
                ..r.clone()
            })
            .collect()
    };
    let (best, _) = merge(&with_track(|r| &r.best));
    let best_particle = evaluate(&best, &truth)?.overall;
    let (mean_track, _) = merge(&with_track(|r| &r.mean));
    let mean_pose = evaluate(&mean_track, &truth)?;
    let actions: Vec<String> = model.actions.iter().map(|a| a.name.clone()).collect();
    let mut confusion = vec![vec![0usize; actions.len()]; actions.len()];
    for i in &report.instances {
        if let (Some(t), Some(p)) = (
            actions.iter().position(|a| *a == i.action),
            actions.iter().position(|a| *a == i.predicted),
        ) {
            confusion[t][p] += 1;
        }
    }
    let mean = |v: Vec<f64>| {
        let n = v.len().max(1) as f64;
        v.iter().sum::<f64>() / n
    };
    let frames: usize = runs.iter().map(|r| r.step_ms.len()).sum();
    let in_view = runs
        .iter()
        .map(|r| r.in_view * r.step_ms.len() as f64)
        .sum::<f64>()
        / frames.max(1) as f64;
    Ok(ConditionResult {
        condition: cond.clone(),
        videos: runs.len(),
        report,
        best_particle,
        mean_pose,
        actions,
        confusion,
        ms_per_frame: mean(runs.iter().flat_map(|r| r.step_ms.clone()).collect()),
        render_ms_per_frame: mean(runs.iter().flat_map(|r| r.render_ms.clone()).collect()),
        in_view,
        wall_seconds,
    })
}

/// Relabels a three-action model's test labels onto two actions (reach-forward and reach-across
/// become `reach`).
pub fn two_action_label(a: &str) -> String {
    if a.starts_with("reach") {
        "reach".into()
    } else {
        a.to_string()
    }
}

/// Tracks the trial called `name` of `trials` under `cond` as [`run_condition`] does on
/// `trials` (the subject's arm lengths and rest height from all its trials there) and writes
/// what `actrack-cli track` needs to track it again into `dir`: `frames/` (PNG, lossless),
/// `scene.toml`, `config.toml` and `model.actrack.json`, and the experiment's own track as
/// `track.csv` (with the configuration in its header, as `track` writes it). Returns the run.
pub fn export_trial(
    model: &ActionModel,
    trials: &[TestTrial],
    name: &str,
    cond: &Condition,
    dir: &Path,
) -> Result<VideoRun> {
    let trial = trials
        .iter()
        .find(|t| t.name == name)
        .ok_or_else(|| Error::Config(format!("export: no trial {name}")))?;
    let lengths = subject_lengths(trials);
    let rest = rest_heights(trials);
    let (scene, config) =
        subject_setup(model, cond, &trial.subject, &lengths, &rest, trial.lengths)?;
    let run = run_video(
        model,
        &scene,
        &[Segment::from(trial)],
        cond,
        &config,
        &[],
        true,
    )?;
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).map_err(|e| Error::write(&frames, e))?;
    for (i, img) in run.frames.iter().enumerate() {
        let p = frames.join(format!("frame_{i:05}.png"));
        img.save(&p)
            .map_err(|e| Error::write(&p, std::io::Error::other(e.to_string())))?;
    }
    let write = |name: &str, text: &str| -> Result<()> {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|e| Error::write(&p, e))
    };
    write("scene.toml", &scene.to_toml_string())?;
    write("config.toml", &config.to_toml())?;
    model.save(&dir.join("model.actrack.json"))?;
    run.track
        .save_with_comment(&dir.join("track.csv"), &config.to_comment())?;
    Ok(run)
}
