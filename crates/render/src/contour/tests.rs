use nalgebra::{Vector2, Vector3};

use super::*;

fn cam() -> Camera {
    Camera::look_at(
        Vector3::new(0.1, -1.6, 1.5),
        Vector3::new(0.0, 0.25, 0.85),
        Vector3::z(),
        640,
        480,
        60f64.to_radians(),
    )
    .unwrap()
}

fn poses() -> Vec<[f64; 9]> {
    vec![
        [0.2, 0.0, 1.2, 0.25, 0.1, 0.93, 0.2, 0.52, 0.9],
        [0.2, 0.0, 1.2, 0.35, 0.15, 1.0, 0.05, 0.5, 0.95],
        [0.2, 0.0, 1.2, 0.2, 0.0, 0.9, 0.2, 0.45, 0.9],
        [-0.2, 0.1, 1.2, -0.3, 0.2, 0.95, 0.1, 0.4, 0.8],
    ]
}

#[test]
fn raster_contour_is_inner_boundary_of_silhouette() {
    let c = cam();
    let g = ArmGeometry::default();
    for pose in poses() {
        let parts = project_prepared(&c, &g, &pose);
        assert_eq!(parts.n, 3);
        let s = silhouette(&parts, c.width, c.height);
        let w = c.width as usize;
        let h = c.height as usize;
        let mut expected = Vec::new();
        for v in 0..h {
            for u in 0..w {
                if s[v * w + u] == 0 {
                    continue;
                }
                let out = |du: i64, dv: i64| {
                    let (uu, vv) = (u as i64 + du, v as i64 + dv);
                    uu < 0
                        || vv < 0
                        || uu >= w as i64
                        || vv >= h as i64
                        || s[vv as usize * w + uu as usize] == 0
                };
                if out(-1, 0) || out(1, 0) || out(0, -1) || out(0, 1) {
                    expected.push([u, v]);
                }
            }
        }
        let mut scratch = RenderScratch::new();
        let mut got = Vec::new();
        // Twice with the same scratch: the mask must come back clean.
        for _ in 0..2 {
            got.clear();
            raster_contour(&parts, c.width, c.height, &mut scratch, |u, v| {
                got.push([u, v]);
            });
            got.sort_by_key(|p| (p[1], p[0]));
            assert_eq!(got, expected);
        }
        assert!(got.len() > 100);
    }
}

#[test]
fn raster_and_analytic_agree() {
    let c = cam();
    let g = ArmGeometry::default();
    for pose in poses() {
        let raster = contour_points(&c, &g, &pose, ContourMethod::Raster);
        let analytic = contour_points(&c, &g, &pose, ContourMethod::Analytic);
        let near = |p: &[f64; 2], set: &[[f64; 2]], tol: f64| {
            set.iter().any(|q| (p[0] - q[0]).hypot(p[1] - q[1]) <= tol)
        };
        let far_a = analytic.iter().filter(|p| !near(p, &raster, 1.5)).count();
        assert_eq!(far_a, 0, "analytic samples away from the raster contour");
        let far_r = raster.iter().filter(|p| !near(p, &analytic, 2.0)).count();
        assert!(
            (far_r as f64) < 0.03 * raster.len() as f64,
            "{far_r} of {} raster pixels far from analytic samples",
            raster.len()
        );
    }
}

#[test]
fn sample_runs_are_the_outline_walk() {
    // The runs of the likelihood's sampler give the points of the reference outline walk
    // (same number, same order, equal up to rounding), for every part kind and several
    // spacings.
    let c = cam();
    let g = ArmGeometry::default();
    let mut parts: Vec<Prepared> = poses()
        .iter()
        .flat_map(|p| {
            let pr = project_prepared(&c, &g, p);
            pr.iter().copied().collect::<Vec<_>>()
        })
        .collect();
    parts.push(Prepared::new(&Part2::Capsule {
        c0: [10.0, 10.0],
        c1: [10.5, 10.0],
        r0: 5.0,
        r1: 2.0,
    }));
    // Small radii: arcs with θ > ½ (libm sine and cosine instead of the polynomials).
    parts.push(Prepared::new(&Part2::Capsule {
        c0: [30.0, 20.0],
        c1: [60.0, 35.0],
        r0: 1.5,
        r1: 0.7,
    }));
    assert!(parts.iter().any(|p| matches!(p, Prepared::Circle { .. })));
    for part in &parts {
        for step in [0.7, 2.0, 3.3] {
            let mut walk = Vec::new();
            part.walk_outline(step, false, |x| walk.push(x));
            let mut runs = Vec::new();
            let (r, n) = part.sample_runs(step);
            for run in &r[..n] {
                run.for_each(|x| runs.push(x));
            }
            assert_eq!(walk.len(), runs.len());
            for (a, b) in walk.iter().zip(&runs) {
                assert!((a - b).norm() < 1e-9, "{a:?} vs {b:?}");
            }
            // Consecutive samples at most Δ apart (the arcs' chords and line steps).
            for w in runs.windows(2) {
                assert!((w[1] - w[0]).norm() <= step + 1e-9);
            }
        }
    }
}

