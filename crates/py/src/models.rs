//! `actrack.Hmm` and `actrack.Phmm`: the left-right Gaussian HMM and the linear parametric HMM
//! of `actrack-phmm`, numpy in and out.
//!
//! Both classes wrap an [`actrack::phmm::Phmm`] (a plain HMM is one whose θ has dimension 0), so
//! they share one file format and one set of helpers; `Hmm` simply has no θ arguments. Heavy
//! calls (fit, inference, θ estimation, sampling) release the GIL.

use std::path::PathBuf;

use actrack::phmm::{
    CovarianceKind, EndMode, FitReport, Phmm, PhmmParams, ThetaEmOptions, ThetaEstimate,
};
use nalgebra::{DMatrix, DVector};
use numpy::ndarray::{Array1, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::{PyTuple, PyType};
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

use crate::convert::{
    dvector_to_py, matrices, matrix, matrix_to_py, sequences as read_sequences, stack_to_py,
    vec_to_py, vector,
};
use crate::errors::{os_error, phmm_error, value_error};

/// `format` field of the files written by `save`.
const FORMAT: &str = "actrack-phmm";
/// `version` field of the files written by `save`.
const VERSION: u64 = 1;

/// Parse an end mode name.
pub(crate) fn parse_end_mode(s: &str) -> PyResult<EndMode> {
    match s {
        "must_end" => Ok(EndMode::MustEnd),
        "free" => Ok(EndMode::Free),
        "none" => Ok(EndMode::None),
        _ => Err(value_error(format!(
            "end_mode must be 'must_end', 'free' or 'none', got {s:?}"
        ))),
    }
}

/// The Python name of an end mode.
pub(crate) fn end_mode_name(m: EndMode) -> &'static str {
    match m {
        EndMode::MustEnd => "must_end",
        EndMode::Free => "free",
        EndMode::None => "none",
    }
}

fn parse_covariance(s: &str) -> PyResult<CovarianceKind> {
    match s {
        "full" => Ok(CovarianceKind::Full),
        "diag" => Ok(CovarianceKind::Diagonal),
        _ => Err(value_error(format!(
            "covariance_type must be 'full' or 'diag', got {s:?}"
        ))),
    }
}

fn covariance_name(k: CovarianceKind) -> &'static str {
    match k {
        CovarianceKind::Full => "full",
        CovarianceKind::Diagonal => "diag",
    }
}

/// What a fit did: iterations, the log-likelihood history and whether it converged.
#[pyclass(module = "actrack._actrack", name = "FitReport", frozen)]
#[derive(Clone)]
pub struct PyFitReport {
    report: FitReport,
}

#[pymethods]
impl PyFitReport {
    /// Number of Baum–Welch iterations (M-steps).
    #[getter]
    fn iterations(&self) -> usize {
        self.report.iterations
    }
    /// Total log-likelihood before each M-step and of the returned model (length iterations + 1).
    #[getter]
    fn log_likelihoods<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_to_py(py, self.report.log_likelihoods.clone())
    }
    /// Whether the per-frame change fell below the tolerance before `n_iter`.
    #[getter]
    fn converged(&self) -> bool {
        self.report.converged
    }
    fn __repr__(&self) -> String {
        format!(
            "FitReport(iterations={}, converged={}, log_likelihood={})",
            self.report.iterations,
            if self.report.converged {
                "True"
            } else {
                "False"
            },
            self.report
                .log_likelihoods
                .last()
                .copied()
                .unwrap_or(f64::NAN)
        )
    }
}

/// The result of θ estimation: θ̂ (caller units), log P(X | θ̂), EM iterations and history.
#[pyclass(module = "actrack._actrack", name = "ThetaEstimate", frozen)]
pub struct PyThetaEstimate {
    est: ThetaEstimate,
}

#[pymethods]
impl PyThetaEstimate {
    /// θ̂, caller units.
    #[getter]
    fn theta<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        dvector_to_py(py, &self.est.theta)
    }
    /// log P(X | θ̂).
    #[getter]
    fn log_likelihood(&self) -> f64 {
        self.est.log_likelihood
    }
    /// EM iterations of the run that produced the estimate.
    #[getter]
    fn iterations(&self) -> usize {
        self.est.iterations
    }
    /// log P(X | θ⁽ⁿ⁾) at every E-step of that run.
    #[getter]
    fn history<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_to_py(py, self.est.history.clone())
    }
    fn __repr__(&self) -> String {
        format!(
            "ThetaEstimate(theta={:?}, log_likelihood={}, iterations={})",
            self.est.theta.as_slice(),
            self.est.log_likelihood,
            self.est.iterations
        )
    }
}

