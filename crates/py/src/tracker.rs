//! `actrack.Tracker` (an [`actrack::Session`]: the action-space particle filter with the
//! configured observation model, frame by frame from numpy images) and `actrack.track_video`
//! (the `actrack-cli track` pipeline on a file: MCAP and CSV out). Both release the GIL while
//! they compute, and both take the same configuration keywords (read by `build_config`): a
//! `TrackConfig` from a file, a dict or a preset, then `set=["key=value", …]`, `n_particles`
//! and `seed`.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use actrack::frames::{FrameOptions, FrameSource};
use actrack::pipeline::{TrackOutputs, centred_median as pipeline_centred_median, track};
use actrack::render::{ContourMethod, EdgeImage, EdgeWorkspace, ImageView, LikelihoodModel};
use actrack::scene::{edge_params, render_arm};
use actrack::{FrameResult, Session, TrackConfig};
use image::RgbImage;
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

use crate::convert::{array_arg, matrix, vec_to_py};
use crate::errors::{actrack_error, value_error};
use crate::io::{PyActionModel, PyScene, to_python};

/// A Python value as a TOML literal for [`TrackConfig::set`]: bool, int, float (`inf`, `nan`
/// included), str, or a list / tuple of those. `key` names the configuration key in errors.
fn toml_literal(key: &str, value: &Bound<'_, PyAny>) -> PyResult<String> {
    if value.is_instance_of::<PyBool>() {
        return Ok(value.extract::<bool>()?.to_string());
    }
    if value.is_instance_of::<PyInt>() {
        return Ok(value.str()?.to_string());
    }
    if value.is_instance_of::<PyFloat>() {
        return Ok(float_literal(value.extract::<f64>()?));
    }
    if let Ok(s) = value.cast::<PyString>() {
        return Ok(string_literal(s.to_str()?));
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items = value
            .try_iter()?
            .map(|v| toml_literal(key, &v?))
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(format!("[{}]", items.join(", ")));
    }
    // numpy scalars and other numbers.
    if let Ok(i) = value.extract::<i64>() {
        return Ok(i.to_string());
    }
    if let Ok(x) = value.extract::<f64>() {
        return Ok(float_literal(x));
    }
    let kind = value
        .get_type()
        .name()
        .map_or_else(|_| "?".to_string(), |n| n.to_string());
    Err(value_error(format!(
        "invalid configuration: config key `{key}`: a {kind} is not a configuration value \
         (bool, int, float, str or a list of them)"
    )))
}

/// A float as TOML (`1.0`, `1e-5`, `inf`, `-inf`, `nan`).
fn float_literal(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else {
        format!("{x:?}")
    }
}