#[test]
fn prepared_hand_axes_are_those_of_the_angle() {
    // The half-angle axis directions of `project_prepared` equal cos/sin of the public
    // `Part2::Ellipse::angle` (atan2), over hand orientations in every quadrant.
    let c = cam();
    let g = ArmGeometry::default();
    let mut n = 0;
    for k in 0..64 {
        let t = f64::from(k) * std::f64::consts::TAU / 64.0;
        let mut pose = [
            0.2,
            0.0,
            1.2,
            0.3,
            0.1,
            0.95,
            0.3 + 0.25 * t.cos(),
            0.1 + 0.25 * t.sin(),
            0.95 + 0.1 * (2.0 * t).sin(),
        ];
        crate::correct_arm(&g, &mut pose, None);
        let parts = project_prepared(&c, &g, &pose);
        let public = project_parts(&c, &g, &pose);
        let (
            Some(Prepared::Ellipse {
                c: c1,
                a,
                b,
                ea,
                eb,
            }),
            Some(part),
        ) = (parts.iter().last(), public.last())
        else {
            continue;
        };
        let Prepared::Ellipse {
            c: c2,
            a: a2,
            b: b2,
            ea: ea2,
            eb: eb2,
        } = Prepared::new(part)
        else {
            panic!("not an ellipse");
        };
        assert_eq!((c1, a, b), (&c2, &a2, &b2));
        assert!(
            (ea - ea2).norm() < 1e-12 && (eb - eb2).norm() < 1e-12,
            "{ea:?} {ea2:?}"
        );
        n += 1;
    }
    assert!(n > 50);
}

#[test]
fn four_lane_inside_test_is_the_scalar_one() {
    // `Inside::deep` agrees with the scalar `deep_inside` except within rounding of the
    // boundary (it multiplies by 1/a, 1/b where the scalar test divides).
    let c = cam();
    let g = ArmGeometry::default();
    let mut checked = 0;
    for pose in poses() {
        let parts = project_prepared(&c, &g, &pose);
        for part in parts.iter() {
            let shape = Inside::new(part);
            let bb = part.bbox();
            for j in 0..40 {
                for i in 0..10 {
                    let y = bb[1] - 3.0 + (bb[3] - bb[1] + 6.0) * f64::from(j) / 39.0;
                    let x: Lanes =
                        lanes(|l| bb[0] - 3.0 + (bb[2] - bb[0] + 6.0) * (4 * i + l) as f64 / 39.0);
                    let deep = shape.deep(x, [y; LANES]);
                    for l in 0..LANES {
                        let p = Vector2::new(x[l], y);
                        let margin = part.signed_distance(p) + INSIDE_TOL;
                        if margin.abs() > 1e-6 {
                            assert_eq!(deep[l], part.deep_inside(p), "{p:?}");
                            checked += 1;
                        }
                    }
                }
            }
        }
    }
    assert!(checked > 10_000);
}

