use super::*;

/// Straightforward reference of SPEC §4.1 in f64 with per-pixel clamping.
fn reference(grey: &[f64], w: usize, h: usize, p: &EdgeParams) -> Vec<f64> {
    finish_reference(sobel_reference(grey, w, h), w, h, p)
}

/// The colour variant: per pixel the largest Sobel magnitude of R, G and B, then as SPEC §4.1.
fn colour_reference(rgb: &[u8], w: usize, h: usize, p: &EdgeParams) -> Vec<f64> {
    let mut g = vec![0.0f64; w * h];
    for c in 0..3 {
        let chan: Vec<f64> = rgb.chunks_exact(3).map(|px| f64::from(px[c])).collect();
        for (m, v) in g.iter_mut().zip(sobel_reference(&chan, w, h)) {
            *m = m.max(v);
        }
    }
    finish_reference(g, w, h, p)
}

/// Sobel/8 magnitude with clamped borders.
#[allow(clippy::imprecise_flops)]
fn sobel_reference(grey: &[f64], w: usize, h: usize) -> Vec<f64> {
    let at = |x: i64, y: i64| {
        let x = x.clamp(0, w as i64 - 1) as usize;
        let y = y.clamp(0, h as i64 - 1) as usize;
        grey[y * w + x]
    };
    let mut g = vec![0.0; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let gx = (at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x - 1, y)
                - at(x - 1, y + 1))
                / 8.0;
            let gy = (at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x, y - 1)
                - at(x + 1, y - 1))
                / 8.0;
            g[y as usize * w + x as usize] = (gx * gx + gy * gy).sqrt();
        }
    }
    g
}

/// Normalisation, threshold, Gaussian and normalisation of SPEC §4.1 on a magnitude image.
fn finish_reference(mut g: Vec<f64>, w: usize, h: usize, p: &EdgeParams) -> Vec<f64> {
    let m = g.iter().copied().fold(0.0, f64::max);
    for v in &mut g {
        *v /= m;
        if *v > f64::from(p.tau) {
            *v = 1.0;
        } else if p.binary {
            *v = 0.0;
        }
    }
    let s = f64::from(p.sigma);
    let r = (3.0 * s).ceil() as i64;
    let k: Vec<f64> = (-r..=r)
        .map(|j| (-((j * j) as f64) / (2.0 * s * s)).exp())
        .collect();
    let gat = |g: &[f64], x: i64, y: i64| {
        g[y.clamp(0, h as i64 - 1) as usize * w + x.clamp(0, w as i64 - 1) as usize]
    };
    let mut t = vec![0.0; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            t[y as usize * w + x as usize] = (-r..=r)
                .map(|j| k[(j + r) as usize] * gat(&g, x + j, y))
                .sum();
        }
    }
    let mut o = vec![0.0; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            o[y as usize * w + x as usize] = (-r..=r)
                .map(|j| k[(j + r) as usize] * gat(&t, x, y + j))
                .sum();
        }
    }
    let m = o.iter().copied().fold(0.0, f64::max);
    o.iter().map(|v| v / m).collect()
}

fn test_frame(w: usize, h: usize) -> Vec<u8> {
    let mut rgb = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let i = 3 * (y * w + x);
            let inside = (x as f64 - 20.0).hypot(y as f64 - 15.0) < 9.0 || (x > 30 && y > 20);
            let base = if inside { 200u8 } else { 40 };
            rgb[i] = base;
            rgb[i + 1] = base.wrapping_add((x * 7 % 13) as u8);
            rgb[i + 2] = (y * 3 % 50) as u8;
        }
    }
    rgb
}

