//! The library side of `actrack-cli bench`: tracks a synthetic sequence (built-in motion
//! generator, generator-trained models, rendered frames with known truth) and times every frame
//! and every stage of SPEC §3.8, so users can check the real-time budget on their own machine.
//!
//! Stages are measured from outside the filter: the edge image is computed and timed here, and
//! the tracker step runs with a timing wrapper around the observation model, which notes the
//! first arm correction (the end of resampling), the start and the end of the batch likelihood.
//! So a step splits into resample | propagate + sample | render + contour + likelihood |
//! weights + estimates. Peak memory is the process's `VmHWM` from `/proc/self/status` (Linux).

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use actrack_pf::{ObservationModel, TableRegion, Tracker, TrackerConfig};
use actrack_render::synth::SceneSynth;
use actrack_render::{
    ArmGeometry as RenderArm, ContourMethod, EdgeImage, EdgeWorkspace, ImageRgb8, ImageView,
    LikelihoodModel, correct_arm,
};
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::demo::train_generator_model;
use crate::error::{Error, Result};
use crate::motion::ACTIONS;
use crate::pipeline::{GAMMA, edge_params, render_arm, render_camera};
use crate::scene::{Scene, default_scene, look_at};
use crate::synth::{MotionSource, random_targets, scene_synth, sequence};

/// Where the likelihood of a batch of particles is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Device {
    /// The CPU (rayon over particles).
    #[default]
    Cpu,
    /// The GPU through wgpu (feature `gpu`); an error when there is no adapter.
    Gpu,
    /// The GPU when a hardware adapter exists, else the CPU (with a note in the report; a
    /// software adapter such as lavapipe is slower than the CPU path).
    Auto,
}

/// Options of a bench run.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Particles M.
    pub particles: usize,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// Synchronised views (cameras around the table).
    pub views: usize,
    /// Contour method of the likelihood.
    pub contour: ContourMethod,
    /// Timed frames (after the warm-up).
    pub frames: usize,
    /// Untimed frames first (caches, allocations, thread pool).
    pub warmup: usize,
    /// Worker threads (a local rayon pool).
    pub threads: usize,
    /// Seed of the sequence, the models and the filter.
    pub seed: u64,
    /// PHMM states per action of the generator-trained models.
    pub states: usize,
    /// Likelihood device.
    pub device: Device,
    /// Overlap each frame's tracker step with the next frame's edge images
    /// ([`Runner::step_overlapped`]; what `track` does on a video, where the next frame's
    /// decoding joins the edge image). Default `false`: the serial order edge image → step,
    /// whose stage times add up to the frame.
    pub overlap: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            particles: 400,
            width: 640,
            height: 480,
            views: 1,
            contour: ContourMethod::Analytic,
            frames: 100,
            warmup: 5,
            threads: 1,
            seed: 7,
            states: 20,
            device: Device::Cpu,
            overlap: false,
        }
    }
}

/// Per-frame medians of the stages, milliseconds.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageMedians {
    /// Edge image G of every view.
    pub edge_image: f64,
    /// Resampling (SPEC §3.6).
    pub resample: f64,
    /// Propagation and pose sampling + arm correction (§3.3, §3.4).
    pub propagate_sample: f64,
    /// Render + contour + likelihood of every particle in every view (§4).
    pub likelihood: f64,
    /// Weights and estimates (§3.5, §3.7).
    pub estimates: f64,
}

/// What a bench run measured.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// Particles M.
    pub particles: usize,
    /// Worker threads.
    pub threads: usize,
    /// Whether each step overlapped the next frame's edge images (see [`BenchOptions::overlap`]).
    pub overlap: bool,
    /// Frame size.
    pub width: u32,
    /// Frame size.
    pub height: u32,
    /// Views.
    pub views: usize,
    /// `raster` or `analytic`.
    pub contour: String,
    /// `cpu` or `gpu` (what was used).
    pub device: String,
    /// A note on the device choice (fallback), if any.
    pub device_note: Option<String>,
    /// Timed frames.
    pub frames: usize,
    /// Median wall time per frame, ms (edge image + tracker step).
    pub median_ms: f64,
    /// 95th percentile per frame, ms.
    pub p95_ms: f64,
    /// Mean per frame, ms.
    pub mean_ms: f64,
    /// Frames per second at the median.
    pub fps: f64,
    /// Per-stage medians, ms.
    pub stages_ms: StageMedians,
    /// Peak resident memory of the process (`VmHWM`), KiB; `None` off Linux.
    pub peak_rss_kib: Option<u64>,
    /// Resident memory after the warm-up and at the end, KiB (memory must not grow with frames).
    pub rss_kib_after_warmup: Option<u64>,
    /// Resident memory at the end, KiB.
    pub rss_kib_end: Option<u64>,
    /// Seconds spent preparing (training the models, rendering the frames).
    pub setup_seconds: f64,
}

