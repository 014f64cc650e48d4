//! [`Session`]: the one per-frame tracking loop (SPEC §3.8). Built from action models, a scene and
//! a [`TrackConfig`], fed one frame at a time (one image per camera), it yields the per-frame
//! estimates. `actrack-cli track`, `demo` and `bench`, the Python `Tracker` and the experiments
//! all drive it.
//!
//! Per frame: the edge image of every view (SPEC §4.1, then the configuration's local
//! normalisation and foreground gate), one filter step in action space scored by the configured
//! observation model ([`crate::observation`]), the estimates mapped to the world, and the
//! gate's background updated away from the tracked arm.
//!
//! The reported pose's median filter over time runs downstream of the step: causal in the
//! filter itself, centred in [`PoseReport`], which delays each frame by half its window.

use std::collections::VecDeque;
use std::sync::Mutex;
use std::time::Instant;

use actrack_pf::{
    ActionBalance, CentredMedian, Estimate, ObservationModel, TableRegion, Tracker, TrackerConfig,
};
use actrack_render::{
    ArmGeometry as RenderArm, Camera as RenderCamera, CropBuf, DownscaleBuf, EdgeImage,
    EdgeWorkspace, ImageView, LikelihoodModel, LocalNorm, LocalNormScratch, PixelRect,
};
use image::RgbImage;
use nalgebra::Vector3;

use crate::config::{
    EdgeRegion, FloorSetting, Gradient, Median, ObservationConfig, OutputConfig, ThetaPrior,
    TrackConfig,
};
use crate::error::{Error, Result};
use crate::gate::ForegroundGate;
use crate::model::ActionModel;
use crate::observation::{
    Correction, FingertipFloor, Floor, SceneObservation, Scorer, ShortContourPenalty, Timed,
};
use crate::scene::{Scene, render_arm};

/// The filter's causal median window (SPEC §3.7's recommendation, frames) when the reported
/// pose is the centred median: the causal one still feeds the gate's background.
pub const CAUSAL_WINDOW: usize = 5;

/// One frame's result.
#[derive(Clone, Debug)]
pub struct FrameResult {
    /// The filter's estimate (actor frame).
    pub estimate: Estimate,
    /// Best particle's pose, world.
    pub best_world: [f64; 9],
    /// The causally median-filtered pose, world.
    pub smoothed_world: [f64; 9],
    /// θ̄ on the table, world.
    pub theta_world: Vector3<f64>,
}

/// Wall-clock milliseconds of the last step's stages.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Edge images of every view (the region, shrinking, G and its normalisation).
    pub edges: f64,
    /// The foreground gate's mask and its product with G, every view.
    pub foreground: f64,
    /// Resampling (SPEC §3.6).
    pub resample: f64,
    /// Propagation, pose sampling and arm correction (SPEC §3.3, §3.4).
    pub propagate: f64,
    /// Render + contour + likelihood of every particle in every view (SPEC §4).
    pub likelihood: f64,
    /// Weights and estimates (SPEC §3.5, §3.7).
    pub estimates: f64,
    /// The foreground gate's background update.
    pub background: f64,
    /// The whole step.
    pub total: f64,
}

/// The edge stage of one view (buffers reused across frames).
#[derive(Default)]
struct ViewStage {
    /// The integer factor the view's frames are shrunk by (1: full size).
    factor: u32,
    shrink: DownscaleBuf,
    /// The pixels of the edge region (`observation.edge_region = "particles"`).
    crop: CropBuf,
    /// The rectangle of the last edge image that may hold non-zero pixels.
    kept: Option<PixelRect>,
    /// The pixels the gate was applied to this frame (`None`: the whole frame).
    gated: Option<PixelRect>,
    ws: EdgeWorkspace,
    local: LocalNormScratch,
    spec: EdgeImage,
    /// The edge image of the region before it is pasted into the frame's.
    part: EdgeImage,
    gate: ForegroundGate,
}

/// The per-video tracking state: edge stages, foreground backgrounds, the filter and its
/// observation model.
pub struct Session {
    scene: Scene,
    config: TrackConfig,
    geometry: RenderArm,
    /// The cameras of the images the observation works on (shrunk, see
    /// `observation.max_width`).
    cameras: Vec<RenderCamera>,
    scorer: Scorer,
    device_note: Option<String>,
    tracker: Tracker,
    views: Vec<ViewStage>,
    edges: Vec<EdgeImage>,
    world: Mutex<Vec<[f64; 9]>>,
    floor: Option<Floor>,
    names: Vec<String>,
    times: StageTimes,
}

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

