//! Observation-model benches (SPEC §4): the edge image G at 640×480 and 1920×1080, and one
//! likelihood evaluation per particle and view (raster and analytic contour) at 640×480, on one
//! core. Targets: edge image ≤ 1 ms at 640×480, raster ≤ 15 µs, analytic ≤ 1 µs per particle.

use std::hint::black_box;

use actrack_render::fixtures::{camera, edges, poses_around, scene, true_pose};
use actrack_render::{ArmGeometry, ContourMethod, EdgeParams, EdgeWorkspace, LikelihoodModel};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench_edges(c: &mut Criterion) {
    let mut group = c.benchmark_group("edge_image");
    for (w, h) in [(640u32, 480u32), (1920, 1080)] {
        let frame = scene()
            .render(&camera(w, h), &true_pose(), 1)
            .expect("frame");
        let mut ws = EdgeWorkspace::new();
        let params = EdgeParams::default();
        group.bench_function(format!("{w}x{h}"), |b| {
            b.iter(|| {
                let g = ws.compute(black_box(frame.view()), &params).expect("edges");
                black_box(g.data()[0]);
            });
        });
    }
    group.finish();
}

fn bench_likelihood(c: &mut Criterion) {
    let cam = camera(640, 480);
    let edges = [edges(&cam, 1)];
    // Particles around the true pose (±10 cm on the elbow and fingertip), corrected.
    let poses = poses_around(256, 0.1, 5);
    let mut group = c.benchmark_group("likelihood_per_particle_640x480");
    for method in [ContourMethod::Raster, ContourMethod::Analytic] {
        let model = LikelihoodModel::new(vec![cam.clone()], ArmGeometry::default(), 0.15, method)
            .expect("model");
        let mut i = 0;
        group.bench_function(format!("{method:?}"), |b| {
            b.iter(|| {
                i = (i + 1) % poses.len();
                black_box(
                    model
                        .log_likelihood(&edges, black_box(&poses[i]))
                        .expect("score"),
                )
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench_edges, bench_likelihood);
criterion_main!(benches);