#[test]
fn analytic_sums_are_over_the_contour_points() {
    // The specialised loops of the sampler (part inside / cut by the image border, 0–2
    // occluders), portable and AVX2, give exactly the points of `analytic_contour`: the
    // same number, and the sums agree with the sum over the points in order to rounding.
    // Cameras of several sizes cut parts at the border.
    let g = ArmGeometry::default();
    let mut occluder_counts = [0usize; 3];
    let mut cut = 0;
    let check = |parts: &Projected, w: u32, h: u32| {
        let cost = |u: f64, v: f64| (u * 0.37 + v * 1.3).sin();
        let (mut sum, mut count) = (0.0, 0usize);
        analytic_contour(parts, w, h, 2.0, |u, v| {
            sum += cost(u, v);
            count += 1;
        });
        let (s2, n2) = analytic_sum(parts, w, h, 2.0, cost);
        assert_eq!(count, n2);
        assert!((sum - s2).abs() < 1e-12 * count as f64, "{sum} vs {s2}");
        // Nearest-pixel (1 − G)² on a synthetic G, dispatched (AVX2 here when available).
        let data: Vec<f32> = (0..w as usize * h as usize)
            .map(|i| ((i * 37) % 101) as f32 / 100.0)
            .collect();
        let c = nearest_cost(&data, w as usize);
        let (mut sum, mut count) = (0.0, 0usize);
        analytic_contour(parts, w, h, 2.0, |u, v| {
            sum += c(u, v);
            count += 1;
        });
        let (s3, n3) = analytic_sum_nearest(parts, w, h, 2.0, &data, w as usize);
        assert_eq!(count, n3);
        assert!((sum - s3).abs() < 1e-12 * count as f64, "{sum} vs {s3}");
        let (s4, n4) = analytic_sum(parts, w, h, 2.0, &c);
        assert_eq!((s4.to_bits(), n4), (s3.to_bits(), n3));
        count
    };
    let shapes_of = |parts: &Projected| {
        let mut shapes = [Inside::Never; 3];
        for (s, p) in shapes.iter_mut().zip(parts.iter()) {
            *s = Inside::new(p);
        }
        shapes
    };
    for (w, h) in [(640, 480), (200, 150), (90, 300)] {
        let c = Camera::look_at(
            Vector3::new(0.1, -1.6, 1.5),
            Vector3::new(0.0, 0.25, 0.85),
            Vector3::z(),
            w,
            h,
            60f64.to_radians(),
        )
        .unwrap();
        // Plus a straight arm, whose upper arm and hand boxes do not overlap.
        let mut straight = [0.2, 0.0, 1.2, 0.2, 0.3, 1.2, 0.2, 0.6, 1.2];
        crate::correct_arm(&g, &mut straight, None);
        for pose in poses().into_iter().chain([straight]) {
            let parts = project_prepared(&c, &g, &pose);
            let boxes = part_boxes(&parts);
            let shapes = shapes_of(&parts);
            let (wf, hf) = (f64::from(w) - 0.5, f64::from(h) - 0.5);
            for i in 0..parts.n {
                if let Some((occ, inside)) = occluders(parts.n, &boxes, &shapes, i, wf, hf) {
                    occluder_counts[occ.n] += 1;
                    cut += usize::from(!inside);
                }
            }
            check(&parts, w, h);
        }
    }
    // Separated parts (no occluders), one of them cut by the border.
    let mut apart = Projected::default();
    for part in [
        Part2::Capsule {
            c0: [50.0, 50.0],
            c1: [100.0, 60.0],
            r0: 10.0,
            r1: 8.0,
        },
        Part2::Capsule {
            c0: [300.0, 300.0],
            c1: [350.0, 475.0],
            r0: 9.0,
            r1: 7.0,
        },
        Part2::Ellipse {
            c: [500.0, 100.0],
            a: 20.0,
            b: 9.0,
            angle: 0.4,
        },
    ] {
        apart.push(Prepared::new(&part));
    }
    let boxes = part_boxes(&apart);
    let shapes = shapes_of(&apart);
    for i in 0..apart.n {
        let (occ, inside) = occluders(apart.n, &boxes, &shapes, i, 639.5, 479.5).unwrap();
        occluder_counts[occ.n] += 1;
        cut += usize::from(!inside);
    }
    assert!(check(&apart, 640, 480) > 100);
    assert!(
        occluder_counts.iter().all(|&n| n > 0),
        "{occluder_counts:?}"
    );
    assert!(cut > 0);
}

#[test]
fn analytic_samples_are_on_the_union_outline() {
    let c = cam();
    let g = ArmGeometry::default();
    let pose = poses()[0];
    let parts = project_prepared(&c, &g, &pose);
    let mut n = 0;
    analytic_contour(&parts, c.width, c.height, 2.0, |u, v| {
        n += 1;
        let x = Vector2::new(u, v);
        let min_sd = parts
            .iter()
            .map(|p| p.signed_distance(x))
            .fold(f64::INFINITY, f64::min);
        assert!(min_sd.abs() < 0.51, "{min_sd}");
    });
    assert!(n > 50);
}

