//! The library side of `actrack-cli bench`: tracks a synthetic sequence (built-in motion
//! generator, generator-trained models, rendered frames with known truth) with the same
//! [`Session`] and [`TrackConfig`] as `track`, and times every frame and every stage of SPEC §3.8,
//! so users can check the real-time budget on their own machine.
//!
//! The stages are the session's own marks ([`crate::session::StageTimes`]): edge images (with
//! normalisation), the foreground gate, resample | propagate + sample | render + contour + likelihood |
//! weights + estimates, and the gate's background update. Peak memory is the process's `VmHWM`
//! from `/proc/self/status` (Linux).

use std::time::Instant;

use actrack_render::synth::SceneSynth;
use actrack_render::{ImageRgb8, ImageView};
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::config::TrackConfig;
use crate::demo::train_generator_model;
use crate::error::{Error, Result};
use crate::motion::ACTIONS;
use crate::scene::{Scene, default_scene, look_at};
use crate::session::Session;
use crate::synth::{MotionSource, random_targets, scene_synth, sequence};

/// Options of a bench run.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// The tracking configuration timed (particles, contour, device, …).
    pub config: TrackConfig,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// Synchronised views (cameras around the table).
    pub views: usize,
    /// Timed frames (after the warm-up).
    pub frames: usize,
    /// Untimed frames first (caches, allocations, thread pool).
    pub warmup: usize,
    /// Worker threads (a local rayon pool).
    pub threads: usize,
    /// Seed of the sequence and the models (the filter's is `config.filter.seed`).
    pub seed: u64,
    /// PHMM states per action of the generator-trained models.
    pub states: usize,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            config: TrackConfig::default(),
            width: 640,
            height: 480,
            views: 1,
            frames: 100,
            warmup: 5,
            threads: 1,
            seed: 7,
            states: 20,
        }
    }
}

/// Per-frame medians of the stages, milliseconds.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageMedians {
    /// Edge image G of every view (its region, normalisation).
    pub edge_image: f64,
    /// The foreground gate's mask and product with G.
    pub foreground: f64,
    /// Resampling (SPEC §3.6).
    pub resample: f64,
    /// Propagation and pose sampling + arm correction (§3.3, §3.4).
    pub propagate_sample: f64,
    /// Render + contour + likelihood of every particle in every view (§4).
    pub likelihood: f64,
    /// Weights and estimates (§3.5, §3.7).
    pub estimates: f64,
    /// The foreground gate's background update.
    pub background: f64,
}

/// What a bench run measured.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// Particles M.
    pub particles: usize,
    /// Worker threads.
    pub threads: usize,
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
    /// The median share of a view's pixels whose edges a frame computed
    /// (`observation.edge_region`; 1 for the whole frame).
    pub edge_region_share: f64,
    /// Peak resident memory of the process (`VmHWM`), KiB; `None` off Linux.
    pub peak_rss_kib: Option<u64>,
    /// Resident memory after the warm-up and at the end, KiB (memory must not grow with frames).
    pub rss_kib_after_warmup: Option<u64>,
    /// Resident memory at the end, KiB.
    pub rss_kib_end: Option<u64>,
    /// Seconds spent preparing (training the models, rendering the frames).
    pub setup_seconds: f64,
    /// The configuration timed.
    pub config: TrackConfig,
}

impl BenchReport {
    /// The share of each stage in the sum of the stage medians, percent, in display order.
    pub fn shares(&self) -> [(&'static str, f64, f64); 7] {
        let s = &self.stages_ms;
        let rows = [
            ("edge image", s.edge_image),
            ("foreground gate", s.foreground),
            ("resample", s.resample),
            ("propagate + sample", s.propagate_sample),
            ("render + contour + likelihood", s.likelihood),
            ("weights + estimates", s.estimates),
            ("background update", s.background),
        ];
        let total: f64 = rows.iter().map(|r| r.1).sum();
        rows.map(|(n, v)| (n, v, if total > 0.0 { 100.0 * v / total } else { 0.0 }))
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
        cam.set_pose((r_cw, t_cw));
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
}

/// Trains the models and renders `n_frames` frames of a synthetic sequence in every view.
pub fn prepare(opts: &BenchOptions, n_frames: usize) -> Result<Prepared> {
    let scene = bench_scene(opts.width, opts.height, opts.views)?;
    let (model, _) = train_generator_model(&scene, &ACTIONS, 2, opts.states.max(2), opts.seed)?;
    let lengths = [model.arm_lengths.upper_arm, model.arm_lengths.forearm_hand];
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
    let cams: Vec<_> = scene.cameras.iter().map(|c| c.model.clone()).collect();
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
    })
}

