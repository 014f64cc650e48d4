use super::*;

use crate::synthetic::{self, SHAPES};
use crate::{Resampling, TableRegion, TrackerConfig};
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

fn config(grammar: Grammar, boundary: Boundary) -> TrackerConfig {
    TrackerConfig::builder(synthetic::table_region())
        .grammar(grammar)
        .boundary(boundary)
        .resampling(Resampling::Systematic)
        .build()
        .unwrap()
}

/// The per-particle kernel of frame 1 without per-action θ supports.
fn test_kernel<'a>(
    models: &'a [ActionCache],
    grammar: &'a GrammarCache,
    config: &'a TrackerConfig,
) -> Kernel<'a> {
    Kernel {
        models,
        grammar,
        config,
        boxes: None,
        frame: 1,
    }
}

fn caches(exit: f64, n: usize) -> Vec<ActionCache> {
    SHAPES
        .iter()
        .enumerate()
        .map(|(a, (_, shape))| {
            ActionCache::from_phmm(
                a,
                &synthetic::action_model(shape, n, exit, 0.015).unwrap(),
                0.4,
                1.0 / 16.0,
            )
            .unwrap()
        })
        .collect()
}

/// Phase jumps: with probability ρ the state is redrawn uniformly over the action's states
/// (counted from the last state, which the no-exit model never leaves by itself), the
/// action is kept, and rates outside (0, 1) are refused.
#[test]
fn phase_jumps_redraw_the_state_uniformly() {
    let n = 8;
    let models = caches(0.0, n);
    let grammar = GrammarCache::Uniform;
    let rho = 0.3;
    let cfg = TrackerConfig::builder(synthetic::table_region())
        .phase_jump(Some(rho))
        .build()
        .unwrap();
    let kernel = test_kernel(&models, &grammar, &cfg);
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    let trials = 40_000;
    let mut counts = vec![0usize; n];
    for _ in 0..trials {
        let mut s = ActionState {
            action: 1,
            theta: [0.0, 0.0],
            k: n - 1,
        };
        kernel.propagate(&mut s, &mut 1.0, &mut rng);
        assert_eq!(s.action, 1);
        counts[s.k] += 1;
    }
    let t = f64::from(trials);
    for (k, &c) in counts.iter().enumerate() {
        let p = if k == n - 1 {
            1.0 - rho + rho / n as f64
        } else {
            rho / n as f64
        };
        let sd = (t * p * (1.0 - p)).sqrt();
        assert!(
            (c as f64 - t * p).abs() < 5.0 * sd,
            "state {k}: {c} draws, expected {:.0} ± {sd:.0}",
            t * p
        );
    }
    // Without the option the last state is never left.
    let plain = TrackerConfig::builder(synthetic::table_region())
        .build()
        .unwrap();
    let kernel = test_kernel(&models, &grammar, &plain);
    for _ in 0..1000 {
        let mut s = ActionState {
            action: 0,
            theta: [0.0, 0.0],
            k: n - 1,
        };
        kernel.propagate(&mut s, &mut 1.0, &mut rng);
        assert_eq!(s.k, n - 1);
    }
    for bad in [0.0, 1.0, -0.1, f64::NAN] {
        assert!(
            TrackerConfig::builder(synthetic::table_region())
                .phase_jump(Some(bad))
                .build()
                .is_err(),
            "{bad}"
        );
    }
}