/// Covariances as (N, d, d) full matrices or (N, d) diagonal variances.
fn covariances(obj: &Bound<'_, PyAny>) -> PyResult<Vec<DMatrix<f64>>> {
    let a = crate::convert::array_arg(obj, "covars")?;
    match a.as_array().ndim() {
        3 => matrices(obj, "covars"),
        2 => {
            let m = matrix(obj, "covars", None)?;
            Ok((0..m.nrows())
                .map(|i| DMatrix::from_diagonal(&m.row(i).transpose()))
                .collect())
        }
        _ => Err(value_error(format!(
            "covars must be (n_states, d, d) full covariances or (n_states, d) variances, got a {}-D array",
            a.as_array().ndim()
        ))),
    }
}

/// Validate explicit parameters and build the model (shared by `Hmm` and `Phmm`).
#[allow(clippy::too_many_arguments)]
fn build(
    startprob: &Bound<'_, PyAny>,
    transmat: &Bound<'_, PyAny>,
    mean_bias: &Bound<'_, PyAny>,
    mean_weights: Option<&Bound<'_, PyAny>>,
    covars: &Bound<'_, PyAny>,
    exitprob: Option<&Bound<'_, PyAny>>,
    max_jump: Option<usize>,
    end_mode: Option<&str>,
) -> PyResult<Phmm> {
    let start = vector(startprob, "startprob", None)?;
    let n = start.len();
    let a = matrix(transmat, "transmat", None)?;
    if a.shape() != (n, n) {
        return Err(value_error(format!(
            "transmat must be ({n}, {n}) for {n} states, got ({}, {})",
            a.nrows(),
            a.ncols()
        )));
    }
    let means = matrix(mean_bias, "means", None)?;
    if means.nrows() != n {
        return Err(value_error(format!(
            "means must have one row per state ({n}), got {}",
            means.nrows()
        )));
    }
    let d = means.ncols();
    let bias: Vec<DVector<f64>> = (0..n).map(|i| means.row(i).transpose()).collect();
    let weights: Vec<DMatrix<f64>> = match mean_weights {
        Some(w) => {
            let w = matrices(w, "mean_weights")?;
            if w.len() != n || w.iter().any(|m| m.nrows() != d) {
                return Err(value_error(format!(
                    "mean_weights must be (n_states, d, theta_dim) = ({n}, {d}, p)"
                )));
            }
            w
        }
        None => vec![DMatrix::zeros(d, 0); n],
    };
    let covs = covariances(covars)?;
    if covs.len() != n || covs.iter().any(|c| c.shape() != (d, d)) {
        return Err(value_error(format!(
            "covars must be ({n}, {d}, {d}) (or ({n}, {d}) variances)"
        )));
    }
    let exit = match exitprob {
        Some(e) => vector(e, "exitprob", Some(n))?,
        None => (0..n)
            .map(|i| {
                let deficit = 1.0 - a.row(i).sum();
                if deficit.abs() < 1e-9 { 0.0 } else { deficit }
            })
            .collect(),
    };
    let max_jump = max_jump.unwrap_or_else(|| {
        let mut j = usize::from(n > 1);
        for r in 0..n {
            for c in r..n {
                if a[(r, c)] != 0.0 {
                    j = j.max(c - r);
                }
            }
        }
        j
    });
    let end_mode = match end_mode {
        Some(s) => parse_end_mode(s)?,
        None if exit.iter().all(|&e| e == 0.0) => EndMode::None,
        None if exit[..n - 1].iter().all(|&e| e == 0.0) => EndMode::MustEnd,
        None => EndMode::Free,
    };
    Phmm::from_params(
        &start, &a, &exit, &bias, &weights, &covs, max_jump, end_mode,
    )
    .map_err(|e| phmm_error(&e))
}

