//! numpy ↔ nalgebra conversions with shape checks and clear messages.
//!
//! Every array argument goes through [`PyArrayLikeDyn`] with `AllowTypeChange`, so float64 arrays
//! are read in place, float32 (and integer) arrays and nested lists are converted once, and the
//! dimension check is ours (a `ValueError` naming the argument and the expected shape instead of
//! numpy's generic `TypeError`).

use nalgebra::{DMatrix, DVector};
use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayLikeDyn};
use pyo3::prelude::*;

use crate::errors::value_error;

/// An array argument of any dimension, as float64.
pub(crate) type ArrayArg<'py> = PyArrayLikeDyn<'py, f64, AllowTypeChange>;

/// Read `obj` as a float64 array (any dimension), with the argument name in the error.
pub(crate) fn array_arg<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<ArrayArg<'py>> {
    obj.extract::<ArrayArg<'py>>().map_err(|e| {
        value_error(format!(
            "{name} must be a numeric array (numpy float64/float32 or nested lists): {e}"
        ))
    })
}

fn shape_str(shape: &[usize]) -> String {
    let parts: Vec<String> = shape.iter().map(ToString::to_string).collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// A 1-D array as a `Vec<f64>`; `len` checks the length when given.
pub(crate) fn vector(obj: &Bound<'_, PyAny>, name: &str, len: Option<usize>) -> PyResult<Vec<f64>> {
    let a = array_arg(obj, name)?;
    let v = a.as_array();
    if v.ndim() != 1 {
        return Err(value_error(format!(
            "{name} must be a 1-D array, got shape {}",
            shape_str(v.shape())
        )));
    }
    if let Some(n) = len
        && v.len() != n
    {
        return Err(value_error(format!(
            "{name} must have {n} values, got {}",
            v.len()
        )));
    }
    Ok(v.iter().copied().collect())
}

/// A 2-D array (rows × cols) as a `DMatrix`; `cols` checks the number of columns when given.
pub(crate) fn matrix(
    obj: &Bound<'_, PyAny>,
    name: &str,
    cols: Option<usize>,
) -> PyResult<DMatrix<f64>> {
    let a = array_arg(obj, name)?;
    let v = a.as_array();
    if v.ndim() != 2 {
        return Err(value_error(format!(
            "{name} must be a 2-D array (one row per frame), got shape {}",
            shape_str(v.shape())
        )));
    }
    let (r, c) = (v.shape()[0], v.shape()[1]);
    if let Some(d) = cols
        && c != d
    {
        return Err(value_error(format!(
            "{name} has {c} columns but {d} are expected (shape {})",
            shape_str(v.shape())
        )));
    }
    Ok(DMatrix::from_row_iterator(r, c, v.iter().copied()))
}

/// A 3-D array (n × rows × cols) as `n` matrices.
pub(crate) fn matrices(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<DMatrix<f64>>> {
    let a = array_arg(obj, name)?;
    let v = a.as_array();
    if v.ndim() != 3 {
        return Err(value_error(format!(
            "{name} must be a 3-D array, got shape {}",
            shape_str(v.shape())
        )));
    }
    let (r, c) = (v.shape()[1], v.shape()[2]);
    Ok(v.outer_iter()
        .map(|m| DMatrix::from_row_iterator(r, c, m.iter().copied()))
        .collect())
}

/// A list of 2-D arrays (sequences of varying length) or one 3-D array of equal-length sequences.
pub(crate) fn sequences(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<DMatrix<f64>>> {
    if let Ok(a) = obj.extract::<ArrayArg<'_>>()
        && a.as_array().ndim() == 3
    {
        return matrices(obj, name);
    }
    let mut out = Vec::new();
    for (k, item) in obj
        .try_iter()
        .map_err(|_| value_error(format!("{name} must be a list of 2-D arrays (T, d)")))?
        .enumerate()
    {
        out.push(matrix(&item?, &format!("{name}[{k}]"), None)?);
    }
    Ok(out)
}

/// A matrix as a new numpy array of the same shape.
pub(crate) fn matrix_to_py<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    let (r, c) = m.shape();
    Array2::from_shape_fn((r, c), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// A vector as a new 1-D numpy array.
pub(crate) fn vec_to_py(py: Python<'_>, v: Vec<f64>) -> Bound<'_, PyArray1<f64>> {
    Array1::from(v).into_pyarray(py)
}

/// A vector as a new 1-D numpy array.
pub(crate) fn dvector_to_py<'py>(py: Python<'py>, v: &DVector<f64>) -> Bound<'py, PyArray1<f64>> {
    vec_to_py(py, v.as_slice().to_vec())
}

/// Equal-shaped matrices as an (n, rows, cols) numpy array.
pub(crate) fn stack_to_py<'py>(
    py: Python<'py>,
    ms: &[DMatrix<f64>],
    rows: usize,
    cols: usize,
) -> Bound<'py, PyArray3<f64>> {
    Array3::from_shape_fn((ms.len(), rows, cols), |(k, i, j)| ms[k][(i, j)]).into_pyarray(py)
}

/// Row vectors as an (n, len) numpy array.
pub(crate) fn rows_to_py<'py>(
    py: Python<'py>,
    rows: &[Vec<f64>],
    len: usize,
) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((rows.len(), len), |(i, j)| rows[i][j]).into_pyarray(py)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_print_like_numpy() {
        assert_eq!(shape_str(&[3]), "(3,)");
        assert_eq!(shape_str(&[2, 9]), "(2, 9)");
    }
}
