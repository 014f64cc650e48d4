//! Behaviour of the whole tracker: construction errors, determinism across thread counts,
//! degenerate frames, estimate invariants and the configuration options.

// Test helpers unwrap freely; exact float comparisons are intended where used.
#![allow(clippy::unwrap_used, clippy::float_cmp)]

use actrack_pf::ActionBalance;
use actrack_pf::synthetic::{self, OracleObservation};
use actrack_pf::{
    ConstantObservation, Estimate, Grammar, KInit, ObservationModel, PfError, PoseSampling,
    ResampleWhen, Resampling, Tracker, TrackerConfig,
};
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

fn models(n: usize) -> (Vec<actrack_phmm::Phmm>, Vec<String>) {
    synthetic::demo_models(n, 20).unwrap()
}

fn truth(action: usize, seed: u64) -> Vec<[f64; 9]> {
    let (m, _) = models(3);
    synthetic::sample_sequence(
        &m[action],
        [0.1, 0.5],
        200,
        &mut Pcg64Mcg::seed_from_u64(seed),
    )
    .0
}

fn config() -> actrack_pf::TrackerConfigBuilder {
    TrackerConfig::builder(synthetic::table_region()).seed(42)
}

fn run(tracker: &mut Tracker, truth: &[[f64; 9]]) -> Vec<Estimate> {
    truth
        .iter()
        .map(|x| {
            tracker.step(&OracleObservation {
                truth: *x,
                sigma: 0.04,
            })
        })
        .collect()
}

/// Bitwise comparison of estimates (Debug prints floats in round-trip form).
fn fingerprint(est: &[Estimate]) -> String {
    format!("{est:?}")
}

#[test]
fn construction_errors() {
    let (m, names) = models(2);
    let c = config().build().unwrap();
    assert!(matches!(
        Tracker::new(&m[..0], vec![], c.clone()),
        Err(PfError::NoModels)
    ));
    assert!(matches!(
        Tracker::new(&m, names[..1].to_vec(), c.clone()),
        Err(PfError::NameCount { .. })
    ));
    let g3 = config()
        .grammar(Grammar::Matrix(vec![vec![1.0 / 3.0; 3]; 3]))
        .build()
        .unwrap();
    assert!(matches!(
        Tracker::new(&m, names.clone(), g3),
        Err(PfError::Grammar(_))
    ));
    // A model that does not generate 9-D poses from a 2-D θ.
    let small = actrack_phmm::Phmm::from_params(
        &[1.0],
        &nalgebra::DMatrix::from_element(1, 1, 0.9),
        &[0.1],
        &[nalgebra::DVector::zeros(3)],
        &[nalgebra::DMatrix::zeros(3, 2)],
        &[nalgebra::DMatrix::identity(3, 3)],
        1,
        actrack_phmm::EndMode::MustEnd,
    )
    .unwrap();
    assert!(matches!(
        Tracker::new([&small], vec!["x".into()], c),
        Err(PfError::ModelShape { dim: 3, .. })
    ));
}

/// The same seed gives bit-identical estimates with 1, 2 and 8 rayon threads; another seed
/// differs.
#[test]
fn deterministic_across_thread_counts() {
    let (m, names) = models(3);
    let seq = truth(1, 3);
    let mut prints = Vec::new();
    for threads in [1, 2, 8] {
        for scheme in [Resampling::Systematic, Resampling::Residual] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let est = pool.install(|| {
                let c = config()
                    .particles(1000)
                    .resampling(scheme)
                    .samples_per_particle(2)
                    .build()
                    .unwrap();
                let mut t = Tracker::new(&m, names.clone(), c).unwrap();
                run(&mut t, &seq)
            });
            prints.push((threads, scheme, fingerprint(&est)));
        }
    }
    for (threads, scheme, p) in &prints[2..] {
        let reference = if *scheme == Resampling::Systematic {
            &prints[0].2
        } else {
            &prints[1].2
        };
        assert!(
            p == reference,
            "{threads} threads, {scheme:?}: estimates differ"
        );
    }
    let other = {
        let c = config().seed(43).particles(1000).build().unwrap();
        let mut t = Tracker::new(&m, names.clone(), c).unwrap();
        fingerprint(&run(&mut t, &seq))
    };
    assert!(other != prints[0].2);
    // reset() replays the same draws.
    let c = config().particles(300).build().unwrap();
    let mut t = Tracker::new(&m, names, c).unwrap();
    let a = fingerprint(&run(&mut t, &seq[..10]));
    t.reset();
    assert_eq!(t.frame(), 0);
    let b = fingerprint(&run(&mut t, &seq[..10]));
    assert_eq!(a, b);
}

