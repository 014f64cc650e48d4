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
    ArmGeometry as RenderArm, Camera as RenderCamera, DownscaleBuf, EdgeImage, EdgeWorkspace,
    ImageView, LikelihoodModel, LocalNorm, LocalNormScratch,
};
use image::RgbImage;
use nalgebra::Vector3;

use crate::config::{FloorSetting, Gradient, Median, OutputConfig, ThetaPrior, TrackConfig};
use crate::error::{Error, Result};
use crate::gate::ForegroundGate;
use crate::model::ActionModel;
use crate::observation::{
    FingertipFloor, Floor, SceneObservation, Scorer, ShortContourPenalty, Timed,
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
    /// Edge images of every view (with normalisation and gate).
    pub edges: f64,
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
    ws: EdgeWorkspace,
    local: LocalNormScratch,
    spec: EdgeImage,
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
                    "observation.max_width = {}: camera `{}` ({}×{}) would be shrunk by {f} to                      nothing; raise max_width or set it to 0",
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
    /// (see `observation.max_width`).
    pub fn edges(&self) -> &[EdgeImage] {
        &self.edges
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
        let obs_cfg = &self.config.observation;
        for (v, img) in images.iter().enumerate() {
            let cam = &self.scene.cameras[v];
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
            let err = |e: actrack_render::RenderError| Error::Config(format!("frame {frame}: {e}"));
            let stage = &mut self.views[v];
            let full = self.scene.edge_params(cam.model.width);
            let params = actrack_render::EdgeParams {
                colour: obs_cfg.gradient == Gradient::Colour,
                sigma: full.sigma / stage.factor as f32,
                ..full
            };
            let img = &if stage.factor > 1 {
                actrack_render::downscale(*img, stage.factor, &mut stage.shrink).map_err(err)?
            } else {
                *img
            };
            if obs_cfg.local_norm.enabled {
                stage
                    .ws
                    .compute_into(*img, &params, &mut stage.spec)
                    .map_err(err)?;
                let ln = LocalNorm {
                    radius: obs_cfg.local_norm.radius,
                    floor: obs_cfg.local_norm.floor,
                };
                actrack_render::local_normalise(
                    &stage.spec,
                    &ln,
                    &mut stage.local,
                    &mut self.edges[v],
                )
                .map_err(err)?;
            } else {
                stage
                    .ws
                    .compute_into(*img, &params, &mut self.edges[v])
                    .map_err(err)?;
            }
            if obs_cfg.foreground_gate.enabled {
                stage
                    .gate
                    .apply(&obs_cfg.foreground_gate, *img, &mut self.edges[v])
                    .map_err(|e| Error::Config(format!("frame {frame}: {e}")))?;
            }
        }
        let edges_ms = t0.elapsed().as_secs_f64() * 1e3;
        let (estimate, stages) = self.filter();
        let r = FrameResult {
            best_world: self.scene.pose_to_world(&estimate.best_pose),
            smoothed_world: self.scene.pose_to_world(&estimate.smoothed_pose),
            theta_world: self.scene.theta_to_world(estimate.theta_mean),
            estimate,
        };
        let t1 = Instant::now();
        let gate = &self.config.observation.foreground_gate;
        if gate.enabled {
            let tracked = [&r.best_world, &r.smoothed_world];
            for ((img, cam), stage) in images.iter().zip(&self.cameras).zip(&mut self.views) {
                // The shrunk frame the edge stage made, if the view is shrunk.
                let img = stage.shrink.last().unwrap_or(*img);
                stage
                    .gate
                    .update(gate, img, cam, &self.geometry, &tracked)
                    .map_err(|e| Error::Config(format!("frame {frame}: {e}")))?;
            }
        }
        let background = t1.elapsed().as_secs_f64() * 1e3;
        self.times = StageTimes {
            edges: edges_ms,
            resample: stages[0],
            propagate: stages[1],
            likelihood: stages[2],
            estimates: stages[3],
            background,
            total: t0.elapsed().as_secs_f64() * 1e3,
        };
        Ok(r)
    }

    /// One filter step on the current edge images with the configured observation model.
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

/// The integer factor that brings a frame `width` pixels wide within `max_width` (0: no limit).
pub fn shrink_factor(width: u32, max_width: u32) -> u32 {
    if max_width == 0 || width <= max_width {
        1
    } else {
        width.div_ceil(max_width)
    }
}

/// One filter step on `obs` (under the floor, if any) with its stage times.
fn timed_step<O: ObservationModel>(
    tracker: &mut Tracker,
    obs: O,
    floor: Option<Floor>,
) -> (Estimate, [f64; 4]) {
    #[allow(clippy::single_match_else)] // the two arms differ in type
    match floor {
        Some(f) => {
            let t = Timed::new(FingertipFloor::new(obs, f));
            let e = tracker.step(&t);
            (e, t.stages())
        }
        None => {
            let t = Timed::new(obs);
            let e = tracker.step(&t);
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