/// Per-particle speeds: a speed s takes ⌊s⌋ transition draws per frame plus one with
/// probability s − ⌊s⌋, so the mean advance over a few frames scales with s; speeds are
/// drawn log-uniformly from the range, kept within an action instance and redrawn on
/// re-entry; without a range the particles follow the model's timing exactly.
#[test]
fn particle_speeds_scale_the_progress() {
    let n = 40;
    let models = caches(0.0, n);
    let grammar = GrammarCache::Uniform;
    let cfg = TrackerConfig::builder(synthetic::table_region())
        .speed_range(Some([0.5, 2.0]))
        .build()
        .unwrap();
    let kernel = test_kernel(&models, &grammar, &cfg);
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let frames = 4;
    let advance = |speed: f64, rng: &mut Pcg64Mcg| {
        let trials = 20_000;
        let mut total = 0.0;
        for _ in 0..trials {
            let mut s = ActionState {
                action: 0,
                theta: [0.0, 0.0],
                k: 0,
            };
            let mut sp = speed;
            for _ in 0..frames {
                kernel.propagate(&mut s, &mut sp, rng);
            }
            assert_eq!(sp, speed, "no exit: the speed is kept");
            total += s.k as f64;
        }
        total / f64::from(trials)
    };
    let base = advance(1.0, &mut rng);
    assert!(base > 1.0, "{base}");
    for s in [0.5, 1.5, 2.0] {
        let ratio = advance(s, &mut rng) / base;
        assert!(
            (ratio - s).abs() < 0.05 * s,
            "speed {s}: progress ratio {ratio}"
        );
    }
    // Drawn log-uniformly: inside the range, median near the geometric mean.
    let mut draws: Vec<f64> = (0..20_001).map(|_| kernel.draw_speed(&mut rng)).collect();
    assert!(draws.iter().all(|&v| (0.5..=2.0).contains(&v)));
    draws.sort_by(f64::total_cmp);
    assert!(
        (draws[10_000] - 1.0).abs() < 0.03,
        "median {}",
        draws[10_000]
    );
    // Redrawn on re-entry (from the last state of an exiting model).
    let exiting = caches(1.0, 6);
    let kernel = Kernel {
        models: &exiting,
        ..kernel
    };
    let mut s = ActionState {
        action: 0,
        theta: [0.0, 0.0],
        k: 5,
    };
    let mut sp = 1.9;
    while sp == 1.9 {
        s.k = 5;
        kernel.propagate(&mut s, &mut sp, &mut rng);
    }
    assert!((0.5..=2.0).contains(&sp));
    // Validation.
    for bad in [[0.0, 1.0], [1.5, 1.0], [1.0, 5.0], [f64::NAN, 1.0]] {
        assert!(
            TrackerConfig::builder(synthetic::table_region())
                .speed_range(Some(bad))
                .build()
                .is_err(),
            "{bad:?}"
        );
    }
}

/// Transition draws follow the model's banded row and exit probability.
#[test]
fn timing_follows_the_transition_row() {
    let n = 8;
    let phmm = synthetic::action_model(&SHAPES[0].1, n, 0.2, 0.015).unwrap();
    let cache = ActionCache::from_phmm(0, &phmm, 0.4, 1.0 / 16.0).unwrap();
    let mut rng = Pcg64Mcg::seed_from_u64(3);
    let draws = 200_000;
    for k in [0, 5, n - 2, n - 1] {
        let mut counts = vec![0.0_f64; n + 1];
        for _ in 0..draws {
            match cache.next(k, &mut rng) {
                Next::State(j) => counts[j] += 1.0,
                Next::Exit => counts[n] += 1.0,
            }
        }
        for j in 0..=n {
            let p = if j == n {
                phmm.exit_prob(k)
            } else {
                phmm.transition(k, j)
            };
            let f = counts[j] / f64::from(draws);
            let tol = 5.0 * (p * (1.0 - p) / f64::from(draws)).sqrt() + 1e-12;
            assert!((f - p).abs() <= tol, "k={k} j={j}: {f} vs {p}");
        }
    }
}