impl BenchReport {
    /// The share of each stage in the sum of the stage medians, percent, in display order.
    pub fn shares(&self) -> [(&'static str, f64, f64); 5] {
        let s = &self.stages_ms;
        let rows = [
            ("edge image", s.edge_image),
            ("resample", s.resample),
            ("propagate + sample", s.propagate_sample),
            ("render + contour + likelihood", s.likelihood),
            ("weights + estimates", s.estimates),
        ];
        let total: f64 = rows.iter().map(|r| r.1).sum();
        rows.map(|(n, v)| (n, v, if total > 0.0 { 100.0 * v / total } else { 0.0 }))
    }
}

/// The batch likelihood, on the CPU or on the GPU.
pub enum Scorer {
    /// `actrack-render`'s CPU likelihood.
    Cpu(LikelihoodModel),
    /// The wgpu likelihood (analytic contours).
    #[cfg(feature = "gpu")]
    Gpu(Box<actrack_render::gpu::GpuLikelihood>),
}

impl Scorer {
    /// Scores world poses into `out`; NaN on error.
    pub fn score(&self, edges: &[EdgeImage], world: &[[f64; 9]], out: &mut [f64]) {
        let ok = match self {
            Scorer::Cpu(m) => m.log_likelihood_batch(edges, world, out).is_ok(),
            #[cfg(feature = "gpu")]
            Scorer::Gpu(g) => g.log_likelihood_batch(edges, world, out).is_ok(),
        };
        if !ok {
            out.fill(f64::NAN);
        }
    }
}

/// Nanoseconds since `base`, saturating.
fn since(base: Instant) -> u64 {
    u64::try_from(base.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// The observation model of one frame with timing marks.
struct TimedObservation<'a> {
    scene: &'a Scene,
    geometry: &'a RenderArm,
    scorer: &'a Scorer,
    edges: &'a [EdgeImage],
    world: &'a Mutex<Vec<[f64; 9]>>,
    base: Instant,
    first_correct: AtomicU64,
    ll_start: AtomicU64,
    ll_end: AtomicU64,
}

impl ObservationModel for TimedObservation<'_> {
    fn correct(&self, pose: &mut [f64; 9]) {
        if self.first_correct.load(Ordering::Relaxed) == u64::MAX {
            self.first_correct
                .fetch_min(since(self.base), Ordering::Relaxed);
        }
        correct_arm(self.geometry, pose, None);
    }

    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        self.ll_start.store(since(self.base), Ordering::Relaxed);
        let mut world = match self.world.lock() {
            Ok(w) => w,
            Err(p) => p.into_inner(),
        };
        world.clear();
        world.extend(poses.iter().map(|p| self.scene.pose_to_world(p)));
        self.scorer.score(self.edges, &world, out);
        self.ll_end.store(since(self.base), Ordering::Relaxed);
    }
}

/// The default scene with `views` cameras on a circle around the workspace (the first is the
/// default camera; the others are turned about the vertical through the target by ±50°, ±100° …).
pub fn bench_scene(width: u32, height: u32, views: usize) -> Result<Scene> {
    if views == 0 {
        return Err(Error::Config("--views must be ≥ 1".into()));
    }
    let mut scene = default_scene(width, height);
    let first = scene.cameras[0].clone();
    let eye0 = first.centre();
    let target = Vector3::new(0.0, 0.35, 0.8);
    for v in 1..views {
        let k = v.div_ceil(2) as f64;
        let sign = if v % 2 == 1 { 1.0 } else { -1.0 };
        let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), sign * k * 50f64.to_radians());
        let eye = target + rot * (eye0 - target);
        let (r_cw, t_cw) = look_at(eye, target, Vector3::z())
            .ok_or_else(|| Error::Config("bench: degenerate camera".into()))?;
        let mut cam = first.clone();
        cam.name = format!("camera{v}");
        cam.r_cw = r_cw;
        cam.t_cw = t_cw;
        scene.cameras.push(cam);
    }
    Ok(scene)
}