/// Training options shared by `Hmm.fit` and `Phmm.fit`.
struct FitOptions<'a> {
    n_states: Option<usize>,
    max_jump: usize,
    covariance_type: &'a str,
    end_mode: &'a str,
    n_iter: usize,
    tol: f64,
    cov_floor: f64,
    min_occupancy: Option<f64>,
    transition_floor: f64,
    learn_startprob: bool,
}

fn fit_impl(
    py: Python<'_>,
    seqs: &[DMatrix<f64>],
    thetas: &[DVector<f64>],
    o: &FitOptions<'_>,
    init: Option<&Phmm>,
) -> PyResult<(Phmm, FitReport)> {
    let n_states = match (o.n_states, init) {
        (Some(n), _) => n,
        (None, Some(m)) => m.n_states(),
        (None, None) => {
            return Err(value_error(
                "n_states is required (or pass init=<model> to start from a given model)",
            ));
        }
    };
    let mut params = PhmmParams::new(n_states)
        .max_jump(o.max_jump)
        .covariance(parse_covariance(o.covariance_type)?)
        .end_mode(parse_end_mode(o.end_mode)?)
        .max_iterations(o.n_iter)
        .tolerance(o.tol)
        .cov_floor(o.cov_floor)
        .transition_floor(o.transition_floor)
        .learn_start(o.learn_startprob);
    if let Some(m) = o.min_occupancy {
        params = params.min_occupancy(m);
    }
    let params = params.check().map_err(|e| phmm_error(&e))?;
    py.detach(|| match init {
        Some(m) => params.fit_from(m, seqs, thetas),
        None => params.fit(seqs, thetas),
    })
    .map_err(|e| phmm_error(&e))
}

/// Validate θ against a model (length and finiteness): the sampling functions panic otherwise.
fn theta_arg(model: &Phmm, theta: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    let t = vector(theta, "theta", Some(model.theta_dim()))?;
    if let Some(v) = t.iter().find(|v| !v.is_finite()) {
        return Err(value_error(format!(
            "theta contains the non-finite value {v}"
        )));
    }
    Ok(t)
}

fn no_theta() -> Vec<f64> {
    Vec::new()
}

fn log_likelihood_impl(py: Python<'_>, m: &Phmm, x: &DMatrix<f64>, t: &[f64]) -> PyResult<f64> {
    py.detach(|| m.log_likelihood(x, t))
        .map_err(|e| phmm_error(&e))
}

fn posteriors_impl<'py>(
    py: Python<'py>,
    m: &Phmm,
    x: &DMatrix<f64>,
    t: &[f64],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let g = py
        .detach(|| m.posteriors(x, t))
        .map_err(|e| phmm_error(&e))?;
    Ok(matrix_to_py(py, &g))
}

fn viterbi_impl<'py>(
    py: Python<'py>,
    m: &Phmm,
    x: &DMatrix<f64>,
    t: &[f64],
) -> PyResult<(Bound<'py, PyArray1<i64>>, f64)> {
    let (path, lp) = py.detach(|| m.viterbi(x, t)).map_err(|e| phmm_error(&e))?;
    let path: Array1<i64> = path.iter().map(|&s| s as i64).collect();
    Ok((path.into_pyarray(py), lp))
}

/// `(observations (T, d), states (T,))` of `sample`.
type Sampled<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<i64>>);

fn sample_impl<'py>(
    py: Python<'py>,
    m: &Phmm,
    t: &[f64],
    length: Option<usize>,
    seed: u64,
) -> Sampled<'py> {
    let (x, states) = py.detach(|| {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        m.sample(t, length, &mut rng)
    });
    let states: Array1<i64> = states.iter().map(|&s| s as i64).collect();
    (matrix_to_py(py, &x), states.into_pyarray(py))
}

fn transmat_py<'py>(py: Python<'py>, m: &Phmm) -> Bound<'py, PyArray2<f64>> {
    matrix_to_py(py, &m.transition_matrix())
}

fn covars_py<'py>(py: Python<'py>, m: &Phmm) -> Bound<'py, PyArray3<f64>> {
    let covs: Vec<DMatrix<f64>> = (0..m.n_states()).map(|i| m.covariance(i).clone()).collect();
    stack_to_py(py, &covs, m.dim(), m.dim())
}

