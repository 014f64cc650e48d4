//! The `track` pipeline (SPEC §3.8): frames → edge image → particle filter in action space →
//! per-frame estimates → MCAP, CSV and overlay images.
//!
//! [`SceneObservation`] is the [`ObservationModel`] of the filter: it corrects generated poses
//! with the arm lengths (SPEC §3.4; lengths are invariant under the rigid actor → world map, so
//! correcting in the actor frame is the same), maps them to the world with the scene's actor
//! placement and scores them with `actrack-render`'s contour likelihood over every view.
//!
//! `track` reads one video, filmed by the scene's first camera; several synchronised views go
//! through [`Pipeline::step`] with one image per camera.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use actrack_pf::{Estimate, ObservationModel, TableRegion, Tracker, TrackerConfig};
pub use actrack_render::ContourMethod;
use actrack_render::{
    ArmGeometry as RenderArm, Camera as RenderCamera, EdgeImage, EdgeParams, EdgeWorkspace,
    ImageView, LikelihoodModel, contour_points, correct_arm,
};
use image::RgbImage;
use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::frames::{Frame, FrameSource};
use crate::mcap_out::{EstimateMsg, FrameRecord, TrackWriter};
use crate::model::{ActionModel, DwellCap};
use crate::scene::{Camera, Scene};
use crate::track_csv::{TrajRow, Trajectory};

/// Sets the number of worker threads of the global pool (once, before any tracking).
pub fn set_threads(n: usize) -> Result<()> {
    if n == 0 {
        return Err(Error::Config("--threads must be ≥ 1".into()));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build_global()
        .map_err(|e| Error::Config(format!("cannot set up {n} threads: {e}")))
}

/// γ of SPEC Eq. 3.
pub const GAMMA: f64 = 0.15;

/// Converts a scene camera to the renderer's.
pub fn render_camera(c: &Camera) -> RenderCamera {
    let r = c.r_cw;
    RenderCamera {
        width: c.width,
        height: c.height,
        fx: c.fx,
        fy: c.fy,
        cx: c.cx,
        cy: c.cy,
        distortion: c.distortion,
        rotation: [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]),
        translation: [c.t_cw.x, c.t_cw.y, c.t_cw.z],
    }
}

/// The renderer's arm geometry: the scene's radii and the model's lengths (unless the scene
/// overrides them).
pub fn render_arm(scene: &Scene, lengths: [f64; 2]) -> RenderArm {
    let a = &scene.arm;
    RenderArm {
        l1: a.upper_arm_length.unwrap_or(lengths[0]),
        l2: a.lower_arm_length.unwrap_or(lengths[1]),
        upper_radii: a.upper_arm_radii,
        forearm_radii: a.forearm_radii,
        forearm_fraction: a.forearm_fraction,
        hand_half_axes: a.hand_half_axes,
    }
}

/// Edge-image parameters for a frame width: SPEC §4.1 (σ_G = 4 px at 640 px, scaled).
pub fn edge_params(width: u32) -> EdgeParams {
    EdgeParams {
        sigma: default_edge_sigma(width),
        ..EdgeParams::default()
    }
}

/// σ_G of SPEC §4.1 for an image `width` pixels wide: 4 px at 640, scaled with the width and
/// clamped to [1, 8] px.
pub fn default_edge_sigma(width: u32) -> f32 {
    (4.0 * f64::from(width) / 640.0).clamp(1.0, 8.0) as f32
}

/// The observation model of one frame.
pub struct SceneObservation<'a> {
    scene: &'a Scene,
    geometry: &'a RenderArm,
    likelihood: &'a LikelihoodModel,
    edges: &'a [EdgeImage],
}

impl<'a> SceneObservation<'a> {
    /// The observation model of one frame: `edges` holds one edge image per camera of `scene`.
    pub fn new(
        scene: &'a Scene,
        geometry: &'a RenderArm,
        likelihood: &'a LikelihoodModel,
        edges: &'a [EdgeImage],
    ) -> Self {
        Self {
            scene,
            geometry,
            likelihood,
            edges,
        }
    }
}

impl ObservationModel for SceneObservation<'_> {
    fn correct(&self, pose: &mut [f64; 9]) {
        correct_arm(self.geometry, pose, None);
    }

    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        let world: Vec<[f64; 9]> = poses.iter().map(|p| self.scene.pose_to_world(p)).collect();
        if self
            .likelihood
            .log_likelihood_batch(self.edges, &world, out)
            .is_err()
        {
            out.fill(f64::NAN);
        }
    }
}

/// σ of the [`FingertipFloor`] (metres): chosen on the training subjects ADL001–004 and
/// ADL006–007 (36 trials, the headline configuration, mean over seeds 9, 1, 2 of joint RMSE /
/// table-location error): no floor 3.73 / 2.27 cm, σ = 0.25 cm 3.40 / 1.67, 0.5 cm 3.60 / 1.67,
/// **1 cm 3.53 / 1.60**, 2 cm 3.73 / 1.63 (docs/results.md).
pub const FINGERTIP_FLOOR_SIGMA: f64 = 0.01;