#[test]
fn matches_reference() {
    for &(w, h) in &[(45usize, 37usize), (8, 5), (1, 1), (3, 40), (17, 2)] {
        let rgb = test_frame(w, h);
        let grey: Vec<f64> = rgb
            .chunks_exact(3)
            .map(|p| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
            .collect();
        for params in [
            EdgeParams::default(),
            EdgeParams {
                tau: 0.35,
                sigma: 1.5,
                binary: true,
                colour: false,
            },
            EdgeParams {
                tau: 0.1,
                sigma: 2.2,
                binary: false,
                colour: false,
            },
        ] {
            let mut ws = EdgeWorkspace::new();
            let g = ws
                .compute(ImageView::rgb8(&rgb, w as u32, h as u32).unwrap(), &params)
                .unwrap()
                .clone();
            let has_gradient = grey.iter().any(|&v| (v - grey[0]).abs() > 1e-9);
            if !has_gradient {
                assert!(g.data().iter().all(|&v| v == 0.0));
                continue;
            }
            let r = reference(&grey, w, h, &params);
            let err = g
                .data()
                .iter()
                .zip(&r)
                .map(|(&a, &b)| (f64::from(a) - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-4, "{w}×{h} {params:?}: {err}");
            assert!((max_value(g.data()) - 1.0).abs() < 1e-6);
        }
    }
}

/// Colour gradients match the f64 reference (largest channel magnitude, then SPEC §4.1).
#[test]
fn colour_matches_reference() {
    for &(w, h) in &[(45usize, 37usize), (8, 5), (3, 40), (17, 2)] {
        let rgb = test_frame(w, h);
        for params in [
            EdgeParams {
                colour: true,
                ..EdgeParams::default()
            },
            EdgeParams {
                tau: 0.35,
                sigma: 1.5,
                binary: true,
                colour: true,
            },
        ] {
            let mut ws = EdgeWorkspace::new();
            let g = ws
                .compute(ImageView::rgb8(&rgb, w as u32, h as u32).unwrap(), &params)
                .unwrap()
                .clone();
            let r = colour_reference(&rgb, w, h, &params);
            let err = g
                .data()
                .iter()
                .zip(&r)
                .map(|(&a, &b)| (f64::from(a) - b).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-4, "{w}×{h} {params:?}: {err}");
        }
    }
}

/// A boundary between two colours of (nearly) the same grey value is no edge in the grey
/// gradient beside a strong one (a black stripe), and a full edge in the colour gradient; a
/// grey frame gives the same G either way.
#[test]
fn colour_sees_isoluminant_boundaries() {
    let (w, h) = (40usize, 20usize);
    // Grey 100 on both sides of column 20 (to 0.02), black from column 32.
    let (left, right) = ([100u8, 100, 100], [0u8, 150, 105]);
    let rgb: Vec<u8> = (0..w * h)
        .flat_map(|i| match i % w {
            x if x < 20 => left,
            x if x < 32 => right,
            _ => [0, 0, 0],
        })
        .collect();
    let frame = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
    let grey = EdgeParams {
        sigma: 0.0,
        tau: 0.5,
        ..EdgeParams::default()
    };
    let colour = EdgeParams {
        colour: true,
        ..grey
    };
    let mut ws = EdgeWorkspace::new();
    let g = ws.compute(frame, &grey).unwrap().clone();
    let c = ws.compute(frame, &colour).unwrap().clone();
    for y in 0..h {
        let at = |e: &EdgeImage, x: usize| e.data()[y * w + x];
        assert!(at(&g, 32) > 0.999, "row {y}: {}", at(&g, 32));
        assert!(at(&g, 20) < 0.01, "row {y}: {}", at(&g, 20));
        assert!(at(&c, 20) > 0.999, "row {y}: {}", at(&c, 20));
        assert!(at(&c, 32) > 0.999, "row {y}: {}", at(&c, 32));
        assert!(at(&c, 10).abs() < 1e-6, "row {y}: {}", at(&c, 10));
    }
    // A grey frame: the same G from either gradient.
    let rgb: Vec<u8> = test_frame(w, h)
        .chunks_exact(3)
        .flat_map(|p| [p[1]; 3])
        .collect();
    let frame = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
    let a = ws.compute(frame, &EdgeParams::default()).unwrap().clone();
    let b = ws
        .compute(
            frame,
            &EdgeParams {
                colour: true,
                ..EdgeParams::default()
            },
        )
        .unwrap()
        .clone();
    let err = a
        .data()
        .iter()
        .zip(b.data())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max);
    assert!(err < 1e-5, "{err}");
}

/// `compute_into` gives what `compute` gives and only trades buffers with the caller.
#[test]
fn compute_into_swaps_without_copying() {
    let (w, h) = (45usize, 37usize);
    let a = test_frame(w, h);
    let b: Vec<u8> = a.iter().rev().copied().collect();
    let mut ws = EdgeWorkspace::new();
    let mut reference = EdgeWorkspace::new();
    let mut out = EdgeImage::default();
    let p = EdgeParams::default();
    for rgb in [&a, &b, &a] {
        let frame = ImageView::rgb8(rgb, w as u32, h as u32).unwrap();
        ws.compute_into(frame, &p, &mut out).unwrap();
        assert_eq!(&out, reference.compute(frame, &p).unwrap());
    }
    // After two frames the two buffers just trade places: no new allocation.
    let before = out.data.as_ptr();
    let frame = ImageView::rgb8(&b, w as u32, h as u32).unwrap();
    ws.compute_into(frame, &p, &mut out).unwrap();
    ws.compute_into(frame, &p, &mut out).unwrap();
    assert_eq!(out.data.as_ptr(), before);
    let bad = ImageView::rgb8(&b, 0, 0);
    assert!(bad.is_err() || ws.compute_into(bad.unwrap(), &p, &mut out).is_err());
}

/// Parameter sets of the bit-identity tests: the defaults, a binary map with a small σ on
/// colour gradients, no smoothing.
fn variant_params() -> [EdgeParams; 3] {
    [
        EdgeParams::default(),
        EdgeParams {
            tau: 0.35,
            sigma: 1.5,
            binary: true,
            colour: true,
        },
        EdgeParams {
            sigma: 0.0,
            ..EdgeParams::default()
        },
    ]
}

/// The variant chosen at run time (AVX2 or AVX-512 on most x86-64 machines) gives the same
/// G, bit for bit, as the baseline (SSE2) build of the same kernels.
#[test]
fn dispatched_equals_baseline() {
    for &(w, h) in &[(45usize, 37usize), (67, 9), (2, 3)] {
        let rgb = test_frame(w, h);
        let frame = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
        for params in variant_params() {
            let mut ws = EdgeWorkspace::new();
            let fast = ws.compute(frame, &params).unwrap().clone();
            let mut base = EdgeWorkspace::new();
            base.compute_banded(&frame, &params, 1, Isa::Scalar);
            assert_eq!(fast, base.out, "{w}×{h} {params:?}");
            // Split into bands, the baseline variant gives the same G as well.
            base.compute_banded(&frame, &params, 3, Isa::Scalar);
            assert_eq!(fast, base.out, "{w}×{h} {params:?}, 3 bands");
        }
    }
}

/// G is bit-identical for every split into row bands (from one band to one row per band,
/// bands thinner than the Gaussian's halo) and for every thread count of the pool,
/// including images smaller than a band; a workspace reused across sizes and band counts
/// gives the same G as a fresh one.
#[test]
fn bands_and_threads_give_identical_g() {
    let params = variant_params();
    let mut reused = EdgeWorkspace::new();
    for &(w, h) in &[
        (45usize, 37usize),
        (67, 9),
        (2, 3),
        (1, 1),
        (17, 2),
        (131, 97),
        (5, 70),
    ] {
        let rgb = test_frame(w, h);
        let frame = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
        for p in &params {
            let mut one = EdgeWorkspace::new();
            one.compute_banded(&frame, p, 1, Isa::Dispatch(pulp::Arch::new()));
            let g = one.out.clone();
            for bands in [2, 3, 4, 7, h / 2, h, h + 5] {
                reused.compute_banded(&frame, p, bands, Isa::Dispatch(pulp::Arch::new()));
                assert_eq!(reused.out, g, "{w}×{h} {p:?}, {bands} bands");
            }
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let mut ws = EdgeWorkspace::new();
                let got = pool.install(|| ws.compute(frame, p).unwrap().clone());
                assert_eq!(got, g, "{w}×{h} {p:?}, {threads} threads");
            }
        }
    }
}

