//! Bad input, serde, determinism across thread counts, generation, θ estimation variants,
//! recognition, and the plain `Hmm`.

#![allow(clippy::unwrap_used, clippy::float_cmp)] // helpers outside #[test] fns; exact zeros are the point

mod common;

use actrack_phmm::{
    __private, CovarianceKind, EndMode, Hmm, Phmm, PhmmError, PhmmParams, ThetaEmOptions, recognise,
};
use common::*;
use nalgebra::{DMatrix, DVector};
use rand::Rng;

fn small_set(seed: u64) -> (Phmm, Vec<DMatrix<f64>>, Vec<DVector<f64>>) {
    let truth = smooth_truth(EndMode::MustEnd);
    let (seqs, thetas) = corner_training_set(&truth, seed);
    (truth, seqs, thetas)
}

fn fit12(
    seqs: &[DMatrix<f64>],
    thetas: &[DVector<f64>],
) -> Result<(Phmm, actrack_phmm::FitReport), PhmmError> {
    PhmmParams::new(12)
        .max_iterations(15)
        .check()
        .unwrap()
        .fit(seqs, thetas)
}

#[test]
fn bad_input_gives_typed_errors() {
    let (_, seqs, thetas) = small_set(10);
    // No sequences.
    assert!(matches!(fit12(&[], &[]), Err(PhmmError::Empty { .. })));
    // An empty sequence.
    let mut s = seqs.clone();
    s[3] = DMatrix::zeros(0, 9);
    assert!(matches!(
        fit12(&s, &thetas),
        Err(PhmmError::EmptySequence { index: 3 })
    ));
    // Too short to reach the last state under MustEnd (12 states, J = 3 ⇒ ≥ 5 frames).
    let mut s = seqs.clone();
    s[2] = s[2].rows(0, 4).into_owned();
    let e = fit12(&s, &thetas).unwrap_err();
    assert!(
        matches!(
            e,
            PhmmError::SequenceTooShort {
                index: 2,
                len: 4,
                min_len: 5,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string().contains("EndMode::Free"),
        "the message says what to change: {e}"
    );
    // Callers can check first: the builder knows the minimum.
    let must_end = |n, j| PhmmParams::new(n).max_jump(j).check().unwrap();
    assert_eq!(must_end(12, 3).min_sequence_len(), 5);
    assert_eq!(must_end(20, 3).min_sequence_len(), 8);
    assert_eq!(must_end(6, 1).min_sequence_len(), 6);
    assert_eq!(must_end(1, 1).min_sequence_len(), 1);
    // … but fine without the end constraint.
    let free = PhmmParams::new(12)
        .end_mode(EndMode::Free)
        .max_iterations(3)
        .check()
        .unwrap();
    assert_eq!(free.min_sequence_len(), 1);
    assert!(free.fit(&s, &thetas).is_ok());
    // NaN / inf.
    for bad in [f64::NAN, f64::INFINITY] {
        let mut s = seqs.clone();
        s[1][(5, 4)] = bad;
        assert!(matches!(
            fit12(&s, &thetas),
            Err(PhmmError::NonFinite { row: 5, col: 4, .. })
        ));
        let mut t = thetas.clone();
        t[0][1] = bad;
        assert!(matches!(fit12(&seqs, &t), Err(PhmmError::NonFinite { .. })));
    }
    // θ of the wrong dimension, wrong count.
    let mut t = thetas.clone();
    t[4] = DVector::from_row_slice(&[1.0, 2.0, 3.0]);
    assert!(matches!(
        fit12(&seqs, &t),
        Err(PhmmError::ThetaDimension {
            expected: 2,
            got: 3,
            ..
        })
    ));
    assert!(matches!(
        fit12(&seqs, &thetas[..3]),
        Err(PhmmError::ThetaCount { .. })
    ));
    // θ that cannot determine W: all equal, or collinear (affine dimension 1 < 2).
    let same = vec![DVector::from_row_slice(&[0.3, 0.3]); seqs.len()];
    assert!(matches!(
        fit12(&seqs, &same),
        Err(PhmmError::ThetaRankDeficient { .. })
    ));
    let line: Vec<DVector<f64>> = (0..seqs.len())
        .map(|m| DVector::from_row_slice(&[m as f64, 2.0 * m as f64 + 1.0]))
        .collect();
    let e = fit12(&seqs, &line).unwrap_err();
    assert!(
        matches!(
            e,
            PhmmError::ThetaRankDeficient {
                rank: 1,
                theta_dim: 2,
                needed: 3
            }
        ),
        "{e}"
    );
    // Wrong observation dimension.
    let mut s = seqs.clone();
    s[6] = DMatrix::zeros(20, 8);
    assert!(matches!(
        fit12(&s, &thetas),
        Err(PhmmError::ObservationDimension {
            index: 6,
            expected: 9,
            got: 8
        })
    ));

    // Inference on a fitted model.
    let (model, _) = fit12(&seqs, &thetas).unwrap();
    let th = [0.0, 0.0];
    assert!(matches!(
        model.log_likelihood(&DMatrix::zeros(0, 9), &th),
        Err(PhmmError::EmptySequence { .. })
    ));
    assert!(matches!(
        model.log_likelihood(&DMatrix::zeros(10, 3), &th),
        Err(PhmmError::ObservationDimension { .. })
    ));
    assert!(matches!(
        model.log_likelihood(&seqs[0], &[1.0]),
        Err(PhmmError::ThetaDimension { .. })
    ));
    assert!(matches!(
        model.viterbi(&seqs[0].rows(0, 3).into_owned(), &th),
        Err(PhmmError::SequenceTooShort { .. })
    ));
    assert!(matches!(
        model.posteriors(&seqs[0], &[f64::NAN, 0.0]),
        Err(PhmmError::NonFinite { .. })
    ));
    let mut x = seqs[0].clone();
    x[(0, 0)] = f64::NEG_INFINITY;
    assert!(matches!(
        model.estimate_theta(&x, &ThetaEmOptions::default()),
        Err(PhmmError::NonFinite { .. })
    ));
    assert!(matches!(
        recognise(&[], &seqs[0], &ThetaEmOptions::default()),
        Err(PhmmError::Empty { .. })
    ));
}

#[test]
fn builder_errors_name_the_parameter() {
    let cases: Vec<(PhmmParams, &str)> = vec![
        (PhmmParams::new(0), "n_states"),
        (PhmmParams::new(4).max_jump(0), "max_jump"),
        (PhmmParams::new(4).tolerance(f64::NAN), "tolerance"),
        (PhmmParams::new(4).cov_floor(-1.0), "cov_floor"),
        (
            PhmmParams::new(4).min_occupancy(f64::INFINITY),
            "min_occupancy",
        ),
        (PhmmParams::new(4).transition_floor(0.5), "transition_floor"),
    ];
    for (p, name) in cases {
        match p.check() {
            Err(PhmmError::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
            other => panic!("{name}: expected InvalidParameter, got {other:?}"),
        }
    }
}

#[test]
fn from_params_rejects_inconsistent_models() {
    let mut r = rng(11);
    let good = random_model(&mut r, 4, 2, 2, 1, EndMode::MustEnd, false);
    let a = good.transition_matrix();
    let exit: Vec<f64> = (0..4).map(|i| good.exit_prob(i)).collect();
    let start: Vec<f64> = (0..4).map(|i| good.start_prob(i)).collect();
    let (mus, ws): (Vec<_>, Vec<_>) = (0..4).map(|i| good.mean_affine(i)).unzip();
    let covs: Vec<_> = (0..4).map(|i| good.covariance(i).clone()).collect();
    let build = |a: &DMatrix<f64>, exit: &[f64], covs: &[DMatrix<f64>], j: usize, mode| {
        Phmm::from_params(&start, a, exit, &mus, &ws, covs, j, mode)
    };
    assert!(build(&a, &exit, &covs, 2, EndMode::MustEnd).is_ok());
    let mut outside = a.clone();
    outside[(0, 3)] = 0.1;
    assert!(
        matches!(build(&outside, &exit, &covs, 2, EndMode::MustEnd), Err(PhmmError::InvalidModel(m)) if m.contains("band"))
    );
    let mut unnorm = a.clone();
    unnorm[(1, 1)] += 0.2;
    assert!(build(&unnorm, &exit, &covs, 2, EndMode::MustEnd).is_err());
    assert!(
        build(&a, &exit, &covs, 2, EndMode::None).is_err(),
        "None has no exit"
    );
    let mut bad_cov = covs.clone();
    bad_cov[2] = -bad_cov[2].clone();
    assert!(build(&a, &exit, &bad_cov, 2, EndMode::MustEnd).is_err());
    let mut nan_cov = covs.clone();
    nan_cov[1][(0, 0)] = f64::NAN;
    assert!(matches!(
        build(&a, &exit, &nan_cov, 2, EndMode::MustEnd),
        Err(PhmmError::NonFinite { .. })
    ));
}

#[test]
fn serde_round_trip_is_exact_and_validated() {
    let (_, seqs, thetas) = small_set(12);
    let (model, _) = fit12(&seqs, &thetas).unwrap();
    let json = serde_json::to_string(&model).unwrap();
    let back: Phmm = serde_json::from_str(&json).unwrap();
    let json2 = serde_json::to_string(&back).unwrap();
    if json2 != json {
        let i = json
            .bytes()
            .zip(json2.bytes())
            .position(|(a, b)| a != b)
            .unwrap_or(0);
        panic!(
            "round trip differs at {i}: {} vs {}",
            &json[i.saturating_sub(80)..(i + 40).min(json.len())],
            &json2[i.saturating_sub(80)..(i + 40).min(json2.len())]
        );
    }
    let th = [0.3, -0.2];
    assert_eq!(
        model.log_likelihood(&seqs[0], &th).unwrap().to_bits(),
        back.log_likelihood(&seqs[0], &th).unwrap().to_bits()
    );
    assert_eq!(model.mean(5, &th), back.mean(5, &th));
    // A tampered file is an error, never a panic or a broken model.
    let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
    v["transitions_banded"][0][0] = serde_json::json!(5.0);
    assert!(serde_json::from_value::<Phmm>(v).is_err());
    let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
    v["covariances"][0][0] = serde_json::json!(-1.0);
    assert!(serde_json::from_value::<Phmm>(v).is_err());
    let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
    v["mean_bias"][0] = serde_json::json!([1.0]);
    assert!(serde_json::from_value::<Phmm>(v).is_err());
}

#[test]
fn fit_is_bitwise_identical_across_thread_counts() {
    let (_, seqs, thetas) = small_set(13);
    let params = PhmmParams::new(12).max_iterations(8).check().unwrap();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let (m, r) = params.fit(&seqs, &thetas).unwrap();
            (
                serde_json::to_string(&m).unwrap(),
                r.log_likelihoods
                    .iter()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>(),
            )
        })
    };
    let one = run(1);
    let two = run(2);
    let three = run(3);
    assert_eq!(one, two);
    assert_eq!(one, three);
}

