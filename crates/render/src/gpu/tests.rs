//! The GPU likelihood against the CPU's on the shared fixture scene (skipped without an
//! adapter).

use super::*;
use crate::fixtures::{EYE, camera_at, edges, poses_around, true_pose};

fn gpu(cams: Vec<Camera>) -> Option<GpuLikelihood> {
    match GpuLikelihood::new(cams, ArmGeometry::default(), 0.15) {
        Ok(g) => {
            eprintln!("GPU adapter: {}", g.adapter_name());
            Some(g)
        }
        Err(GpuError::NoAdapter(e)) => {
            eprintln!("note: no GPU adapter ({e}); skipping the GPU test");
            None
        }
        Err(e) => panic!("GPU adapter present but unusable: {e}"),
    }
}

/// The fixture camera at `eye` with Brown `distortion`.
fn camera(eye: [f64; 3], w: u32, h: u32, distortion: [f64; 5]) -> Camera {
    let mut c = camera_at(eye, w, h);
    c.distortion = distortion;
    c
}

/// Random corrected poses around the true one (elbow and hand within ±25 cm), some far
/// off, seeded.
fn random_poses(n: usize, seed: u64) -> Vec<[f64; 9]> {
    poses_around(n, 0.25, seed)
}

fn compare(g: &GpuLikelihood, e: &[EdgeImage], poses: &[[f64; 9]]) -> f64 {
    let mut got = vec![0.0; poses.len()];
    g.log_likelihood_batch(e, poses, &mut got).unwrap();
    let mut want = vec![0.0; poses.len()];
    g.cpu_model()
        .log_likelihood_batch(e, poses, &mut want)
        .unwrap();
    let mut worst = 0.0f64;
    for (i, (a, b)) in got.iter().zip(&want).enumerate() {
        assert!(
            (a - b).abs() < 1e-4,
            "pose {i} {:?}: gpu {a} cpu {b}",
            poses[i]
        );
        worst = worst.max((a - b).abs());
    }
    eprintln!(
        "{} poses × {} views: max |Δ log P| = {worst:.2e}, {} views rescored on the CPU",
        poses.len(),
        e.len(),
        g.last_fallbacks()
    );
    worst
}

#[test]
fn gpu_matches_cpu_analytic_single_view() {
    let cam = camera(EYE, 640, 480, [0.0; 5]);
    let Some(g) = gpu(vec![cam.clone()]) else {
        return;
    };
    let e = [edges(&cam, 3)];
    let poses = random_poses(400, 11);
    compare(&g, &e, &poses);
    let capacity = |g: &GpuLikelihood| g.state.lock().unwrap().buffers.as_ref().unwrap().capacity;
    let cap = capacity(&g);
    // Same batch again (buffers and edge image reused), then a smaller batch.
    compare(&g, &e, &poses);
    compare(&g, &e, &poses[..37]);
    assert_eq!(
        capacity(&g),
        cap,
        "buffers reallocated for a batch that did not grow"
    );
}

#[test]
fn gpu_matches_cpu_multi_view_with_distortion() {
    let cams = vec![
        camera(EYE, 320, 240, [-0.12, 0.03, 0.001, -0.0005, 0.0]),
        camera([-1.2, 1.2, 1.5], 400, 300, [0.08, -0.02, 0.0, 0.0, 0.004]),
        camera([0.2, -1.4, 1.9], 360, 240, [0.0; 5]),
    ];
    let Some(g) = gpu(cams.clone()) else {
        return;
    };
    let e: Vec<EdgeImage> = cams
        .iter()
        .enumerate()
        .map(|(i, c)| edges(c, 20 + i as u64))
        .collect();
    let poses = random_poses(300, 12);
    compare(&g, &e, &poses);
    // A new frame: new edge images are uploaded.
    let e2: Vec<EdgeImage> = cams
        .iter()
        .enumerate()
        .map(|(i, c)| edges(c, 40 + i as u64))
        .collect();
    compare(&g, &e2, &poses);
}

