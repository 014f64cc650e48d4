//! Observation-model benches (SPEC §4): the edge image G at 640×480 and 1920×1080, and one
//! likelihood evaluation per particle and view (raster and analytic contour) at 640×480, on one
//! core. Targets: edge image ≤ 1 ms at 640×480, raster ≤ 15 µs, analytic ≤ 1 µs per particle.

use std::hint::black_box;

use actrack_render::synth::{Body, SceneSynth, Table};
use actrack_render::{
    ArmGeometry, Camera, ContourMethod, EdgeParams, EdgeWorkspace, LikelihoodModel, correct_arm,
};
use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

const SHOULDER: [f64; 3] = [0.2, 0.0, 1.2];

fn camera(w: u32, h: u32) -> Camera {
    Camera::look_at(
        Vector3::new(0.7, 1.9, 1.65),
        Vector3::new(0.1, 0.25, 0.95),
        Vector3::z(),
        w,
        h,
        55f64.to_radians(),
    )
    .expect("valid camera")
}

fn scene() -> SceneSynth {
    SceneSynth::new(
        ArmGeometry::default(),
        Some(Table {
            center: [0.0, 0.5, 0.75],
            half_extents: [0.8, 0.45],
            yaw: 0.0,
            thickness: 0.04,
        }),
        Some(Body::for_shoulder(SHOULDER, [0.0, 1.0], true)),
    )
}

fn true_pose() -> [f64; 9] {
    let mut p = [
        SHOULDER[0],
        SHOULDER[1],
        SHOULDER[2],
        0.3,
        0.15,
        0.95,
        0.25,
        0.55,
        0.8,
    ];
    correct_arm(&ArmGeometry::default(), &mut p, None);
    p
}

/// Particles around the true pose (±10 cm on the elbow and fingertip), corrected.
fn particles(n: usize) -> Vec<[f64; 9]> {
    let g = ArmGeometry::default();
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let base = true_pose();
    (0..n)
        .map(|_| {
            let mut p = base;
            for x in &mut p[3..] {
                *x += rng.random_range(-0.1..0.1);
            }
            correct_arm(&g, &mut p, None);
            p
        })
        .collect()
}

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
    let frame = scene().render(&cam, &true_pose(), 1).expect("frame");
    let mut ws = EdgeWorkspace::new();
    let edges = [ws
        .compute(frame.view(), &EdgeParams::default())
        .expect("edges")
        .clone()];
    let poses = particles(256);
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
