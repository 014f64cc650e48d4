//! Tests across modules: synthesised frames, the likelihood peak at the true pose, bad input
//! and property tests.

use nalgebra::Vector3;
use proptest::prelude::*;

use crate::fixtures::{SHOULDER, camera, scene};
use crate::{
    ArmGeometry, Camera, ContourMethod, EdgeImage, EdgeParams, EdgeWorkspace, ImageView,
    LikelihoodModel, RenderError, correct_arm,
};

/// Reaching poses toward table targets, corrected.
fn poses() -> Vec<[f64; 9]> {
    let g = ArmGeometry::default();
    let targets = [
        [0.25, 0.55, 0.8],
        [-0.1, 0.45, 0.82],
        [0.45, 0.4, 0.85],
        [0.15, 0.3, 0.95],
    ];
    let elbows = [
        [0.3, 0.15, 0.95],
        [0.15, 0.15, 0.95],
        [0.45, 0.05, 1.0],
        [0.3, 0.1, 0.92],
    ];
    targets
        .iter()
        .zip(&elbows)
        .map(|(t, e)| {
            let mut p = [
                SHOULDER[0],
                SHOULDER[1],
                SHOULDER[2],
                e[0],
                e[1],
                e[2],
                t[0],
                t[1],
                t[2],
            ];
            correct_arm(&g, &mut p, None);
            p
        })
        .collect()
}

fn edges_of(img: &crate::ImageRgb8) -> EdgeImage {
    let mut ws = EdgeWorkspace::new();
    ws.compute(img.view(), &EdgeParams::default())
        .unwrap()
        .clone()
}

fn shifted(pose: &[f64; 9], d: Vector3<f64>) -> [f64; 9] {
    let mut p = *pose;
    for j in 0..3 {
        for k in 0..3 {
            p[3 * j + k] += d[k];
        }
    }
    p
}

#[test]
fn synth_is_deterministic_and_plausible() {
    let cam = camera(320, 240);
    let s = scene();
    let pose = poses()[0];
    let a = s.render(&cam, &pose, 7).unwrap();
    let b = s.render(&cam, &pose, 7).unwrap();
    let c = s.render(&cam, &pose, 8).unwrap();
    assert_eq!(a, b);
    assert_ne!(a, c);
    assert_eq!(a.data.len(), 320 * 240 * 3);
    // The hand is skin-coloured (modulo shading and noise).
    let parts = ArmGeometry::default().parts(&pose).unwrap();
    let uv = cam.project(&parts.hand_centre).unwrap();
    let px = a.get(uv.x.round() as u32, uv.y.round() as u32).unwrap();
    assert!(px[0] > px[2] + 30, "{px:?}");
    if std::env::var_os("ACTRACK_WRITE_PNG").is_some() {
        for (i, pose) in poses().iter().enumerate() {
            let big = s.render(&camera(640, 480), pose, 100 + i as u64).unwrap();
            let name = format!("/tmp/actrack_synth{i}.png");
            image::save_buffer(&name, &big.data, 640, 480, image::ExtendedColorType::Rgb8).unwrap();
            let g = edges_of(&big);
            let grey: Vec<u8> = g.data().iter().map(|v| (v * 255.0) as u8).collect();
            let name = format!("/tmp/actrack_edges{i}.png");
            image::save_buffer(&name, &grey, 640, 480, image::ExtendedColorType::L8).unwrap();
        }
    }
}

#[test]
fn cached_synthesis_gives_the_bytes_of_render() {
    let s = scene();
    let mut more = scene();
    more.clutter = 5;
    let (small, big) = (camera(320, 240), camera(160, 120));
    let mut cache = crate::synth::SynthCache::default();
    // The same layer over several poses, then each part of the key changed in turn.
    let runs = [
        (&s, &small, 7),
        (&s, &small, 7),
        (&s, &small, 8),
        (&s, &big, 8),
        (&more, &big, 8),
        (&s, &small, 7),
    ];
    for (synth, cam, seed) in runs {
        for pose in poses() {
            let want = synth.render(cam, &pose, seed).unwrap();
            let got = synth.render_cached(&mut cache, cam, &pose, seed).unwrap();
            assert!(want == got, "seed {seed}, {}x{}", cam.width, cam.height);
        }
    }
    let mut quiet = scene();
    quiet.noise_sigma = 0.0;
    let a = quiet
        .render_cached(&mut cache, &small, &poses()[0], 3)
        .unwrap();
    assert!(a == quiet.render(&small, &poses()[0], 3).unwrap());
}