#[test]
fn parts_outside_or_behind() {
    let c = cam();
    let g = ArmGeometry::default();
    // Behind the camera.
    let eye = c.center();
    let behind = [
        eye.x,
        eye.y - 1.0,
        eye.z,
        eye.x,
        eye.y - 1.2,
        eye.z,
        eye.x,
        eye.y - 1.5,
        eye.z,
    ];
    assert!(project_parts(&c, &g, &behind).is_empty());
    assert!(contour_points(&c, &g, &behind, ContourMethod::Raster).is_empty());
    // Straddling the camera plane: clipped, no panic.
    let straddle = [
        eye.x,
        eye.y - 0.2,
        eye.z,
        eye.x + 0.05,
        eye.y + 0.1,
        eye.z,
        eye.x,
        eye.y + 0.5,
        eye.z,
    ];
    let _ = contour_points(&c, &g, &straddle, ContourMethod::Raster);
    let _ = contour_points(&c, &g, &straddle, ContourMethod::Analytic);
    // Far outside the image.
    let off = [50.0, 0.0, 1.0, 50.3, 0.0, 1.0, 50.7, 0.0, 1.0];
    assert!(contour_points(&c, &g, &off, ContourMethod::Raster).is_empty());
    assert!(contour_points(&c, &g, &off, ContourMethod::Analytic).is_empty());
    // Partly outside: every point inside the image.
    let part = [-1.2, 0.3, 1.0, -0.9, 0.3, 1.0, -0.5, 0.3, 1.0];
    for m in [ContourMethod::Raster, ContourMethod::Analytic] {
        for p in contour_points(&c, &g, &part, m) {
            assert!(p[0].round() >= 0.0 && p[0].round() < 640.0);
            assert!(p[1].round() >= 0.0 && p[1].round() < 480.0);
        }
    }
}

/// `cover_parts` steps over pixels by the distance bound; it sets exactly the pixels of the
/// part's bounding box grown by `grow` whose signed distance to the part is within `grow`, as
/// a test of every pixel does, for discs, thin and thick capsules at any slope and ellipses
/// with either axis the larger. The capsule's distance is the exact one (brute force over the
/// discs it is the hull of).
#[test]
fn cover_parts_sets_exactly_the_pixels_within_the_growth() {
    let (w, h) = (96u32, 72u32);
    let mut seed = 11u64;
    let mut uniform = |lo: f64, hi: f64| {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        lo + (hi - lo) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
    };
    for _ in 0..60 {
        let part = if uniform(0.0, 1.0) < 0.6 {
            Part2::Capsule {
                c0: [uniform(-20.0, 110.0), uniform(-20.0, 90.0)],
                c1: [uniform(-20.0, 110.0), uniform(-20.0, 90.0)],
                r0: uniform(0.3, 12.0),
                r1: uniform(0.3, 12.0),
            }
        } else {
            Part2::Ellipse {
                c: [uniform(0.0, 96.0), uniform(0.0, 72.0)],
                a: uniform(0.5, 25.0),
                b: uniform(0.5, 25.0),
                angle: uniform(0.0, 6.3),
            }
        };
        for grow in [0.0, 2.5, 8.0] {
            let mut mask = vec![0u8; (w * h) as usize];
            cover_parts(&[part], grow, w, h, &mut mask).unwrap();
            let p = Prepared::new(&part);
            let b = p.bbox();
            for v in 0..h {
                for u in 0..w {
                    let x = [f64::from(u), f64::from(v)];
                    let sd = p.signed_distance(Vector2::from(x));
                    let boxed = b[0] - grow <= x[0]
                        && x[0] <= b[2] + grow
                        && b[1] - grow <= x[1]
                        && x[1] <= b[3] + grow;
                    assert_eq!(
                        mask[(v * w + u) as usize] == 1,
                        boxed && sd <= grow,
                        "({u}, {v}) {part:?} grow {grow}: sd {sd}"
                    );
                    if let Part2::Capsule { c0, c1, r0, r1 } = part
                        && grow == 0.0
                        && (u + v) % 3 == 0
                    {
                        let brute = (0..=1000)
                            .map(|i| {
                                let t = f64::from(i) / 1000.0;
                                let c = [c0[0] + t * (c1[0] - c0[0]), c0[1] + t * (c1[1] - c0[1])];
                                (x[0] - c[0]).hypot(x[1] - c[1]) - (r0 + t * (r1 - r0))
                            })
                            .fold(f64::INFINITY, f64::min);
                        // Outside, the hull's distance is the discs' smallest; inside, the
                        // discs' value is at least the (negative) distance.
                        let tol = 0.05;
                        if brute > 0.0 {
                            assert!(
                                (sd - brute).abs() < tol,
                                "({u}, {v}) {part:?}: {sd} vs {brute}"
                            );
                        } else {
                            assert!(sd <= brute + tol, "({u}, {v}) {part:?}: {sd} vs {brute}");
                        }
                    }
                }
            }
        }
    }
}