fn means_py<'py>(py: Python<'py>, m: &Phmm, theta: &[f64]) -> Bound<'py, PyArray2<f64>> {
    let (n, d) = (m.n_states(), m.dim());
    let mut out = DMatrix::zeros(n, d);
    let mut buf = vec![0.0; d];
    for i in 0..n {
        m.mean_into(i, theta, &mut buf);
        for (c, v) in buf.iter().enumerate() {
            out[(i, c)] = *v;
        }
    }
    matrix_to_py(py, &out)
}

/// Serialise a model to the JSON text `save` writes.
fn to_json(m: &Phmm, kind: &str) -> PyResult<String> {
    let model = serde_json::to_value(m)
        .map_err(|e| value_error(format!("cannot serialise the model: {e}")))?;
    let doc = serde_json::json!({
        "format": FORMAT,
        "version": VERSION,
        "kind": kind,
        "model": model,
    });
    serde_json::to_string_pretty(&doc)
        .map_err(|e| value_error(format!("cannot serialise the model: {e}")))
}

/// Parse the JSON text of `save` (or a bare serialised model). `origin` prefixes error messages.
fn from_json(text: &str, origin: &str) -> PyResult<Phmm> {
    let doc: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| value_error(format!("{origin}: not valid JSON: {e}")))?;
    let model = match doc.get("format").and_then(serde_json::Value::as_str) {
        Some(FORMAT) => {
            let v = doc.get("version").and_then(serde_json::Value::as_u64);
            if v != Some(VERSION) {
                return Err(value_error(format!(
                    "{origin}: unsupported {FORMAT} version {}: this build reads version {VERSION}",
                    doc.get("version")
                        .map_or_else(|| "(missing)".to_string(), ToString::to_string)
                )));
            }
            doc.get("model")
                .cloned()
                .ok_or_else(|| value_error(format!("{origin}: no `model` field")))?
        }
        Some(other) => {
            return Err(value_error(format!(
                "{origin}: this is an {other:?} file, not an {FORMAT:?} file{}",
                if other == "actrack-model" {
                    " (use actrack.ActionModel.load)"
                } else {
                    ""
                }
            )));
        }
        None => doc,
    };
    serde_json::from_value(model).map_err(|e| value_error(format!("{origin}: invalid model: {e}")))
}

fn save_impl(m: &Phmm, kind: &str, path: &PathBuf) -> PyResult<()> {
    let text = to_json(m, kind)?;
    std::fs::write(path, text)
        .map_err(|e| os_error(path, &e, format!("{}: cannot write: {e}", path.display())))
}

fn load_impl(path: &PathBuf) -> PyResult<Phmm> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| os_error(path, &e, format!("{}: cannot read: {e}", path.display())))?;
    from_json(&text, &path.display().to_string())
}

fn repr(name: &str, m: &Phmm) -> String {
    let theta = if name == "Phmm" {
        format!(", theta_dim={}", m.theta_dim())
    } else {
        String::new()
    };
    format!(
        "{name}(n_states={}, dim={}{theta}, max_jump={}, end_mode='{}', covariance_type='{}')",
        m.n_states(),
        m.dim(),
        m.max_jump(),
        end_mode_name(m.end_mode()),
        covariance_name(m.covariance_kind())
    )
}