#[test]
fn sampling_is_seeded_and_follows_the_topology() {
    let truth = smooth_truth(EndMode::MustEnd);
    let th = [0.5, -0.5];
    let (a, sa) = truth.sample(&th, None, &mut rng(7));
    let (b, sb) = truth.sample(&th, None, &mut rng(7));
    assert_eq!(a, b);
    assert_eq!(sa, sb);
    assert_eq!(
        truth.sample_default(&th, Some(20)),
        truth.sample_default(&th, Some(20))
    );
    assert_eq!(
        *sa.last().unwrap(),
        11,
        "MustEnd samples end in the last state"
    );
    assert_eq!(sa[0], 0);
    for w in sa.windows(2) {
        assert!(w[1] >= w[0] && w[1] <= w[0] + 3);
    }
    let (x, s) = truth.sample(&th, Some(40), &mut rng(8));
    assert_eq!((x.nrows(), x.ncols(), s.len()), (40, 9, 40));
    // Sample mean of many draws in one state approaches μ_i(θ).
    let mut r = rng(9);
    let mut acc = DVector::<f64>::zeros(9);
    let mut count = 0.0;
    for _ in 0..300 {
        let (x, s) = truth.sample(&th, Some(3), &mut r);
        for (t, &q) in s.iter().enumerate() {
            if q == 0 {
                acc += x.row(t).transpose();
                count += 1.0;
            }
        }
    }
    let err = (acc / count - truth.mean(0, &th)).amax();
    assert!(err < 0.05, "sample mean error {err}");
}