/// Different band counts for the Sobel and the Gaussian passes, run by several workers on
/// pools of 1–3 threads (more workers than threads included: a worker that finds every
/// band claimed returns), give the same G as one band.
#[test]
fn workers_and_mixed_splits_give_identical_g() {
    let params = variant_params();
    for &(w, h) in &[(45usize, 37usize), (131, 97), (5, 70), (17, 2)] {
        let rgb = test_frame(w, h);
        let frame = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
        for p in &params {
            let mut one = EdgeWorkspace::new();
            one.compute_banded(&frame, p, 1, Isa::Dispatch(pulp::Arch::new()));
            let mut ws = EdgeWorkspace::new();
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                for (sobel, gauss) in [(8, 2), (3, 5), (1, 4), (h, 1), (h, h)] {
                    for workers in [1, 2, 4] {
                        pool.install(|| {
                            ws.compute_split(
                                &frame,
                                p,
                                Split::forced(h, sobel, gauss),
                                workers,
                                Isa::Dispatch(pulp::Arch::new()),
                            );
                        });
                        assert_eq!(
                            ws.out, one.out,
                            "{w}×{h} {p:?}, {sobel}/{gauss} bands, {workers} workers, {threads} threads"
                        );
                    }
                }
            }
        }
    }
}

/// The Gaussian pass split into column strips of any width (one column, narrower than the
/// kernel's radius, not dividing the width, the whole width) gives the same G, bit for bit,
/// as the automatic width, in both instruction-set variants; the automatic width is a
/// multiple of 8 whose ring fits in `RING_BYTES`.
#[test]
fn column_strips_give_identical_g() {
    for &(w, h) in &[(45usize, 37usize), (131, 20), (2, 3), (300, 9)] {
        let rgb = test_frame(w, h);
        let frame = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
        for p in &variant_params() {
            let mut auto = EdgeWorkspace::new();
            auto.compute_banded(&frame, p, 1, Isa::Dispatch(pulp::Arch::new()));
            let mut ws = EdgeWorkspace::new();
            for strip in [1, 3, 8, 17, 64, w - 1, w, w + 9] {
                for isa in [Isa::Dispatch(pulp::Arch::new()), Isa::Scalar] {
                    let split = Split {
                        strip: Some(strip.max(1)),
                        ..Split::forced(h, 2, 2)
                    };
                    ws.compute_split(&frame, p, split, 1, isa);
                    assert_eq!(ws.out, auto.out, "{w}×{h} {p:?}, strips of {strip}");
                }
            }
        }
    }
    for (w, r) in [
        (640, 12),
        (1920, 12),
        (640, 3),
        (100, 12),
        (7, 1),
        (640, 300),
    ] {
        let sw = strip_columns(w, r);
        assert!(sw >= 1 && sw <= w, "{w} {r}: {sw}");
        assert!(sw == w || sw.is_multiple_of(8), "{w} {r}: {sw}");
        // At least 64 columns: a wider kernel's ring may exceed the budget.
        assert!(sw >= 64.min(w), "{w} {r}: {sw}");
        if sw < w && (2 * r + 1) * 64 * 4 <= RING_BYTES {
            assert!((2 * r + 1) * sw * 4 <= RING_BYTES, "{w} {r}: {sw}");
        }
    }
    assert_eq!(strip_columns(640, 12), 216);
}