/// Properties and methods common to both classes.
macro_rules! pymethods_with_common {
    ($ty:ident, $($extra:tt)*) => {
        #[pymethods]
        impl $ty {
            $($extra)*

            /// Number of states N.
            #[getter]
            fn n_states(&self) -> usize {
                self.inner.n_states()
            }
            /// Observation dimension d.
            #[getter]
            fn dim(&self) -> usize {
                self.inner.dim()
            }
            /// Maximum forward jump J.
            #[getter]
            fn max_jump(&self) -> usize {
                self.inner.max_jump()
            }
            /// How sequences end: 'must_end', 'free' or 'none'.
            #[getter]
            fn end_mode(&self) -> &'static str {
                end_mode_name(self.inner.end_mode())
            }
            /// 'full' or 'diag'.
            #[getter]
            fn covariance_type(&self) -> &'static str {
                covariance_name(self.inner.covariance_kind())
            }
            /// π, shape (N,).
            #[getter]
            fn startprob<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
                let m = &self.inner;
                vec_to_py(py, (0..m.n_states()).map(|i| m.start_prob(i)).collect())
            }
            /// Transition matrix a_ij, shape (N, N), zero outside the band.
            #[getter]
            fn transmat<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
                transmat_py(py, &self.inner)
            }
            /// Exit probabilities a_iE, shape (N,); each row of transmat plus its exit sums to 1.
            #[getter]
            fn exitprob<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
                dvector_to_py(py, &self.inner.exit_probs())
            }
            /// Covariances Σ_i, shape (N, d, d).
            #[getter]
            fn covars<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
                covars_py(py, &self.inner)
            }
            /// The report of the fit that produced this model (None for explicit parameters).
            #[getter]
            fn fit_report(&self) -> Option<PyFitReport> {
                self.report.clone().map(|report| PyFitReport { report })
            }
            /// Write the model as JSON (`{"format": "actrack-phmm", "version": 1, ...}`).
            fn save(&self, path: PathBuf) -> PyResult<()> {
                save_impl(&self.inner, Self::KIND, &path)
            }
            /// The JSON text `save` writes.
            fn to_json(&self) -> PyResult<String> {
                to_json(&self.inner, Self::KIND)
            }
            fn __repr__(&self) -> String {
                repr(Self::KIND_NAME, &self.inner)
            }
            fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
                let py = slf.py();
                let ctor = slf.get_type().getattr("from_json")?;
                let text = slf.get().to_json()?;
                PyTuple::new(py, [ctor, PyTuple::new(py, [text])?.into_any()])
            }
        }
    };
}

/// A plain left-right Gaussian HMM (numpy in, numpy out). Build one with `Hmm.from_params` or
/// `Hmm.fit`; `log_likelihood`, `posteriors` and `viterbi` take a (T, d) array.
#[pyclass(module = "actrack._actrack", name = "Hmm", frozen)]
pub struct PyHmm {
    pub(crate) inner: Phmm,
    report: Option<FitReport>,
}

impl PyHmm {
    const KIND: &'static str = "hmm";
    const KIND_NAME: &'static str = "Hmm";

    fn new(inner: Phmm, report: Option<FitReport>) -> PyResult<Self> {
        if inner.theta_dim() != 0 {
            return Err(value_error(format!(
                "this model's θ is {}-D: load it with actrack.Phmm",
                inner.theta_dim()
            )));
        }
        Ok(PyHmm { inner, report })
    }
}

