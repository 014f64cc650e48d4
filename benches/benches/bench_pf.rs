//! One step of the action-space particle filter without an observation model (a constant
//! log-likelihood), so it measures propagate + pose sampling + weighting + estimates +
//! resampling: 400 and 4000 particles on the ambient rayon pool.
//! Target (issue 4): under 100 µs for 400 particles on one core: run it with
//! `RAYON_NUM_THREADS=1 cargo bench -p actrack-benches --bench bench_pf` for that figure.

use std::hint::black_box;

use actrack_pf::synthetic;
use actrack_pf::{ConstantObservation, Tracker, TrackerConfig};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

fn tracker(particles: usize) -> Tracker {
    let Ok((models, names)) = synthetic::demo_models(3, 50) else {
        panic!("synthetic models");
    };
    let Ok(config) = TrackerConfig::builder(synthetic::table_region())
        .particles(particles)
        .seed(1)
        .build()
    else {
        panic!("config");
    };
    let Ok(mut t) = Tracker::new(&models, names, config) else {
        panic!("tracker");
    };
    // Past the first frame, so every step is resample → propagate → sample → weight → estimate.
    for _ in 0..5 {
        t.step(&ConstantObservation(0.0));
    }
    t
}

fn bench_pf(c: &mut Criterion) {
    let mut group = c.benchmark_group("pf_step");
    for particles in [400_usize, 4000] {
        let obs = ConstantObservation(0.0);
        let mut t = tracker(particles);
        group.bench_function(BenchmarkId::from_parameter(particles), |b| {
            b.iter(|| black_box(t.step(black_box(&obs))));
        });
    }
    group.finish();
}

criterion_group!(benches, bench_pf);
criterion_main!(benches);