/// A TOML basic string.
fn string_literal(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if c.is_control() => {
                let _ = write!(out, "\\u{:04X}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// The `key=value` assignments of a (nested) configuration dict: `{"filter": {"particles": 800}}`
/// and `{"filter.particles": 800}` both give `filter.particles=800`.
fn dict_assignments(prefix: &str, dict: &Bound<'_, PyDict>, out: &mut Vec<String>) -> PyResult<()> {
    for (k, v) in dict.iter() {
        let name: String = k.extract().map_err(|_| {
            value_error(format!(
                "invalid configuration: the keys of a config dict must be strings, got {}",
                k.repr().map_or_else(|_| "?".into(), |r| r.to_string())
            ))
        })?;
        let key = if prefix.is_empty() {
            name
        } else {
            format!("{prefix}.{name}")
        };
        if let Ok(sub) = v.cast::<PyDict>() {
            dict_assignments(&key, sub, out)?;
        } else {
            let value = toml_literal(&key, &v)?;
            out.push(format!("{key}={value}"));
        }
    }
    Ok(())
}

/// The effective configuration of the keywords shared by `Tracker` and `track_video`, in the
/// order of `actrack-cli track`: the base (`config` a TOML file, or the preset `preset` —
/// `"default"` when not given — with the keys of `config` a dict over it), then each `set`
/// assignment, then `n_particles` (`filter.particles`) and `seed` (`filter.seed`). Every error
/// is an `ActrackError` (a `ValueError`) naming the offending key; a file that cannot be read is
/// an `ActrackOSError`.
pub(crate) fn build_config(
    config: Option<&Bound<'_, PyAny>>,
    preset: Option<&str>,
    set: Option<&Bound<'_, PyAny>>,
    n_particles: Option<&Bound<'_, PyAny>>,
    seed: Option<&Bound<'_, PyAny>>,
) -> PyResult<TrackConfig> {
    let base = |name: Option<&str>| {
        TrackConfig::preset(name.unwrap_or("default")).map_err(|e| actrack_error(&e))
    };
    let mut assignments = Vec::new();
    let mut cfg = match config {
        None => base(preset)?,
        Some(c) if c.is_none() => base(preset)?,
        Some(c) => {
            if let Ok(d) = c.cast::<PyDict>() {
                dict_assignments("", d, &mut assignments)?;
                base(preset)?
            } else {
                let path: PathBuf = c.extract().map_err(|_| {
                    value_error(
                        "config must be the path of a TOML file (str or os.PathLike) or a dict \
                         of configuration keys",
                    )
                })?;
                if preset.is_some() {
                    return Err(value_error(
                        "give config (a file) or preset, not both (a config dict goes over the \
                         preset)",
                    ));
                }
                TrackConfig::load(&path).map_err(|e| actrack_error(&e))?
            }
        }
    };
    if let Some(s) = set.filter(|s| !s.is_none()) {
        if let Ok(one) = s.cast::<PyString>() {
            assignments.push(one.to_str()?.to_string());
        } else {
            let items = s.try_iter().map_err(|_| {
                value_error(
                    "set must be a list of \"key=value\" strings, e.g. [\"filter.particles=800\"]",
                )
            })?;
            for item in items {
                let item = item?;
                let text: String = item.extract().map_err(|_| {
                    value_error(format!(
                        "set must be a list of \"key=value\" strings, got the item {}",
                        item.repr().map_or_else(|_| "?".into(), |r| r.to_string())
                    ))
                })?;
                assignments.push(text);
            }
        }
    }
    for (key, value) in [("filter.particles", n_particles), ("filter.seed", seed)] {
        if let Some(v) = value.filter(|v| !v.is_none()) {
            assignments.push(format!("{key}={}", toml_literal(key, v)?));
        }
    }
    for a in &assignments {
        cfg.set(a).map_err(|e| actrack_error(&e))?;
    }
    Ok(cfg)
}

/// An (H, W, 3) or (H, W) uint8 array as an RGB image.
fn rgb_image(frame: &Bound<'_, PyAny>) -> PyResult<RgbImage> {
    let arr: PyReadonlyArrayDyn<'_, u8> = frame.extract().map_err(|_| {
        value_error("a frame must be a uint8 numpy array of shape (H, W, 3) (RGB) or (H, W) (grey)")
    })?;
    let shape = arr.shape().to_vec();
    let view = arr.as_array();
    let (h, w) = match shape.as_slice() {
        [h, w, 3] | [h, w] => (*h, *w),
        _ => {
            return Err(value_error(format!(
                "a frame must have shape (H, W, 3) or (H, W), got {shape:?}"
            )));
        }
    };
    let data: Vec<u8> = if shape.len() == 3 {
        view.iter().copied().collect()
    } else {
        view.iter().flat_map(|&g| [g, g, g]).collect()
    };
    let (w32, h32) = (
        u32::try_from(w).map_err(|_| value_error("frame too wide"))?,
        u32::try_from(h).map_err(|_| value_error("frame too high"))?,
    );
    RgbImage::from_raw(w32, h32, data).ok_or_else(|| value_error("frame buffer size mismatch"))
}

/// One frame's estimate: the action posterior, θ (actor frame) with its uncertainty, the
/// histogram entropy, the effective sample size, and the best / smoothed arm pose (world).
#[pyclass(module = "actrack._actrack", name = "Estimate", frozen)]
pub struct PyEstimate {
    names: Vec<String>,
    r: FrameResult,
}

#[pymethods]
impl PyEstimate {
    /// 0-based frame index.
    #[getter]
    fn frame(&self) -> usize {
        self.r.estimate.frame
    }
    /// P(action | frames so far), as {name: probability}.
    #[getter]
    fn action_posterior<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (n, p) in self.names.iter().zip(&self.r.estimate.action_posterior) {
            d.set_item(n, p)?;
        }
        Ok(d)
    }
    /// The most probable action.
    #[getter]
    fn action(&self) -> String {
        self.names
            .get(self.r.estimate.map_action)
            .cloned()
            .unwrap_or_default()
    }
    /// θ̄ (actor frame, metres), shape (2,).
    #[getter]
    fn theta_mean<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_to_py(py, self.r.estimate.theta_mean.to_vec())
    }
    /// Per-component standard deviation of θ (metres), shape (2,).
    #[getter]
    fn theta_std<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_to_py(py, self.r.estimate.theta_std.to_vec())
    }
    /// θ̄ on the table in world coordinates, shape (3,).
    #[getter]
    fn theta_world<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_to_py(py, self.r.theta_world.as_slice().to_vec())
    }
    /// Entropy of the θ histogram over the table region, 0 (one cell) … 1 (uniform).
    #[getter]
    fn entropy(&self) -> f64 {
        self.r.estimate.theta_histogram_entropy
    }
    /// Effective sample size of this frame's weights.
    #[getter]
    fn ess(&self) -> f64 {
        self.r.estimate.ess
    }
    /// Weighted mean progress k/N in (0, 1].
    #[getter]
    fn progress(&self) -> f64 {
        self.r.estimate.progress
    }
    /// True when no particle had a usable likelihood (the estimate is the prediction only).
    #[getter]
    fn degenerate(&self) -> bool {
        self.r.estimate.degenerate
    }
    /// The best particle's pose (p, q, r) in world coordinates, shape (9,).
    #[getter]
    fn best_pose<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_to_py(py, self.r.best_world.to_vec())
    }
    /// The median-filtered best pose in world coordinates, shape (9,).
    #[getter]
    fn smoothed_pose<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_to_py(py, self.r.smoothed_world.to_vec())
    }
    fn __repr__(&self) -> String {
        let e = &self.r.estimate;
        format!(
            "Estimate(frame={}, action={:?}, theta_mean=[{:.3}, {:.3}], ess={:.1})",
            e.frame,
            self.action(),
            e.theta_mean[0],
            e.theta_mean[1],
            e.ess
        )
    }
}