#[test]
fn expected_trajectory_follows_the_means() {
    let truth = smooth_truth(EndMode::MustEnd);
    let th = [-0.4, 0.8];
    let x = truth.expected_trajectory(&th, None);
    // Median length: mean dwell ≈ 1/(1 − 0.6) frames per state, skips shorten it.
    assert!(x.nrows() > 12 && x.nrows() < 60, "length {}", x.nrows());
    let first = x.row(0).transpose();
    assert!(
        (first - truth.mean(0, &th)).amax() < 1e-12,
        "starts at μ_1(θ)"
    );
    let last = x.row(x.nrows() - 1).transpose();
    let (to_last, to_mid) = (
        (&last - truth.mean(11, &th)).norm(),
        (&last - truth.mean(5, &th)).norm(),
    );
    assert!(to_last < to_mid, "ends near μ_N(θ): {to_last} vs {to_mid}");
    assert_eq!(truth.expected_trajectory(&th, Some(7)).nrows(), 7);
    let none = smooth_truth(EndMode::None);
    let y = none.expected_trajectory(&th, None);
    assert!(y.nrows() > 10 && y.nrows() < 100);
}

#[test]
fn theta_estimation_map_multistart_and_recognition() {
    let truth = smooth_truth(EndMode::MustEnd);
    let (seqs, thetas) = corner_training_set(&truth, 14);
    let (model, _) = PhmmParams::new(12)
        .max_iterations(60)
        .check()
        .unwrap()
        .fit(&seqs, &thetas)
        .unwrap();
    let th = [0.6, -0.7];
    let (x, _) = truth.sample(&th, None, &mut rng(15));
    let ml = model
        .estimate_theta(&x, &ThetaEmOptions::default())
        .unwrap();
    assert!(
        (ml.theta[0] - th[0]).abs() < 0.15 && (ml.theta[1] - th[1]).abs() < 0.15,
        "{:?}",
        ml.theta
    );
    let multi = model
        .estimate_theta(
            &x,
            &ThetaEmOptions {
                multi_start: true,
                ..Default::default()
            },
        )
        .unwrap();
    assert!(multi.log_likelihood >= ml.log_likelihood - 1e-6);
    // MAP on the first frames only (W ≈ 0 early, H ill-conditioned): a tight prior dominates.
    let early = x.rows(0, 5).into_owned();
    let free = PhmmParams::new(12)
        .end_mode(EndMode::Free)
        .max_iterations(30)
        .check()
        .unwrap();
    let (fmodel, _) = free.fit(&seqs, &thetas).unwrap();
    let prior_mean = DVector::from_row_slice(&[0.2, 0.1]);
    let opts = ThetaEmOptions {
        prior: Some((prior_mean.clone(), DMatrix::identity(2, 2) * 1e-6)),
        ..Default::default()
    };
    let map = fmodel.estimate_theta(&early, &opts).unwrap();
    assert!(
        (map.theta.clone() - prior_mean).amax() < 1e-3,
        "tight prior: {:?}",
        map.theta
    );
    let opts = ThetaEmOptions {
        prior: Some((DVector::zeros(2), DMatrix::identity(2, 2) * 4.0)),
        ..Default::default()
    };
    let map = fmodel.estimate_theta(&x, &opts).unwrap();
    assert!(
        (map.theta[0] - th[0]).abs() < 0.2,
        "weak prior keeps the data's answer: {:?}",
        map.theta
    );
    // Caller units: scaling θ by 10 in training scales the estimate by 10.
    let thetas10: Vec<DVector<f64>> = thetas.iter().map(|t| t * 10.0).collect();
    let (m10, _) = PhmmParams::new(12)
        .max_iterations(60)
        .check()
        .unwrap()
        .fit(&seqs, &thetas10)
        .unwrap();
    let e10 = m10.estimate_theta(&x, &ThetaEmOptions::default()).unwrap();
    assert!(
        (e10.theta.clone() / 10.0 - ml.theta.clone()).amax() < 1e-3,
        "{:?} vs {:?}",
        e10.theta,
        ml.theta
    );
    // Recognition: a sequence of this action scores higher under its own model than under a
    // model of a different action (means shifted).
    let other_truth = {
        let (n, d) = (12, 9);
        let a = truth.transition_matrix();
        let exit: Vec<f64> = (0..n).map(|i| truth.exit_prob(i)).collect();
        let start: Vec<f64> = (0..n).map(|i| truth.start_prob(i)).collect();
        let (mus, ws): (Vec<_>, Vec<_>) = (0..n)
            .map(|i| {
                let (b, w) = truth.mean_affine(i);
                (b.map(|v| -v) + DVector::from_element(d, 0.5), w)
            })
            .unzip();
        let covs: Vec<_> = (0..n).map(|i| truth.covariance(i).clone()).collect();
        Phmm::from_params(&start, &a, &exit, &mus, &ws, &covs, 3, EndMode::MustEnd).unwrap()
    };
    let (oseqs, othetas) = corner_training_set(&other_truth, 16);
    let (other, _) = PhmmParams::new(12)
        .max_iterations(40)
        .check()
        .unwrap()
        .fit(&oseqs, &othetas)
        .unwrap();
    let res = recognise(&[&model, &other], &x, &ThetaEmOptions::default()).unwrap();
    assert!(res[0].log_likelihood > res[1].log_likelihood);
    assert!(
        res[1].log_likelihood.is_finite(),
        "a far-off model still gives a finite likelihood"
    );
    // The scaled fast path agrees with log space even for the badly fitting model.
    let a = other.log_likelihood(&x, res[1].theta.as_slice()).unwrap();
    let b = __private::log_likelihood_log_space(&other, &x, res[1].theta.as_slice()).unwrap();
    assert!((a - b).abs() < 1e-9 * a.abs().max(1.0), "{a} vs {b}");
}