/// The filter's configuration for `model` in `scene`.
fn tracker_config(model: &ActionModel, scene: &Scene, cfg: &TrackConfig) -> Result<TrackerConfig> {
    let (centre, half) = scene.theta_region();
    let f = &cfg.filter;
    let causal = match cfg.output.median {
        Median::Causal => cfg.output.median_window,
        Median::Centred => CAUSAL_WINDOW,
    };
    let balance = if f.action_floor > 0.0 {
        ActionBalance::Mixture(f.action_floor)
    } else {
        ActionBalance::Joint
    };
    let mut b = TrackerConfig::builder(TableRegion::new(centre, half))
        .particles(f.particles)
        .seed(f.seed)
        .sigma_end_ratio(f.sigma_end_ratio)
        .speed_range(cfg.speed_range())
        .median_window(causal)
        .action_balance(balance)
        .action_switch(if f.action_floor > 0.0 {
            f.action_switch
        } else {
            0.0
        });
    if cfg.prior.theta == ThetaPrior::Training {
        b = b.action_regions(training_theta_regions(
            model,
            cfg.prior.theta_pad,
            (centre, half),
        ));
    }
    b.build()
        .map_err(|e| Error::Config(format!("tracker: {e}")))
}

impl Session {
    /// A session for `model` in `scene` with `config` (checked here).
    ///
    /// # Errors
    /// [`Error::Config`] naming the key of an invalid configuration, or what does not fit the
    /// scene or the models.
    pub fn new(model: &ActionModel, scene: &Scene, config: &TrackConfig) -> Result<Self> {
        config.check()?;
        if scene.cameras.is_empty() {
            return Err(Error::Config("the scene has no camera".into()));
        }
        let geometry = render_arm(
            scene,
            [model.arm_lengths.upper_arm, model.arm_lengths.forearm_hand],
        );
        let factors: Vec<u32> = scene
            .cameras
            .iter()
            .map(|c| shrink_factor(c.model.width, config.observation.max_width))
            .collect();
        for (c, &f) in scene.cameras.iter().zip(&factors) {
            if c.model.height / f == 0 {
                return Err(Error::Config(format!(
                    "observation.max_width = {}: camera `{}` ({}×{}) would be shrunk by {f} to nothing; \
                     raise max_width or set it to 0",
                    config.observation.max_width, c.name, c.model.width, c.model.height
                )));
            }
        }
        let cameras: Vec<RenderCamera> = scene
            .cameras
            .iter()
            .zip(&factors)
            .map(|(c, &f)| c.model.downscaled(f))
            .collect();
        let likelihood = LikelihoodModel::new(
            cameras.clone(),
            geometry.clone(),
            config.gamma(cameras.len()),
            config.observation.contour.into(),
        )
        .map_err(|e| Error::Config(format!("observation model: {e}")))?;
        let (scorer, device_note) = Scorer::new(config.observation.device, likelihood)?;
        let floor = match config.actor.fingertip_floor {
            FloorSetting::Off => None,
            FloorSetting::Table => {
                Some(Floor::new(scene.table_height(), config.actor.floor_sigma)?)
            }
            FloorSetting::Height(z) => Some(Floor::new(z, config.actor.floor_sigma)?),
        };
        let names: Vec<String> = model.actions.iter().map(|a| a.name.clone()).collect();
        #[allow(clippy::float_cmp)] // exactly 1: the trained models, bit for bit
        let scale = (config.prior.height_scale != 1.0).then_some(config.prior.height_scale);
        let phmms = model.tracking_phmms_scaled(config.dwell_cap(), scale)?;
        let tracker = Tracker::new(
            phmms.iter(),
            names.clone(),
            tracker_config(model, scene, config)?,
        )
        .map_err(|e| Error::Model {
            context: "building the tracker".into(),
            message: e.to_string(),
        })?;
        Ok(Self {
            scene: scene.clone(),
            config: config.clone(),
            geometry,
            views: factors
                .iter()
                .map(|&factor| ViewStage {
                    factor,
                    ..ViewStage::default()
                })
                .collect(),
            edges: cameras.iter().map(|_| EdgeImage::default()).collect(),
            cameras,
            scorer,
            device_note,
            tracker,
            world: Mutex::new(Vec::with_capacity(config.filter.particles)),
            floor,
            names,
            times: StageTimes::default(),
        })
    }

