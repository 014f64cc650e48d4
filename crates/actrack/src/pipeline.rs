//! The `track` pipeline (SPEC §3.8): frames from a video → [`Session`] → per-frame estimates →
//! MCAP, CSV and overlay images.
//!
//! `track` reads one video, filmed by the scene's only camera; several synchronised views go
//! through [`Session::step`] with one image per camera.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

pub use actrack_pf::centred_median;
use actrack_render::{
    ArmGeometry as RenderArm, Camera as RenderCamera, ContourMethod, contour_points,
};
use image::RgbImage;

use crate::config::TrackConfig;
use crate::error::{Error, Result};
use crate::frames::{Frame, FrameSource};
use crate::mcap_out::{EstimateMsg, FrameRecord, TrackWriter};
use crate::model::ActionModel;
use crate::scene::Scene;
use crate::session::{FrameResult, PoseReport, Session};
use crate::track_csv::{TrajRow, Trajectory, TrajectoryWriter};

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
    /// Keep every row in [`TrackSummary::trajectory`] (memory grows with the video; the CSV is
    /// written row by row either way).
    pub keep_trajectory: bool,
}

/// What [`track`] did.
#[derive(Clone, Debug)]
pub struct TrackSummary {
    /// Frames tracked.
    pub frames: usize,
    /// Wall-clock seconds of the tracking loop (decoding included).
    pub seconds: f64,
    /// Seconds spent in the session's steps (edge images, filter, background), decoding and
    /// output excluded.
    pub filter_seconds: f64,
    /// Stopped by the interrupt flag before the end of the input.
    pub interrupted: bool,
    /// Frames skipped as bad (index, reason).
    pub skipped: Vec<(usize, String)>,
    /// The input broke off (a truncated stream, a failing decoder): why and where. The outputs
    /// are finished and hold every frame tracked before.
    pub stopped: Option<String>,
    /// The trajectory (tracker-output rows) when [`TrackOutputs::keep_trajectory`] asked for
    /// it, else empty.
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

/// A tracked frame on its way to the outputs.
struct Tracked {
    frame: Frame,
    r: FrameResult,
    /// The θ particle cloud (action, world point), when the MCAP is written.
    particles: Vec<(usize, [f64; 3])>,
}

/// Where [`track`] writes each frame: MCAP, trajectory, overlays.
struct Sink<'a> {
    scene: &'a Scene,
    names: &'a [String],
    cam0: RenderCamera,
    geometry: RenderArm,
    contour: ContourMethod,
    outputs: &'a TrackOutputs,
    writer: Option<TrackWriter>,
    csv: Option<TrajectoryWriter>,
    traj: Trajectory,
    frames: usize,
}