#[test]
fn scaled_path_falls_back_for_extreme_sequences() {
    // Tiny covariances and a sequence far from every mean: raw densities underflow; the result
    // must still be finite and equal the log-space value.
    let truth = smooth_truth(EndMode::MustEnd);
    let n = 12;
    let start: Vec<f64> = (0..n).map(|i| truth.start_prob(i)).collect();
    let exit: Vec<f64> = (0..n).map(|i| truth.exit_prob(i)).collect();
    let (mus, ws): (Vec<_>, Vec<_>) = (0..n).map(|i| truth.mean_affine(i)).unzip();
    let covs = vec![DMatrix::identity(9, 9) * 1e-6; n];
    let sharp = Phmm::from_params(
        &start,
        &truth.transition_matrix(),
        &exit,
        &mus,
        &ws,
        &covs,
        3,
        EndMode::MustEnd,
    )
    .unwrap();
    let mut r = rng(17);
    let x = DMatrix::from_fn(30, 9, |_, _| 5.0 + r.random_range(-1.0..1.0));
    let th = [0.0, 0.0];
    let a = sharp.log_likelihood(&x, &th).unwrap();
    let b = __private::log_likelihood_log_space(&sharp, &x, &th).unwrap();
    assert!(
        a.is_finite() && (a - b).abs() < 1e-9 * a.abs(),
        "{a} vs {b}"
    );
    let g = sharp.posteriors(&x, &th).unwrap();
    for t in 0..30 {
        assert!((g.row(t).sum() - 1.0).abs() < 1e-9, "t={t} {}", g.row(t));
    }
}