/// A soft floor under the fingertip (not in the paper): the hand rests on the table before and
/// after a movement and cannot go through it, so a pose whose fingertip r lies below the
/// floor z₀ (actor frame) loses ½((z₀ − r_z)/σ)² of log-likelihood; poses above it are scored
/// by the inner model alone. In a monocular view a hand lower and nearer the body can lie on
/// the same viewing ray as the true one; the floor rules out the part of the ray under the
/// table. z₀ is the fingertip's height at rest (the fingertip sits on the table then).
#[derive(Clone, Copy, Debug)]
pub struct FingertipFloor<O> {
    inner: O,
    floor: Floor,
}

/// The floor of a [`FingertipFloor`]: its height z₀ (metres, actor frame) and softness σ
/// (metres), validated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    z: f64,
    sigma: f64,
}

impl Floor {
    /// The floor at z₀ = `z` with softness `sigma` (> 0).
    ///
    /// # Errors
    /// When `z` is not finite or `sigma` is not positive and finite.
    pub fn new(z: f64, sigma: f64) -> Result<Self> {
        if !(z.is_finite() && sigma.is_finite() && sigma > 0.0) {
            return Err(Error::Config(format!(
                "fingertip floor: needs a finite height (metres, actor frame) and a positive \
                 σ, got {z} and {sigma}"
            )));
        }
        Ok(Self { z, sigma })
    }

    /// The log-likelihood a pose loses to the floor (0 when its fingertip is on or above it).
    pub fn penalty(&self, pose: &[f64; 9]) -> f64 {
        let below = (self.z - pose[8]).max(0.0) / self.sigma;
        0.5 * below * below
    }
}

impl<O> FingertipFloor<O> {
    /// `inner` under `floor`.
    pub fn new(inner: O, floor: Floor) -> Self {
        Self { inner, floor }
    }
}

impl<O: ObservationModel> ObservationModel for FingertipFloor<O> {
    fn correct(&self, pose: &mut [f64; 9]) {
        self.inner.correct(pose);
    }

    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        self.inner.log_likelihoods(poses, out);
        for (o, p) in out.iter_mut().zip(poses) {
            *o -= self.floor.penalty(p);
        }
    }
}

/// Options of the pipeline.
#[derive(Clone, Debug)]
pub struct TrackOptions {
    /// Number of particles M.
    pub particles: usize,
    /// Seed of every random draw.
    pub seed: u64,
    /// Contour method of the likelihood.
    pub contour: ContourMethod,
    /// Where each action's θ prior lives: its own training targets (default) or the scene's
    /// table region.
    pub theta_prior: ThetaPrior,
    /// Per-particle speed range (`TrackerConfigBuilder::speed_range`); `None`: the models'
    /// timing.
    pub speed_range: Option<[f64; 2]>,
    /// Cap of the model states' self-transition probabilities ([`DwellCap`]; not in the
    /// paper); `None`: the models' dwell times.
    pub dwell_cap: Option<DwellCap>,
    /// Factor on the models' vertical outputs for an actor whose table lies nearer to or
    /// farther from the shoulder than the demonstrators' ([`ActionModel::tracking_phmms_scaled`];
    /// not in the paper); `None`: the models' heights.
    pub height_scale: Option<f64>,
    /// Height z₀ of the [`FingertipFloor`] (metres, actor frame: negative, below the shoulder;
    /// the actor's fingertip at rest on the table), with σ = [`FINGERTIP_FLOOR_SIGMA`]; `None`:
    /// no floor.
    pub fingertip_floor: Option<f64>,
    /// The fraction ε ∈ (0, 1) of the particles split evenly over the actions as a floor
    /// ([`actrack_pf::ActionBalance::Mixture`]); `None`: the default
    /// [`actrack_pf::DEFAULT_ACTION_FLOOR`].
    pub action_floor: Option<f64>,
}

impl Default for TrackOptions {
    fn default() -> Self {
        Self {
            particles: 400,
            seed: 0,
            contour: ContourMethod::Raster,
            theta_prior: ThetaPrior::Training,
            speed_range: None,
            dwell_cap: None,
            height_scale: None,
            fingertip_floor: None,
            action_floor: None,
        }
    }
}

/// The θ prior of every action (SPEC §3.2 draws θ ~ U(R) for every action).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ThetaPrior {
    /// Each action draws θ from the box of its own training targets, padded by
    /// [`THETA_PRIOR_PAD`] and clipped to the scene's table region, and θ is reflected at that box enlarged by 1.25 (not in the SPEC:
    /// a linear PHMM extrapolated far outside the targets it was trained on generates
    /// implausible poses, which measurably costs accuracy and recognition on real motion, see
    /// docs/results.md).
    #[default]
    Training,
    /// Every action draws θ from the scene's table region R (SPEC §3.2 literally).
    Scene,
}

/// Padding of the per-action θ prior around the action's training targets (metres).
pub const THETA_PRIOR_PAD: f64 = 0.05;