pymethods_with_common! {
PyHmm,
    /// Build from explicit parameters. `transmat` is N × N and must be zero outside the band
    /// `i ≤ j ≤ i + max_jump` (max_jump defaults to the widest band used). `exitprob` defaults to
    /// `1 − transmat.sum(axis=1)`; `end_mode` defaults to 'none' when every exit is zero,
    /// 'must_end' when only the last state exits, else 'free'. `covars` is (N, d, d) or (N, d).
    #[classmethod]
    #[pyo3(signature = (startprob, transmat, means, covars, *, exitprob=None, max_jump=None, end_mode=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_params(
        _cls: &Bound<'_, PyType>,
        startprob: &Bound<'_, PyAny>,
        transmat: &Bound<'_, PyAny>,
        means: &Bound<'_, PyAny>,
        covars: &Bound<'_, PyAny>,
        exitprob: Option<&Bound<'_, PyAny>>,
        max_jump: Option<usize>,
        end_mode: Option<&str>,
    ) -> PyResult<Self> {
        let m = build(
            startprob, transmat, means, None, covars, exitprob, max_jump, end_mode,
        )?;
        PyHmm::new(m, None)
    }

    /// Train on a list of (T_m, d) sequences: uniform segmentation, then Baum–Welch. With
    /// `init=<Hmm>`, Baum–Welch starts from that model (its topology and end mode are kept).
    /// `cov_floor` is σ_min (a standard deviation, observation units; 0 disables the floor).
    #[classmethod]
    #[pyo3(signature = (sequences, *, n_states=None, max_jump=3, covariance_type="full", end_mode="must_end", n_iter=100, tol=1e-4, cov_floor=0.005, min_occupancy=None, transition_floor=0.0, learn_startprob=false, init=None))]
    #[allow(clippy::too_many_arguments)]
    fn fit(
        _cls: &Bound<'_, PyType>,
        py: Python<'_>,
        sequences: &Bound<'_, PyAny>,
        n_states: Option<usize>,
        max_jump: usize,
        covariance_type: &str,
        end_mode: &str,
        n_iter: usize,
        tol: f64,
        cov_floor: f64,
        min_occupancy: Option<f64>,
        transition_floor: f64,
        learn_startprob: bool,
        init: Option<PyRef<'_, PyHmm>>,
    ) -> PyResult<Self> {
        let seqs = read_sequences(sequences, "sequences")?;
        let o = FitOptions {
            n_states,
            max_jump,
            covariance_type,
            end_mode,
            n_iter,
            tol,
            cov_floor,
            min_occupancy,
            transition_floor,
            learn_startprob,
        };
        let (m, r) = fit_impl(py, &seqs, &[], &o, init.as_ref().map(|h| &h.inner))?;
        PyHmm::new(m, Some(r))
    }

    /// Read a model written by `save`.
    #[classmethod]
    fn load(_cls: &Bound<'_, PyType>, path: PathBuf) -> PyResult<Self> {
        PyHmm::new(load_impl(&path)?, None)
    }

    /// Parse the text of `to_json`.
    #[classmethod]
    fn from_json(_cls: &Bound<'_, PyType>, text: &str) -> PyResult<Self> {
        PyHmm::new(from_json(text, "model JSON")?, None)
    }

    /// State means μ_i, shape (N, d).
    #[getter]
    fn means<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        means_py(py, &self.inner, &[])
    }

    /// log P(X) of a (T, d) sequence.
    fn log_likelihood(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        let x = matrix(x, "x", None)?;
        log_likelihood_impl(py, &self.inner, &x, &no_theta())
    }

    /// State posteriors γ_t(i), shape (T, N); rows sum to 1.
    fn posteriors<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let x = matrix(x, "x", None)?;
        posteriors_impl(py, &self.inner, &x, &no_theta())
    }

    /// The most likely state path (int64, 0-based) and its log-probability.
    fn viterbi<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'_, PyAny>,
    ) -> PyResult<(Bound<'py, PyArray1<i64>>, f64)> {
        let x = matrix(x, "x", None)?;
        viterbi_impl(py, &self.inner, &x, &no_theta())
    }

    /// Sample a sequence: (X of shape (T, d), states of shape (T,)). `length=None` runs until
    /// the model exits.
    #[pyo3(signature = (*, length=None, seed=0))]
    fn sample<'py>(
        &self,
        py: Python<'py>,
        length: Option<usize>,
        seed: u64,
    ) -> Sampled<'py> {
        sample_impl(py, &self.inner, &no_theta(), length, seed)
    }

    /// The deterministic expected trajectory, shape (T, d).
    #[pyo3(signature = (*, length=None))]
    fn expected_trajectory<'py>(
        &self,
        py: Python<'py>,
        length: Option<usize>,
    ) -> Bound<'py, PyArray2<f64>> {
        let x = py.detach(|| self.inner.expected_trajectory(&[], length));
        matrix_to_py(py, &x)
    }
}

/// A linear parametric HMM: state means μ_i(θ) = mean_bias_i + mean_weights_i · θ (θ in the
/// caller's units). Every method that looks at data takes θ.
#[pyclass(module = "actrack._actrack", name = "Phmm", frozen)]
pub struct PyPhmm {
    pub(crate) inner: Phmm,
    report: Option<FitReport>,
}

impl PyPhmm {
    const KIND: &'static str = "phmm";
    const KIND_NAME: &'static str = "Phmm";

    pub(crate) fn wrap(inner: Phmm) -> Self {
        PyPhmm {
            inner,
            report: None,
        }
    }
}