#[test]
fn plain_hmm_fit_and_inference() {
    let mut r = rng(18);
    let truth = random_model(&mut r, 5, 2, 3, 0, EndMode::MustEnd, false);
    let seqs: Vec<DMatrix<f64>> = (0..10).map(|_| truth.sample(&[], None, &mut r).0).collect();
    for kind in [CovarianceKind::Full, CovarianceKind::Diagonal] {
        let params = PhmmParams::new(5)
            .max_jump(2)
            .covariance(kind)
            .cov_floor(0.0)
            .check()
            .unwrap();
        let (hmm, report) = Hmm::fit(&params, &seqs).unwrap();
        assert!(
            report
                .log_likelihoods
                .windows(2)
                .all(|w| w[1] >= w[0] - 1e-9 * w[0].abs())
        );
        let ll = hmm.log_likelihood(&seqs[0]).unwrap();
        let (path, vlp) = hmm.viterbi(&seqs[0]).unwrap();
        assert!(vlp <= ll);
        assert_eq!(path.len(), seqs[0].nrows());
        assert_eq!(hmm.posteriors(&seqs[0]).unwrap().ncols(), 5);
        if kind == CovarianceKind::Diagonal {
            let c = hmm.as_phmm().covariance(2);
            assert_eq!(c[(0, 1)], 0.0);
        }
        let (x, s) = hmm.sample_seeded(Some(12), 3);
        assert_eq!((x.nrows(), s.len()), (12, 12));
        let json = serde_json::to_string(&hmm).unwrap();
        let back: Hmm = serde_json::from_str(&json).unwrap();
        assert_eq!(
            back.log_likelihood(&seqs[1]).unwrap(),
            hmm.log_likelihood(&seqs[1]).unwrap()
        );
    }
}