/// Runs the bench: prepares, warms up, then times `opts.frames` frames of one [`Session`].
pub fn run_bench(opts: &BenchOptions) -> Result<BenchReport> {
    if opts.frames == 0 || opts.threads == 0 || opts.states < 2 {
        return Err(Error::Config(format!(
            "bench: --frames and --threads must be ≥ 1 and --states ≥ 2, got {}, {} and {}",
            opts.frames, opts.threads, opts.states
        )));
    }
    opts.config.check()?;
    let setup = Instant::now();
    let prep = prepare(opts, opts.warmup + opts.frames)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads)
        .build()
        .map_err(|e| Error::Config(format!("cannot set up {} threads: {e}", opts.threads)))?;
    let mut session = Session::new(&prep.model, &prep.scene, &opts.config)?;
    let setup_seconds = setup.elapsed().as_secs_f64();
    let mut per_frame = Vec::with_capacity(opts.frames);
    let mut st: [Vec<f64>; 7] = Default::default();
    let mut shares = Vec::with_capacity(opts.frames * opts.views);
    let mut rss_after_warmup = None;
    pool.install(|| -> Result<()> {
        for (t, views) in prep.frames.iter().enumerate() {
            if t == opts.warmup {
                rss_after_warmup = memory_kib().0;
            }
            let images = views
                .iter()
                .map(|img| {
                    ImageView::rgb8(&img.data, img.width, img.height)
                        .map_err(|e| Error::Config(format!("bench: {e}")))
                })
                .collect::<Result<Vec<_>>>()?;
            let r = session.step(t, &images)?;
            std::hint::black_box(&r);
            if t >= opts.warmup {
                let times = session.last_times();
                per_frame.push(times.total);
                let stages = [
                    times.edges,
                    times.foreground,
                    times.resample,
                    times.propagate,
                    times.likelihood,
                    times.estimates,
                    times.background,
                ];
                for (s, v) in st.iter_mut().zip(stages) {
                    s.push(v);
                }
                for (v, g) in session.edges().iter().enumerate() {
                    let all = f64::from(g.width()) * f64::from(g.height());
                    shares.push(
                        session
                            .edge_region(v)
                            .map_or(1.0, |r| r.area() as f64 / all.max(1.0)),
                    );
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
        particles: opts.config.filter.particles,
        threads: opts.threads,
        width: opts.width,
        height: opts.height,
        views: opts.views,
        contour: match opts.config.observation.contour {
            crate::config::Contour::Raster => "raster",
            crate::config::Contour::Analytic => "analytic",
        }
        .into(),
        device: session.device().into(),
        device_note: session.device_note().map(str::to_string),
        frames: per_frame.len(),
        median_ms: med,
        p95_ms: percentile(&sorted, 0.95),
        mean_ms: per_frame.iter().sum::<f64>() / per_frame.len().max(1) as f64,
        fps: if med > 0.0 { 1e3 / med } else { f64::INFINITY },
        stages_ms: StageMedians {
            edge_image: median(&st[0]),
            foreground: median(&st[1]),
            resample: median(&st[2]),
            propagate_sample: median(&st[3]),
            likelihood: median(&st[4]),
            estimates: median(&st[5]),
            background: median(&st[6]),
        },
        edge_region_share: median(&shares),
        peak_rss_kib: hwm,
        rss_kib_after_warmup: rss_after_warmup,
        rss_kib_end: rss_end,
        setup_seconds,
        config: opts.config.clone(),
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
        assert_ne!(s.cameras[1].t_cw(), s.cameras[0].t_cw());
        if cfg!(target_os = "linux") {
            let (rss, hwm) = memory_kib();
            assert!(rss.unwrap() > 0 && hwm.unwrap() >= rss.unwrap());
        }
    }
}