/// Resident memory figures from `/proc/self/status` (KiB): (`VmRSS`, `VmHWM`).
pub fn memory_kib() -> (Option<u64>, Option<u64>) {
    let Ok(s) = std::fs::read_to_string("/proc/self/status") else {
        return (None, None);
    };
    let field = |name: &str| {
        s.lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
    };
    (field("VmRSS:"), field("VmHWM:"))
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    percentile(&s, 0.5)
}

/// Everything a bench needs before the timed loop: scene, models, frames of every view.
pub struct Prepared {
    /// The scene (one camera per view).
    pub scene: Scene,
    /// The models (built-in generator, trained).
    pub model: crate::model::ActionModel,
    /// Frames, `frames[t][v]`.
    pub frames: Vec<Vec<ImageRgb8>>,
    /// Rendering geometry.
    pub geometry: RenderArm,
}

/// Trains the models and renders `n_frames` frames of a synthetic sequence in every view.
pub fn prepare(opts: &BenchOptions, n_frames: usize) -> Result<Prepared> {
    let scene = bench_scene(opts.width, opts.height, opts.views)?;
    let (model, _) = train_generator_model(&scene, &ACTIONS, 2, opts.states.max(2), opts.seed)?;
    let lengths = [model.arm_lengths.upper_arm, model.arm_lengths.forearm_hand];
    let geometry = render_arm(&scene, lengths);
    let mut poses = Vec::new();
    let mut round = 0u64;
    while poses.len() < n_frames.max(1) {
        let targets = random_targets(&scene, &ACTIONS, opts.seed.wrapping_add(round));
        let seq = sequence(
            &scene,
            MotionSource::Generator,
            &targets,
            30.0,
            opts.seed.wrapping_add(round),
        )?;
        poses.extend(seq.truth.rows.iter().map(|r| r.pose));
        round += 1;
    }
    poses.truncate(n_frames.max(1));
    let synth: SceneSynth = scene_synth(&scene, lengths);
    let cams: Vec<_> = scene.cameras.iter().map(render_camera).collect();
    let frames = poses
        .par_iter()
        .enumerate()
        .map_init(
            || vec![actrack_render::synth::SynthCache::default(); cams.len()],
            |caches, (i, p)| {
                cams.iter()
                    .zip(caches.iter_mut())
                    .map(|(c, cache)| {
                        synth
                            .render_frame(cache, c, p, opts.seed, i as u64)
                            .map_err(|e| Error::Config(format!("bench: rendering a frame: {e}")))
                    })
                    .collect::<Result<Vec<_>>>()
            },
        )
        .collect::<Result<Vec<_>>>()?;
    Ok(Prepared {
        scene,
        model,
        frames,
        geometry,
    })
}

/// Builds the scorer for `device`; the note says what happened when `Auto` fell back.
pub fn make_scorer(
    device: Device,
    likelihood: LikelihoodModel,
) -> Result<(Scorer, &'static str, Option<String>)> {
    match device {
        Device::Cpu => Ok((Scorer::Cpu(likelihood), "cpu", None)),
        #[cfg(feature = "gpu")]
        Device::Gpu | Device::Auto => {
            match actrack_render::gpu::GpuLikelihood::new(
                likelihood.cameras().to_vec(),
                likelihood.geometry().clone(),
                likelihood.gamma(),
            ) {
                // A software adapter (lavapipe) is slower than the CPU likelihood.
                Ok(g) if device == Device::Auto && g.is_software() => Ok((
                    Scorer::Cpu(likelihood),
                    "cpu",
                    Some(format!(
                        "only a software GPU ({}); using the CPU",
                        g.adapter_name()
                    )),
                )),
                Ok(g) => Ok((Scorer::Gpu(Box::new(g)), "gpu", None)),
                Err(e) if device == Device::Auto => Ok((
                    Scorer::Cpu(likelihood),
                    "cpu",
                    Some(format!("no usable GPU ({e}); using the CPU")),
                )),
                Err(e) => Err(Error::Config(format!("--device gpu: {e}"))),
            }
        }
        #[cfg(not(feature = "gpu"))]
        Device::Gpu => Err(Error::Config(
            "--device gpu: this build has no GPU support (build with `--features gpu`)".into(),
        )),
        #[cfg(not(feature = "gpu"))]
        Device::Auto => Ok((
            Scorer::Cpu(likelihood),
            "cpu",
            Some("this build has no GPU support (feature `gpu`); using the CPU".into()),
        )),
    }
}