pymethods_with_common! {
PyPhmm,
    /// Build from explicit parameters: `mean_bias` (N, d) and `mean_weights` (N, d, p) with
    /// μ_i(θ) = mean_bias[i] + mean_weights[i] @ θ. The rest as in `Hmm.from_params`.
    #[classmethod]
    #[pyo3(signature = (startprob, transmat, mean_bias, mean_weights, covars, *, exitprob=None, max_jump=None, end_mode=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_params(
        _cls: &Bound<'_, PyType>,
        startprob: &Bound<'_, PyAny>,
        transmat: &Bound<'_, PyAny>,
        mean_bias: &Bound<'_, PyAny>,
        mean_weights: &Bound<'_, PyAny>,
        covars: &Bound<'_, PyAny>,
        exitprob: Option<&Bound<'_, PyAny>>,
        max_jump: Option<usize>,
        end_mode: Option<&str>,
    ) -> PyResult<Self> {
        let m = build(
            startprob,
            transmat,
            mean_bias,
            Some(mean_weights),
            covars,
            exitprob,
            max_jump,
            end_mode,
        )?;
        Ok(PyPhmm::wrap(m))
    }

    /// Train on (T_m, d) sequences with one θ per sequence (`thetas` of shape (S, p)): uniform
    /// segmentation and the normal equations, then Baum–Welch. `init=<Phmm>` starts Baum–Welch
    /// from that model instead.
    #[classmethod]
    #[pyo3(signature = (sequences, thetas, *, n_states=None, max_jump=3, covariance_type="full", end_mode="must_end", n_iter=100, tol=1e-4, cov_floor=0.005, min_occupancy=None, transition_floor=0.0, learn_startprob=false, init=None))]
    #[allow(clippy::too_many_arguments)]
    fn fit(
        _cls: &Bound<'_, PyType>,
        py: Python<'_>,
        sequences: &Bound<'_, PyAny>,
        thetas: &Bound<'_, PyAny>,
        n_states: Option<usize>,
        max_jump: usize,
        covariance_type: &str,
        end_mode: &str,
        n_iter: usize,
        tol: f64,
        cov_floor: f64,
        min_occupancy: Option<f64>,
        transition_floor: f64,
        learn_startprob: bool,
        init: Option<PyRef<'_, PyPhmm>>,
    ) -> PyResult<Self> {
        let seqs = read_sequences(sequences, "sequences")?;
        let th = matrix(thetas, "thetas", None)?;
        if th.nrows() != seqs.len() {
            return Err(value_error(format!(
                "{} sequences but {} thetas: pass one θ row per sequence",
                seqs.len(),
                th.nrows()
            )));
        }
        let th: Vec<DVector<f64>> = (0..th.nrows()).map(|i| th.row(i).transpose()).collect();
        let o = FitOptions {
            n_states,
            max_jump,
            covariance_type,
            end_mode,
            n_iter,
            tol,
            cov_floor,
            min_occupancy,
            transition_floor,
            learn_startprob,
        };
        let (m, r) = fit_impl(py, &seqs, &th, &o, init.as_ref().map(|h| &h.inner))?;
        Ok(PyPhmm {
            inner: m,
            report: Some(r),
        })
    }

    /// Read a model written by `save` (a plain `Hmm` file loads as a Phmm with theta_dim 0).
    #[classmethod]
    fn load(_cls: &Bound<'_, PyType>, path: PathBuf) -> PyResult<Self> {
        Ok(PyPhmm::wrap(load_impl(&path)?))
    }

    /// Parse the text of `to_json`.
    #[classmethod]
    fn from_json(_cls: &Bound<'_, PyType>, text: &str) -> PyResult<Self> {
        Ok(PyPhmm::wrap(from_json(text, "model JSON")?))
    }

    /// Dimension p of θ.
    #[getter]
    fn theta_dim(&self) -> usize {
        self.inner.theta_dim()
    }

    /// mean_bias_i with μ_i(θ) = mean_bias_i + mean_weights_i · θ, shape (N, d), caller units.
    #[getter]
    fn mean_bias<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let m = &self.inner;
        let rows: Vec<Vec<f64>> = (0..m.n_states())
            .map(|i| m.mean_affine(i).0.as_slice().to_vec())
            .collect();
        crate::convert::rows_to_py(py, &rows, m.dim())
    }

    /// mean_weights_i, shape (N, d, p), caller units.
    #[getter]
    fn mean_weights<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        let m = &self.inner;
        let (n, d, p) = (m.n_states(), m.dim(), m.theta_dim());
        let ws: Vec<DMatrix<f64>> = (0..n).map(|i| m.mean_affine(i).1).collect();
        Array3::from_shape_fn((n, d, p), |(k, r, c)| ws[k][(r, c)]).into_pyarray(py)
    }

    /// State means μ_i(θ), shape (N, d).
    fn means<'py>(
        &self,
        py: Python<'py>,
        theta: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let t = theta_arg(&self.inner, theta)?;
        Ok(means_py(py, &self.inner, &t))
    }

    /// log P(X | θ) of a (T, d) sequence.
    fn log_likelihood(
        &self,
        py: Python<'_>,
        x: &Bound<'_, PyAny>,
        theta: &Bound<'_, PyAny>,
    ) -> PyResult<f64> {
        let x = matrix(x, "x", None)?;
        let t = vector(theta, "theta", None)?;
        log_likelihood_impl(py, &self.inner, &x, &t)
    }

    /// State posteriors γ_t(i) at θ, shape (T, N).
    fn posteriors<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'_, PyAny>,
        theta: &Bound<'_, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let x = matrix(x, "x", None)?;
        let t = vector(theta, "theta", None)?;
        posteriors_impl(py, &self.inner, &x, &t)
    }

    /// The most likely state path at θ (int64, 0-based) and its log-probability.
    fn viterbi<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'_, PyAny>,
        theta: &Bound<'_, PyAny>,
    ) -> PyResult<(Bound<'py, PyArray1<i64>>, f64)> {
        let x = matrix(x, "x", None)?;
        let t = vector(theta, "theta", None)?;
        viterbi_impl(py, &self.inner, &x, &t)
    }

    /// Estimate θ of a (T, d) sequence by EM with the model fixed. `init` defaults to the
    /// training mean; `prior=(mean, cov)` gives the MAP variant; `multi_start` also starts from
    /// every training θ.
    #[pyo3(signature = (x, *, init=None, n_iter=50, tol=1e-6, prior=None, multi_start=false))]
    fn estimate_theta(
        &self,
        py: Python<'_>,
        x: &Bound<'_, PyAny>,
        init: Option<&Bound<'_, PyAny>>,
        n_iter: usize,
        tol: f64,
        prior: Option<(Bound<'_, PyAny>, Bound<'_, PyAny>)>,
        multi_start: bool,
    ) -> PyResult<PyThetaEstimate> {
        let x = matrix(x, "x", None)?;
        let p = self.inner.theta_dim();
        let init = init
            .map(|i| vector(i, "init", Some(p)).map(DVector::from_vec))
            .transpose()?;
        let prior = match prior {
            Some((mean, cov)) => {
                let mean = DVector::from_vec(vector(&mean, "prior mean", Some(p))?);
                let cov = matrix(&cov, "prior covariance", Some(p))?;
                if cov.nrows() != p {
                    return Err(value_error(format!(
                        "prior covariance must be ({p}, {p})"
                    )));
                }
                Some((mean, cov))
            }
            None => None,
        };
        let opts = ThetaEmOptions {
            init,
            max_iterations: n_iter,
            tolerance: tol,
            prior,
            multi_start,
            bounds: None,
        };
        let est = py
            .detach(|| self.inner.estimate_theta(&x, &opts))
            .map_err(|e| phmm_error(&e))?;
        Ok(PyThetaEstimate { est })
    }

    /// Sample a sequence at θ: (X of shape (T, d), states of shape (T,)). `length=None` runs
    /// until the model exits.
    #[pyo3(signature = (theta, *, length=None, seed=0))]
    fn sample<'py>(
        &self,
        py: Python<'py>,
        theta: &Bound<'_, PyAny>,
        length: Option<usize>,
        seed: u64,
    ) -> PyResult<Sampled<'py>> {
        let t = theta_arg(&self.inner, theta)?;
        Ok(sample_impl(py, &self.inner, &t, length, seed))
    }

    /// The deterministic expected trajectory at θ, shape (T, d).
    #[pyo3(signature = (theta, *, length=None))]
    fn expected_trajectory<'py>(
        &self,
        py: Python<'py>,
        theta: &Bound<'_, PyAny>,
        length: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let t = theta_arg(&self.inner, theta)?;
        let x = py.detach(|| self.inner.expected_trajectory(&t, length));
        Ok(matrix_to_py(py, &x))
    }
}
