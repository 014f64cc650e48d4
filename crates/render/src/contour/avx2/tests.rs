use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

use super::*;
use crate::{ArmGeometry, Camera, contour::project_prepared};

/// Random poses around the arm's rest pose, seen by cameras from far to close (parts
/// from a few pixels to a few hundred across), at 320×240, 480×360, 640×480, 1280×720 and
/// 1920×1080 (each image size picks its own G window, or the f64 loop).
fn scenes() -> Vec<(Camera, [f64; 9])> {
    let g = ArmGeometry::default();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
    let mut out = Vec::new();
    for &(w, h) in &[
        (320u32, 240u32),
        (480, 360),
        (640, 480),
        (1280, 720),
        (1920, 1080),
    ] {
        for &dist in &[0.6, 1.0, 1.8, 4.0] {
            let eye = Vector3::new(0.1, -dist, 1.3);
            let c =
                Camera::look_at(eye, Vector3::new(0.1, 0.3, 1.0), Vector3::z(), w, h, 1.0).unwrap();
            for _ in 0..40 {
                let mut p = [0.2, 0.0, 1.2, 0.3, 0.15, 0.95, 0.25, 0.55, 0.8];
                for x in &mut p[3..] {
                    *x += rng.random_range(-0.2..0.2);
                }
                crate::correct_arm(&g, &mut p, None);
                out.push((c.clone(), p));
            }
        }
    }
    out
}

#[test]
fn f32_positions_are_within_the_bound() {
    // The f32 loop relies on its samples being within `tol` of the f64 samples (less
    // the anchor): check with a margin of 4 over many runs of every kind.
    let Some(s) = V3::try_new() else {
        return;
    };
    let g = ArmGeometry::default();
    let (mut worst, mut checked) = (0.0f64, 0usize);
    for (cam, pose) in scenes() {
        let parts = project_prepared(&cam, &g, &pose);
        for part in parts.iter() {
            let bb = part.bbox();
            let a = [
                (0.5 * (bb[0] + bb[2])).round() + 37.0,
                (0.5 * (bb[1] + bb[3])).round() - 21.0,
            ];
            let mut sink = Collect {
                simd: s,
                a,
                runs: Vec::new(),
            };
            s.vectorize(Outline {
                part,
                sink: &mut sink,
            });
            let (runs, nr) = part.sample_runs(2.0);
            assert_eq!(nr, sink.runs.len());
            for (run, r32) in runs[..nr].iter().zip(&sink.runs) {
                assert_eq!(run.len(), r32.n);
                let mut exact = Vec::new();
                run.for_each(|x| exact.push(x));
                let mut got = Vec::new();
                s.vectorize(Positions {
                    run: r32,
                    out: &mut got,
                });
                for (k, x) in exact.iter().enumerate() {
                    let (u, v) = got[k];
                    let e = (f64::from(u) - (x.x - a[0]))
                        .abs()
                        .max((f64::from(v) - (x.y - a[1])).abs());
                    worst = worst.max(e / r32.tol);
                    checked += 1;
                }
                let b = r32.bx;
                for x in &exact {
                    let (u, v) = (x.x - a[0], x.y - a[1]);
                    assert!(b[0] <= u && u <= b[2] && b[1] <= v && v <= b[3]);
                }
            }
        }
    }
    assert!(checked > 100_000, "{checked}");
    assert!(worst < 0.25, "error / bound up to {worst}");
}

#[test]
fn f32_loop_and_its_fallback_give_the_f64_sums() {
    // Every chunk through the f64 fallback, the f32 loop (which falls back only near
    // rounding or inside-test boundaries) and the portable f64 loop: the same points
    // and the same sums, bit for bit, for parts from tiny to larger than the G windows,
    // inside and cut by the image border.
    let g = ArmGeometry::default();
    let (mut n, mut total) = (0usize, 0usize);
    for (cam, pose) in scenes() {
        let (w, h) = (cam.width, cam.height);
        let data: Vec<f32> = (0..w as usize * h as usize)
            .map(|i| ((i * 37) % 101) as f32 / 100.0)
            .collect();
        let parts = project_prepared(&cam, &g, &pose);
        let fast = crate::contour::analytic_sum_nearest(&parts, w, h, 2.0, &data, w as usize);
        let Some(slow) =
            crate::contour::analytic_sum_nearest_by_fallback(&parts, w, h, 2.0, &data, w as usize)
        else {
            return;
        };
        let portable = crate::contour::analytic_sum(
            &parts,
            w,
            h,
            2.0,
            crate::contour::nearest_cost(&data, w as usize),
        );
        assert_eq!((fast.0.to_bits(), fast.1), (slow.0.to_bits(), slow.1));
        assert_eq!(
            (fast.0.to_bits(), fast.1),
            (portable.0.to_bits(), portable.1)
        );
        n += usize::from(fast.1 > 0);
        total += fast.1;
    }
    assert!(n > 300 && total > 100_000, "{n} {total}");
}