/// An observation model that returns no information (−∞ or NaN everywhere) on chosen frames.
struct Blackout<'a> {
    inner: OracleObservation,
    value: Option<f64>,
    _marker: std::marker::PhantomData<&'a ()>,
}

impl ObservationModel for Blackout<'_> {
    fn log_likelihoods(&self, poses: &[[f64; 9]], out: &mut [f64]) {
        match self.value {
            Some(v) => out.fill(v),
            None => self.inner.log_likelihoods(poses, out),
        }
    }
}

/// Frames whose likelihoods are all −∞ or NaN keep the prior weights, are flagged, produce finite
/// estimates, and the filter carries on and still converges.
#[test]
fn degenerate_frames_do_not_corrupt_the_filter() {
    let (m, names) = models(3);
    let seq = truth(2, 8);
    for (when, balance) in [
        (ResampleWhen::EveryFrame, ActionBalance::Joint),
        (ResampleWhen::EssBelow(0.5), ActionBalance::Joint),
        (ResampleWhen::EveryFrame, ActionBalance::Mixture(0.25)),
        (ResampleWhen::EssBelow(0.5), ActionBalance::Mixture(0.25)),
    ] {
        let c = config()
            .resample_when(when)
            .action_balance(balance)
            .build()
            .unwrap();
        let mut t = Tracker::new(&m, names.clone(), c).unwrap();
        let mut last = None;
        for (f, x) in seq.iter().enumerate() {
            let value = match f % 9 {
                4 => Some(f64::NEG_INFINITY),
                7 => Some(f64::NAN),
                _ => None,
            };
            let prior_w: Vec<f64> = t.weights().to_vec();
            let will_resample = f > 0
                && match when {
                    ResampleWhen::EveryFrame => true,
                    ResampleWhen::EssBelow(r) => {
                        let s2: f64 = prior_w.iter().map(|w| w * w).sum();
                        1.0 / s2 < r * prior_w.len() as f64
                    }
                };
            let obs = Blackout {
                inner: OracleObservation {
                    truth: *x,
                    sigma: 0.04,
                },
                value,
                _marker: std::marker::PhantomData,
            };
            let e = t.step(&obs);
            assert_eq!(e.degenerate, value.is_some(), "frame {f}");
            let sum: f64 = t.weights().iter().sum();
            assert!((sum - 1.0).abs() < 1e-9, "frame {f}: Σw = {sum}");
            assert!((e.action_posterior.iter().sum::<f64>() - 1.0).abs() < 1e-9);
            assert!(
                e.theta_mean
                    .iter()
                    .chain(&e.theta_std)
                    .all(|v| v.is_finite())
            );
            assert!(
                e.best_pose
                    .iter()
                    .chain(&e.smoothed_pose)
                    .all(|v| v.is_finite())
            );
            assert!(e.ess.is_finite() && e.theta_entropy.is_finite());
            if value.is_some() {
                // Prior weights kept: uniform after joint resampling, P(a)/n_a after mixture
                // resampling (at most |𝒜| distinct values), else the previous weights.
                let m = t.weights().len() as f64;
                if will_resample && balance == ActionBalance::Joint {
                    assert!(t.weights().iter().all(|w| (w - 1.0 / m).abs() < 1e-12));
                } else if will_resample {
                    let mut distinct: Vec<f64> = t.weights().to_vec();
                    distinct.sort_by(f64::total_cmp);
                    distinct.dedup();
                    assert!(distinct.len() <= 3, "{distinct:?}");
                } else {
                    for (a, b) in t.weights().iter().zip(&prior_w) {
                        assert!((a - b).abs() < 1e-12);
                    }
                }
                assert!(t.log_likelihoods().iter().all(|l| *l == f64::NEG_INFINITY));
            }
            last = Some(e);
        }
        let last = last.unwrap();
        assert!(
            last.action_posterior[2] > 0.9,
            "{when:?} {balance:?}: {:?}",
            last.action_posterior
        );
        assert!((last.theta_mean[0] - 0.1).hypot(last.theta_mean[1] - 0.5) < 0.03);
    }
}