/// Stage times of one frame, ms: edge image, resample, propagate + sample, likelihood,
/// weights + estimates; and the total.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameTimes {
    /// The five stages in [`BenchReport::shares`] order.
    pub stages: [f64; 5],
    /// Edge images + tracker step, ms.
    pub total: f64,
}

/// A tracker with its observation model and edge workspaces, ready to be stepped on frames
/// (what `bench` and the criterion bench `realtime` time).
pub struct Runner {
    scene: Scene,
    geometry: RenderArm,
    scorer: Scorer,
    tracker: Tracker,
    params: Vec<actrack_render::EdgeParams>,
    workspaces: Vec<EdgeWorkspace>,
    edges: Vec<EdgeImage>,
    /// The next frame's edge images while an overlapped step runs.
    next_edges: Vec<EdgeImage>,
    /// Whether `edges` holds the edge images of the frame the next overlapped step tracks.
    primed: bool,
    world: Mutex<Vec<[f64; 9]>>,
    /// `cpu` or `gpu`.
    pub device: &'static str,
    /// A note on the device choice, if any.
    pub device_note: Option<String>,
}

impl Runner {
    /// Builds the tracker for `prep` with the options' particles, contour, device and seed.
    pub fn new(prep: &Prepared, opts: &BenchOptions) -> Result<Self> {
        let cams: Vec<_> = prep.scene.cameras.iter().map(render_camera).collect();
        let contour = opts.contour;
        let likelihood = LikelihoodModel::new(cams, prep.geometry.clone(), GAMMA, contour)
            .map_err(|e| Error::Config(format!("observation model: {e}")))?;
        let (scorer, device, device_note) =
            if contour == ContourMethod::Raster && opts.device != Device::Cpu {
                // The GPU kernel scores analytic contours only.
                let note = "the GPU scores analytic contours only; raster runs on the CPU";
                if opts.device == Device::Gpu {
                    return Err(Error::Config(format!("--device gpu: {note}")));
                }
                (Scorer::Cpu(likelihood), "cpu", Some(note.to_string()))
            } else {
                make_scorer(opts.device, likelihood)?
            };
        let (centre, half) = prep.scene.theta_region();
        let config = TrackerConfig::builder(TableRegion::new(centre, half))
            .particles(opts.particles)
            .seed(opts.seed)
            .build()
            .map_err(|e| Error::Config(format!("tracker: {e}")))?;
        let names: Vec<String> = prep.model.actions.iter().map(|a| a.name.clone()).collect();
        let tracker = Tracker::new(prep.model.actions.iter().map(|a| &a.phmm), names, config)
            .map_err(|e| Error::Model {
                context: "building the tracker".into(),
                message: e.to_string(),
            })?;
        let params = prep
            .scene
            .cameras
            .iter()
            .map(|c| edge_params(c.width))
            .collect();
        Ok(Self {
            scene: prep.scene.clone(),
            geometry: prep.geometry.clone(),
            scorer,
            tracker,
            params,
            workspaces: prep
                .scene
                .cameras
                .iter()
                .map(|_| EdgeWorkspace::new())
                .collect(),
            edges: Vec::with_capacity(prep.scene.cameras.len()),
            next_edges: Vec::with_capacity(prep.scene.cameras.len()),
            primed: false,
            world: Mutex::new(Vec::with_capacity(opts.particles)),
            device,
            device_note,
        })
    }

