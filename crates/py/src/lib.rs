//! Python bindings of actrack (module `actrack._actrack`, packaged by maturin as `actrack`).
//!
//! The Python package re-exports everything from `python/actrack/__init__.py`; the stubs are in
//! `python/actrack/_actrack.pyi`. This crate holds no algorithm: each class or function wraps a
//! Rust API of `actrack-phmm` or `actrack`, converts numpy arrays at the boundary
//! ([`convert`]), maps errors to `actrack.ActrackError` (a `ValueError`) or
//! `actrack.ActrackOSError` (an `OSError`) ([`errors`]), and releases the GIL around heavy work.
//!
//! Modules: [`models`] (`Hmm`, `Phmm`, `FitReport`, `ThetaEstimate`), [`io`] (`ActionModel`,
//! `load_mocap`, `Scene`, `evaluate`), [`tracker`] (`Tracker`, `Estimate`, `track_video`,
//! `centred_median`, `edge_image`, `contour_likelihood`).

// pyo3 extracts arguments as owned values (`PathBuf`, `PyRef`), so by-value parameters are the
// binding convention here, not an oversight.
#![allow(clippy::needless_pass_by_value)]

use pyo3::prelude::*;

pub mod convert;
pub mod errors;
pub mod io;
pub mod models;
pub mod tracker;

/// The extension module `actrack._actrack`.
#[pymodule]
fn _actrack(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("ActrackError", py.get_type::<errors::ActrackError>())?;
    m.add("ActrackOSError", py.get_type::<errors::ActrackOSError>())?;
    m.add_class::<models::PyHmm>()?;
    m.add_class::<models::PyPhmm>()?;
    m.add_class::<models::PyFitReport>()?;
    m.add_class::<models::PyThetaEstimate>()?;
    m.add_class::<io::PyActionModel>()?;
    m.add_class::<io::PyScene>()?;
    m.add_function(wrap_pyfunction!(io::load_mocap, m)?)?;
    m.add_function(wrap_pyfunction!(io::evaluate, m)?)?;
    m.add_class::<tracker::PyTracker>()?;
    m.add_class::<tracker::PyEstimate>()?;
    m.add_function(wrap_pyfunction!(tracker::track_video, m)?)?;
    m.add_function(wrap_pyfunction!(tracker::centred_median, m)?)?;
    m.add_function(wrap_pyfunction!(tracker::edge_image, m)?)?;
    m.add_function(wrap_pyfunction!(tracker::contour_likelihood, m)?)?;
    Ok(())
}
