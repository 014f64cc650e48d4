//! Small linear-algebra helpers: Cholesky with jitter retries, the eigenvalue floor of SPEC §1.7,
//! packed triangular solves used by the emission kernel. Never an explicit inverse.

use nalgebra::{DMatrix, SymmetricEigen};

/// Number of jitter retries when a Cholesky factorisation fails (SPEC §1.7).
pub(crate) const CHOLESKY_RETRIES: usize = 5;

/// Lower Cholesky factor of a symmetric matrix, or `None` if it is not positive definite.
pub(crate) fn cholesky_lower(m: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let l = nalgebra::Cholesky::new(m.clone())?.l();
    // nalgebra accepts tiny/zero pivots in some cases; demand a strictly positive, finite diagonal.
    let ok = (0..l.nrows()).all(|k| {
        let v = l[(k, k)];
        v.is_finite() && v > 0.0
    });
    ok.then_some(l)
}

/// Cholesky with the SPEC §1.7 fallback: add `10·ε·I`, `20·ε·I`, … up to [`CHOLESKY_RETRIES`] times.
/// `eps` should be a scale of the matrix (e.g. `1e-3·tr/d`, or a small absolute value).
/// Returns the (possibly jittered) matrix and its factor.
pub(crate) fn cholesky_with_jitter(
    m: &DMatrix<f64>,
    eps: f64,
) -> Option<(DMatrix<f64>, DMatrix<f64>)> {
    if let Some(l) = cholesky_lower(m) {
        return Some((m.clone(), l));
    }
    let d = m.nrows();
    let eps = if eps.is_finite() && eps > 0.0 {
        eps
    } else {
        1e-12
    };
    let mut jitter = 10.0 * eps;
    for _ in 0..CHOLESKY_RETRIES {
        let mut mj = m.clone();
        for k in 0..d {
            mj[(k, k)] += jitter;
        }
        if let Some(l) = cholesky_lower(&mj) {
            return Some((mj, l));
        }
        jitter *= 10.0;
    }
    None
}

/// Symmetrise in place: `m ← (m + mᵀ)/2`.
pub(crate) fn symmetrise(m: &mut DMatrix<f64>) {
    let d = m.nrows();
    for r in 0..d {
        for c in 0..r {
            let v = 0.5 * (m[(r, c)] + m[(c, r)]);
            m[(r, c)] = v;
            m[(c, r)] = v;
        }
    }
}

/// Eigenvalue-clamp floor of SPEC §1.7: `Σ = V diag(max(λ, floor_var)) Vᵀ`.
/// Returns the input unchanged when every eigenvalue is already at or above the floor.
pub(crate) fn eigen_floor(m: &DMatrix<f64>, floor_var: f64) -> DMatrix<f64> {
    if floor_var <= 0.0 {
        return m.clone();
    }
    let eig = SymmetricEigen::new(m.clone());
    if eig.eigenvalues.iter().all(|&l| l >= floor_var) {
        return m.clone();
    }
    let d = m.nrows();
    let v = &eig.eigenvectors;
    let mut out = DMatrix::zeros(d, d);
    for k in 0..d {
        let l = eig.eigenvalues[k].max(floor_var);
        for r in 0..d {
            let vr = v[(r, k)] * l;
            for c in 0..d {
                out[(r, c)] += vr * v[(c, k)];
            }
        }
    }
    symmetrise(&mut out);
    out
}

/// `Σ_k log L_kk` = ½ log det Σ for a lower Cholesky factor.
pub(crate) fn half_log_det(l: &DMatrix<f64>) -> f64 {
    (0..l.nrows()).map(|k| l[(k, k)].ln()).sum()
}

/// Pack the lower triangle of `l` row by row (row r holds `l[r][0..=r]`).
pub(crate) fn pack_lower(l: &DMatrix<f64>, out: &mut Vec<f64>) {
    let d = l.nrows();
    for r in 0..d {
        for c in 0..=r {
            out.push(l[(r, c)]);
        }
    }
}

/// Squared norm of `L⁻¹ r` by forward substitution on a packed lower factor (no allocation:
/// `z` is scratch of length d). `inv_diag` holds `1/L_kk`.
#[inline]
pub(crate) fn mahalanobis_packed(lp: &[f64], inv_diag: &[f64], r: &[f64], z: &mut [f64]) -> f64 {
    let d = r.len();
    let mut acc = 0.0;
    let mut off = 0;
    for k in 0..d {
        let row = &lp[off..off + k];
        let mut s = r[k];
        for (a, b) in row.iter().zip(&z[..k]) {
            s -= a * b;
        }
        let zk = s * inv_diag[k];
        z[k] = zk;
        acc += zk * zk;
        off += k + 1;
    }
    acc
}

/// Solve `L y = b` in place (lower triangular, dense nalgebra factor).
pub(crate) fn solve_lower_in_place(l: &DMatrix<f64>, b: &mut [f64]) {
    let d = b.len();
    for k in 0..d {
        let mut s = b[k];
        for c in 0..k {
            s -= l[(k, c)] * b[c];
        }
        b[k] = s / l[(k, k)];
    }
}

/// Solve `Lᵀ y = b` in place (L lower triangular).
pub(crate) fn solve_upper_t_in_place(l: &DMatrix<f64>, b: &mut [f64]) {
    let d = b.len();
    for k in (0..d).rev() {
        let mut s = b[k];
        for r in k + 1..d {
            s -= l[(r, k)] * b[r];
        }
        b[k] = s / l[(k, k)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigen_floor_raises_small_eigenvalues_only() {
        let m = DMatrix::from_row_slice(2, 2, &[4.0, 0.0, 0.0, 1e-6]);
        let f = eigen_floor(&m, 0.01);
        assert!((f[(0, 0)] - 4.0).abs() < 1e-12);
        assert!((f[(1, 1)] - 0.01).abs() < 1e-12);
    }

    #[test]
    fn packed_mahalanobis_matches_dense_solve() {
        let s = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]);
        let l = cholesky_lower(&s).unwrap();
        let mut lp = Vec::new();
        pack_lower(&l, &mut lp);
        let inv: Vec<f64> = (0..3).map(|k| 1.0 / l[(k, k)]).collect();
        let r = [0.3, -1.0, 2.0];
        let mut z = [0.0; 3];
        let m = mahalanobis_packed(&lp, &inv, &r, &mut z);
        let rv = nalgebra::DVector::from_row_slice(&r);
        let want = (rv.transpose() * s.clone().try_inverse().unwrap() * rv)[(0, 0)];
        assert!((m - want).abs() < 1e-12);
        let mut b = r;
        solve_lower_in_place(&l, &mut b);
        solve_upper_t_in_place(&l, &mut b);
        let x = nalgebra::DVector::from_row_slice(&b);
        assert!((s * x - nalgebra::DVector::from_row_slice(&r)).norm() < 1e-12);
    }
}