    /// One frame (one image per view): edge images, then the tracker step; the stage times.
    pub fn step(&mut self, views: &[ImageRgb8]) -> Result<FrameTimes> {
        let t0 = Instant::now();
        // The frame is tracked now: an overlapped step must not track it a second time.
        self.primed = false;
        compute_edges(views, &self.params, &mut self.workspaces, &mut self.edges)?;
        let edge_ms = t0.elapsed().as_secs_f64() * 1e3;
        let stages = filter_step(
            &mut self.tracker,
            &self.scene,
            &self.geometry,
            &self.scorer,
            &self.edges,
            &self.world,
        );
        Ok(FrameTimes {
            stages: [edge_ms, stages[0], stages[1], stages[2], stages[3]],
            total: t0.elapsed().as_secs_f64() * 1e3,
        })
    }

    /// Computes the edge images of the first frame of an overlapped run (see
    /// [`Runner::step_overlapped`]).
    pub fn prime(&mut self, views: &[ImageRgb8]) -> Result<()> {
        compute_edges(views, &self.params, &mut self.workspaces, &mut self.edges)?;
        self.primed = true;
        Ok(())
    }

    /// One frame of a video whose frames are known ahead (a file, a stream being caught up):
    /// the tracker step on the edge images computed during the previous call (or by
    /// [`Runner::prime`]) runs alongside the edge images of `next` (`rayon::join`, so the two
    /// share the pool's threads). On one thread this is the serial order; with more, the edge
    /// image's and the filter's serial parts overlap. The result is bit-identical to
    /// [`Runner::step`]'s; the edge-image stage time is that of `next`.
    pub fn step_overlapped(&mut self, next: Option<&[ImageRgb8]>) -> Result<FrameTimes> {
        if !self.primed {
            return Err(Error::Config(
                "bench: step_overlapped before prime (no edge images for this frame)".into(),
            ));
        }
        let Self {
            scene,
            geometry,
            scorer,
            tracker,
            params,
            workspaces,
            edges,
            next_edges,
            world,
            primed,
            ..
        } = self;
        let t0 = Instant::now();
        let (edge, stages) = rayon::join(
            || -> Result<f64> {
                let Some(views) = next else { return Ok(0.0) };
                let t = Instant::now();
                compute_edges(views, params, workspaces, next_edges)?;
                Ok(t.elapsed().as_secs_f64() * 1e3)
            },
            || filter_step(tracker, scene, geometry, scorer, edges, world),
        );
        let total = t0.elapsed().as_secs_f64() * 1e3;
        let edge_ms = edge.inspect_err(|_| *primed = false)?;
        std::mem::swap(edges, next_edges);
        *primed = next.is_some();
        Ok(FrameTimes {
            stages: [edge_ms, stages[0], stages[1], stages[2], stages[3]],
            total,
        })
    }
}

/// The edge image of every view into `out` (buffers reused).
fn compute_edges(
    views: &[ImageRgb8],
    params: &[actrack_render::EdgeParams],
    workspaces: &mut [EdgeWorkspace],
    out: &mut Vec<EdgeImage>,
) -> Result<()> {
    for (v, img) in views.iter().enumerate().take(workspaces.len()) {
        let view = ImageView::rgb8(&img.data, img.width, img.height)
            .map_err(|e| Error::Config(format!("bench: {e}")))?;
        if out.len() <= v {
            out.push(EdgeImage::default());
        }
        workspaces[v]
            .compute_into(view, &params[v], &mut out[v])
            .map_err(|e| Error::Config(format!("bench: {e}")))?;
    }
    Ok(())
}