/// The box of every action's training targets, padded by `pad` and clipped to the prior region
/// `(centre, half_extents)` (actor frame, metres). An action whose padded box misses the region
/// keeps its padded box.
pub fn training_theta_regions(
    model: &ActionModel,
    pad: f64,
    region: ([f64; 2], [f64; 2]),
) -> Vec<TableRegion> {
    let (rc, rh) = region;
    model
        .actions
        .iter()
        .map(|a| {
            let centre = [0, 1].map(|c| 0.5 * (a.theta_min[c] + a.theta_max[c]));
            let half = [0, 1].map(|c| 0.5 * (a.theta_max[c] - a.theta_min[c]) + pad);
            let lo = [0, 1].map(|c| centre[c] - half[c]);
            let hi = [0, 1].map(|c| centre[c] + half[c]);
            let clipped = (0..2).any(|c| lo[c] < rc[c] - rh[c] || hi[c] > rc[c] + rh[c]);
            let clo = [0, 1].map(|c| lo[c].max(rc[c] - rh[c]));
            let chi = [0, 1].map(|c| hi[c].min(rc[c] + rh[c]));
            if !clipped || !(0..2).all(|c| chi[c] > clo[c]) {
                TableRegion::new(centre, half)
            } else {
                TableRegion::new(
                    [0, 1].map(|c| 0.5 * (clo[c] + chi[c])),
                    [0, 1].map(|c| 0.5 * (chi[c] - clo[c])),
                )
            }
        })
        .collect()
}

/// One frame's result in the world.
#[derive(Clone, Debug)]
pub struct FrameResult {
    /// The filter's estimate (actor frame).
    pub estimate: Estimate,
    /// Best particle's pose, world.
    pub best_world: [f64; 9],
    /// Median-filtered pose, world.
    pub smoothed_world: [f64; 9],
    /// θ̄ on the table, world.
    pub theta_world: Vector3<f64>,
}

/// The tracker with its observation model.
pub struct Pipeline {
    scene: Scene,
    geometry: RenderArm,
    likelihood: LikelihoodModel,
    tracker: Tracker,
    /// The edge images the next filter step scores, one per view used (buffers reused).
    edges: Vec<EdgeImage>,
    /// Whether `edges` holds a frame not yet tracked (see [`Pipeline::prime`]).
    primed: bool,
    /// Workspaces and the back buffer the next frame's edge images are computed into.
    ahead: Lookahead,
    /// Wall seconds of the primed frame's edge images.
    edge_seconds: f64,
    /// Wall seconds of the last step's edge images + filter step (decoding excluded).
    step_seconds: f64,
    names: Vec<String>,
    /// The fingertip floor, if any ([`TrackOptions::fingertip_floor`]).
    floor: Option<Floor>,
}

/// Where a frame's edge images are computed before the filter step that scores them: the
/// workspaces of [`Pipeline`] and a back buffer. [`Pipeline::step_overlapped`] hands it to the
/// work that runs alongside a filter step.
pub struct Lookahead {
    scene: Scene,
    workspaces: Vec<EdgeWorkspace>,
    edges: Vec<EdgeImage>,
    /// Whether `edges` holds the images of a frame since the last swap.
    ready: bool,
    /// Wall seconds of the last `prepare`.
    seconds: f64,
}

impl Lookahead {
    /// Computes the edge images of `images` (one per camera; fewer: the missing views carry no
    /// contour) into the back buffer. Errors name the frame when an image does not fit its
    /// camera.
    pub fn prepare(&mut self, frame: usize, images: &[&RgbImage]) -> Result<()> {
        self.ready = false;
        let t0 = Instant::now();
        let views = images.len().min(self.scene.cameras.len());
        self.edges.resize_with(views, EdgeImage::default);
        for (v, img) in images.iter().enumerate().take(views) {
            let cam = &self.scene.cameras[v];
            if img.dimensions() != (cam.width, cam.height) {
                return Err(Error::Config(format!(
                    "frame {frame}: the image is {}×{} but camera `{}` of the scene is {}×{}",
                    img.width(),
                    img.height(),
                    cam.name,
                    cam.width,
                    cam.height
                )));
            }
            let view = ImageView::rgb8(img.as_raw(), img.width(), img.height())
                .map_err(|e| Error::Config(format!("frame {frame}: {e}")))?;
            self.workspaces[v]
                .compute_into(view, &self.scene.edge_params(cam.width), &mut self.edges[v])
                .map_err(|e| Error::Config(format!("frame {frame}: {e}")))?;
        }
        self.ready = true;
        self.seconds = t0.elapsed().as_secs_f64();
        Ok(())
    }
}

