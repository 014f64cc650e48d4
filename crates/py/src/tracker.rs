//! `actrack.Tracker` (the action-space particle filter with the scene's contour likelihood, frame
//! by frame from numpy images) and `actrack.track_video` (the `actrack-cli track` pipeline on a
//! file: MCAP and CSV out). Both release the GIL while they compute.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use actrack::frames::{FrameOptions, FrameSource};
use actrack::pipeline::{
    ContourMethod, FrameResult, GAMMA, Pipeline, TrackOptions, TrackOutputs, edge_params,
    render_arm, render_camera, track,
};
use actrack_render::{EdgeImage, EdgeWorkspace, ImageView, LikelihoodModel};
use image::RgbImage;
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{array_arg, matrix, vec_to_py};
use crate::errors::{actrack_error, value_error};
use crate::io::{PyActionModel, PyScene};

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

/// The action-space particle filter of an action model in a scene, scoring particles by the
/// contour likelihood of each frame (one (H, W, 3) uint8 RGB image for the scene's first camera,
/// or a list with one image per camera).
#[pyclass(module = "actrack._actrack", name = "Tracker")]
pub struct PyTracker {
    pipeline: Pipeline,
    names: Vec<String>,
    frames: usize,
}

impl PyTracker {
    fn images(frame: &Bound<'_, PyAny>) -> PyResult<Vec<RgbImage>> {
        if frame.is_instance_of::<pyo3::types::PyList>()
            || frame.is_instance_of::<pyo3::types::PyTuple>()
        {
            frame.try_iter()?.map(|f| rgb_image(&f?)).collect()
        } else {
            Ok(vec![rgb_image(frame)?])
        }
    }

    fn step_images(&mut self, py: Python<'_>, images: &[RgbImage]) -> PyResult<FrameResult> {
        let index = self.frames;
        let pipeline = &mut self.pipeline;
        let r = py
            .detach(|| {
                let refs: Vec<&RgbImage> = images.iter().collect();
                pipeline.step(index, &refs)
            })
            .map_err(|e| actrack_error(&e))?;
        self.frames += 1;
        Ok(r)
    }
}

#[pymethods]
impl PyTracker {
    #[new]
    #[pyo3(signature = (model, scene, *, n_particles=400, seed=0, height_scale=None, fingertip_floor=None, action_floor=None))]
    fn new(
        model: PyRef<'_, PyActionModel>,
        scene: PyRef<'_, PyScene>,
        n_particles: usize,
        seed: u64,
        height_scale: Option<f64>,
        fingertip_floor: Option<f64>,
        action_floor: Option<f64>,
    ) -> PyResult<Self> {
        let opts = TrackOptions {
            particles: n_particles,
            seed,
            height_scale,
            fingertip_floor,
            action_floor,
            ..TrackOptions::default()
        };
        let pipeline =
            Pipeline::new(&model.inner, &scene.inner, &opts).map_err(|e| actrack_error(&e))?;
        let names = pipeline.action_names().to_vec();
        Ok(PyTracker {
            pipeline,
            names,
            frames: 0,
        })
    }

    /// The action names, in model order (the columns of `action_posterior`).
    #[getter]
    fn actions(&self) -> Vec<String> {
        self.names.clone()
    }

    /// One filter step on a frame; returns its `Estimate`.
    fn step(&mut self, py: Python<'_>, frame: &Bound<'_, PyAny>) -> PyResult<PyEstimate> {
        let images = Self::images(frame)?;
        let r = self.step_images(py, &images)?;
        Ok(PyEstimate {
            names: self.names.clone(),
            r,
        })
    }