/// One tracker step on `edges` with timing marks: resample, propagate + sample, likelihood,
/// estimates (ms).
fn filter_step(
    tracker: &mut Tracker,
    scene: &Scene,
    geometry: &RenderArm,
    scorer: &Scorer,
    edges: &[EdgeImage],
    world: &Mutex<Vec<[f64; 9]>>,
) -> [f64; 4] {
    let base = Instant::now();
    let obs = TimedObservation {
        scene,
        geometry,
        scorer,
        edges,
        world,
        base,
        first_correct: AtomicU64::new(u64::MAX),
        ll_start: AtomicU64::new(0),
        ll_end: AtomicU64::new(0),
    };
    let est = tracker.step(&obs);
    std::hint::black_box(&est);
    let end = since(base);
    let ms = |ns: u64| ns as f64 * 1e-6;
    let (ls, le) = (
        obs.ll_start.load(Ordering::Relaxed),
        obs.ll_end.load(Ordering::Relaxed),
    );
    let fc = obs.first_correct.load(Ordering::Relaxed);
    let fc = if fc == u64::MAX { ls } else { fc.min(ls) };
    [
        ms(fc),
        ms(ls.saturating_sub(fc)),
        ms(le.saturating_sub(ls)),
        ms(end.saturating_sub(le)),
    ]
}

/// Runs the bench: prepares, warms up, then times `opts.frames` frames.
pub fn run_bench(opts: &BenchOptions) -> Result<BenchReport> {
    if opts.particles == 0 || opts.frames == 0 || opts.threads == 0 {
        return Err(Error::Config(
            "bench: --particles, --frames and --threads must be ≥ 1".into(),
        ));
    }
    let setup = Instant::now();
    let prep = prepare(opts, opts.warmup + opts.frames)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| Error::Config(format!("cannot set up {} threads: {e}", opts.threads)))?;
    let mut runner = Runner::new(&prep, opts)?;
    let setup_seconds = setup.elapsed().as_secs_f64();
    let mut per_frame = Vec::with_capacity(opts.frames);
    let mut st: [Vec<f64>; 5] = Default::default();
    let mut rss_after_warmup = None;
    pool.install(|| -> Result<()> {
        if opts.overlap {
            runner.prime(&prep.frames[0])?;
        }
        for (t, views) in prep.frames.iter().enumerate() {
            if t == opts.warmup {
                rss_after_warmup = memory_kib().0;
            }
            let ft = if opts.overlap {
                runner.step_overlapped(prep.frames.get(t + 1).map(Vec::as_slice))?
            } else {
                runner.step(views)?
            };
            if t >= opts.warmup {
                per_frame.push(ft.total);
                for (s, v) in st.iter_mut().zip(ft.stages) {
                    s.push(v);
                }
            }
        }
        Ok(())
    })?;
    let mut sorted = per_frame.clone();
    sorted.sort_by(f64::total_cmp);
    let med = percentile(&sorted, 0.5);
    let (rss_end, hwm) = memory_kib();
    Ok(BenchReport {
        particles: opts.particles,
        threads: opts.threads,
        overlap: opts.overlap,
        width: opts.width,
        height: opts.height,
        views: opts.views,
        contour: match opts.contour {
            ContourMethod::Raster => "raster",
            ContourMethod::Analytic => "analytic",
        }
        .into(),
        device: runner.device.into(),
        device_note: runner.device_note.clone(),
        frames: per_frame.len(),
        median_ms: med,
        p95_ms: percentile(&sorted, 0.95),
        mean_ms: per_frame.iter().sum::<f64>() / per_frame.len().max(1) as f64,
        fps: if med > 0.0 { 1e3 / med } else { f64::INFINITY },
        stages_ms: StageMedians {
            edge_image: median(&st[0]),
            resample: median(&st[1]),
            propagate_sample: median(&st[2]),
            likelihood: median(&st[3]),
            estimates: median(&st[4]),
        },
        peak_rss_kib: hwm,
        rss_kib_after_warmup: rss_after_warmup,
        rss_kib_end: rss_end,
        setup_seconds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::float_cmp)] // exact order statistics of exact values
    fn percentiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.5), 50.0);
        assert_eq!(percentile(&v, 0.95), 95.0);
        assert_eq!(percentile(&[3.0], 0.95), 3.0);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
    }

    #[test]
    fn scene_views_and_memory() {
        let s = bench_scene(160, 120, 3).unwrap();
        assert_eq!(s.cameras.len(), 3);
        assert_ne!(s.cameras[1].t_cw, s.cameras[0].t_cw);
        if cfg!(target_os = "linux") {
            let (rss, hwm) = memory_kib();
            assert!(rss.unwrap() > 0 && hwm.unwrap() >= rss.unwrap());
        }
    }
}
