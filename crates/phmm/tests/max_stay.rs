//! `Phmm::with_max_self_transition`: self-transitions capped, the rest of each row scaled.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // bit-identical values are the claim

use actrack_phmm::{EndMode, Phmm, PhmmError};
use nalgebra::{DMatrix, DVector};

/// Four states, max jump 2, one long-dwell state (a₁₁ = 0.98) and a final state with exit.
fn model() -> Phmm {
    let a = DMatrix::from_row_slice(
        4,
        4,
        &[
            0.5, 0.3, 0.2, 0.0, //
            0.0, 0.98, 0.015, 0.005, //
            0.0, 0.0, 0.9, 0.1, //
            0.0, 0.0, 0.0, 0.95,
        ],
    );
    let exit = [0.0, 0.0, 0.0, 0.05];
    let start = [1.0, 0.0, 0.0, 0.0];
    let bias: Vec<DVector<f64>> = (0..4)
        .map(|i| DVector::from_row_slice(&[0.1 * f64::from(i), -0.05 * f64::from(i)]))
        .collect();
    let weights: Vec<DMatrix<f64>> = (0..4)
        .map(|i| DMatrix::from_row_slice(2, 1, &[0.01 * f64::from(i), 0.02]))
        .collect();
    let covs: Vec<DMatrix<f64>> = (0..4)
        .map(|i| DMatrix::from_diagonal_element(2, 2, 1e-4 * (1.0 + f64::from(i))))
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

#[test]
fn long_dwells_are_capped_and_the_jumps_keep_their_odds() {
    let m = model();
    let c = m.with_max_self_transition(0.92).unwrap();
    for i in 0..4 {
        let row: f64 = (0..4).map(|j| c.transition(i, j)).sum::<f64>() + c.exit_prob(i);
        assert!((row - 1.0).abs() < 1e-12, "row {i} sums to {row}");
        assert!(c.transition(i, i) <= 0.92 + 1e-15);
    }
    // State 1: 0.98 → 0.92, its jumps scaled by 0.08 / 0.02 = 4 (odds 3 : 1 kept).
    assert!((c.transition(1, 1) - 0.92).abs() < 1e-15);
    assert!((c.transition(1, 2) - 0.06).abs() < 1e-12);
    assert!((c.transition(1, 3) - 0.02).abs() < 1e-12);
    // State 3: 0.95 → 0.92, the exit scaled to 0.08.
    assert!((c.exit_prob(3) - 0.08).abs() < 1e-12);
    // States at or below the cap are unchanged, bit for bit.
    for (i, j) in [(0, 0), (0, 1), (0, 2), (2, 2), (2, 3)] {
        assert_eq!(c.transition(i, j), m.transition(i, j));
    }
    // Everything but the transitions is the model's: same means, covariances, start.
    for i in 0..4 {
        assert_eq!(c.mean(i, &[0.3]), m.mean(i, &[0.3]));
        assert_eq!(c.covariance(i), m.covariance(i));
        assert_eq!(c.start_prob(i), m.start_prob(i));
    }
    // A cap of 1 is the model.
    let same = m.with_max_self_transition(1.0).unwrap();
    for i in 0..4 {
        for j in 0..4 {
            assert_eq!(same.transition(i, j), m.transition(i, j));
        }
    }
}

#[test]
fn bad_caps_are_errors() {
    let m = model();
    for cap in [0.0, -0.1, 1.5, f64::NAN] {
        assert!(
            matches!(
                m.with_max_self_transition(cap),
                Err(PhmmError::InvalidParameter { .. })
            ),
            "{cap}"
        );
    }
}

#[test]
fn the_last_state_can_keep_its_dwell() {
    let m = model();
    let c = m.with_max_self_transition_before_last(0.92).unwrap();
    // State 1 is capped as before; the last state keeps 0.95 and its exit 0.05, bit for bit.
    assert!((c.transition(1, 1) - 0.92).abs() < 1e-15);
    assert!((c.transition(1, 2) - 0.06).abs() < 1e-12);
    assert_eq!(c.transition(3, 3), m.transition(3, 3));
    assert_eq!(c.exit_prob(3), m.exit_prob(3));
    let all = m.with_max_self_transition(0.92).unwrap();
    for i in 0..3 {
        for j in 0..4 {
            assert_eq!(c.transition(i, j), all.transition(i, j), "({i}, {j})");
        }
    }
    assert!(matches!(
        m.with_max_self_transition_before_last(f64::NAN),
        Err(PhmmError::InvalidParameter { .. })
    ));
}
