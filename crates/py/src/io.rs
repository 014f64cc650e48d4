//! Bindings of the `actrack` crate's files and pipelines: `ActionModel` (train / classify /
//! save / load, the same model files as `actrack-cli`), `load_mocap`, `Scene` and `evaluate`.

use std::path::PathBuf;

use actrack::eval;
use actrack::manifest::Manifest;
use actrack::mocap::ArmSide;
use actrack::mocap::trial::{Importer, Preprocessing, TrimOptions};
use actrack::model::ActionModel;
use actrack::scene::Scene;
use actrack::track_csv::Trajectory;
use actrack::train::{Classifier, fit_actions, import_manifest};
use nalgebra::Vector3;
use numpy::ndarray::{Array1, Array2};
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyType};

use crate::convert::{matrix, vec_to_py, vector};
use crate::errors::{actrack_error, value_error};
use crate::models::PyPhmm;

/// A serde value as the matching Python object (through JSON: dicts, lists, floats, None).
pub(crate) fn to_python<'py, T: serde::Serialize>(
    py: Python<'py>,
    value: &T,
) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value)
        .map_err(|e| value_error(format!("cannot convert the result: {e}")))?;
    py.import("json")?.call_method1("loads", (text,))
}

fn points_to_py<'py>(py: Python<'py>, pts: &[Vector3<f64>]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((pts.len(), 3), |(t, c)| pts[t][c]).into_pyarray(py)
}

fn arm_side(arm: &str) -> PyResult<ArmSide> {
    arm.parse::<ArmSide>().map_err(value_error)
}

/// Several named actions, one parametric HMM each, with the arm geometry and preprocessing they
/// were trained with. Files are those of `actrack-cli train` (`*.actrack.json`).
#[pyclass(module = "actrack._actrack", name = "ActionModel", frozen)]
pub struct PyActionModel {
    pub(crate) inner: ActionModel,
}

#[pymethods]
impl PyActionModel {
    /// Train from a manifest (TOML), exactly like `actrack-cli train`; keyword options override
    /// the manifest's `[options]`.
    #[classmethod]
    #[pyo3(signature = (manifest, *, states=None, max_jump=None, n_iter=None, cov_floor=None))]
    fn train(
        _cls: &Bound<'_, PyType>,
        py: Python<'_>,
        manifest: PathBuf,
        states: Option<usize>,
        max_jump: Option<usize>,
        n_iter: Option<usize>,
        cov_floor: Option<f64>,
    ) -> PyResult<Self> {
        let inner = py
            .detach(|| {
                let m = Manifest::load(&manifest)?;
                let mut options = m.options.clone();
                options.states = states.unwrap_or(options.states);
                options.max_jump = max_jump.unwrap_or(options.max_jump);
                options.iterations = n_iter.unwrap_or(options.iterations);
                options.cov_floor = cov_floor.unwrap_or(options.cov_floor);
                if options.states == 0
                    || options.max_jump == 0
                    || options.cov_floor.is_nan()
                    || options.cov_floor <= 0.0
                {
                    return Err(actrack::Error::Config(
                        "states and max_jump must be ≥ 1 and cov_floor > 0".into(),
                    ));
                }
                let trials = import_manifest(&m, None, &|_| {})?;
                fit_actions(
                    &trials,
                    &options,
                    &m.preprocessing,
                    Some(&manifest),
                    &|_| {},
                )
            })
            .map_err(|e| actrack_error(&e))?;
        Ok(PyActionModel { inner })
    }

    /// The shipped default model (reach and drink, trained on every UE-ADL subject), the one
    /// `actrack-cli track` uses without `--model`.
    #[classmethod]
    fn load_default(_cls: &Bound<'_, PyType>) -> PyResult<Self> {
        let inner = actrack::model::default_model().map_err(|e| actrack_error(&e))?;
        Ok(PyActionModel { inner })
    }

    /// Read a model file (`*.actrack.json`).
    #[classmethod]
    fn load(_cls: &Bound<'_, PyType>, path: PathBuf) -> PyResult<Self> {
        let inner = ActionModel::load(&path).map_err(|e| actrack_error(&e))?;
        Ok(PyActionModel { inner })
    }

    /// Parse the text of a model file (what `to_json` returns).
    #[classmethod]
    fn from_json(_cls: &Bound<'_, PyType>, text: &str) -> PyResult<Self> {
        let inner = ActionModel::from_json(std::path::Path::new("<string>"), text)
            .map_err(|e| actrack_error(&e))?;
        Ok(PyActionModel { inner })
    }