#[test]
fn f32_inside_test_is_sure_only_when_the_f64_test_agrees() {
    let Some(s) = V3::try_new() else {
        return;
    };
    let g = ArmGeometry::default();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
    let (mut sure, mut unsure) = (0usize, 0usize);
    for (cam, pose) in scenes().into_iter().step_by(7) {
        let parts = project_prepared(&cam, &g, &pose);
        for part in parts.iter() {
            let bb = part.bbox();
            let a = [
                (0.5 * (bb[0] + bb[2])).round() - 3.0,
                (0.5 * (bb[1] + bb[3])).round() + 5.0,
            ];
            let shape = Inside::new(part);
            let t = 1e-4;
            let s32 = Shape32::of_part(part, a, t);
            for _ in 0..200 {
                let x: [f64; L8] =
                    core::array::from_fn(|_| rng.random_range(bb[0] - 2.0..bb[2] + 2.0));
                let y: [f64; L8] =
                    core::array::from_fn(|_| rng.random_range(bb[1] - 2.0..bb[3] + 2.0));
                let (u, v) = (x.map(|x| (x - a[0]) as f32), y.map(|y| (y - a[1]) as f32));
                let (deep, out) = s.vectorize(Test { s32: &s32, u, v });
                for l in 0..L8 {
                    let d64 = shape.deep([x[l]; LANES], [y[l]; LANES])[0];
                    if deep[l] {
                        assert!(d64, "{x:?} {y:?} {l}");
                    }
                    if out[l] {
                        assert!(!d64, "{x:?} {y:?} {l}");
                    }
                    assert!(!(deep[l] && out[l]));
                    if deep[l] || out[l] {
                        sure += 1;
                    } else {
                        unsure += 1;
                    }
                }
            }
        }
    }
    assert!(sure > 100_000 && unsure * 1000 < sure, "{sure} {unsure}");
}

struct Test<'a> {
    s32: &'a Shape32,
    u: [f32; L8],
    v: [f32; L8],
}

impl pulp::NullaryFnOnce for Test<'_> {
    type Output = ([bool; L8], [bool; L8]);
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn call(self) -> Self::Output {
        let s = V3::try_new().unwrap();
        let (d, o) = self.s32.test(s, pulp::cast(self.u), pulp::cast(self.v));
        let (d, o): ([u32; L8], [u32; L8]) = (pulp::cast(d), pulp::cast(o));
        (d.map(|x| x != 0), o.map(|x| x != 0))
    }
}

/// The f32 runs of a part.
struct Collect {
    simd: V3,
    a: [f64; 2],
    runs: Vec<Run32>,
}

impl crate::contour::OutlineSink for Collect {
    fn line(&mut self, p: Vector2<f64>, q: Vector2<f64>, n: usize) {
        self.runs.push(Run32::line(self.a, p, q, n));
    }
    fn trig(
        &mut self,
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
        circle: bool,
    ) {
        self.runs
            .push(Run32::trig(self.simd, self.a, c, u, w, theta, n, circle));
    }
}

struct Outline<'a> {
    part: &'a Prepared,
    sink: &'a mut Collect,
}

impl pulp::NullaryFnOnce for Outline<'_> {
    type Output = ();
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn call(self) {
        self.part.sample_outline(2.0, self.sink);
    }
}

struct Positions<'a> {
    run: &'a Run32,
    out: &'a mut Vec<(f32, f32)>,
}

impl pulp::NullaryFnOnce for Positions<'_> {
    type Output = ();
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn call(self) {
        let s = V3::try_new().unwrap();
        for_each_chunk32(s, self.run, |_, u, v, _| {
            let (u, v): ([f32; L8], [f32; L8]) = (pulp::cast(u), pulp::cast(v));
            self.out.extend(u.iter().zip(&v).map(|(&a, &b)| (a, b)));
        });
    }
}