/// The tracker of an action model in a scene (an `actrack::Session`), fed one frame at a time:
/// one (H, W, 3) uint8 RGB (or (H, W) grey) image for a scene with one camera, or a list with
/// one image per camera of the scene, in its order.
#[pyclass(module = "actrack._actrack", name = "Tracker")]
pub struct PyTracker {
    session: Session,
    names: Vec<String>,
    frames: usize,
}

impl PyTracker {
    fn images(frame: &Bound<'_, PyAny>) -> PyResult<Vec<RgbImage>> {
        if frame.is_instance_of::<PyList>() || frame.is_instance_of::<PyTuple>() {
            frame.try_iter()?.map(|f| rgb_image(&f?)).collect()
        } else {
            Ok(vec![rgb_image(frame)?])
        }
    }

    fn step_images(&mut self, py: Python<'_>, images: &[RgbImage]) -> PyResult<FrameResult> {
        let index = self.frames;
        let session = &mut self.session;
        let r = py
            .detach(|| {
                let refs: Vec<&RgbImage> = images.iter().collect();
                session.step_rgb(index, &refs)
            })
            .map_err(|e| actrack_error(&e))?;
        self.frames += 1;
        Ok(r)
    }
}

#[pymethods]
impl PyTracker {
    /// A tracker of `model` in `scene` with the configuration of `config` (a TOML file, or a
    /// dict of keys over `preset`), `preset` (`"default"` when not given, or `"paper"`), `set`
    /// (`["key=value", …]` overrides), `n_particles` (`filter.particles`) and `seed`
    /// (`filter.seed`), applied in that order. An invalid configuration raises `ActrackError`
    /// (a `ValueError`) naming the key.
    #[new]
    #[pyo3(signature = (model, scene, *, config=None, preset=None, n_particles=None, seed=None, set=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        model: PyRef<'_, PyActionModel>,
        scene: PyRef<'_, PyScene>,
        config: Option<Bound<'_, PyAny>>,
        preset: Option<String>,
        n_particles: Option<Bound<'_, PyAny>>,
        seed: Option<Bound<'_, PyAny>>,
        set: Option<Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let cfg = build_config(
            config.as_ref(),
            preset.as_deref(),
            set.as_ref(),
            n_particles.as_ref(),
            seed.as_ref(),
        )?;
        let (m, s) = (&model.inner, &scene.inner);
        let session = py
            .detach(|| Session::new(m, s, &cfg))
            .map_err(|e| actrack_error(&e))?;
        let names = session.action_names().to_vec();
        Ok(PyTracker {
            session,
            names,
            frames: 0,
        })
    }

    /// The action names, in model order (the columns of `action_posterior`).
    #[getter]
    fn actions(&self) -> Vec<String> {
        self.names.clone()
    }

    /// The effective configuration as TOML (every key; `Tracker(..., config=path)` with this
    /// text in a file, or `actrack-cli track --config`, reproduces the track).
    #[getter]
    fn config(&self) -> String {
        self.session.config().to_toml()
    }

    /// The effective configuration as a nested dict (what `config=` accepts).
    #[getter]
    fn config_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, self.session.config())
    }

    /// Frames stepped so far (the index of the next frame).
    #[getter]
    fn frames(&self) -> usize {
        self.frames
    }

    /// One filter step on a frame; returns its `Estimate`. Its `smoothed_pose` is the causal
    /// median of the best poses (known at once): of the last `output.median_window` frames when
    /// `output.median` is `"causal"`, else of the last 5. The centred median of the `default`
    /// preset needs the frames after each one: `track_video` applies it, or
    /// `centred_median(best poses, window)` on the poses of a finished sequence.
    fn step(&mut self, py: Python<'_>, frame: &Bound<'_, PyAny>) -> PyResult<PyEstimate> {
        let images = Self::images(frame)?;
        let r = self.step_images(py, &images)?;
        Ok(PyEstimate {
            names: self.names.clone(),
            r,
        })
    }

    /// Step through frames (an iterable of frames as `step` takes them, or a (T, H, W, 3)
    /// array) and return arrays over time: `action_posterior` (T, A), `theta_mean` /
    /// `theta_std` (T, 2), `entropy`, `ess` (T,), `best_pose` / `smoothed_pose` (T, 9, world;
    /// `smoothed_pose` causal, as in `step`), `action` (T,) int64 indices into `actions`.
    fn track<'py>(
        &mut self,
        py: Python<'py>,
        frames: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut results = Vec::new();
        for frame in frames.try_iter()? {
            let images = Self::images(&frame?)?;
            results.push(self.step_images(py, &images)?);
        }
        let t = results.len();
        let a = self.names.len();
        let out = PyDict::new(py);
        let post = Array2::from_shape_fn((t, a), |(i, k)| {
            results[i]
                .estimate
                .action_posterior
                .get(k)
                .copied()
                .unwrap_or(f64::NAN)
        });
        out.set_item("action_posterior", post.into_pyarray(py))?;
        let pair = |f: &dyn Fn(&FrameResult) -> [f64; 2]| {
            Array2::from_shape_fn((t, 2), |(i, k)| f(&results[i])[k])
        };
        out.set_item(
            "theta_mean",
            pair(&|r| r.estimate.theta_mean).into_pyarray(py),
        )?;
        out.set_item(
            "theta_std",
            pair(&|r| r.estimate.theta_std).into_pyarray(py),
        )?;
        let scalar =
            |f: &dyn Fn(&FrameResult) -> f64| -> Array1<f64> { results.iter().map(f).collect() };
        out.set_item(
            "entropy",
            scalar(&|r| r.estimate.theta_histogram_entropy).into_pyarray(py),
        )?;
        out.set_item("ess", scalar(&|r| r.estimate.ess).into_pyarray(py))?;
        let poses = |f: &dyn Fn(&FrameResult) -> [f64; 9]| {
            Array2::from_shape_fn((t, 9), |(i, k)| f(&results[i])[k])
        };
        out.set_item("best_pose", poses(&|r| r.best_world).into_pyarray(py))?;
        out.set_item(
            "smoothed_pose",
            poses(&|r| r.smoothed_world).into_pyarray(py),
        )?;
        let action: Array1<i64> = results
            .iter()
            .map(|r| r.estimate.map_action as i64)
            .collect();
        out.set_item("action", action.into_pyarray(py))?;
        Ok(out)
    }
}