    /// Write the model file.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.inner.save(&path).map_err(|e| actrack_error(&e))
    }

    /// The model file's JSON text.
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json().map_err(|e| actrack_error(&e))
    }

    /// The action names, in training order.
    #[getter]
    fn actions(&self) -> Vec<String> {
        self.inner.actions.iter().map(|a| a.name.clone()).collect()
    }

    /// The parametric HMM of one action (poses in the actor frame, θ in metres).
    fn phmm(&self, action: &str) -> PyResult<PyPhmm> {
        let a = self.inner.action(action).ok_or_else(|| {
            value_error(format!(
                "no action `{action}` in this model (it has: {})",
                self.inner.action_names().join(", ")
            ))
        })?;
        Ok(PyPhmm::wrap(a.phmm.clone()))
    }

    /// (upper arm, forearm with hand) lengths in metres.
    #[getter]
    fn arm_lengths(&self) -> (f64, f64) {
        (
            self.inner.arm_lengths.upper_arm,
            self.inner.arm_lengths.forearm_hand,
        )
    }

    /// Training provenance (tool, date, files, states, …) as a dict.
    #[getter]
    fn provenance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.inner.provenance)
    }

    /// Recognise the action of a (T, 9) pose sequence (actor frame, metres): for each action,
    /// θ̂ by EM and log P(X | θ̂). `partial=True` for the beginning of an action only;
    /// `multi_start=True` also starts θ-EM from every training θ (slower). Returns
    /// `{"action": name, "theta": θ̂, "scores": {name: {"log_likelihood": …, "theta": …}}}`.
    #[pyo3(signature = (x, *, partial=false, multi_start=false))]
    fn classify<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'_, PyAny>,
        partial: bool,
        multi_start: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let x = matrix(x, "x", Some(9))?;
        let result = py
            .detach(|| {
                let mut c = Classifier::new(&self.inner)?;
                c.multi_start = multi_start;
                c.classify(&x, partial)
            })
            .map_err(|e| actrack_error(&e))?;
        let out = PyDict::new(py);
        out.set_item("action", &result.action)?;
        out.set_item("theta", vec_to_py(py, result.theta.to_vec()))?;
        let scores = PyDict::new(py);
        for s in &result.scores {
            let d = PyDict::new(py);
            d.set_item("log_likelihood", s.log_likelihood)?;
            d.set_item("theta", vec_to_py(py, s.theta.to_vec()))?;
            scores.set_item(&s.action, d)?;
        }
        out.set_item("scores", scores)?;
        Ok(out)
    }

    fn __repr__(&self) -> String {
        format!("ActionModel(actions={:?})", self.inner.action_names())
    }
}

/// Import one mocap trial (Vicon CSV plain/.xz/.gz, C3D with its subject's static trial, or a
/// joint-trajectory CSV) into the actor frame. Returns a dict of arrays: `shoulder`, `elbow`,
/// `wrist`, `fingertip` (T, 3) metres, `time` (T,) seconds, `theta` (2,) metres.
#[pyfunction]
#[pyo3(
    signature = (path, *, static_trial=None, arm="R", theta=None, frame_rate=Some(30.0), trim=true, max_gap=10),
    text_signature = "(path, *, static_trial=None, arm='R', theta=None, frame_rate=30.0, trim=True, max_gap=10)"
)]
pub fn load_mocap<'py>(
    py: Python<'py>,
    path: PathBuf,
    static_trial: Option<PathBuf>,
    arm: &str,
    theta: Option<&Bound<'_, PyAny>>,
    frame_rate: Option<f64>,
    trim: bool,
    max_gap: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let side = arm_side(arm)?;
    let theta = theta
        .map(|t| vector(t, "theta", Some(2)).map(|v| [v[0], v[1]]))
        .transpose()?;
    let options = Preprocessing {
        max_gap,
        frame_rate,
        trim: trim.then(TrimOptions::default),
        ..Preprocessing::default()
    };
    let trial = py
        .detach(|| {
            let importer = Importer::new(options)?;
            importer.load(&path, static_trial.as_deref(), side, theta, None)
        })
        .map_err(|e| actrack_error(&e))?;
    let a = &trial.arm_trajectory;
    let out = PyDict::new(py);
    out.set_item("shoulder", points_to_py(py, &a.p))?;
    out.set_item("elbow", points_to_py(py, &a.q))?;
    out.set_item("wrist", points_to_py(py, &a.w))?;
    out.set_item("fingertip", points_to_py(py, &a.r))?;
    let time: Array1<f64> = (0..a.len()).map(|t| t as f64 / a.rate).collect();
    out.set_item("time", time.into_pyarray(py))?;
    out.set_item("theta", vec_to_py(py, trial.theta.to_vec()))?;
    Ok(out)
}

/// A scene file (TOML): cameras, the table region, the actor's placement, the arm geometry.
#[pyclass(module = "actrack._actrack", name = "Scene", frozen)]
pub struct PyScene {
    pub(crate) inner: Scene,
}

#[pymethods]
impl PyScene {
    /// Read and validate a scene file.
    #[classmethod]
    fn load(_cls: &Bound<'_, PyType>, path: PathBuf) -> PyResult<Self> {
        let inner = Scene::load(&path).map_err(|e| actrack_error(&e))?;
        Ok(PyScene { inner })
    }