    /// Action names.
    pub fn action_names(&self) -> &[String] {
        &self.names
    }

    /// The filter (particles, weights).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// The arm geometry used for rendering.
    pub fn geometry(&self) -> &RenderArm {
        &self.geometry
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The configuration.
    pub fn config(&self) -> &TrackConfig {
        &self.config
    }

    /// `cpu` or `gpu`: where the likelihood runs.
    pub fn device(&self) -> &'static str {
        self.scorer.device()
    }

    /// A note on the device choice (`observation.device = auto` fell back), if any.
    pub fn device_note(&self) -> Option<&str> {
        self.device_note.as_deref()
    }

    /// The stage times of the last step.
    pub fn last_times(&self) -> StageTimes {
        self.times
    }

    /// The edge images of the last step, one per view, at the size the observation works on
    /// (see `observation.max_width`); 0 outside [`Session::edge_region`].
    pub fn edges(&self) -> &[EdgeImage] {
        &self.edges
    }

    /// The rectangle of view `view`'s edge image (pixels of the image the observation works
    /// on, see `observation.max_width`) that the last step computed; the rest of the image
    /// is 0. `None` when the whole frame was computed (`observation.edge_region = "frame"`,
    /// or before the first step).
    pub fn edge_region(&self, view: usize) -> Option<PixelRect> {
        self.views.get(view).and_then(|v| v.kept)
    }

    /// One step on RGB images, one per camera of the scene.
    ///
    /// # Errors
    /// As [`Session::step`].
    pub fn step_rgb(&mut self, frame: usize, images: &[&RgbImage]) -> Result<FrameResult> {
        let views = images
            .iter()
            .map(|img| {
                ImageView::rgb8(img.as_raw(), img.width(), img.height())
                    .map_err(|e| Error::Config(format!("frame {frame}: {e}")))
            })
            .collect::<Result<Vec<_>>>()?;
        self.step(frame, &views)
    }

