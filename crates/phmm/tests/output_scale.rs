//! `Phmm::with_output_scale`: the model of `y' = D y`, checked against the change of variables
//! `log p'(D X | θ) = log p(X | θ) − T Σ_k log d_k` and against the scaled means and covariances;
//! `Phmm::with_covariance_scale` against the Gaussian's closed form.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // unchanged transitions are bit-identical

use actrack_phmm::{EndMode, Phmm, PhmmError};
use nalgebra::{DMatrix, DVector};

mod common;

/// Three states, 3-D observations, 2-D θ, full covariances (off-diagonal terms make the
/// `D Σ D` test meaningful).
fn model() -> Phmm {
    let a = DMatrix::from_row_slice(
        3,
        3,
        &[
            0.6, 0.3, 0.1, //
            0.0, 0.8, 0.2, //
            0.0, 0.0, 0.9,
        ],
    );
    let exit = [0.0, 0.0, 0.1];
    let start = [0.7, 0.3, 0.0];
    let bias: Vec<DVector<f64>> = (0..3)
        .map(|i| {
            let i = f64::from(i);
            DVector::from_row_slice(&[0.1 * i, -0.2 + 0.05 * i, -0.3 * i])
        })
        .collect();
    let weights: Vec<DMatrix<f64>> = (0..3)
        .map(|i| {
            let i = f64::from(i);
            DMatrix::from_row_slice(3, 2, &[0.02, 0.01 * i, -0.03, 0.0, 0.01 * i, 0.04])
        })
        .collect();
    let covs: Vec<DMatrix<f64>> = (0..3)
        .map(|i| {
            let s = 1e-3 * (1.0 + f64::from(i));
            DMatrix::from_row_slice(
                3,
                3,
                &[
                    s,
                    0.3 * s,
                    -0.2 * s, //
                    0.3 * s,
                    2.0 * s,
                    0.1 * s, //
                    -0.2 * s,
                    0.1 * s,
                    1.5 * s,
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
        2,
        EndMode::MustEnd,
    )
    .unwrap()
}

const SCALE: [f64; 3] = [1.0, 0.7, 1.6];

#[test]
fn means_and_covariances_are_scaled() {
    let m = model();
    let s = m.with_output_scale(&SCALE).unwrap();
    let d = DMatrix::from_diagonal(&DVector::from_row_slice(&SCALE));
    for i in 0..3 {
        for theta in [[0.0, 0.0], [0.3, -0.2], [-1.0, 2.0]] {
            let want = &d * m.mean(i, &theta);
            assert!(
                (s.mean(i, &theta) - want).amax() < 1e-12,
                "state {i}, θ {theta:?}"
            );
        }
        let want = &d * m.covariance(i) * &d;
        assert!((s.covariance(i) - want).amax() < 1e-15, "state {i}");
        for j in 0..3 {
            assert_eq!(s.transition(i, j), m.transition(i, j));
        }
        assert_eq!(s.exit_prob(i), m.exit_prob(i));
        assert_eq!(s.start_prob(i), m.start_prob(i));
    }
}

#[test]
fn likelihood_follows_the_change_of_variables() {
    let m = model();
    let s = m.with_output_scale(&SCALE).unwrap();
    let log_det: f64 = SCALE.iter().map(|d| d.ln()).sum();
    for (theta, seed) in [([0.1, 0.2], 1_u64), ([-0.5, 0.4], 2), ([0.0, 0.0], 3)] {
        let mut rng = common::rng(seed);
        let (x, _) = m.sample(&theta, Some(25), &mut rng);
        let mut y = x.clone();
        for mut row in y.row_iter_mut() {
            for (k, v) in row.iter_mut().enumerate() {
                *v *= SCALE[k];
            }
        }
        let lp = m.log_likelihood(&x, &theta).unwrap();
        let lq = s.log_likelihood(&y, &theta).unwrap();
        let want = lp - x.nrows() as f64 * log_det;
        assert!(
            (lq - want).abs() < 1e-9 * want.abs().max(1.0),
            "seed {seed}: {lq} against {want}"
        );
    }
}

#[test]
fn bad_scales_are_errors() {
    let m = model();
    for bad in [
        vec![1.0, 1.0],
        vec![1.0, 0.0, 1.0],
        vec![1.0, -2.0, 1.0],
        vec![1.0, f64::NAN, 1.0],
        vec![f64::INFINITY, 1.0, 1.0],
    ] {
        assert!(
            matches!(
                m.with_output_scale(&bad),
                Err(PhmmError::InvalidParameter { name: "scale", .. })
            ),
            "{bad:?}"
        );
    }
    // The identity scale gives the same model.
    let same = m.with_output_scale(&[1.0; 3]).unwrap();
    assert_eq!(same.covariance(2), m.covariance(2));
}

#[test]
fn covariance_scale_against_the_closed_form() {
    let m = model();
    let c = 0.4;
    let s = m.with_covariance_scale(c).unwrap();
    for i in 0..3 {
        assert!(
            (s.covariance(i) - m.covariance(i) * c).amax() < 1e-18,
            "state {i}"
        );
        assert_eq!(s.mean(i, &[0.2, -0.1]), m.mean(i, &[0.2, -0.1]));
    }
    // A one-state model and a one-frame sequence: log N(μ + √c (x − μ); μ, cΣ) =
    // log N(x; μ, Σ) − (d/2) ln c, the start and exit terms being the same in both models.
    let a = DMatrix::from_row_slice(1, 1, &[0.9]);
    let mu = DVector::from_row_slice(&[0.1, -0.2, 0.3]);
    let one = Phmm::from_params(
        &[1.0],
        &a,
        &[0.1],
        std::slice::from_ref(&mu),
        &[DMatrix::from_row_slice(
            3,
            2,
            &[0.02, 0.0, -0.01, 0.03, 0.0, 0.01],
        )],
        &[m.covariance(1).clone()],
        1,
        EndMode::MustEnd,
    )
    .unwrap();
    let scaled = one.with_covariance_scale(c).unwrap();
    let theta = [0.3, -0.4];
    let mean = one.mean(0, &theta);
    let x = DMatrix::from_row_slice(1, 3, &[0.13, -0.25, 0.27]);
    let y = DMatrix::from_fn(1, 3, |_, k| mean[k] + c.sqrt() * (x[(0, k)] - mean[k]));
    let lp = one.log_likelihood(&x, &theta).unwrap();
    let lq = scaled.log_likelihood(&y, &theta).unwrap();
    let want = lp - 1.5 * c.ln();
    assert!((lq - want).abs() < 1e-9, "{lq} against {want}");
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            m.with_covariance_scale(bad),
            Err(PhmmError::InvalidParameter { name: "c", .. })
        ));
    }
}