impl Pipeline {
    /// Builds the tracker for `model` in `scene`.
    pub fn new(model: &ActionModel, scene: &Scene, opts: &TrackOptions) -> Result<Self> {
        let geometry = render_arm(
            scene,
            [model.arm_lengths.upper_arm, model.arm_lengths.forearm_hand],
        );
        let cameras: Vec<RenderCamera> = scene.cameras.iter().map(render_camera).collect();
        let likelihood = LikelihoodModel::new(cameras, geometry.clone(), GAMMA, opts.contour)
            .map_err(|e| Error::Config(format!("observation model: {e}")))?;
        let (centre, half) = scene.theta_region();
        let mut builder = TrackerConfig::builder(TableRegion::new(centre, half))
            .particles(opts.particles)
            .seed(opts.seed)
            .speed_range(opts.speed_range);
        if let Some(f) = opts.action_floor {
            builder = builder.action_balance(actrack_pf::ActionBalance::Mixture(f));
        }
        if opts.theta_prior == ThetaPrior::Training {
            builder = builder.action_regions(training_theta_regions(
                model,
                THETA_PRIOR_PAD,
                (centre, half),
            ));
        }
        let config = builder
            .build()
            .map_err(|e| Error::Config(format!("tracker: {e}")))?;
        let floor = opts
            .fingertip_floor
            .map(|z| Floor::new(z, FINGERTIP_FLOOR_SIGMA))
            .transpose()?;
        let names: Vec<String> = model.actions.iter().map(|a| a.name.clone()).collect();
        let phmms = model.tracking_phmms_scaled(opts.dwell_cap, opts.height_scale)?;
        let tracker =
            Tracker::new(phmms.iter(), names.clone(), config).map_err(|e| Error::Model {
                context: "building the tracker".into(),
                message: e.to_string(),
            })?;
        Ok(Self {
            scene: scene.clone(),
            geometry,
            likelihood,
            tracker,
            edges: Vec::with_capacity(scene.cameras.len()),
            primed: false,
            ahead: Lookahead {
                scene: scene.clone(),
                workspaces: scene.cameras.iter().map(|_| EdgeWorkspace::new()).collect(),
                edges: Vec::with_capacity(scene.cameras.len()),
                ready: false,
                seconds: 0.0,
            },
            edge_seconds: 0.0,
            step_seconds: 0.0,
            names,
            floor,
        })
    }

    /// Action names.
    pub fn action_names(&self) -> &[String] {
        &self.names
    }

    /// The tracker (particles, weights).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// The arm geometry used for rendering.
    pub fn geometry(&self) -> &RenderArm {
        &self.geometry
    }

    /// One step on synchronised images, one per camera (fewer: the missing views carry no
    /// contour). Errors name the frame when an image does not fit its camera.
    pub fn step(&mut self, frame: usize, images: &[&RgbImage]) -> Result<FrameResult> {
        self.prime(frame, images)?;
        self.primed = false;
        let t0 = Instant::now();
        let r = self.filter();
        self.step_seconds = self.edge_seconds + t0.elapsed().as_secs_f64();
        Ok(r)
    }

    /// Wall seconds of the last step's own work: its frame's edge images plus the filter step
    /// (decoding excluded; in [`Pipeline::step_overlapped`] the two ran in different calls,
    /// each alongside other work).
    pub fn last_step_seconds(&self) -> f64 {
        self.step_seconds
    }

    /// Computes the edge images of a frame that [`Pipeline::step_overlapped`] then tracks.
    pub fn prime(&mut self, frame: usize, images: &[&RgbImage]) -> Result<()> {
        self.ahead.prepare(frame, images)?;
        self.swap_ahead();
        Ok(())
    }

    /// Tracks the primed frame (by [`Pipeline::prime`] or the previous call) while `alongside`
    /// runs with the [`Lookahead`] (`rayon::join`: both share the pool's threads). `alongside`
    /// typically decodes the next frame and calls [`Lookahead::prepare`] on it; if it did, that
    /// frame is primed for the next call. On one thread this is the serial order; on more, the
    /// next frame's decoding and edge image overlap the filter's serial parts. The estimates are
    /// bit-identical to [`Pipeline::step`]'s.
    ///
    /// # Errors
    /// When no frame is primed.
    pub fn step_overlapped<R: Send>(
        &mut self,
        alongside: impl FnOnce(&mut Lookahead) -> R + Send,
    ) -> Result<(FrameResult, R)> {
        if !self.primed {
            return Err(Error::Config(
                "step_overlapped: no frame primed (call prime first)".into(),
            ));
        }
        self.ahead.ready = false;
        let Self {
            scene,
            geometry,
            likelihood,
            tracker,
            edges,
            ahead,
            floor,
            ..
        } = self;
        let ((r, filter_seconds), side) = rayon::join(
            || {
                let t0 = Instant::now();
                let r = filter(scene, geometry, likelihood, tracker, edges, *floor);
                (r, t0.elapsed().as_secs_f64())
            },
            || alongside(ahead),
        );
        self.step_seconds = self.edge_seconds + filter_seconds;
        self.primed = false;
        if self.ahead.ready {
            self.swap_ahead();
        }
        Ok((r, side))
    }

    fn swap_ahead(&mut self) {
        std::mem::swap(&mut self.edges, &mut self.ahead.edges);
        self.edge_seconds = self.ahead.seconds;
        self.ahead.ready = false;
        self.primed = true;
    }

    fn filter(&mut self) -> FrameResult {
        filter(
            &self.scene,
            &self.geometry,
            &self.likelihood,
            &mut self.tracker,
            &self.edges,
            self.floor,
        )
    }
}

/// One filter step on `edges` and the estimates mapped to the world.
fn filter(
    scene: &Scene,
    geometry: &RenderArm,
    likelihood: &LikelihoodModel,
    tracker: &mut Tracker,
    edges: &[EdgeImage],
    floor: Option<Floor>,
) -> FrameResult {
    let obs = SceneObservation {
        scene,
        geometry,
        likelihood,
        edges,
    };
    let estimate = step_with_floor(tracker, &obs, floor);
    let best_world = scene.pose_to_world(&estimate.best_pose);
    let smoothed_world = scene.pose_to_world(&estimate.smoothed_pose);
    let theta_world = scene.theta_to_world(estimate.theta_mean);
    FrameResult {
        estimate,
        best_world,
        smoothed_world,
        theta_world,
    }
}

