//! SPEC §7 conformance tests 1–6, against brute force on small models.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // helpers outside #[test] fns; exact zeros are the point

mod common;

use actrack_phmm::{__private, EndMode, PhmmParams, ThetaEmOptions};
use common::*;
use nalgebra::{DMatrix, DVector};
use rand::Rng;

const MODES: [EndMode; 3] = [EndMode::MustEnd, EndMode::Free, EndMode::None];

/// Test 1: log P equals the brute-force sum over all paths (N = 4, J = 3, d = 2, T = 5), with and
/// without an end state; the scaled and log-space recursions agree.
#[test]
fn t1_forward_matches_brute_force() {
    let mut r = rng(1);
    for mode in MODES {
        for trial in 0..10 {
            let p = trial % 2; // plain and parametric
            let model = random_model(&mut r, 4, 3, 2, p, mode, trial % 3 != 0);
            let theta: Vec<f64> = (0..p).map(|_| normal(&mut r)).collect();
            let x = random_seq(&mut r, 5, 2);
            let brute = logsumexp(all_paths(&model, &x, &theta).into_iter().map(|(_, lp)| lp));
            let ll = model.log_likelihood(&x, &theta).unwrap();
            assert!(
                (ll - brute).abs() < 1e-10,
                "{mode:?}: {ll} vs brute force {brute}"
            );
            let ll_log = __private::log_likelihood_log_space(&model, &x, &theta).unwrap();
            assert!(
                (ll - ll_log).abs() < 1e-9,
                "{mode:?}: scaled {ll} vs log-space {ll_log}"
            );
        }
    }
}

/// Test 2: Σ_i γ_t(i) = 1, Σ_j ξ(i, j) = Σ_{t<T} γ_t(i), ξ zero outside the band; both equal
/// their brute-force values.
#[test]
fn t2_posterior_invariants_and_brute_force() {
    let mut r = rng(2);
    for mode in MODES {
        for trial in 0..6 {
            let model = random_model(&mut r, 4, 3, 2, 0, mode, trial % 2 == 0);
            let x = random_seq(&mut r, 5, 2);
            let (gamma, xi, lp) = model.posteriors_with_transitions(&x, &[]).unwrap();
            let paths = all_paths(&model, &x, &[]);
            let (t_len, n) = (5, 4);
            let mut g_bf = DMatrix::<f64>::zeros(t_len, n);
            let mut xi_bf = DMatrix::<f64>::zeros(n, n);
            for (path, plp) in &paths {
                let w = (plp - lp).exp();
                for t in 0..t_len {
                    g_bf[(t, path[t])] += w;
                    if t + 1 < t_len {
                        xi_bf[(path[t], path[t + 1])] += w;
                    }
                }
            }
            for t in 0..t_len {
                let s: f64 = gamma.row(t).sum();
                assert!((s - 1.0).abs() < 1e-12, "Σγ_{t} = {s}");
                for i in 0..n {
                    assert!((gamma[(t, i)] - g_bf[(t, i)]).abs() < 1e-10);
                }
            }
            for i in 0..n {
                let row: f64 = xi.row(i).sum();
                let occ: f64 = (0..t_len - 1).map(|t| gamma[(t, i)]).sum();
                assert!(
                    (row - occ).abs() < 1e-12,
                    "Σ_j ξ(i,j) = {row} vs Σ_t<T γ = {occ}"
                );
                for j in 0..n {
                    if j < i || j > i + 3 {
                        assert_eq!(xi[(i, j)], 0.0, "ξ outside the band");
                    }
                    assert!((xi[(i, j)] - xi_bf[(i, j)]).abs() < 1e-10, "ξ({i},{j})");
                }
            }
        }
    }
}

fn check_rows_and_band(model: &actrack_phmm::Phmm, j: usize) {
    let n = model.n_states();
    for i in 0..n {
        let s: f64 = (0..n).map(|k| model.transition(i, k)).sum::<f64>() + model.exit_prob(i);
        assert!((s - 1.0).abs() < 1e-12, "row {i} sums to {s}");
        let dense = model.transition_matrix();
        for k in 0..n {
            if k < i || k > i + j {
                assert_eq!(dense[(i, k)], 0.0, "band zero ({i},{k}) became non-zero");
            }
        }
        if model.end_mode() == EndMode::MustEnd && i + 1 < n {
            assert_eq!(model.exit_prob(i), 0.0);
        }
        if model.end_mode() == EndMode::None {
            assert_eq!(model.exit_prob(i), 0.0);
        }
    }
}