    /// Step through frames (an iterable of images or a (T, H, W, 3) array) and return arrays over
    /// time: `action_posterior` (T, A), `theta_mean` / `theta_std` (T, 2), `entropy`, `ess`
    /// (T,), `best_pose` / `smoothed_pose` (T, 9, world), `action` (T,) int64 indices into
    /// `actions`.
    fn track<'py>(
        &mut self,
        py: Python<'py>,
        frames: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        // One frame of look-ahead, as `track_video`: while the filter tracks frame t (GIL
        // released), frame t + 1's edge image is computed alongside; frames are converted from
        // Python one ahead, under the GIL.
        let mut results = Vec::new();
        let mut iter = frames.try_iter()?;
        let mut next = iter.next().map(|f| Self::images(&f?)).transpose()?;
        if let Some(images) = &next {
            let (index, pipeline) = (self.frames, &mut self.pipeline);
            py.detach(|| {
                let refs: Vec<&RgbImage> = images.iter().collect();
                pipeline.prime(index, &refs)
            })
            .map_err(|e| actrack_error(&e))?;
        }
        while next.take().is_some() {
            let upcoming = iter.next().map(|f| Self::images(&f?)).transpose()?;
            let (index, pipeline) = (self.frames, &mut self.pipeline);
            let (r, prepared) = py
                .detach(|| {
                    pipeline.step_overlapped(|ahead| match &upcoming {
                        Some(images) => {
                            let refs: Vec<&RgbImage> = images.iter().collect();
                            ahead.prepare(index + 1, &refs)
                        }
                        None => Ok(()),
                    })
                })
                .map_err(|e| actrack_error(&e))?;
            self.frames += 1;
            results.push(r);
            prepared.map_err(|e| actrack_error(&e))?;
            next = upcoming;
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
/// trajectory CSV (`csv=`); returns a summary dict (frames, seconds, filter_seconds, skipped).
#[pyfunction]
#[pyo3(signature = (model, scene, source, *, mcap=None, csv=None, mcap_images=false, n_particles=400, seed=0, fps=None))]
#[allow(clippy::too_many_arguments)]
pub fn track_video<'py>(
    py: Python<'py>,
    model: PyRef<'_, PyActionModel>,
    scene: PyRef<'_, PyScene>,
    source: PathBuf,
    mcap: Option<PathBuf>,
    csv: Option<PathBuf>,
    mcap_images: bool,
    n_particles: usize,
    seed: u64,
    fps: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let opts = TrackOptions {
        particles: n_particles,
        seed,
        ..TrackOptions::default()
    };
    let outputs = TrackOutputs {
        mcap,
        mcap_images,
        csv,
        overlay: None,
    };
    let (m, s) = (&model.inner, &scene.inner);
    let summary = py
        .detach(|| {
            let mut src = FrameSource::open(
                &source,
                &FrameOptions {
                    fps,
                    skip_bad_frames: false,
                },
            )?;
            let stop = AtomicBool::new(false);
            track(m, s, &mut src, &opts, &outputs, &stop, &mut |_, _| {})
        })
        .map_err(|e| actrack_error(&e))?;
    let out = PyDict::new(py);
    out.set_item("frames", summary.frames)?;
    out.set_item("seconds", summary.seconds)?;
    out.set_item("filter_seconds", summary.filter_seconds)?;
    out.set_item("skipped", summary.skipped.clone())?;
    Ok(out)
}

/// The edge-distance image G of SPEC §4.1 for an (H, W, 3) or (H, W) uint8 frame, as the tracker
/// computes it: shape (H, W), float32 in [0, 1]. `sigma` (pixels, default 4 at 640 px wide,
/// scaled with the width), `tau` (default 0.2) and `binary` override the defaults.
#[pyfunction]
#[pyo3(signature = (frame, *, sigma=None, tau=None, binary=None))]
pub fn edge_image<'py>(
    py: Python<'py>,
    frame: &Bound<'_, PyAny>,
    sigma: Option<f32>,
    tau: Option<f32>,
    binary: Option<bool>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let img = rgb_image(frame)?;
    let mut params = edge_params(img.width());
    params.sigma = sigma.unwrap_or(params.sigma);
    params.tau = tau.unwrap_or(params.tau);
    params.binary = binary.unwrap_or(params.binary);
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

/// log P(I | pose) of SPEC §4 (contour likelihood, γ = 0.15) for world poses (N, 9) = (p, q, r),
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
    let cameras = s.cameras.iter().map(render_camera).collect();
    let lik = LikelihoodModel::new(
        cameras,
        render_arm(s, lengths),
        GAMMA,
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