/// Track a video file exactly like `actrack-cli track`: `source` is a directory of PNG/JPEG
/// frames, a `.y4m` file or any video ffmpeg reads. Writes the MCAP track (`mcap=`) and/or the
/// trajectory CSV (`csv=`), each with the effective configuration; returns a summary dict
/// (frames, seconds, filter_seconds, skipped, config: the configuration as TOML). The
/// configuration keywords are `Tracker`'s; the reported pose is `output.median`'s: the centred
/// median of the `default` preset delays each frame by half the window, which a file allows.
#[pyfunction]
#[pyo3(signature = (model, scene, source, *, mcap=None, csv=None, mcap_images=false, config=None, preset=None, n_particles=None, seed=None, set=None, fps=None))]
#[allow(clippy::too_many_arguments)]
pub fn track_video<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyActionModel>,
    scene: PyRef<'_, PyScene>,
    source: PathBuf,
    mcap: Option<PathBuf>,
    csv: Option<PathBuf>,
    mcap_images: bool,
    config: Option<Bound<'_, PyAny>>,
    preset: Option<String>,
    n_particles: Option<Bound<'_, PyAny>>,
    seed: Option<Bound<'_, PyAny>>,
    set: Option<Bound<'_, PyAny>>,
    fps: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let cfg = build_config(
        config.as_ref(),
        preset.as_deref(),
        set.as_ref(),
        n_particles.as_ref(),
        seed.as_ref(),
    )?;
    let outputs = TrackOutputs {
        mcap,
        mcap_images,
        csv,
        overlay: None,
        keep_trajectory: false,
    };
    let (m, s) = (&model.inner, &scene.inner);
    let summary = py
        .detach(|| {
            let mut src = FrameSource::open(
                &source,
                &FrameOptions {
                    fps,
                    ..FrameOptions::default()
                },
            )?;
            let stop = AtomicBool::new(false);
            track(m, s, &mut src, &cfg, &outputs, &stop, &mut |_, _| {})
        })
        .map_err(|e| actrack_error(&e))?;
    let out = PyDict::new(py);
    out.set_item("frames", summary.frames)?;
    out.set_item("seconds", summary.seconds)?;
    out.set_item("filter_seconds", summary.filter_seconds)?;
    out.set_item("skipped", summary.skipped.clone())?;
    out.set_item("config", cfg.to_toml())?;
    Ok(out)
}