    /// Parse the text of a scene file.
    #[classmethod]
    fn parse(_cls: &Bound<'_, PyType>, text: &str) -> PyResult<Self> {
        let inner =
            Scene::parse(text, std::path::Path::new("<string>")).map_err(|e| actrack_error(&e))?;
        Ok(PyScene { inner })
    }

    /// The built-in scene of `actrack-cli demo`: one camera of the given size over a table.
    #[classmethod]
    #[pyo3(signature = (width=640, height=480))]
    fn default(_cls: &Bound<'_, PyType>, width: u32, height: u32) -> Self {
        PyScene {
            inner: actrack::scene::default_scene(width, height),
        }
    }

    /// The scene as TOML text (what `load` reads).
    fn to_toml(&self) -> String {
        self.inner.to_toml_string()
    }

    /// Camera names.
    #[getter]
    fn cameras(&self) -> Vec<String> {
        self.inner.cameras.iter().map(|c| c.name.clone()).collect()
    }

    /// (width, height) of each camera, in pixels.
    #[getter]
    fn image_sizes(&self) -> Vec<(u32, u32)> {
        self.inner
            .cameras
            .iter()
            .map(|c| (c.model.width, c.model.height))
            .collect()
    }

    /// The θ prior region in the actor frame: (centre (2,), half-extents (2,)), metres.
    #[getter]
    fn theta_region<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>) {
        let (c, h) = self.inner.theta_region();
        (vec_to_py(py, c.to_vec()), vec_to_py(py, h.to_vec()))
    }

    /// The table surface's height in the actor frame (metres; negative: below the shoulder):
    /// the fingertip floor `actor.fingertip_floor = "table"` of the tracker's configuration.
    #[getter]
    fn table_height(&self) -> f64 {
        self.inner.table_height()
    }

    /// Project world points (N, 3) into camera `camera`: (N, 2) pixels, NaN for points behind
    /// the camera.
    #[pyo3(signature = (points, *, camera=0))]
    fn project<'py>(
        &self,
        py: Python<'py>,
        points: &Bound<'_, PyAny>,
        camera: usize,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let cam = self.inner.cameras.get(camera).ok_or_else(|| {
            value_error(format!(
                "camera {camera} does not exist (the scene has {})",
                self.inner.cameras.len()
            ))
        })?;
        let p = matrix(points, "points", Some(3))?;
        let mut out = Array2::from_elem((p.nrows(), 2), f64::NAN);
        for i in 0..p.nrows() {
            if let Some((u, v)) = cam.project(&Vector3::new(p[(i, 0)], p[(i, 1)], p[(i, 2)])) {
                out[(i, 0)] = u;
                out[(i, 1)] = v;
            }
        }
        Ok(out.into_pyarray(py))
    }

    /// Actor-frame poses (N, 9) = (p, q, r) to world coordinates.
    fn pose_to_world<'py>(
        &self,
        py: Python<'py>,
        poses: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        map_poses(py, poses, |p| self.inner.pose_to_world(p))
    }

    /// World poses (N, 9) to the actor frame.
    fn pose_to_actor<'py>(
        &self,
        py: Python<'py>,
        poses: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        map_poses(py, poses, |p| self.inner.pose_to_actor(p))
    }

    /// The world point on the table surface of θ (actor frame, metres).
    fn theta_to_world<'py>(
        &self,
        py: Python<'py>,
        theta: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let t = vector(theta, "theta", Some(2))?;
        let w = self.inner.theta_to_world([t[0], t[1]]);
        Ok(vec_to_py(py, w.as_slice().to_vec()))
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene(cameras={:?})",
            self.inner
                .cameras
                .iter()
                .map(|c| c.name.as_str())
                .collect::<Vec<_>>()
        )
    }
}

fn map_poses<'py>(
    py: Python<'py>,
    poses: &Bound<'_, PyAny>,
    f: impl Fn(&[f64; 9]) -> [f64; 9],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let m = matrix(poses, "poses", Some(9))?;
    let mut out = Array2::zeros((m.nrows(), 9));
    for i in 0..m.nrows() {
        let mut p = [0.0; 9];
        for (c, v) in p.iter_mut().enumerate() {
            *v = m[(i, c)];
        }
        for (c, v) in f(&p).iter().enumerate() {
            out[(i, c)] = *v;
        }
    }
    Ok(out.into_pyarray(py))
}

/// The metrics of SPEC §5.4 for a tracker output CSV against a ground-truth CSV (trajectory CSV
/// files, matched by frame): per-joint RMSE/MAE, table-location error, θ error, recognition rate,
/// frames to convergence, per-instance details. Returns a dict.
#[pyfunction]
pub fn evaluate(py: Python<'_>, track: PathBuf, truth: PathBuf) -> PyResult<Bound<'_, PyAny>> {
    let report = py
        .detach(|| {
            let t = Trajectory::load(&track)?;
            let g = Trajectory::load(&truth)?;
            eval::evaluate(&t, &g)
        })
        .map_err(|e| actrack_error(&e))?;
    to_python(py, &report)
}