#[test]
fn constant_frame_gives_zero_and_reuse() {
    let mut ws = EdgeWorkspace::new();
    let flat = vec![77u8; 30 * 20];
    let g = ws.compute(
        ImageView::grey8(&flat, 30, 20).unwrap(),
        &EdgeParams::default(),
    );
    assert!(g.unwrap().data().iter().all(|&v| v == 0.0));
    // Different sizes in sequence on one workspace.
    let rgb = test_frame(50, 40);
    let g = ws.compute(
        ImageView::rgb8(&rgb, 50, 40).unwrap(),
        &EdgeParams::default(),
    );
    let g = g.unwrap();
    assert_eq!((g.width(), g.height()), (50, 40));
    assert!(g.data().iter().all(|v| (0.0..=1.0).contains(v)));
    let f: Vec<f32> = vec![f32::NAN; 12];
    let g = ws.compute(
        ImageView::grey_f32(&f, 4, 3).unwrap(),
        &EdgeParams::default(),
    );
    assert!(g.unwrap().data().iter().all(|&v| v == 0.0));
}

#[test]
fn bad_input() {
    assert!(ImageView::rgb8(&[], 0, 0).is_err());
    assert!(ImageView::rgb8(&[0; 10], 2, 2).is_err());
    assert!(ImageView::grey8(&[0; 4], 0, 4).is_err());
    let mut ws = EdgeWorkspace::new();
    let bad = ImageView::Grey8 {
        data: &[1, 2, 3],
        width: 2,
        height: 2,
    };
    assert!(ws.compute(bad, &EdgeParams::default()).is_err());
    let img = [0u8; 4];
    let v = ImageView::grey8(&img, 2, 2).unwrap();
    assert!(
        ws.compute(
            v,
            &EdgeParams {
                tau: f32::NAN,
                ..EdgeParams::default()
            }
        )
        .is_err()
    );
    assert!(
        ws.compute(
            v,
            &EdgeParams {
                sigma: -1.0,
                ..EdgeParams::default()
            }
        )
        .is_err()
    );
}