/// The centred per-coordinate median of poses over time (SPEC §3.7's option, as `track_video`
/// applies it with `output.median = "centred"`): row t of the (T, 9) result is the median of rows
/// t − h … t + h of `poses` (T, 9), window = 2h + 1 odd, truncated at both ends.
#[pyfunction]
#[pyo3(signature = (poses, window=7))]
pub fn centred_median<'py>(
    py: Python<'py>,
    poses: &Bound<'_, PyAny>,
    window: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let p = matrix(poses, "poses", Some(9))?;
    if let Some(i) = (0..p.nrows()).find(|&i| p.row(i).iter().any(|v| !v.is_finite())) {
        return Err(value_error(format!(
            "poses row {i} is not finite: {:?}",
            p.row(i).iter().collect::<Vec<_>>()
        )));
    }
    let rows: Vec<[f64; 9]> = (0..p.nrows())
        .map(|i| std::array::from_fn(|c| p[(i, c)]))
        .collect();
    let out = pipeline_centred_median(&rows, window).map_err(|e| value_error(e.to_string()))?;
    Ok(Array2::from_shape_fn((out.len(), 9), |(i, c)| out[i][c]).into_pyarray(py))
}

/// The edge-distance image G of SPEC §4.1 for an (H, W, 3) or (H, W) uint8 frame, computed by
/// the tracker's edge stage: shape (H, W), float32 in [0, 1]. `sigma` (pixels, default 4 at
/// 640 px wide, scaled with the width), `tau` (default 0.2) and `binary` override SPEC's
/// defaults; `colour=True` takes the colour gradient, as the tracker does by default (the key
/// `observation.gradient = "colour"`), instead of SPEC's grey one.
#[pyfunction]
#[pyo3(signature = (frame, *, sigma=None, tau=None, binary=None, colour=false))]
pub fn edge_image<'py>(
    py: Python<'py>,
    frame: &Bound<'_, PyAny>,
    sigma: Option<f32>,
    tau: Option<f32>,
    binary: Option<bool>,
    colour: bool,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let img = rgb_image(frame)?;
    let mut params = edge_params(img.width());
    params.sigma = sigma.unwrap_or(params.sigma);
    params.tau = tau.unwrap_or(params.tau);
    params.binary = binary.unwrap_or(params.binary);
    params.colour = colour;
    let g = py
        .detach(|| {
            let view = ImageView::rgb8(img.as_raw(), img.width(), img.height())?;
            let mut ws = EdgeWorkspace::new();
            ws.compute(view, &params).cloned()
        })
        .map_err(|e| value_error(e.to_string()))?;
    let (w, h) = (g.width() as usize, g.height() as usize);
    let arr = Array2::from_shape_vec((h, w), g.data().to_vec())
        .map_err(|e| value_error(e.to_string()))?;
    Ok(arr.into_pyarray(py))
}