/// One filter step on `obs`, under a [`FingertipFloor`] when a floor is given.
pub fn step_with_floor<O: ObservationModel + ?Sized>(
    tracker: &mut Tracker,
    obs: &O,
    floor: Option<Floor>,
) -> Estimate {
    match floor {
        Some(floor) => tracker.step(&FingertipFloor::new(obs, floor)),
        None => tracker.step(obs),
    }
}

/// Outputs of [`track`].
#[derive(Clone, Debug, Default)]
pub struct TrackOutputs {
    /// The MCAP track.
    pub mcap: Option<PathBuf>,
    /// Camera image, calibration and contour topics in the MCAP.
    pub mcap_images: bool,
    /// The trajectory CSV.
    pub csv: Option<PathBuf>,
    /// A directory for overlay PNGs.
    pub overlay: Option<PathBuf>,
}

/// What [`track`] did.
#[derive(Clone, Debug)]
pub struct TrackSummary {
    /// Frames tracked.
    pub frames: usize,
    /// Wall-clock seconds of the tracking loop (decoding included).
    pub seconds: f64,
    /// Seconds spent in the edge images and filter steps (propagation, likelihood, estimates)
    /// of the frames, decoding excluded; with look-ahead these ran alongside the decoding.
    pub filter_seconds: f64,
    /// Stopped by the interrupt flag before the end of the input.
    pub interrupted: bool,
    /// Frames skipped as bad (index, reason).
    pub skipped: Vec<(usize, String)>,
    /// The trajectory (tracker-output rows).
    pub trajectory: Trajectory,
}

/// Histogram entropy in [0, 1] → display colour (red at 1, green at 0).
pub fn entropy_colour(h: f64) -> [f64; 3] {
    let h = if h.is_finite() {
        h.clamp(0.0, 1.0)
    } else {
        1.0
    };
    [h, 1.0 - h, 0.0]
}

/// The tracker-output row of a frame.
pub fn track_row(frame: usize, time: f64, names: &[String], r: &FrameResult) -> TrajRow {
    let e = &r.estimate;
    TrajRow {
        frame,
        time,
        action: names.get(e.map_action).cloned().unwrap_or_default(),
        theta: e.theta_mean,
        pose: r.smoothed_world,
        posterior: e.action_posterior.clone(),
        theta_std: Some(e.theta_std),
        entropy: Some(e.theta_histogram_entropy),
        ess: Some(e.ess),
    }
}

/// Draws the overlay of Fig. 3: the best pose's contour and the θ̄ dot coloured by entropy.
pub fn draw_overlay(img: &mut RgbImage, contour: &[[f64; 2]], dot: Option<([f64; 2], [f64; 3])>) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    for p in contour {
        let (u, v) = (p[0].round() as i64, p[1].round() as i64);
        if (0..w).contains(&u) && (0..h).contains(&v) {
            img.put_pixel(u as u32, v as u32, image::Rgb([255, 230, 0]));
        }
    }
    if let Some(([cu, cv], c)) = dot {
        let col = c.map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8);
        for dv in -6i64..=6 {
            for du in -6i64..=6 {
                let d2 = du * du + dv * dv;
                if d2 > 36 {
                    continue;
                }
                let (u, v) = (cu.round() as i64 + du, cv.round() as i64 + dv);
                if (0..w).contains(&u) && (0..h).contains(&v) {
                    img.put_pixel(
                        u as u32,
                        v as u32,
                        image::Rgb(if d2 > 20 { [0, 0, 0] } else { col }),
                    );
                }
            }
        }
    }
}

fn png_bytes(img: &RgbImage) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    image::DynamicImage::ImageRgb8(img.clone())
        .write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
        .map_err(|e| Error::Config(format!("cannot encode PNG: {e}")))?;
    Ok(out)
}

