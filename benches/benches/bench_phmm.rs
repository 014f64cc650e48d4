//! Parametric HMM benches (issue 2): Baum–Welch training on the fixed synthetic workload
//! (40 states, 9-D observations, full covariance, 20 sequences × 110 frames, 2-D θ,
//! 20 iterations) on one thread and on the default pool, and the forward pass of one sequence.
//! `scripts/compare-hmmlearn` compares the same kind of workload with hmmlearn.

use actrack_phmm::{Phmm, PhmmParams};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;
use std::hint::black_box;

const N_STATES: usize = 40;
const DIM: usize = 9;
const SEQS: usize = 20;
const FRAMES: usize = 110;
const ITERATIONS: usize = 20;

/// A smooth 9-D reach-like path whose shape depends on θ ∈ [−1, 1]², with a per-sequence speed
/// and 1 cm noise. Seeded.
fn workload() -> (Vec<DMatrix<f64>>, Vec<DVector<f64>>) {
    let mut rng = Pcg64Mcg::seed_from_u64(42);
    let mut seqs = Vec::with_capacity(SEQS);
    let mut thetas = Vec::with_capacity(SEQS);
    for _ in 0..SEQS {
        let th = [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)];
        let speed: f64 = rng.random_range(0.8..1.2);
        let x = DMatrix::from_fn(FRAMES, DIM, |t, k| {
            let ph = (t as f64 / FRAMES as f64 * speed).min(1.0);
            let kf = k as f64;
            let noise: f64 = StandardNormal.sample(&mut rng);
            0.3 * (3.0 * ph + kf).sin()
                + 0.2 * ph * (th[0] * (0.7 * (kf + 1.0)).cos() + th[1] * (0.3 * (kf + 2.0)).sin())
                + 0.01 * noise
        });
        seqs.push(x);
        thetas.push(DVector::from_row_slice(&th));
    }
    (seqs, thetas)
}

fn fit(seqs: &[DMatrix<f64>], thetas: &[DVector<f64>]) -> Phmm {
    let params = PhmmParams::new(N_STATES)
        .max_iterations(ITERATIONS)
        .tolerance(0.0)
        .check()
        .expect("valid parameters");
    let (model, report) = params.fit(seqs, thetas).expect("fit");
    assert_eq!(report.iterations, ITERATIONS);
    model
}

fn bench_phmm(c: &mut Criterion) {
    let (seqs, thetas) = workload();
    let mut g = c.benchmark_group("phmm_fit_40states_9d_full_20x110_20iter");
    g.sample_size(10);
    g.measurement_time(std::time::Duration::from_secs(8));
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("one-thread pool");
    g.bench_function("one_thread", |b| {
        b.iter(|| one.install(|| fit(black_box(&seqs), black_box(&thetas))));
    });
    g.bench_function("default_threads", |b| {
        b.iter(|| fit(black_box(&seqs), black_box(&thetas)));
    });
    g.finish();

    let model = fit(&seqs, &thetas);
    let th = [0.3, -0.4];
    let mut g = c.benchmark_group("phmm_forward_40states_9d_110frames");
    g.bench_function("log_likelihood", |b| {
        b.iter(|| {
            model
                .log_likelihood(black_box(&seqs[0]), black_box(&th))
                .expect("log-likelihood")
        });
    });
    g.bench_function("posteriors", |b| {
        b.iter(|| {
            model
                .posteriors(black_box(&seqs[0]), black_box(&th))
                .expect("posteriors")
        });
    });
    g.finish();
}

criterion_group!(benches, bench_phmm);
criterion_main!(benches);