#[test]
fn video_noise_changes_from_frame_to_frame() {
    let cam = camera(320, 240);
    let s = scene();
    let pose = poses()[0];
    let mut quiet = scene();
    quiet.noise_sigma = 0.0;
    let clean = quiet.render(&cam, &pose, 7).unwrap();
    let mut cache = crate::synth::SynthCache::default();
    // Frame 0 is `render`'s frame; without noise every frame is the same.
    assert!(
        s.render_frame(&mut cache, &cam, &pose, 7, 0).unwrap() == s.render(&cam, &pose, 7).unwrap()
    );
    for f in [1, 2, 1000] {
        assert!(quiet.render_frame(&mut cache, &cam, &pose, 7, f).unwrap() == clean);
    }
    // The noise of frames 1 and 2 (frame minus the noiseless frame): σ² plus the rounding's
    // 1/12 each, and uncorrelated with each other and with frame 0's, pixel by pixel.
    let mut noise = |f: u64| -> Vec<f64> {
        let img = s.render_frame(&mut cache, &cam, &pose, 7, f).unwrap();
        img.data
            .iter()
            .zip(&clean.data)
            .map(|(&a, &b)| f64::from(a) - f64::from(b))
            .collect()
    };
    let (n0, n1, n2) = (noise(0), noise(1), noise(2));
    assert!(n1 == noise(1), "frame 1 is deterministic");
    let dot =
        |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() / a.len() as f64;
    let var = s.noise_sigma * s.noise_sigma + 1.0 / 12.0;
    for n in [&n0, &n1, &n2] {
        assert!(
            (dot(n, n) / var - 1.0).abs() < 0.05,
            "variance {}",
            dot(n, n)
        );
    }
    for (a, b) in [(&n0, &n1), (&n1, &n2), (&n0, &n2)] {
        assert!(
            dot(a, b).abs() / var < 0.02,
            "correlation {}",
            dot(a, b) / var
        );
    }
}

#[test]
fn cover_parts_matches_brute_force() {
    use crate::{Part2, cover_parts};
    let (w, h) = (120u32, 90u32);
    let capsules = [
        ([20.0, 30.0], [95.0, 55.0], 12.0, 6.0),
        ([60.0, 10.0], [62.0, 80.0], 4.0, 9.5),
        ([-20.0, 40.0], [30.0, 100.0], 8.0, 8.0), // cut by the border
        ([50.0, 50.0], [51.0, 50.5], 10.0, 3.0),  // one disc holds the other
    ];
    let ellipse = ([70.0, 40.0], 18.0, 7.0, 0.6);
    // Brute force: a capsule is the union of the discs c(t), r(t), t ∈ [0, 1].
    let dist = |(c0, c1, r0, r1): ([f64; 2], [f64; 2], f64, f64), x: [f64; 2]| {
        (0..=4000)
            .map(|i| {
                let t = f64::from(i) / 4000.0;
                let c = [c0[0] + t * (c1[0] - c0[0]), c0[1] + t * (c1[1] - c0[1])];
                (x[0] - c[0]).hypot(x[1] - c[1]) - (r0 + t * (r1 - r0))
            })
            .fold(f64::INFINITY, f64::min)
    };
    for grow in [0.0, 3.0] {
        for cap in capsules {
            let (c0, c1, r0, r1) = cap;
            let mut mask = vec![0u8; (w * h) as usize];
            let set =
                cover_parts(&[Part2::Capsule { c0, c1, r0, r1 }], grow, w, h, &mut mask).unwrap();
            // The returned rectangle is the bounding box of the set pixels.
            let (mut lo, mut hi) = ([w, h], [0, 0]);
            for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m == 1) {
                let (u, v) = (i as u32 % w, i as u32 / w);
                (lo, hi) = (
                    [lo[0].min(u), lo[1].min(v)],
                    [hi[0].max(u + 1), hi[1].max(v + 1)],
                );
            }
            assert_eq!(
                [set.x0, set.y0, set.x1, set.y1],
                [lo[0], lo[1], hi[0], hi[1]]
            );
            for v in 0..h {
                for u in 0..w {
                    let d = dist(cap, [f64::from(u), f64::from(v)]);
                    if (d - grow).abs() > 0.02 {
                        assert_eq!(
                            mask[(v * w + u) as usize] == 1,
                            d < grow,
                            "({u}, {v}) {cap:?}"
                        );
                    }
                }
            }
        }
    }
    let (c, a, b, angle) = ellipse;
    let mut mask = vec![0u8; (w * h) as usize];
    cover_parts(&[Part2::Ellipse { c, a, b, angle }], 0.0, w, h, &mut mask).unwrap();
    let mut inside = 0;
    for v in 0..h {
        for u in 0..w {
            let (x, y) = (f64::from(u) - c[0], f64::from(v) - c[1]);
            let (xa, xb) = (
                x * angle.cos() + y * angle.sin(),
                -x * angle.sin() + y * angle.cos(),
            );
            let rho = (xa / a).powi(2) + (xb / b).powi(2);
            if (rho - 1.0).abs() > 1e-9 {
                assert_eq!(mask[(v * w + u) as usize] == 1, rho < 1.0, "({u}, {v})");
                inside += usize::from(rho < 1.0);
            }
        }
    }
    // About π·a·b pixels.
    assert!((inside as f64 / (std::f64::consts::PI * a * b) - 1.0).abs() < 0.05);
    // The union: covered pixels are left covered, the rest untouched.
    let mut both = mask.clone();
    let (c0, c1, r0, r1) = capsules[0];
    cover_parts(&[Part2::Capsule { c0, c1, r0, r1 }], 0.0, w, h, &mut both).unwrap();
    assert!(mask.iter().zip(&both).all(|(m, b)| b >= m));
    assert!(both.iter().map(|&x| usize::from(x)).sum::<usize>() > inside);
    // Bad sizes give an error; a non-finite growth or part covers nothing.
    assert!(cover_parts(&[], 0.0, w, h, &mut [0u8; 3]).is_err());
    let mut none = vec![0u8; (w * h) as usize];
    cover_parts(
        &[Part2::Capsule { c0, c1, r0, r1 }],
        f64::NAN,
        w,
        h,
        &mut none,
    )
    .unwrap();
    let nan = Part2::Capsule {
        c0: [f64::NAN, 1.0],
        c1,
        r0,
        r1,
    };
    assert!(
        cover_parts(&[nan], 1.0, w, h, &mut none)
            .unwrap()
            .is_empty()
    );
    assert!(none.iter().all(|&x| x == 0));
}