/// On exit the grammar picks the next action; θ is redrawn; k restarts from π (state 0).
#[test]
fn grammar_on_exit() {
    let models = caches(1.0, 5);
    let last = 4;
    let mut rng = Pcg64Mcg::seed_from_u64(9);
    let run = |grammar: Grammar, rng: &mut Pcg64Mcg| {
        let cfg = config(grammar, Boundary::Reflect(1.25));
        let grammar = match cfg.grammar() {
            Grammar::Loop => GrammarCache::Loop,
            Grammar::Uniform => GrammarCache::Uniform,
            Grammar::Matrix(rows) => GrammarCache::Matrix(
                rows.iter()
                    .flat_map(|r| {
                        r.iter().scan(0.0, |acc, g| {
                            *acc += g;
                            Some(*acc)
                        })
                    })
                    .collect(),
            ),
        };
        let kernel = test_kernel(&models, &grammar, &cfg);
        let mut counts = [0_usize; 3];
        let mut thetas = Vec::new();
        for _ in 0..3000 {
            let mut s = ActionState {
                action: 1,
                theta: [0.9, 0.9],
                k: last,
            };
            kernel.propagate(&mut s, &mut 1.0, rng);
            assert_eq!(s.k, 0, "re-entry at the first state");
            counts[s.action] += 1;
            thetas.push(s.theta);
        }
        (counts, thetas)
    };
    let (c, thetas) = run(Grammar::Loop, &mut rng);
    assert_eq!(c, [0, 3000, 0]);
    // θ ~ U(R) (+ diffusion): mean near 0, spread over the region.
    let mu: f64 = thetas.iter().map(|t| t[0]).sum::<f64>() / 3000.0;
    assert!(mu.abs() < 0.06, "θ not redrawn uniformly: mean {mu}");
    assert!(thetas.iter().any(|t| t[0] < -0.8) && thetas.iter().any(|t| t[1] < -0.8));
    let m = vec![
        vec![1.0, 0.0, 0.0],
        vec![0.0, 0.0, 1.0],
        vec![0.0, 1.0, 0.0],
    ];
    let (c, _) = run(Grammar::Matrix(m), &mut rng);
    assert_eq!(c, [0, 0, 3000]);
    let (c, _) = run(Grammar::Uniform, &mut rng);
    for x in c {
        assert!((900..1100).contains(&x), "uniform switching: {c:?}");
    }
}

/// A model without exit (EndMode::None) never leaves its action; at the absorbing last state
/// θ diffuses with σ(N) = 0.4/16 (cooling evaluated at the post-transition k').
#[test]
fn no_exit_and_cooling_at_the_last_state() {
    let n = 6;
    let models = caches(0.0, n);
    let cfg = config(Grammar::Uniform, Boundary::None);
    let grammar = GrammarCache::Uniform;
    let kernel = test_kernel(&models, &grammar, &cfg);
    let mut rng = Pcg64Mcg::seed_from_u64(11);
    let draws = 40_000;
    let mut s2 = [0.0; 2];
    for _ in 0..draws {
        let mut s = ActionState {
            action: 2,
            theta: [0.0, 0.0],
            k: n - 1,
        };
        kernel.propagate(&mut s, &mut 1.0, &mut rng);
        assert_eq!((s.action, s.k), (2, n - 1));
        s2[0] += s.theta[0] * s.theta[0];
        s2[1] += s.theta[1] * s.theta[1];
    }
    for v in s2 {
        let sd = (v / f64::from(draws)).sqrt();
        assert!((sd - 0.025).abs() < 0.025 * 0.02, "σ(N) = {sd}");
    }
    // From state 0 the next state is 0..3, so the spread is a mixture of σ(1..4).
    let mut s = ActionState {
        action: 0,
        theta: [0.0, 0.0],
        k: 0,
    };
    let before = s;
    kernel.propagate(&mut s, &mut 1.0, &mut rng);
    assert!(s.k <= 3 && s.action == before.action);
}

/// Generated poses have the model's mean μ_k(θ) (θ converted to metres) and covariance.
#[test]
fn pose_samples_match_the_model() {
    let mut shape = SHAPES[2].1;
    shape.lift = 0.07;
    let phmm = synthetic::action_model(&shape, 10, 0.2, 0.02).unwrap();
    let cache = ActionCache::from_phmm(0, &phmm, 0.4, 1.0 / 16.0).unwrap();
    let region = synthetic::table_region();
    let u = [0.6, -0.3];
    let theta_m = region.to_metres(u);
    let k = 7;
    let mu = phmm.mean(k, &theta_m);
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let draws = 50_000;
    let mut sum = [0.0; 9];
    let mut sq = [0.0; 9];
    let mut x = [0.0; 9];
    for _ in 0..draws {
        cache.sample(k, theta_m, &mut rng, &mut x);
        for r in 0..9 {
            sum[r] += x[r];
            sq[r] += (x[r] - mu[r]) * (x[r] - mu[r]);
        }
    }
    cache.mean(k, theta_m, &mut x);
    for r in 0..9 {
        assert!((x[r] - mu[r]).abs() < 1e-12);
        let mean = sum[r] / f64::from(draws);
        assert!(
            (mean - mu[r]).abs() < 5.0 * 0.02 / f64::from(draws).sqrt(),
            "coord {r}"
        );
        let var = sq[r] / f64::from(draws);
        assert!(
            (var / phmm.covariance(k)[(r, r)] - 1.0).abs() < 0.03,
            "coord {r}: {var}"
        );
    }
}

