//! Quick single-core timing of the observation model (minimum and median wall time per call).
//! `cargo run --release -p actrack-render --example perf`.

use std::time::Instant;

use actrack_render::synth::{Body, SceneSynth, Table};
use actrack_render::{
    ArmGeometry, Camera, ContourMethod, EdgeParams, EdgeWorkspace, LikelihoodModel, correct_arm,
};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

/// Per-call wall time of `f` run `inner` times, over `reps` repetitions, in ns:
/// (minimum, median). On a loaded machine the minimum is the better estimate of the cost on an
/// idle core.
fn time<F: FnMut()>(reps: usize, inner: usize, mut f: F) -> (f64, f64) {
    let mut wall: Vec<f64> = (0..reps)
        .map(|_| {
            let t0 = Instant::now();
            for _ in 0..inner {
                f();
            }
            t0.elapsed().as_nanos() as f64 / inner as f64
        })
        .collect();
    wall.sort_by(f64::total_cmp);
    (wall[0], wall[wall.len() / 2])
}

fn main() {
    let shoulder = [0.2, 0.0, 1.2];
    let cam = |w, h| {
        Camera::look_at(
            Vector3::new(0.7, 1.9, 1.65),
            Vector3::new(0.1, 0.25, 0.95),
            Vector3::z(),
            w,
            h,
            55f64.to_radians(),
        )
        .expect("camera")
    };
    let s = SceneSynth::new(
        ArmGeometry::default(),
        Some(Table {
            center: [0.0, 0.5, 0.75],
            half_extents: [0.8, 0.45],
            yaw: 0.0,
            thickness: 0.04,
        }),
        Some(Body::for_shoulder(shoulder, [0.0, 1.0], true)),
    );
    let g = ArmGeometry::default();
    let mut pose = [0.2, 0.0, 1.2, 0.3, 0.15, 0.95, 0.25, 0.55, 0.8];
    correct_arm(&g, &mut pose, None);
    for (w, h) in [(640, 480), (1920, 1080)] {
        let frame = s.render(&cam(w, h), &pose, 1).expect("frame");
        let mut ws = EdgeWorkspace::new();
        let p = EdgeParams::default();
        let (c, t) = time(41, 2, || {
            std::hint::black_box(ws.compute(frame.view(), &p).expect("edges").data()[0]);
        });
        println!(
            "edge image {w}x{h}: min {:.3} ms, median {:.3} ms",
            c / 1e6,
            t / 1e6
        );
        let p0 = EdgeParams { sigma: 0.0, ..p };
        let (c, t) = time(41, 2, || {
            std::hint::black_box(ws.compute(frame.view(), &p0).expect("edges").data()[0]);
        });
        println!(
            "  without smoothing: min {:.3} ms, median {:.3} ms",
            c / 1e6,
            t / 1e6
        );
    }
    let c640 = cam(640, 480);
    let frame = s.render(&c640, &pose, 1).expect("frame");
    let edges = [EdgeWorkspace::new()
        .compute(frame.view(), &EdgeParams::default())
        .expect("e")
        .clone()];
    let mut rng = Pcg64Mcg::seed_from_u64(5);
    let poses: Vec<[f64; 9]> = (0..256)
        .map(|_| {
            let mut p = pose;
            for x in &mut p[3..] {
                *x += rng.random_range(-0.1..0.1);
            }
            correct_arm(&g, &mut p, None);
            p
        })
        .collect();
    for method in [ContourMethod::Raster, ContourMethod::Analytic] {
        let n = actrack_render::contour_points(&c640, &g, &pose, method).len();
        let m = LikelihoodModel::new(vec![c640.clone()], g.clone(), 0.15, method).expect("model");
        let mut i = 0;
        let (c, t) = time(101, 64, || {
            i = (i + 1) % poses.len();
            std::hint::black_box(m.log_likelihood(&edges, &poses[i]).expect("score"));
        });
        println!(
            "{method:?} likelihood (|C| = {n}): min {:.2} µs, median {:.2} µs",
            c / 1e3,
            t / 1e3
        );
    }
}
