//! `Phmm::marginal`: the exact marginal model of some observation coordinates, and θ estimated
//! from those coordinates only.

#![allow(clippy::unwrap_used)]

use actrack_phmm::{EndMode, Phmm, PhmmError, ThetaEmOptions};
use nalgebra::{DMatrix, DVector};

/// Three states, d = 3, θ 2-D: coordinate 0 is an "elbow" that moves with θ_u, coordinates 1, 2
/// a "fingertip" that moves with θ. Full covariances with correlations.
fn model() -> Phmm {
    let n: u32 = 3;
    let a = DMatrix::from_row_slice(3, 3, &[0.6, 0.4, 0.0, 0.0, 0.7, 0.3, 0.0, 0.0, 0.8]);
    let exit = [0.0, 0.0, 0.2];
    let start = [1.0, 0.0, 0.0];
    let bias: Vec<DVector<f64>> = (0..n)
        .map(|i| DVector::from_row_slice(&[0.1 * f64::from(i), 0.2, -0.1 * f64::from(i)]))
        .collect();
    let weights: Vec<DMatrix<f64>> = (0..n)
        .map(|i| {
            let s = f64::from(i + 1) / f64::from(n);
            DMatrix::from_row_slice(3, 2, &[0.5 * s, 0.0, s, 0.0, 0.0, s])
        })
        .collect();
    let covs: Vec<DMatrix<f64>> = (0..n)
        .map(|i| {
            let v = 1e-4 * (1.0 + f64::from(i));
            DMatrix::from_row_slice(
                3,
                3,
                &[
                    v,
                    0.3 * v,
                    0.1 * v,
                    0.3 * v,
                    2.0 * v,
                    0.2 * v,
                    0.1 * v,
                    0.2 * v,
                    1.5 * v,
                ],
            )
        })
        .collect();
    Phmm::from_params(
        &start,
        &a,
        &exit,
        &bias,
        &weights,
        &covs,
        1,
        EndMode::MustEnd,
    )
    .unwrap()
}

/// The deterministic sequence of `model()` at θ: two frames per state at the state means, plus
/// a small wiggle, with `offset` added to coordinate 0.
fn sequence(m: &Phmm, theta: &[f64], offset: f64) -> DMatrix<f64> {
    let mut rows = Vec::new();
    for i in 0..m.n_states() {
        for k in 0..2_u32 {
            let mut mu = m.mean(i, theta);
            mu[0] += offset;
            mu[1] += 0.002 * (f64::from(k) - 0.5);
            rows.extend(mu.iter().copied());
        }
    }
    DMatrix::from_row_slice(rows.len() / 3, 3, &rows)
}

fn columns(x: &DMatrix<f64>, dims: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(x.nrows(), dims.len(), |t, k| x[(t, dims[k])])
}

#[test]
fn marginal_of_every_coordinate_is_the_model() {
    let m = model();
    let x = sequence(&m, &[0.05, -0.03], 0.0);
    let full = m.marginal(&[0, 1, 2]).unwrap();
    for theta in [[0.0, 0.0], [0.05, -0.03], [-0.2, 0.1]] {
        let a = m.log_likelihood(&x, &theta).unwrap();
        let b = full.log_likelihood(&x, &theta).unwrap();
        assert!((a - b).abs() <= 1e-9 * a.abs().max(1.0), "{a} vs {b}");
    }
}

#[test]
fn marginal_is_the_model_of_the_sub_blocks() {
    let m = model();
    let dims = [2, 1];
    let mg = m.marginal(&dims).unwrap();
    assert_eq!(mg.dim(), 2);
    assert_eq!(mg.theta_dim(), 2);
    // Built by hand from the sub-blocks of the same parameters.
    let n = m.n_states();
    let start: Vec<f64> = (0..n).map(|i| m.start_prob(i)).collect();
    let a = DMatrix::from_fn(n, n, |i, j| m.transition(i, j));
    let exit: Vec<f64> = (0..n).map(|i| m.exit_prob(i)).collect();
    let mut bias = Vec::new();
    let mut w = Vec::new();
    let mut cov = Vec::new();
    for i in 0..n {
        let (b, wi) = m.mean_affine(i);
        let c = m.covariance(i);
        bias.push(DVector::from_fn(2, |r, _| b[dims[r]]));
        w.push(DMatrix::from_fn(2, 2, |r, q| wi[(dims[r], q)]));
        cov.push(DMatrix::from_fn(2, 2, |r, q| c[(dims[r], dims[q])]));
    }
    let by_hand =
        Phmm::from_params(&start, &a, &exit, &bias, &w, &cov, 1, EndMode::MustEnd).unwrap();
    let x = columns(&sequence(&m, &[0.05, -0.03], 0.01), &dims);
    for theta in [[0.0, 0.0], [0.05, -0.03], [0.3, 0.2]] {
        let p = mg.log_likelihood(&x, &theta).unwrap();
        let q = by_hand.log_likelihood(&x, &theta).unwrap();
        assert!((p - q).abs() <= 1e-9 * p.abs().max(1.0), "{p} vs {q}");
        for i in 0..n {
            let mu = mg.mean(i, &theta);
            let full = m.mean(i, &theta);
            assert!((mu[0] - full[2]).abs() < 1e-12 && (mu[1] - full[1]).abs() < 1e-12);
        }
    }
}

#[test]
fn theta_from_the_fingertip_ignores_an_offset_elsewhere() {
    let m = model();
    let truth = [0.04, -0.02];
    // A demonstrator whose "elbow" sits 1 cm off the model: the full estimate is pulled away,
    // the fingertip marginal is not.
    let x = sequence(&m, &truth, 0.01);
    let opts = ThetaEmOptions::default();
    let full = m.estimate_theta(&x, &opts).unwrap();
    let tip = m
        .marginal(&[1, 2])
        .unwrap()
        .estimate_theta(&columns(&x, &[1, 2]), &opts)
        .unwrap();
    let err = |t: &DVector<f64>| (t[0] - truth[0]).hypot(t[1] - truth[1]);
    assert!(
        err(&tip.theta) < 1e-3,
        "fingertip θ error {}",
        err(&tip.theta)
    );
    assert!(
        err(&full.theta) > 5.0 * err(&tip.theta).max(1e-4),
        "full θ error {} (fingertip {})",
        err(&full.theta),
        err(&tip.theta)
    );
    // Multi-start is carried over (the training θ set is part of the marginal).
    let ms = m
        .marginal(&[1, 2])
        .unwrap()
        .estimate_theta(
            &columns(&x, &[1, 2]),
            &ThetaEmOptions {
                multi_start: true,
                ..ThetaEmOptions::default()
            },
        )
        .unwrap();
    assert!(err(&ms.theta) < 1e-3);
}

#[test]
fn bad_coordinates_are_errors() {
    let m = model();
    for dims in [&[][..], &[3][..], &[0, 0][..], &[1, 2, 1][..]] {
        let e = m.marginal(dims).unwrap_err();
        assert!(
            matches!(e, PhmmError::InvalidParameter { name: "dims", .. }),
            "{dims:?}: {e}"
        );
    }
    assert!(m.marginal(&[2]).is_ok());
}