#[test]
fn likelihood_peaks_at_true_pose() {
    let cam = camera(640, 480);
    let s = scene();
    let r = cam.rotation_matrix();
    // Camera right and down in the world, and the diagonals; plus world up/down.
    let right: Vector3<f64> = r.row(0).transpose();
    let down: Vector3<f64> = r.row(1).transpose();
    let dirs = [
        right,
        -right,
        down,
        -down,
        (right + down).normalize(),
        (right - down).normalize(),
        Vector3::z(),
        -Vector3::z(),
    ];
    for method in [ContourMethod::Raster, ContourMethod::Analytic] {
        let m =
            LikelihoodModel::new(vec![cam.clone()], ArmGeometry::default(), 0.15, method).unwrap();
        for (i, pose) in poses().iter().enumerate() {
            let frame = s.render(&cam, pose, 100 + i as u64).unwrap();
            let g = [edges_of(&frame)];
            let truth = m.log_likelihood(&g, pose).unwrap();
            assert!(
                truth > -15.0,
                "{method:?} pose {i}: truth scores only {truth}"
            );
            for d in [0.02, 0.05, 0.10] {
                for dir in &dirs {
                    let moved = m.log_likelihood(&g, &shifted(pose, dir * d)).unwrap();
                    assert!(
                        moved < truth,
                        "{method:?} pose {i}: moved {d} m along {dir:?} scores {moved} ≥ truth {truth}"
                    );
                }
                // Moving the fingertip alone (with re-correction).
                for dir in &dirs[..4] {
                    let mut p = *pose;
                    for k in 0..3 {
                        p[6 + k] += dir[k] * d;
                    }
                    correct_arm(&ArmGeometry::default(), &mut p, None);
                    let moved = m.log_likelihood(&g, &p).unwrap();
                    assert!(
                        moved < truth,
                        "{method:?} pose {i}: hand moved {d}: {moved} ≥ {truth}"
                    );
                }
            }
        }
    }
}