impl Sink<'_> {
    fn write(&mut self, t: &Tracked) -> Result<()> {
        let (frame, r, outputs) = (&t.frame, &t.r, self.outputs);
        let row = track_row(frame.index, frame.time, self.names, r);
        if let Some(csv) = self.csv.as_mut() {
            csv.push(&row)?;
        }
        if outputs.keep_trajectory {
            self.traj.rows.push(row);
        }
        self.frames += 1;
        let need_contour =
            outputs.overlay.is_some() || (self.writer.is_some() && outputs.mcap_images);
        let contour = if need_contour {
            contour_points(&self.cam0, &self.geometry, &r.best_world, self.contour)
        } else {
            Vec::new()
        };
        let dot = self.scene.cameras[0]
            .project(&r.theta_world)
            .map(|(u, v)| ([u, v], entropy_colour(r.estimate.theta_histogram_entropy)));
        if let Some(w) = self.writer.as_mut() {
            let e = &r.estimate;
            let msg = EstimateMsg {
                frame_id: "actor".into(),
                frame: frame.index,
                time: frame.time,
                actions: self.names.to_vec(),
                action_posterior: e.action_posterior.clone(),
                map_action: self.names.get(e.map_action).cloned().unwrap_or_default(),
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
                particles: &t.particles,
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
        Ok(())
    }
}

impl TrackOutputs {
    /// Checks the output paths before any work: their directories exist, no two outputs are
    /// the same file, none is the input, and overlays are not written into the input
    /// directory (they would be read back as frames).
    pub fn check(&self, input: &Path) -> Result<()> {
        let files = [("-o", &self.mcap), ("--csv", &self.csv)];
        for (flag, p) in files {
            let Some(p) = p else { continue };
            let dir = p.parent().filter(|d| !d.as_os_str().is_empty());
            if let Some(d) = dir
                && !d.is_dir()
            {
                return Err(Error::invalid(
                    p,
                    format!("{flag}: the directory {} does not exist", d.display()),
                ));
            }
            if p.is_dir() {
                return Err(Error::invalid(p, format!("{flag}: is a directory")));
            }
            if same_file(p, input) {
                return Err(Error::invalid(
                    p,
                    format!("{flag}: is the input; it would be overwritten"),
                ));
            }
        }
        if let (Some(a), Some(b)) = (&self.mcap, &self.csv)
            && same_file(a, b)
        {
            return Err(Error::invalid(
                a,
                "-o and --csv name the same file: the CSV would overwrite the MCAP",
            ));
        }
        if let Some(o) = &self.overlay
            && input.is_dir()
        {
            let (oc, ic) = (absolute(o), absolute(input));
            if oc.starts_with(&ic) {
                return Err(Error::invalid(
                    o,
                    format!(
                        "--overlay: inside the input directory {}; the overlays would be read \
                         back as frames",
                        input.display()
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// `p` made absolute and canonical as far as it exists (the rest appended as written).
fn absolute(p: &Path) -> PathBuf {
    let p = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut existing = p.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(c) = existing.canonicalize() {
            let mut out = c;
            for r in rest.iter().rev() {
                out.push(r);
            }
            return out;
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                existing = parent;
            }
            _ => return p,
        }
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    absolute(a) == absolute(b)
}

/// Tracks every frame of `source` with `config`, writing the requested outputs (each carries
/// the configuration). `stop` is polled between frames: when set, the outputs are finished with
/// the frames done so far. `progress` is called after each frame written with (frames written,
/// frames in total when known). With a centred median of window 2h + 1, each frame is written
/// once h more frames have been tracked (the last h at the end, or when stopped).
pub fn track(
    model: &ActionModel,
    scene: &Scene,
    source: &mut FrameSource,
    config: &TrackConfig,
    outputs: &TrackOutputs,
    stop: &AtomicBool,
    progress: &mut dyn FnMut(usize, Option<usize>),
) -> Result<TrackSummary> {
    if scene.cameras.len() != 1 {
        return Err(Error::Config(format!(
            "track reads one video, but the scene has {} cameras: give a scene with the one \
             camera that filmed it",
            scene.cameras.len()
        )));
    }
    outputs.check(source.name())?;
    let mut session = Session::new(model, scene, config)?;
    let names = session.action_names().to_vec();
    if let Some(d) = &outputs.overlay {
        std::fs::create_dir_all(d).map_err(|e| Error::write(d, e))?;
    }
    let writer = match &outputs.mcap {
        Some(p) => {
            let mut w = TrackWriter::create(p, scene, outputs.mcap_images)?;
            w.write_config(config)?;
            Some(w)
        }
        None => None,
    };
    let mut sink = Sink {
        scene,
        names: &names,
        cam0: scene.cameras[0].model.clone(),
        geometry: session.geometry().clone(),
        contour: config.observation.contour.into(),
        outputs,
        writer,
        csv: match &outputs.csv {
            Some(p) => Some(TrajectoryWriter::create(p, &config.to_comment(), &names)?),
            None => None,
        },
        traj: Trajectory {
            actions: names.clone(),
            rows: Vec::new(),
        },
        frames: 0,
    };
    let mut report = PoseReport::new(&config.output)?;
    let total = source.len_hint();
    let start = Instant::now();
    let mut filter_seconds = 0.0;
    let mut interrupted = false;
    let mut stopped = None;
    let mut tracked = 0usize;
    let mut cloud = Vec::new();
    loop {
        if stop.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let frame = match source.next_frame() {
            Ok(Some(f)) => f,
            Ok(None) => break,
            // Keep the work done: finish the outputs with the frames tracked so far.
            Err(e) if tracked > 0 => {
                stopped = Some(e.to_string());
                break;
            }
            Err(e) => return Err(e),
        };
        let r = session.step_rgb(frame.index, &[&frame.image])?;
        tracked += 1;
        filter_seconds += session.last_times().total * 1e-3;
        let shown = config.output.mcap_particles;
        let particles = if sink.writer.is_some() && shown > 0 {
            session.tracker().cloud_into(&mut cloud);
            // A systematic sample: the cloud is grouped by action, so each action keeps its
            // share.
            let step = (cloud.len() as f64 / shown as f64).max(1.0);
            (0..cloud.len().min(shown))
                .map(|i| &cloud[((i as f64 + 0.5) * step) as usize])
                .map(|c| (c.action, scene.theta_to_world(c.theta).into()))
                .collect()
        } else {
            Vec::new()
        };
        let (best, causal) = (r.estimate.best_pose, r.estimate.smoothed_pose);
        let t = Tracked {
            frame,
            r,
            particles,
        };
        if let Some((mut t, pose)) = report.push(t, best, causal) {
            t.r.smoothed_world = scene.pose_to_world(&pose);
            sink.write(&t)?;
            progress(sink.frames, total);
        }
    }
    for (mut t, pose) in report.finish() {
        t.r.smoothed_world = scene.pose_to_world(&pose);
        sink.write(&t)?;
        progress(sink.frames, total);
    }
    let Sink {
        writer,
        csv,
        traj,
        frames,
        ..
    } = sink;
    if let Some(w) = writer {
        w.finish()?;
    }
    if let Some(csv) = csv {
        csv.finish()?;
    }
    Ok(TrackSummary {
        frames,
        seconds: start.elapsed().as_secs_f64(),
        filter_seconds,
        interrupted,
        skipped: source.skipped().to_vec(),
        stopped,
        trajectory: traj,
    })
}