fn non_decreasing(lls: &[f64], rel: f64) {
    for w in lls.windows(2) {
        assert!(
            w[1] >= w[0] - rel * w[0].abs(),
            "log-likelihood decreased: {} -> {}",
            w[0],
            w[1]
        );
    }
}

/// Test 3: with the floor disabled, Baum–Welch never decreases the total log-likelihood over
/// several sequences; band zeros stay zero; rows sum to one.
#[test]
fn t3_baum_welch_monotone_band_rows() {
    let mut r = rng(3);
    for mode in MODES {
        for p in [0usize, 2] {
            let truth = random_model(&mut r, 5, 2, 2, p, mode, false);
            let mut seqs = Vec::new();
            let mut thetas = Vec::new();
            for m in 0..8 {
                let th: Vec<f64> = (0..p).map(|_| r.random_range(-1.0..1.0)).collect();
                let len = if mode == EndMode::MustEnd {
                    None
                } else {
                    Some(25 + m)
                };
                let (x, _) = loop {
                    let s = truth.sample(&th, len, &mut r);
                    if s.0.nrows() >= 4 {
                        break s;
                    }
                };
                seqs.push(x);
                if p > 0 {
                    thetas.push(DVector::from_vec(th));
                }
            }
            let params = PhmmParams::new(5)
                .max_jump(2)
                .end_mode(mode)
                .cov_floor(0.0)
                .max_iterations(40)
                .tolerance(0.0)
                .check()
                .unwrap();
            let (model, report) = params.fit(&seqs, &thetas).unwrap();
            assert_eq!(report.log_likelihoods.len(), report.iterations + 1);
            non_decreasing(&report.log_likelihoods, 1e-12);
            check_rows_and_band(&model, 2);
        }
    }
}

/// Test 4: Viterbi respects the band, ends in N under MustEnd, its log-prob is ≤ log P and it
/// equals the brute-force best path.
#[test]
fn t4_viterbi_matches_brute_force() {
    let mut r = rng(4);
    for mode in MODES {
        for trial in 0..8 {
            let model = random_model(&mut r, 4, 3, 2, 0, mode, trial % 2 == 0);
            let x = random_seq(&mut r, 5, 2);
            let (path, vlp) = model.viterbi(&x, &[]).unwrap();
            let ll = model.log_likelihood(&x, &[]).unwrap();
            assert!(vlp <= ll + 1e-12);
            let best = all_paths(&model, &x, &[]).into_iter().fold(
                (Vec::new(), f64::NEG_INFINITY),
                |b, c| {
                    if c.1 > b.1 { c } else { b }
                },
            );
            assert_eq!(path, best.0, "{mode:?}");
            assert!((vlp - best.1).abs() < 1e-10);
            for w in path.windows(2) {
                assert!(w[1] >= w[0] && w[1] <= w[0] + 3, "path leaves the band");
            }
            if mode == EndMode::MustEnd {
                assert_eq!(*path.last().unwrap(), 3);
            }
        }
    }
}

/// Viterbi ties break to the smaller state index.
#[test]
fn t4_viterbi_ties_prefer_smaller_state() {
    // Two identical states: every path through either has the same probability.
    let cov = DMatrix::identity(1, 1);
    let mu = DVector::from_element(1, 0.0);
    let a = DMatrix::from_row_slice(2, 2, &[0.5, 0.5, 0.0, 1.0]);
    let m = actrack_phmm::Phmm::from_params(
        &[0.5, 0.5],
        &a,
        &[0.0, 0.0],
        &[mu.clone(), mu],
        &[DMatrix::zeros(1, 0), DMatrix::zeros(1, 0)],
        &[cov.clone(), cov],
        1,
        EndMode::None,
    )
    .unwrap();
    let x = DMatrix::from_element(3, 1, 0.1);
    let (path, _) = m.viterbi(&x, &[]).unwrap();
    // 0→0→0 has 0.5·0.5·0.5, 1→1→1 has 0.5·1·1: the unique best is all-ones.
    assert_eq!(path, vec![1, 1, 1]);
    let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1.0]);
    let mu = DVector::from_element(1, 0.0);
    let m = actrack_phmm::Phmm::from_params(
        &[0.5, 0.5],
        &a,
        &[0.0, 0.0],
        &[mu.clone(), mu],
        &[DMatrix::zeros(1, 0), DMatrix::zeros(1, 0)],
        &[DMatrix::identity(1, 1), DMatrix::identity(1, 1)],
        1,
        EndMode::None,
    )
    .unwrap();
    let (path, _) = m.viterbi(&x, &[]).unwrap();
    assert_eq!(
        path,
        vec![0, 0, 0],
        "exact tie must go to the smaller state"
    );
}