#[test]
fn gpu_empty_contours_and_edge_cases() {
    let cam = camera(EYE, 320, 240, [0.0; 5]);
    let Some(g) = gpu(vec![cam.clone(), cam.clone()]) else {
        return;
    };
    let ones = EdgeImage::constant(320, 240, 1.0).unwrap();
    let zeros = EdgeImage::constant(320, 240, 0.0).unwrap();
    let min = -2.0 / (2.0 * 0.15 * 0.15);
    let off = [50.0, 0.0, 1.0, 50.3, 0.0, 1.0, 50.7, 0.0, 1.0];
    let mut nan = true_pose();
    nan[4] = f64::NAN;
    let eye = cam.center();
    let behind = [
        eye.x,
        eye.y + 1.0,
        eye.z,
        eye.x,
        eye.y + 1.2,
        eye.z,
        eye.x,
        eye.y + 1.5,
        eye.z,
    ];
    let poses = [true_pose(), off, nan, behind, true_pose()];
    let mut out = [0.0; 5];
    // |C| = 0 in both views → ε̄ = 1 per view, the minimum.
    g.log_likelihood_batch(&[ones.clone(), ones.clone()], &poses, &mut out)
        .unwrap();
    assert!(out[0].abs() < 1e-6, "{out:?}");
    for o in &out[1..4] {
        assert!((o - min).abs() < 1e-9, "{out:?}");
    }
    assert!(out[4].abs() < 1e-6);
    // One view with edges everywhere, one without: exactly half the minimum.
    g.log_likelihood_batch(&[ones.clone(), zeros.clone()], &poses, &mut out)
        .unwrap();
    assert!((out[0] - min / 2.0).abs() < 1e-6, "{out:?}");
    assert!((out[1] - min).abs() < 1e-9);
    compare(&g, &[ones.clone(), zeros.clone()], &poses);
    // Errors, not panics.
    assert!(
        g.log_likelihood_batch(std::slice::from_ref(&ones), &poses, &mut out)
            .is_err()
    );
    assert!(
        g.log_likelihood_batch(&[ones.clone(), ones.clone()], &poses, &mut out[..2])
            .is_err()
    );
    g.log_likelihood_batch(&[ones.clone(), ones], &[], &mut [])
        .unwrap();
}

#[test]
fn gpu_close_and_large_parts() {
    // A camera about 0.5 m from the arm: parts several times wider than in the other
    // tests, many cut by the image border.
    let cam = camera([0.3, 0.6, 1.1], 320, 240, [0.0; 5]);
    let Some(g) = gpu(vec![cam.clone()]) else {
        return;
    };
    let e = [edges(&cam, 5)];
    compare(&g, &e, &random_poses(200, 13));
}

/// Wall time of a 400-pose batch on the GPU and on the CPU (rayon), 640×480, one view.
/// `cargo test -p actrack-render --features gpu --release -- --ignored --nocapture timing`
#[test]
#[ignore = "timing, not a check"]
fn gpu_timing_400_poses() {
    let cam = camera(EYE, 640, 480, [0.0; 5]);
    let Some(g) = gpu(vec![cam.clone()]) else {
        return;
    };
    let e = [edges(&cam, 3)];
    let poses = random_poses(400, 11);
    let mut out = vec![0.0; poses.len()];
    let time = |f: &mut dyn FnMut()| {
        f();
        let reps = 20;
        let t = std::time::Instant::now();
        for _ in 0..reps {
            f();
        }
        t.elapsed().as_secs_f64() * 1e3 / f64::from(reps)
    };
    let gpu_ms = time(&mut || g.log_likelihood_batch(&e, &poses, &mut out).unwrap());
    let fallbacks = g.last_fallbacks();
    let cpu_ms = time(&mut || {
        g.cpu_model()
            .log_likelihood_batch(&e, &poses, &mut out)
            .unwrap();
    });
    eprintln!(
        "400 poses, 640×480: GPU ({}) {gpu_ms:.2} ms ({fallbacks} views on the CPU), \
         CPU ({} rayon threads) {cpu_ms:.2} ms",
        g.adapter_name(),
        rayon::current_num_threads()
    );
}