#[test]
fn bad_input_never_panics() {
    let cam = camera(64, 48);
    // Zero-size images are rejected.
    assert!(matches!(
        ImageView::rgb8(&[], 0, 48),
        Err(RenderError::InvalidImage(_))
    ));
    assert!(EdgeImage::constant(0, 0, 1.0).is_err());
    // Non-finite calibration.
    let mut bad = cam.clone();
    bad.rotation[1][2] = f64::NAN;
    assert!(
        LikelihoodModel::new(
            vec![bad.clone()],
            ArmGeometry::default(),
            0.15,
            ContourMethod::Raster
        )
        .is_err()
    );
    assert!(scene().render(&bad, &poses()[0], 1).is_err());
    let m = LikelihoodModel::new(
        vec![cam.clone()],
        ArmGeometry::default(),
        0.15,
        ContourMethod::Raster,
    )
    .unwrap();
    let g = [EdgeImage::constant(64, 48, 1.0).unwrap()];
    // NaN / infinite poses: the minimum.
    for bad_pose in [[f64::NAN; 9], [f64::INFINITY; 9], [1e300; 9]] {
        let l = m.log_likelihood(&g, &bad_pose).unwrap();
        assert!(
            l.is_finite() && (l - m.min_log_likelihood()).abs() < 1e-9,
            "{l}"
        );
    }
    // The camera behind the arm: no contour, ε̄ = 1.
    let eye = cam.center();
    let back: Vector3<f64> = cam.rotation_matrix().row(2).transpose();
    let b = eye - back * 0.5;
    let behind = [
        b.x,
        b.y,
        b.z + 0.1,
        b.x,
        b.y,
        b.z - 0.2,
        b.x + 0.1,
        b.y,
        b.z - 0.5,
    ];
    let l = m.log_likelihood(&g, &behind).unwrap();
    assert!((l - m.min_log_likelihood()).abs() < 1e-9);
    // Arm through the camera centre: clipped, finite.
    let through = [
        eye.x - back.x * 0.3,
        eye.y - back.y * 0.3,
        eye.z - back.z * 0.3,
        eye.x,
        eye.y,
        eye.z,
        eye.x + back.x * 0.4,
        eye.y + back.y * 0.4,
        eye.z + back.z * 0.4,
    ];
    for method in [ContourMethod::Raster, ContourMethod::Analytic] {
        let l = m
            .clone()
            .with_contour(method)
            .log_likelihood(&g, &through)
            .unwrap();
        assert!(l.is_finite() && l <= 0.0);
    }
    // Synthesis of degenerate poses.
    let img = scene().render(&cam, &[f64::NAN; 9], 3).unwrap();
    assert_eq!(img.data.len(), 64 * 48 * 3);
    let img = scene().render(&cam, &behind, 3).unwrap();
    assert_eq!(img.data.len(), 64 * 48 * 3);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn random_poses_and_cameras_give_finite_scores(
        pose in prop::array::uniform9(-3.0f64..3.0),
        eye in prop::array::uniform3(-4.0f64..4.0),
        target in prop::array::uniform3(-1.0f64..1.0),
        fov in 0.2f64..2.5,
        k1 in -0.4f64..0.4,
        w in 1u32..120,
        h in 1u32..90,
        analytic in any::<bool>(),
        correct in any::<bool>(),
    ) {
        let Ok(mut cam) = Camera::look_at(Vector3::from(eye), Vector3::from(target), Vector3::z(), w, h, fov) else {
            return Ok(());
        };
        cam.distortion[0] = k1;
        let method = if analytic { ContourMethod::Analytic } else { ContourMethod::Raster };
        let m = LikelihoodModel::new(vec![cam.clone()], ArmGeometry::default(), 0.15, method).unwrap();
        let g: Vec<f32> = (0..w * h).map(|i| (i % 7) as f32 / 6.0).collect();
        let g = [EdgeImage::from_vec(w, h, g).unwrap()];
        let mut pose = pose;
        if correct {
            correct_arm(&ArmGeometry::default(), &mut pose, None);
        }
        let l = m.log_likelihood(&g, &pose).unwrap();
        prop_assert!(l.is_finite() && l <= 0.0 && l >= m.min_log_likelihood() - 1e-9);
        let pts = crate::contour_points(&cam, &ArmGeometry::default(), &pose, method);
        for p in pts {
            prop_assert!(p[0].round() >= 0.0 && p[0].round() < f64::from(w));
            prop_assert!(p[1].round() >= 0.0 && p[1].round() < f64::from(h));
        }
    }

    #[test]
    fn correction_invariants(pose in prop::array::uniform9(-1.0f64..1.0), l1 in 0.1f64..0.5, l2 in 0.1f64..0.6) {
        let g = ArmGeometry::with_lengths(l1, l2);
        let mut x = pose;
        correct_arm(&g, &mut x, None);
        let p = Vector3::new(x[0], x[1], x[2]);
        let q = Vector3::new(x[3], x[4], x[5]);
        let r = Vector3::new(x[6], x[7], x[8]);
        prop_assert!(((q - p).norm() - l1).abs() < 1e-9);
        prop_assert!(((r - q).norm() - l2).abs() < 1e-9);
    }

    #[test]
    fn edge_image_any_size(w in 1u32..40, h in 1u32..40, seed in any::<u64>(), binary in any::<bool>(), colour in any::<bool>(), sigma in 0.0f32..6.0) {
        let n = (w * h * 3) as usize;
        let data: Vec<u8> = (0..n).map(|i| (seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(i as u64).wrapping_mul(1_442_695_040_888_963_407) >> 56) as u8).collect();
        let mut ws = EdgeWorkspace::new();
        let g = ws.compute(ImageView::rgb8(&data, w, h).unwrap(), &EdgeParams { tau: 0.2, sigma, binary, colour }).unwrap();
        prop_assert!(g.data().iter().all(|v| (0.0..=1.0).contains(v)));
    }
}