/// Tracks every frame of `source`, writing the requested outputs. `stop` is polled between
/// frames: when set, the outputs are finished with the frames done so far. `progress` is called
/// after each frame with (frames done, frames in total when known).
pub fn track(
    model: &ActionModel,
    scene: &Scene,
    source: &mut FrameSource,
    opts: &TrackOptions,
    outputs: &TrackOutputs,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(usize, Option<usize>),
) -> Result<TrackSummary> {
    let mut pipeline = Pipeline::new(model, scene, opts)?;
    let names = pipeline.action_names().to_vec();
    if let Some(d) = &outputs.overlay {
        std::fs::create_dir_all(d).map_err(|e| Error::write(d, e))?;
    }
    let mut writer = match &outputs.mcap {
        Some(p) => Some(TrackWriter::create(p, scene, outputs.mcap_images)?),
        None => None,
    };
    let cam0 = render_camera(&scene.cameras[0]);
    let total = source.len_hint();
    let start = Instant::now();
    let mut filter_seconds = 0.0;
    let mut traj = Trajectory {
        actions: names.clone(),
        rows: Vec::new(),
    };
    let mut interrupted = false;
    let mut cloud = Vec::new();
    // One frame of look-ahead: while the filter tracks frame t, frame t + 1 is decoded and its
    // edge image computed (`Pipeline::step_overlapped`). An error reading or preparing frame
    // t + 1 is returned after frame t is done, as the serial loop would.
    let mut next = source.next_frame()?;
    if let Some(f) = &next {
        pipeline.prime(f.index, &[&f.image])?;
    }
    let mut pending: Option<Error> = None;
    loop {
        if let Some(e) = pending.take() {
            return Err(e);
        }
        if stop.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let Some(frame) = next.take() else {
            break;
        };
        let (r, read) = pipeline.step_overlapped(|ahead| -> Result<Option<Frame>> {
            let f = source.next_frame()?;
            if let Some(f) = &f {
                ahead.prepare(f.index, &[&f.image])?;
            }
            Ok(f)
        })?;
        filter_seconds += pipeline.last_step_seconds();
        match read {
            Ok(f) => next = f,
            Err(e) => pending = Some(e),
        }
        traj.rows
            .push(track_row(frame.index, frame.time, &names, &r));
        let need_contour = outputs.overlay.is_some() || (writer.is_some() && outputs.mcap_images);
        let contour = if need_contour {
            contour_points(&cam0, pipeline.geometry(), &r.best_world, opts.contour)
        } else {
            Vec::new()
        };
        let dot = scene.cameras[0]
            .project(&r.theta_world)
            .map(|(u, v)| ([u, v], entropy_colour(r.estimate.theta_histogram_entropy)));
        if let Some(w) = writer.as_mut() {
            pipeline.tracker().cloud_into(&mut cloud);
            let parts: Vec<(usize, [f64; 3])> = cloud
                .iter()
                .map(|c| (c.action, scene.theta_to_world(c.theta).into()))
                .collect();
            let e = &r.estimate;
            let msg = EstimateMsg {
                frame_id: "actor".into(),
                frame: frame.index,
                time: frame.time,
                actions: names.clone(),
                action_posterior: e.action_posterior.clone(),
                map_action: names.get(e.map_action).cloned().unwrap_or_default(),
                theta_mean: e.theta_mean,
                theta_std: e.theta_std,
                theta_world: r.theta_world.into(),
                theta_entropy: e.theta_histogram_entropy,
                action_entropy: e.action_entropy,
                ess: e.ess,
                k: e.mean_k,
                progress: e.progress,
            };
            let png = if outputs.mcap_images {
                Some(png_bytes(&frame.image)?)
            } else {
                None
            };
            w.write_frame(&FrameRecord {
                frame: frame.index,
                time: frame.time,
                best_pose: r.best_world,
                smoothed_pose: r.smoothed_world,
                particles: &parts,
                estimate: &msg,
                png: png.as_deref(),
                contour: outputs.mcap_images.then_some(contour.as_slice()),
                theta_dot: dot,
            })?;
        }
        if let Some(d) = &outputs.overlay {
            let mut img = frame.image.clone();
            draw_overlay(&mut img, &contour, dot);
            let p = d.join(format!("overlay_{:05}.png", frame.index));
            img.save(&p)
                .map_err(|e| Error::write(&p, std::io::Error::other(e.to_string())))?;
        }
        progress(traj.rows.len(), total);
    }
    if let Some(w) = writer {
        w.finish()?;
    }
    if let Some(p) = &outputs.csv {
        traj.save(p)?;
    }
    Ok(TrackSummary {
        frames: traj.rows.len(),
        seconds: start.elapsed().as_secs_f64(),
        filter_seconds,
        interrupted,
        skipped: source.skipped().to_vec(),
        trajectory: traj,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::{BenchOptions, Prepared, prepare};

    /// Generator-trained models and `frames` rendered frames at 160×120.
    fn small(states: usize, frames: usize) -> Prepared {
        let opts = BenchOptions {
            width: 160,
            height: 120,
            states,
            ..BenchOptions::default()
        };
        prepare(&opts, frames).unwrap()
    }

    /// The prepared frames of the first camera as images.
    fn first_view_frames(prep: &Prepared) -> Vec<RgbImage> {
        prep.frames
            .iter()
            .map(|v| RgbImage::from_raw(v[0].width, v[0].height, v[0].data.clone()).unwrap())
            .collect()
    }

    /// The overlapped loop (next frame's edge image alongside the filter step, on two threads)
    /// tracks exactly as the serial one; a step with nothing primed is an error, not a stale
    /// frame tracked twice.
    #[test]
    #[allow(clippy::float_cmp)] // bit-identical estimates are the claim
    fn overlapped_steps_equal_serial_steps() {
        let prep = small(6, 6);
        let frames = first_view_frames(&prep);
        let track = TrackOptions {
            particles: 60,
            seed: 5,
            ..TrackOptions::default()
        };
        let mut serial = Pipeline::new(&prep.model, &prep.scene, &track).unwrap();
        let want: Vec<FrameResult> = frames
            .iter()
            .enumerate()
            .map(|(t, f)| serial.step(t, &[f]).unwrap())
            .collect();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let got = pool.install(|| {
            let mut p = Pipeline::new(&prep.model, &prep.scene, &track).unwrap();
            assert!(p.step_overlapped(|_| ()).is_err());
            p.prime(0, &[&frames[0]]).unwrap();
            let mut out = Vec::new();
            for t in 0..frames.len() {
                let (r, ()) = p
                    .step_overlapped(|ahead| {
                        if let Some(f) = frames.get(t + 1) {
                            ahead.prepare(t + 1, &[f]).unwrap();
                        }
                    })
                    .unwrap();
                out.push(r);
                assert!(p.last_step_seconds() > 0.0);
            }
            assert!(p.step_overlapped(|_| ()).is_err());
            out
        });
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.estimate.best_pose, w.estimate.best_pose);
            assert_eq!(g.estimate.smoothed_pose, w.estimate.smoothed_pose);
            assert_eq!(g.estimate.action_posterior, w.estimate.action_posterior);
            assert_eq!(g.estimate.theta_mean, w.estimate.theta_mean);
        }
    }

    /// The options of the small option tests: 60 particles, seed 5, everything else default.
    const SMALL_TRACK: TrackOptions = TrackOptions {
        particles: 60,
        seed: 5,
        contour: ContourMethod::Raster,
        theta_prior: ThetaPrior::Training,
        speed_range: None,
        dwell_cap: None,
        height_scale: None,
        fingertip_floor: None,
        action_floor: None,
    };

    /// The best pose of every frame of `frames` (first view) tracked with [`SMALL_TRACK`]
    /// changed by `set`.
    fn best_poses(
        prep: &Prepared,
        frames: &[RgbImage],
        set: impl FnOnce(&mut TrackOptions),
    ) -> Vec<[f64; 9]> {
        let mut track = SMALL_TRACK;
        set(&mut track);
        let mut p = Pipeline::new(&prep.model, &prep.scene, &track).unwrap();
        frames
            .iter()
            .enumerate()
            .map(|(t, f)| p.step(t, &[f]).unwrap().estimate.best_pose)
            .collect()
    }

    /// Asserts that the default options changed by `set` cannot build a pipeline, with an
    /// error naming `needle`.
    fn assert_rejected(prep: &Prepared, set: impl FnOnce(&mut TrackOptions), needle: &str) {
        let mut track = TrackOptions::default();
        set(&mut track);
        let e = Pipeline::new(&prep.model, &prep.scene, &track)
            .err()
            .unwrap();
        assert!(e.to_string().contains(needle), "{e}");
    }

    /// `max_stay = 1` is the models' own dwell times (the same track bit for bit), a cap below
    /// the models' self-transitions changes the track, keeping the last states' dwells leaves
    /// those states as trained and caps the rest, and a cap outside (0, 1] is an error.
    #[test]
    #[allow(clippy::float_cmp)] // bit-identical estimates are the claim
    fn max_stay_caps_the_dwell_times() {
        let prep = small(6, 5);
        let frames = first_view_frames(&prep);
        let run = |max_stay: Option<f64>, keep_last: bool| {
            best_poses(&prep, &frames, |o| {
                o.dwell_cap = max_stay.map(|max_stay| DwellCap {
                    max_stay,
                    keep_last,
                });
            })
        };
        let base = run(None, false);
        assert_eq!(run(Some(1.0), false), base);
        assert_eq!(run(None, true), base, "no cap: the flag changes nothing");
        let capped = run(Some(0.3), false);
        assert_ne!(capped, base);
        // Keeping the last states: those keep their trained dwell (above the cap here), every
        // other state is capped as before.
        let kept = prep
            .model
            .tracking_phmms(Some(DwellCap {
                max_stay: 0.3,
                keep_last: true,
            }))
            .unwrap();
        let all = prep.model.tracking_phmms(Some(DwellCap::all(0.3))).unwrap();
        for ((a, k), c) in prep.model.actions.iter().zip(&kept).zip(&all) {
            let n = a.phmm.n_states();
            assert!(a.phmm.transition(n - 1, n - 1) > 0.3);
            assert_eq!(k.transition(n - 1, n - 1), a.phmm.transition(n - 1, n - 1));
            assert_eq!(k.exit_prob(n - 1), a.phmm.exit_prob(n - 1));
            assert!((c.transition(n - 1, n - 1) - 0.3).abs() < 1e-12);
            for i in 0..n - 1 {
                for j in 0..n {
                    assert_eq!(k.transition(i, j), c.transition(i, j), "({i}, {j})");
                }
            }
        }
        for bad in [0.0, 1.5, f64::NAN] {
            assert_rejected(
                &prep,
                |o| o.dwell_cap = Some(DwellCap::all(bad)),
                "max_stay",
            );
        }
    }

    /// `height_scale = 1` is the models' own heights (the same track bit for bit); another
    /// factor scales the tracked poses' heights (the generated fingertip follows the models'
    /// scaled z, so the track changes), the models' rest height scales with it, and a factor
    /// that is not finite and positive is an error.
    #[test]
    #[allow(clippy::float_cmp)] // bit-identical estimates are the claim
    fn height_scale_scales_the_models_heights() {
        let prep = small(6, 5);
        let frames = first_view_frames(&prep);
        let run = |x: Option<f64>| best_poses(&prep, &frames, |o| o.height_scale = x);
        let base = run(None);
        assert_eq!(run(Some(1.0)), base);
        assert_ne!(run(Some(0.8)), base);
        let scaled = prep.model.tracking_phmms_scaled(None, Some(0.8)).unwrap();
        for (a, s) in prep.model.actions.iter().zip(&scaled) {
            let (centre, _) = a.phmm.theta_normalisation();
            let (m, ms) = (a.phmm.mean(0, centre), s.mean(0, centre));
            for k in 0..9 {
                let f = if k % 3 == 2 { 0.8 } else { 1.0 };
                assert!((ms[k] - f * m[k]).abs() < 1e-12, "coordinate {k}");
            }
        }
        let h = prep.model.rest_height();
        assert!(h.is_finite() && h < 0.0, "{h}");
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert_rejected(&prep, |o| o.height_scale = Some(bad), "height scale");
        }
    }

    /// The floor's penalty is ½((z₀ − r_z)/σ)² below z₀ and 0 on or above it, added to the
    /// inner model's log-likelihood; `correct` is the inner model's.
    #[test]
    fn fingertip_floor_penalises_only_below_the_floor() {
        struct Linear;
        impl ObservationModel for Linear {
            fn correct(&self, pose: &mut [f64; 9]) {
                pose[0] = 1.0;
            }
            fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
                for (o, p) in out.iter_mut().zip(poses) {
                    *o = -p[7];
                }
            }
        }
        let floor = FingertipFloor::new(Linear, Floor::new(-0.3, 0.01).unwrap());
        let pose = |y: f64, z: f64| [0.0, 0.0, 0.0, 0.1, 0.2, -0.2, 0.0, y, z];
        let poses = [
            pose(0.4, -0.25),
            pose(0.5, -0.3),
            pose(0.4, -0.32),
            pose(0.3, -0.4),
        ];
        let mut out = [0.0; 4];
        floor.log_likelihoods(&poses, &mut out);
        let want = [-0.4, -0.5, -0.4 - 0.5 * 2.0 * 2.0, -0.3 - 0.5 * 10.0 * 10.0];
        for (o, w) in out.iter().zip(want) {
            assert!((o - w).abs() < 1e-9, "{o} vs {w}");
        }
        let mut p = pose(0.4, -0.5);
        floor.correct(&mut p);
        assert!(
            (p[0] - 1.0).abs() < f64::EPSILON,
            "the inner correction ran"
        );
        for (z, sigma) in [
            (f64::NAN, 0.01),
            (-0.3, 0.0),
            (-0.3, -1.0),
            (-0.3, f64::INFINITY),
        ] {
            let e = Floor::new(z, sigma).err().unwrap();
            assert!(e.to_string().contains("fingertip floor"), "{e}");
        }
    }

    /// A floor far below every pose is the track without it, bit for bit; a floor 5 cm above
    /// the lowest fingertip of the track without it moves the track and raises that lowest
    /// fingertip; a floor that is not finite is an error.
    #[test]
    #[allow(clippy::float_cmp)] // bit-identical estimates are the claim
    fn fingertip_floor_moves_the_track_only_from_below() {
        let prep = small(6, 5);
        let frames = first_view_frames(&prep);
        let run = |x: Option<f64>| best_poses(&prep, &frames, |o| o.fingertip_floor = x);
        let base = run(None);
        assert_eq!(run(Some(-10.0)), base);
        let low = base.iter().map(|p| p[8]).fold(f64::INFINITY, f64::min);
        let raised = run(Some(low + 0.05));
        assert_ne!(raised, base);
        let lowest = raised.iter().map(|p| p[8]).fold(f64::INFINITY, f64::min);
        assert!(
            lowest > low,
            "lowest fingertip {lowest} vs {low} without the floor"
        );
        assert_rejected(
            &prep,
            |o| o.fingertip_floor = Some(f64::NAN),
            "fingertip floor",
        );
    }

    /// The default action floor is the tracker's (the same track bit for bit), another floor
    /// changes the track, and one outside (0, 1) is an error naming it.
    #[test]
    #[allow(clippy::float_cmp)] // bit-identical estimates are the claim
    fn action_floor_sets_the_mixture_floor() {
        let prep = small(6, 5);
        let frames = first_view_frames(&prep);
        let run = |x: Option<f64>| best_poses(&prep, &frames, |o| o.action_floor = x);
        let base = run(None);
        assert_eq!(run(Some(actrack_pf::DEFAULT_ACTION_FLOOR)), base);
        assert_ne!(run(Some(0.9)), base);
        for bad in [0.0, 1.0, -0.5, f64::NAN] {
            assert_rejected(&prep, |o| o.action_floor = Some(bad), "particle floor");
        }
    }

    /// A frame that does not fit the camera is an error naming it, and leaves nothing primed.
    #[test]
    fn lookahead_names_a_frame_of_the_wrong_size() {
        let prep = small(4, 1);
        let mut p = Pipeline::new(&prep.model, &prep.scene, &TrackOptions::default()).unwrap();
        let wrong = RgbImage::new(100, 100);
        let e = p.prime(7, &[&wrong]).unwrap_err().to_string();
        assert!(e.contains("frame 7"), "{e}");
        assert!(p.step_overlapped(|_| ()).is_err());
    }
}