#[test]
fn sampling() {
    let g = EdgeImage::from_vec(3, 2, vec![0.0, 0.5, 1.0, 0.25, 0.75, 0.0]).unwrap();
    assert_eq!(g.sample_nearest(1.4, 0.6), Some(0.75));
    assert_eq!(g.sample_nearest(-0.6, 0.0), None);
    assert_eq!(g.sample_nearest(2.49, 1.49), Some(0.0));
    assert_eq!(g.sample_nearest(f64::NAN, 0.0), None);
    let b = g.sample_bilinear(0.5, 0.5).unwrap();
    assert!((b - (0.0 + 0.5 + 0.25 + 0.75) / 4.0).abs() < 1e-6);
    assert_eq!(g.get(2, 0), Some(1.0));
    assert_eq!(g.get(3, 0), None);
}

#[test]
fn grey_image_equals_the_rows_of_the_edge_stage() {
    // Every byte value in every channel, on an odd width.
    let (w, h) = (37usize, 23usize);
    let rgb: Vec<u8> = (0..3 * w * h)
        .map(|i| ((i * 97 + i / 5) % 256) as u8)
        .collect();
    let view = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
    let (mut chan, mut got) = (Vec::new(), Vec::new());
    grey_image(view, &mut got);
    let mut row = vec![0.0; w];
    for y in 0..h {
        grey_row(&view, y, &mut chan, &mut row);
        assert_eq!(&got[y * w..(y + 1) * w], &row[..], "row {y}");
    }
}

/// The integer colour Sobel gives, bit for bit, the channel-by-channel f32 computation: the
/// grey kernel on each channel as a grey frame, the largest of the three magnitudes kept; for
/// every band split, in the dispatched and the baseline variant.
#[test]
fn colour_sobel_equals_the_largest_channel_magnitude() {
    for &(w, h) in &[(45usize, 37usize), (67, 9), (2, 3), (1, 4), (3, 1)] {
        let rgb = test_frame(w, h);
        let frame = ImageView::rgb8(&rgb, w as u32, h as u32).unwrap();
        let sobel = |frame: &ImageView<'_>, colour: bool, isa: Isa, y0: usize, y1: usize| {
            let mut s = WorkerScratch::default();
            let mut mag = vec![0f32; (y1 - y0) * w];
            let m = isa.run(SobelBand {
                s: &mut s,
                frame,
                y0,
                h,
                mag: &mut mag,
                colour,
            });
            (mag, m)
        };
        let mut want = vec![0f32; w * h];
        for c in 0..3 {
            let chan: Vec<u8> = rgb.chunks_exact(3).map(|px| px[c]).collect();
            let grey = ImageView::grey8(&chan, w as u32, h as u32).unwrap();
            let (mag, _) = sobel(&grey, false, Isa::Scalar, 0, h);
            for (m, v) in want.iter_mut().zip(mag) {
                *m = m.max(v);
            }
        }
        for isa in [Isa::Scalar, Isa::Dispatch(pulp::Arch::new())] {
            for bands in [1, 2, 3] {
                let rows = h.div_ceil(bands);
                for y0 in (0..h).step_by(rows) {
                    let y1 = (y0 + rows).min(h);
                    let (mag, m) = sobel(&frame, true, isa, y0, y1);
                    let part = &want[y0 * w..y1 * w];
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&mag), bits(part), "{w}×{h} rows {y0}..{y1}");
                    assert_eq!(m.to_bits(), max_value(part).to_bits());
                }
            }
        }
    }
}