/// Individual NaN / +∞ likelihoods count as −∞: those particles get weight 0, the frame is not
/// degenerate.
#[test]
fn individual_nans_get_zero_weight() {
    struct HalfNan;
    impl ObservationModel for HalfNan {
        fn log_likelihoods(&self, _poses: &[[f64; 9]], out: &mut [f64]) {
            for (i, o) in out.iter_mut().enumerate() {
                *o = match i % 4 {
                    0 => f64::NAN,
                    1 => f64::INFINITY,
                    2 => -3.0,
                    _ => -1.0 - 1e-3 * i as f64,
                };
            }
        }
    }
    let (m, names) = models(2);
    let mut t = Tracker::new(&m, names, config().particles(100).build().unwrap()).unwrap();
    for _ in 0..3 {
        let e = t.step(&HalfNan);
        assert!(!e.degenerate);
        for (i, w) in t.weights().iter().enumerate() {
            if i % 4 < 2 {
                assert!(*w == 0.0);
            } else {
                assert!(*w > 0.0);
            }
        }
        assert_eq!(e.best_particle, 3);
        assert!((e.best_log_likelihood + 1.003).abs() < 1e-12);
        assert!((e.best_pose[0] - t.particle_pose(3)[0]).abs() < 1e-15);
    }
}

/// Estimate invariants on every frame, for every scheme and option (SPEC §7 test 12).
#[test]
fn estimates_are_consistent_for_all_options() {
    let (m, names) = models(3);
    let seq = truth(0, 21);
    let variants: Vec<TrackerConfig> = vec![
        config().build().unwrap(),
        config()
            .resampling(Resampling::Stratified)
            .k_init(KInit::Uniform)
            .build()
            .unwrap(),
        config()
            .resampling(Resampling::Multinomial)
            .grammar(Grammar::Loop)
            .build()
            .unwrap(),
        config()
            .resampling(Resampling::Residual)
            .ess_threshold()
            .samples_per_particle(3)
            .build()
            .unwrap(),
        config()
            .pose_sampling(PoseSampling::Mean)
            .grammar(Grammar::Matrix(vec![
                vec![0.8, 0.1, 0.1],
                vec![0.1, 0.8, 0.1],
                vec![0.1, 0.1, 0.8],
            ]))
            .median_window(1)
            .build()
            .unwrap(),
    ];
    for c in variants {
        let label = format!("{c:?}");
        let mut t = Tracker::new(&m, names.clone(), c.clone()).unwrap();
        let est = run(&mut t, &seq);
        for (f, e) in est.iter().enumerate() {
            assert_eq!(e.frame, f);
            assert!(
                (e.action_posterior.iter().sum::<f64>() - 1.0).abs() < 1e-12,
                "{label}"
            );
            assert!(e.ess >= 1.0 - 1e-9 && e.ess <= c.particles() as f64 + 1e-9);
            assert!((0.0..=1.0).contains(&e.theta_histogram_entropy));
            assert!(e.action_entropy >= 0.0 && e.action_entropy <= 3f64.ln() + 1e-12);
            assert!(e.theta_std[0] >= 0.0 && e.theta_cov[0][1] == e.theta_cov[1][0]);
            assert!(e.mean_k >= 1.0 - 1e-12 && e.progress > 0.0 && e.progress <= 1.0 + 1e-12);
            assert!(e.map_action < 3);
        }
        let cloud = t.cloud();
        assert_eq!(cloud.len(), c.particles());
        assert!((cloud.iter().map(|p| p.weight).sum::<f64>() - 1.0).abs() < 1e-9);
        assert_eq!(t.particle_poses().len(), c.particles());
        let last = est.last().unwrap();
        if c.median_window() == 1 {
            assert_eq!(last.smoothed_pose, last.best_pose);
        }
        assert!(
            last.action_posterior[0] > 0.9,
            "{label}: {:?}",
            last.action_posterior
        );
    }
    // k_init = First starts every particle in state 1 (π = e₁); Uniform spreads them.
    let mut t = Tracker::new(&m, names.clone(), config().build().unwrap()).unwrap();
    t.step(&ConstantObservation(0.0));
    assert!(t.states().iter().all(|s| s.k == 0));
    let mut t = Tracker::new(&m, names, config().k_init(KInit::Uniform).build().unwrap()).unwrap();
    let e = t.step(&ConstantObservation(0.0));
    assert!(t.states().iter().any(|s| s.k > 10));
    // Uniform initial action and θ: posterior ≈ 1/3, θ spread over R.
    assert!(
        e.action_posterior
            .iter()
            .all(|p| (p - 1.0 / 3.0).abs() < 0.1)
    );
    assert!(e.theta_histogram_entropy > 0.9);
}