/// Mixture resampling is unbiased: over many draws, the expected total weight carried by
/// the copies of particle i equals its weight w_i (so every weighted estimate is unbiased),
/// every action keeps at least its floor of particles, and P(a) is preserved exactly.
#[test]
fn mixture_resampling_is_unbiased() {
    let (models, names) = synthetic::demo_models(3, 10).unwrap();
    for scheme in [Resampling::Systematic, Resampling::Multinomial] {
        let cfg = TrackerConfig::builder(synthetic::table_region())
            .particles(60)
            .resampling(scheme)
            .action_balance(ActionBalance::Mixture(0.25))
            .build()
            .unwrap();
        let mut t = Tracker::new(&models, names.clone(), cfg).unwrap();
        let m = 60;
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        // Uneven weights, action 2 almost dead (P ≈ 1e-4), one zero weight.
        let mut raw = vec![0.0; m];
        for i in 0..m {
            let action = if i < 40 {
                0
            } else if i < 55 {
                1
            } else {
                2
            };
            t.states[i] = ActionState {
                action,
                theta: [0.0; 2],
                k: i,
            };
            let u: f64 = rng.random();
            raw[i] = u * u * if action == 2 { 1e-4 } else { 1.0 };
        }
        raw[7] = 0.0;
        let total: f64 = raw.iter().sum();
        let w0: Vec<f64> = raw.iter().map(|v| v / total).collect();
        let states0 = t.states.clone();
        let mut p0 = [0.0; 3];
        for (s, w) in states0.iter().zip(&w0) {
            p0[s.action] += w;
        }
        let draws = 20_000;
        let mut carried = vec![0.0; m];
        for d in 0..draws {
            t.states.clone_from(&states0);
            t.w.clone_from(&w0);
            for (lw, w) in t.log_w.iter_mut().zip(&w0) {
                *lw = w.ln();
            }
            let mut r = Pcg64Mcg::seed_from_u64(1000 + d);
            assert!(t.resample_mixture(0.25, &mut r));
            assert_eq!(t.ancestors.len(), m);
            let mut count = [0_usize; 3];
            let mut p = [0.0; 3];
            for (&anc, &w) in t.ancestors.iter().zip(&t.w) {
                carried[anc] += w;
                count[states0[anc].action] += 1;
                p[states0[anc].action] += w;
            }
            // Floor ⌈0.25·60/3⌉ = 5 per action.
            assert!(count.iter().all(|&c| c >= 5), "{count:?}");
            for a in 0..3 {
                assert!((p[a] - p0[a]).abs() < 1e-12 * p0[a].max(1e-300) + 1e-15);
            }
            assert!((t.w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        for i in 0..m {
            let mean = carried[i] / f64::from(u32::try_from(draws).unwrap());
            // Within 5 standard errors (a copy carries at most P(a)/n_a ≤ 1/5).
            let tol = 5.0 * (w0[i] * 0.2 / f64::from(u32::try_from(draws).unwrap())).sqrt() + 1e-12;
            assert!(
                (mean - w0[i]).abs() < tol,
                "{scheme:?} particle {i}: carried {mean}, weight {}",
                w0[i]
            );
            if w0[i] == 0.0 {
                assert!(carried[i] == 0.0);
            }
        }
    }
}

#[test]
fn allocation_floor_and_sum() {
    let mut out = Vec::new();
    allocate_actions(&[0.98, 0.02, 0.0], 400, 0.25, &mut out);
    // Floor ⌈0.25·400/3⌉ = 34 for the two live actions; the other 332 shared 0.98 : 0.02.
    assert_eq!(out.iter().sum::<usize>(), 400);
    assert_eq!(out[2], 0);
    assert_eq!(out[1], 34 + 7);
    allocate_actions(&[0.5, 0.5], 7, 0.9, &mut out);
    assert_eq!(out, vec![4, 3]);
    allocate_actions(&[1.0 / 3.0; 3], 1, 0.25, &mut out);
    assert_eq!(out.iter().sum::<usize>(), 1);
}

/// Per-action θ supports: θ is drawn inside the action's own box at the start and on
/// re-entry and stays within the box enlarged by the reflection factor; a region count that
/// does not match the models is an error.
#[test]
fn per_action_regions_bound_theta() {
    let n = 5;
    let models = caches(0.3, n);
    let regions = vec![
        TableRegion::new([-0.30, 0.50], [0.05, 0.04]),
        TableRegion::new([0.00, 0.45], [0.40, 0.15]),
        TableRegion::new([0.10, 0.40], [0.02, 0.10]),
    ];
    let cfg = config(Grammar::Uniform, Boundary::Reflect(1.25))
        .to_builder()
        .action_regions(regions.clone())
        .build()
        .unwrap();
    let table = *cfg.table();
    let boxes: Vec<ThetaBox> = regions
        .iter()
        .map(|r| ThetaBox {
            centre: table.to_normalised(r.centre),
            half: [
                r.half_extents[0] / table.half_extents[0],
                r.half_extents[1] / table.half_extents[1],
            ],
        })
        .collect();
    let grammar = GrammarCache::Uniform;
    let kernel = Kernel {
        models: &models,
        grammar: &grammar,
        config: &cfg,
        boxes: Some(&boxes),
        frame: 1,
    };
    let inside = |a: usize, theta: [f64; 2], scale: f64| {
        let m = table.to_metres(theta);
        let r = &regions[a];
        (0..2).all(|c| (m[c] - r.centre[c]).abs() <= scale * r.half_extents[c] + 1e-12)
    };
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let mut seen = [0_usize; 3];
    for _ in 0..2000 {
        let mut s = kernel.init(&mut rng);
        assert!(
            inside(s.action, s.theta, 1.0),
            "init outside its box: {s:?}"
        );
        for _ in 0..30 {
            kernel.propagate(&mut s, &mut 1.0, &mut rng);
            assert!(inside(s.action, s.theta, 1.25), "θ left its band: {s:?}");
        }
        seen[s.action] += 1;
    }
    assert!(seen.iter().all(|&c| c > 400), "actions switch: {seen:?}");
    let wrong = cfg
        .to_builder()
        .action_regions(regions[..2].to_vec())
        .build()
        .unwrap();
    let phmms: Vec<_> = SHAPES
        .iter()
        .map(|(_, shape)| synthetic::action_model(shape, n, 0.3, 0.015).unwrap())
        .collect();
    let names = SHAPES.iter().map(|(name, _)| (*name).to_string()).collect();
    assert!(matches!(
        Tracker::new(phmms.iter(), names, wrong),
        Err(PfError::InvalidConfig(_))
    ));
}

#[test]
fn reflection_folds_into_the_band() {
    let b = 1.25;
    assert!((reflect(0.3, b) - 0.3).abs() < 1e-15);
    assert!((reflect(1.35, b) - 1.15).abs() < 1e-12);
    assert!((reflect(-1.45, b) + 1.05).abs() < 1e-12);
    assert!((reflect(1.25 + 2.5 + 0.1, b) - (-1.15)).abs() < 1e-12);
    for i in -100..100 {
        let x = f64::from(i) * 0.173;
        let y = reflect(x, b);
        assert!((-b..=b).contains(&y), "{x} -> {y}");
    }
    assert_eq!(reflect(f64::NAN, b), 0.0);
}