    /// One step on synchronised images, one per camera of the scene, in the scene's order.
    ///
    /// # Errors
    /// [`Error::Config`] naming the frame when the number of images is not the number of
    /// cameras or an image does not fit its camera.
    pub fn step(&mut self, frame: usize, images: &[ImageView<'_>]) -> Result<FrameResult> {
        let t0 = Instant::now();
        if images.len() != self.cameras.len() {
            return Err(Error::Config(format!(
                "frame {frame}: {} image(s) for a scene of {} camera(s): every camera needs its \
                 view of the frame",
                images.len(),
                self.cameras.len()
            )));
        }
        for (img, cam) in images.iter().zip(&self.scene.cameras) {
            if img.size() != (cam.model.width, cam.model.height) {
                return Err(Error::Config(format!(
                    "frame {frame}: the image is {}×{} but camera `{}` of the scene is {}×{}",
                    img.size().0,
                    img.size().1,
                    cam.name,
                    cam.model.width,
                    cam.model.height
                )));
            }
        }
        // Resample, propagate and generate: the poses the likelihood will score.
        let predict = Timed::new(Correction::new(&self.geometry));
        self.tracker.predict(&predict);
        let [resample, propagate] = predict.predict_stages();
        let t1 = Instant::now();
        let err = |e: actrack_render::RenderError| Error::Config(format!("frame {frame}: {e}"));
        let regions = self.edge_regions();
        let mut gate_ms = 0.0;
        for (v, img) in images.iter().enumerate() {
            let cam = &self.scene.cameras[v];
            let stage = &mut self.views[v];
            if stage.factor > 1 {
                actrack_render::downscale(*img, stage.factor, &mut stage.shrink).map_err(err)?;
            }
            let full = self.scene.edge_params(cam.model.width);
            let params = actrack_render::EdgeParams {
                colour: self.config.observation.gradient == Gradient::Colour,
                sigma: full.sigma / stage.factor as f32,
                ..full
            };
            view_edges(
                stage,
                &mut self.edges[v],
                &self.config.observation,
                &params,
                *img,
                regions[v],
                &mut gate_ms,
            )
            .map_err(|e| match e {
                Error::Config(m) => Error::Config(format!("frame {frame}: {m}")),
                e => e,
            })?;
        }
        let edges_ms = t1.elapsed().as_secs_f64() * 1e3;
        let (estimate, [_, _, likelihood, estimates]) = self.filter();
        let r = FrameResult {
            best_world: self.scene.pose_to_world(&estimate.best_pose),
            smoothed_world: self.scene.pose_to_world(&estimate.smoothed_pose),
            theta_world: self.scene.theta_to_world(estimate.theta_mean),
            estimate,
        };
        let t2 = Instant::now();
        let gate = &self.config.observation.foreground_gate;
        if gate.enabled {
            let tracked = [&r.best_world, &r.smoothed_world];
            for ((img, cam), stage) in images.iter().zip(&self.cameras).zip(&mut self.views) {
                // The shrunk frame the edge stage made, if the view is shrunk.
                let img = stage.shrink.last().unwrap_or(*img);
                let (w, h) = img.size();
                stage
                    .gate
                    .update(
                        gate,
                        img,
                        stage.gated.unwrap_or(PixelRect::full(w, h)),
                        cam,
                        &self.geometry,
                        &tracked,
                    )
                    .map_err(|e| Error::Config(format!("frame {frame}: {e}")))?;
            }
        }
        let background = t2.elapsed().as_secs_f64() * 1e3;
        self.times = StageTimes {
            edges: edges_ms - gate_ms,
            foreground: gate_ms,
            resample,
            propagate,
            likelihood,
            estimates,
            background,
            total: t0.elapsed().as_secs_f64() * 1e3,
        };
        Ok(r)
    }

    /// The rectangle of every view whose edges the likelihood can read this frame: with
    /// `observation.edge_region = "particles"` the pixels the arms of the predicted poses
    /// project into (2 px for bilinear reads and rounding), else `None` (the whole frame).
    fn edge_regions(&self) -> Vec<Option<PixelRect>> {
        if self.config.observation.edge_region == EdgeRegion::Frame {
            return vec![None; self.cameras.len()];
        }
        let mut world = match self.world.lock() {
            Ok(w) => w,
            Err(p) => p.into_inner(),
        };
        world.clear();
        world.extend(
            self.tracker
                .samples()
                .iter()
                .map(|p| self.scene.pose_to_world(p)),
        );
        self.cameras
            .iter()
            .map(|cam| Some(actrack_render::arm_bounds(cam, &self.geometry, &world, 2.0)))
            .collect()
    }

    /// The update of the filter step (the poses of [`Tracker::predict`] scored on the current
    /// edge images with the configured observation model) and its stage times.
    fn filter(&mut self) -> (Estimate, [f64; 4]) {
        let pen = &self.config.observation.short_contour_penalty;
        #[allow(clippy::single_match_else)] // the GPU variant exists with feature `gpu`
        match (&self.scorer, pen.enabled) {
            (Scorer::Cpu(likelihood), true) => {
                let obs = ShortContourPenalty::new(
                    &self.scene,
                    likelihood,
                    &self.edges,
                    pen.weight,
                    pen.quantile,
                );
                timed_step(&mut self.tracker, obs, self.floor)
            }
            _ => {
                let obs = SceneObservation::new(
                    &self.scene,
                    &self.geometry,
                    &self.scorer,
                    &self.edges,
                    &self.world,
                );
                timed_step(&mut self.tracker, obs, self.floor)
            }
        }
    }
}

/// The edge image `out` of one view from its frame `img` (shrunk by the stage first, if it
/// shrinks): the whole frame, or `keep` and the halo its filters need, pasted into a frame-sized
/// image that is 0 elsewhere. The gate's time is added to `gate_ms`.
fn view_edges(
    stage: &mut ViewStage,
    out: &mut EdgeImage,
    obs_cfg: &ObservationConfig,
    params: &actrack_render::EdgeParams,
    img: ImageView<'_>,
    keep: Option<PixelRect>,
    gate_ms: &mut f64,
) -> Result<()> {
    let err = |e: actrack_render::RenderError| Error::Config(e.to_string());
    let ViewStage {
        shrink,
        crop,
        kept,
        gated,
        ws,
        local,
        spec,
        part,
        gate,
        ..
    } = stage;
    let img = shrink.last().unwrap_or(img);
    let (w, h) = img.size();
    // The pixels the filters read for `keep`: Sobel's 1, the Gaussian's ⌈3σ⌉, the local
    // window and the gate's dilation.
    let region = keep.map(|k| {
        let mut halo = 1 + (3.0 * params.sigma).ceil().max(1.0) as u32;
        if obs_cfg.local_norm.enabled {
            halo += obs_cfg.local_norm.radius;
        }
        if obs_cfg.foreground_gate.enabled {
            halo += obs_cfg.foreground_gate.radius;
        }
        (k, k.grown(halo, w, h))
    });
    let clear = kept.unwrap_or(PixelRect::full(w, h));
    let (pixels, target) = match region {
        Some((k, _)) if k.is_empty() => {
            // No pose to score: nothing to compute.
            actrack_render::paste(
                &EdgeImage::default(),
                PixelRect::default(),
                k,
                clear,
                (w, h),
                out,
            )
            .map_err(err)?;
            *kept = Some(k);
            *gated = Some(k);
            return Ok(());
        }
        Some((_, r)) => (actrack_render::crop(img, r, crop).map_err(err)?, &mut *part),
        None => (img, &mut *out),
    };
    if obs_cfg.local_norm.enabled {
        ws.compute_into(pixels, params, spec).map_err(err)?;
        let ln = LocalNorm {
            radius: obs_cfg.local_norm.radius,
            floor: obs_cfg.local_norm.floor,
        };
        actrack_render::local_normalise(spec, &ln, local, target).map_err(err)?;
    } else {
        ws.compute_into(pixels, params, target).map_err(err)?;
    }
    *gated = region.map(|(_, r)| r);
    if obs_cfg.foreground_gate.enabled {
        let t = Instant::now();
        let rect = region.map_or(PixelRect::full(w, h), |(_, r)| r);
        gate.apply(&obs_cfg.foreground_gate, img, rect, pixels, target)?;
        *gate_ms += t.elapsed().as_secs_f64() * 1e3;
    }
    *kept = match region {
        Some((k, r)) => {
            actrack_render::paste(part, r, k, clear, (w, h), out).map_err(err)?;
            Some(k)
        }
        None => None,
    };
    Ok(())
}

/// The integer factor that brings a frame `width` pixels wide within `max_width` (0: no limit).
pub fn shrink_factor(width: u32, max_width: u32) -> u32 {
    if max_width == 0 || width <= max_width {
        1
    } else {
        width.div_ceil(max_width)
    }
}

/// The update of a filter step on `obs` (under the floor, if any) with its stage times.
fn timed_step<O: ObservationModel>(
    tracker: &mut Tracker,
    obs: O,
    floor: Option<Floor>,
) -> (Estimate, [f64; 4]) {
    #[allow(clippy::single_match_else)] // the two arms differ in type
    match floor {
        Some(f) => {
            let t = Timed::new(FingertipFloor::new(obs, f));
            let e = tracker.update(&t);
            (e, t.stages())
        }
        None => {
            let t = Timed::new(obs);
            let e = tracker.update(&t);
            (e, t.stages())
        }
    }
}

/// The reported pose of each frame (SPEC §3.7): with a causal median, the filter's own
/// (known at once); with a centred one of window 2h + 1, the median of the best particle's
/// poses of frames t − h … t + h, so each frame leaves h frames after it came in (the last h at
/// [`PoseReport::finish`]). `T` is whatever travels with a frame to the outputs.
pub struct PoseReport<T> {
    centred: Option<CentredMedian>,
    waiting: VecDeque<T>,
}

impl<T> PoseReport<T> {
    /// The report of `output`'s median.
    ///
    /// # Errors
    /// [`Error::Config`] for an even centred window.
    pub fn new(output: &OutputConfig) -> Result<Self> {
        let centred = match output.median {
            Median::Centred => Some(
                CentredMedian::new(output.median_window)
                    .map_err(|e| Error::Config(format!("output.median_window: {e}")))?,
            ),
            Median::Causal => None,
        };
        Ok(Self {
            centred,
            waiting: VecDeque::new(),
        })
    }

    /// Feeds a tracked frame: its payload, its best particle's pose and the filter's causal
    /// median ([`Estimate::best_pose`], [`Estimate::smoothed_pose`]); returns the frame now
    /// complete, if any, with its reported pose (actor frame).
    pub fn push(&mut self, item: T, best: [f64; 9], causal: [f64; 9]) -> Option<(T, [f64; 9])> {
        match self.centred.as_mut() {
            None => Some((item, causal)),
            Some(c) => {
                self.waiting.push_back(item);
                let pose = c.push(best)?;
                self.waiting.pop_front().map(|t| (t, pose))
            }
        }
    }

    /// The frames still waiting at the end of the video, with their reported poses.
    pub fn finish(&mut self) -> Vec<(T, [f64; 9])> {
        match self.centred.as_mut() {
            None => Vec::new(),
            Some(c) => c
                .finish()
                .into_iter()
                .zip(self.waiting.drain(..))
                .map(|(p, t)| (t, p))
                .collect(),
        }
    }
}
