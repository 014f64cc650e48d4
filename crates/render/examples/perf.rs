//! Quick single-core timing of the observation model (minimum and median wall time per call).
//!
//! ```sh
//! cargo run --release -p actrack-render --example perf                 # everything
//! cargo run --release -p actrack-render --example perf -- edge640 3    # one kernel, 3 repetitions
//! ```
//!
//! The first argument selects a kernel (`all`, `edge640`, `edge1080`, `raster`, `analytic`), the
//! second scales the number of repetitions (default 1; use a small count under
//! `valgrind --tool=callgrind`, whose instruction counts are stable under load). The first line
//! says whether the edge-image kernels run with AVX-512 or AVX2 on this CPU (runtime dispatch).

use std::time::Instant;

use actrack_render::fixtures::{camera, edges, poses_around, scene, true_pose};
use actrack_render::{ArmGeometry, ContourMethod, EdgeParams, EdgeWorkspace, LikelihoodModel};

/// Per-call wall time of `f` run `inner` times, over `reps` repetitions, in ns:
/// (minimum, median). On a loaded machine the minimum is the better estimate of the cost on an
/// idle core.
fn time<F: FnMut()>(reps: usize, inner: usize, mut f: F) -> (f64, f64) {
    let mut wall: Vec<f64> = (0..reps.max(1))
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
    // Which variant of the dispatched kernels (edge image) runs on this CPU (x86-64: pulp's V4 =
    // AVX-512, V3 = AVX2, or the baseline build).
    let simd = match pulp::Arch::new() {
        pulp::Arch::Scalar => "baseline",
        #[cfg(target_arch = "x86_64")]
        pulp::Arch::V4(_) => "AVX-512",
        #[cfg(target_arch = "x86_64")]
        pulp::Arch::V3(_) => "AVX2",
        #[allow(unreachable_patterns)]
        _ => "wide",
    };
    println!("SIMD dispatch: {simd}");
    let mut args = std::env::args().skip(1);
    let which = args.next().unwrap_or_else(|| "all".to_owned());
    let scale: Option<usize> = args.next().and_then(|s| s.parse().ok());
    let reps = |default: usize| scale.unwrap_or(default);
    // The scene of the crate's tests and benches.
    let s = scene();
    let g = ArmGeometry::default();
    let pose = true_pose();
    for (name, w, h) in [("edge640", 640, 480), ("edge1080", 1920, 1080)] {
        if which != "all" && which != name {
            continue;
        }
        let frame = s.render(&camera(w, h), &pose, 1).expect("frame");
        let mut ws = EdgeWorkspace::new();
        let p = EdgeParams::default();
        let (c, t) = time(reps(41), 2, || {
            std::hint::black_box(ws.compute(frame.view(), &p).expect("edges").data()[0]);
        });
        println!(
            "edge image {w}x{h}: min {:.3} ms, median {:.3} ms",
            c / 1e6,
            t / 1e6
        );
        if which == "all" {
            let p0 = EdgeParams { sigma: 0.0, ..p };
            let (c, t) = time(41, 2, || {
                std::hint::black_box(ws.compute(frame.view(), &p0).expect("edges").data()[0]);
            });
            println!(
                "  without smoothing: min {:.3} ms, median {:.3} ms",
                c / 1e6,
                t / 1e6
            );
            // The colour gradient (the default configuration's): the largest Sobel magnitude
            // of R, G and B.
            let pc = EdgeParams { colour: true, ..p };
            for (label, params) in [
                ("colour gradient", pc),
                (
                    "colour gradient without smoothing",
                    EdgeParams { sigma: 0.0, ..pc },
                ),
            ] {
                let (c, t) = time(41, 2, || {
                    std::hint::black_box(
                        ws.compute(frame.view(), &params).expect("edges").data()[0],
                    );
                });
                println!("  {label}: min {:.3} ms, median {:.3} ms", c / 1e6, t / 1e6);
            }
            // The same work on a grey frame (no colour conversion): what the RGB → grey step
            // costs.
            let grey: Vec<u8> = frame
                .data
                .chunks_exact(3)
                .map(|px| ((u16::from(px[0]) + u16::from(px[1]) + u16::from(px[2])) / 3) as u8)
                .collect();
            let gv = actrack_render::ImageView::grey8(&grey, w, h).expect("grey view");
            let (c, t) = time(41, 2, || {
                std::hint::black_box(ws.compute(gv, &p0).expect("edges").data()[0]);
            });
            println!(
                "  without smoothing, grey input: min {:.3} ms, median {:.3} ms",
                c / 1e6,
                t / 1e6
            );
        }
    }
    let c640 = camera(640, 480);
    let methods: &[ContourMethod] = match which.as_str() {
        "all" => &[ContourMethod::Raster, ContourMethod::Analytic],
        "raster" => &[ContourMethod::Raster],
        "analytic" => &[ContourMethod::Analytic],
        _ => &[],
    };
    if methods.is_empty() {
        return;
    }
    let edges = [edges(&c640, 1)];
    let poses = poses_around(256, 0.1, 5);
    for &method in methods {
        let n = actrack_render::contour_points(&c640, &g, &pose, method).len();
        let m = LikelihoodModel::new(vec![c640.clone()], g.clone(), 0.15, method).expect("model");
        let mut i = 0;
        let (c, t) = time(reps(101), 64, || {
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