/// log P(I | pose) of SPEC §4 (raster contour likelihood, the default configuration's γ = 0.15
/// for one view) for world poses (N, 9) = (p, q, r),
/// given one edge image (H, W) per camera of the scene (a single array for one camera). The arm
/// is rendered with the scene's radii and `arm_lengths` = (upper arm, elbow → fingertip) in
/// metres, or the lengths of `model`, unless the scene fixes them. Returns shape (N,).
#[pyfunction]
#[pyo3(signature = (scene, edges, poses, *, model=None, arm_lengths=None))]
pub fn contour_likelihood<'py>(
    py: Python<'py>,
    scene: PyRef<'_, PyScene>,
    edges: &Bound<'_, PyAny>,
    poses: &Bound<'_, PyAny>,
    model: Option<PyRef<'_, PyActionModel>>,
    arm_lengths: Option<(f64, f64)>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let s = &scene.inner;
    let lengths = match (arm_lengths, &model) {
        (Some((a, b)), _) => [a, b],
        (None, Some(m)) => [
            m.inner.arm_lengths.upper_arm,
            m.inner.arm_lengths.forearm_hand,
        ],
        (None, None) => match (s.arm.upper_arm_length, s.arm.lower_arm_length) {
            (Some(a), Some(b)) => [a, b],
            _ => {
                return Err(value_error(
                    "the arm lengths are unknown: pass model=<ActionModel> or arm_lengths=(L1, L2)",
                ));
            }
        },
    };
    let maps: Vec<Bound<'_, PyAny>> = if edges.is_instance_of::<pyo3::types::PyList>()
        || edges.is_instance_of::<pyo3::types::PyTuple>()
    {
        edges.try_iter()?.collect::<PyResult<_>>()?
    } else {
        vec![edges.clone()]
    };
    let mut images = Vec::with_capacity(maps.len());
    for (v, m) in maps.iter().enumerate() {
        let a = array_arg(m, "edges")?;
        let view = a.as_array();
        let [h, w] = view.shape() else {
            return Err(value_error(format!(
                "edges[{v}] must be a 2-D (H, W) array, got shape {:?}",
                view.shape()
            )));
        };
        let data: Vec<f32> = view.iter().map(|&x| x as f32).collect();
        images.push(
            EdgeImage::from_vec(*w as u32, *h as u32, data)
                .map_err(|e| value_error(format!("edges[{v}]: {e}")))?,
        );
    }
    let p = matrix(poses, "poses", Some(9))?;
    let poses: Vec<[f64; 9]> = (0..p.nrows())
        .map(|i| std::array::from_fn(|c| p[(i, c)]))
        .collect();
    let cameras = s.cameras.iter().map(|c| c.model.clone()).collect();
    let lik = LikelihoodModel::new(
        cameras,
        render_arm(s, lengths),
        TrackConfig::default().observation.gamma,
        ContourMethod::Raster,
    )
    .map_err(|e| value_error(e.to_string()))?;
    let out = py
        .detach(|| {
            let mut out = vec![0.0; poses.len()];
            lik.log_likelihood_batch(&images, &poses, &mut out)
                .map(|()| out)
        })
        .map_err(|e| value_error(e.to_string()))?;
    Ok(vec_to_py(py, out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_read_back_through_set() {
        for x in [0.15, 1e-5, 3.0, 1e20, 0.1 + 0.2] {
            let mut c = TrackConfig::default();
            c.set(&format!("observation.gamma={}", float_literal(x)))
                .unwrap();
            assert_eq!(c.observation.gamma.to_bits(), x.to_bits(), "{x}");
        }
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let e = TrackConfig::default()
                .set(&format!("observation.gamma={}", float_literal(x)))
                .unwrap_err()
                .to_string();
            assert!(e.contains("observation.gamma") && e.contains("got"), "{e}");
        }
        let mut c = TrackConfig::default();
        c.set(&format!("output.median={}", string_literal("causal")))
            .unwrap();
        assert_eq!(c.output.median, actrack::config::Median::Causal);
        assert_eq!(string_literal("a\"b\\c\n"), "\"a\\\"b\\\\c\\u000A\"");
    }
}