/// Test 5: with a fixed hard γ (uniform segmentation) and noiseless data `x = Z_i Ω(θ_m)`, the
/// normal equations recover Z_i to 1e-8 (in the caller's θ units).
#[test]
fn t5_normal_equations_recover_z() {
    let mut r = rng(5);
    let (n, d, p) = (6, 4, 2);
    let z: Vec<DMatrix<f64>> = (0..n)
        .map(|_| DMatrix::from_fn(d, p + 1, |_, _| 2.0 * normal(&mut r)))
        .collect();
    let thetas: Vec<DVector<f64>> = [
        [0.1, 0.2],
        [0.5, 0.2],
        [0.1, 0.6],
        [0.45, 0.55],
        [0.3, 0.35],
        [0.2, 0.5],
    ]
    .iter()
    .map(|t| DVector::from_row_slice(t))
    .collect();
    let mut seqs = Vec::new();
    for (m, th) in thetas.iter().enumerate() {
        let len = 18 + 6 * m; // multiples of N so every state gets whole frames
        let omega = DVector::from_row_slice(&[th[0], th[1], 1.0]);
        seqs.push(DMatrix::from_fn(len, d, |t, k| {
            let i = t * n / len;
            (z[i].row(k) * &omega)[(0, 0)]
        }));
    }
    let params = PhmmParams::new(n).max_iterations(0).check().unwrap();
    let (model, _) = params.fit(&seqs, &thetas).unwrap();
    for i in 0..n {
        let (b, a) = model.mean_affine(i);
        for k in 0..d {
            assert!(
                (b[k] - z[i][(k, p)]).abs() < 1e-8,
                "μ̄[{i}][{k}] = {} vs {}",
                b[k],
                z[i][(k, p)]
            );
            for c in 0..p {
                assert!((a[(k, c)] - z[i][(k, c)]).abs() < 1e-8, "W[{i}][{k},{c}]");
            }
        }
    }
}

/// Test 6: N = 12, d = 9, p_θ = 2, 20 sequences with θ near the corners, noise 0.3. Training
/// log-likelihood non-decreasing; θ-EM on fresh sequences with θ ~ U[−1,1]² within 0.1; θ-EM
/// log-likelihood non-decreasing.
#[test]
fn t6_phmm_em_end_to_end() {
    let truth = smooth_truth(EndMode::MustEnd);
    let (seqs, thetas) = corner_training_set(&truth, 6);
    let params = PhmmParams::new(12).max_iterations(100).check().unwrap();
    let (model, report) = params.fit(&seqs, &thetas).unwrap();
    // The floor (σ_min = 0.005 ≪ 0.3) is on; SPEC tolerates a relative 1e-9 decrease.
    non_decreasing(&report.log_likelihoods, 1e-9);
    let mut r = rng(66);
    let mut worst = 0.0f64;
    for _ in 0..10 {
        let th = [r.random_range(-1.0..1.0), r.random_range(-1.0..1.0)];
        let (x, _) = loop {
            let s = truth.sample(&th, None, &mut r);
            if s.0.nrows() >= 8 {
                break s;
            }
        };
        let est = model
            .estimate_theta(&x, &ThetaEmOptions::default())
            .unwrap();
        non_decreasing(&est.history, 1e-12);
        for k in 0..2 {
            worst = worst.max((est.theta[k] - th[k]).abs());
        }
    }
    eprintln!("test 6: max |θ̂ − θ| = {worst:.4}");
    assert!(worst < 0.1, "max |θ̂ − θ| = {worst}");
}
