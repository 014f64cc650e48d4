//! The analytic sample loop of [`analytic_sum_nearest`](super::analytic_sum_nearest) with explicit
//! AVX2 vectors (pulp's `V3` token, no `unsafe` in our code): eight samples per register in f32,
//! relative to an integer anchor, with a bound of their error against the f64 samples of the
//! portable loop ([`sample_parts`](super::sample_parts)); a chunk of eight with a decision (rounded
//! pixel, image bounds, inside another part) within that bound of flipping is redone by the f64
//! loop (the same IEEE operations in the same order as the portable loop). So the same points pass,
//! and their `(1 − G)²` are summed in f64 in the portable loop's lanes and order: bit-identical
//! sums.

use pulp::{Simd, f32x4, f32x8, f64x4, i32x8, m32x8, m64x4, x86::V3};

use nalgebra::Vector2;

use super::{Inside, LANES, Occluders, Prepared, Projected, Run, occluders, part_boxes};

/// Lanes of the f32 loop: eight samples per AVX2 register.
const L8: usize = 8;

/// Whether any lane of `m` is set.
#[allow(clippy::inline_always)]
#[inline(always)]
fn any(m: m64x4) -> bool {
    let a: [u64; LANES] = pulp::cast(m);
    (a[0] | a[1] | a[2] | a[3]) != 0
}

/// The lanes of `m` as the bits of an integer (`vmovmskps`).
#[allow(clippy::inline_always)]
#[inline(always)]
fn bits(s: V3, m: m32x8) -> u32 {
    s.avx._mm256_movemask_ps(pulp::cast(m)).cast_unsigned()
}

/// `Σ (1 − G)²` over the analytic contour samples at their rounded pixels, and their number.
pub(super) struct Nearest<'a> {
    pub simd: V3,
    pub parts: &'a Projected,
    pub width: u32,
    pub height: u32,
    pub step: f64,
    pub data: &'a [f32],
    pub stride: usize,
    /// Redo every chunk by the f64 loop (tests).
    pub force_fallback: bool,
}

/// Accumulators and constants of the loop.
struct Acc<'a> {
    simd: V3,
    data: &'a [f32],
    /// The row stride, for the f64 chunks (fallback) and the f32 ones.
    stride: f64x4,
    stride_f: f32x8,
    sum: f64x4,
    /// Number of samples.
    n: usize,
}

mod shape;

use shape::{Gen32, Run32, Shape32, abs, abs64, inf, tolerance_bound};

/// Window lengths (f32 values) of G for the loops without bounds checks.
const W16: usize = 1 << 16;
const W17: usize = 1 << 17;
const W18: usize = 1 << 18;
const W20: usize = 1 << 20;

/// The constants of one part's f32 loop: its occluders' tests and (shrunk, splat) boxes,
/// the anchor's index in the G window, the image bounds, and what the fallback needs.
struct PartLoop<'a, 'w, const W: usize> {
    shapes: [&'a Shape32; 2],
    boxes: [[f32x8; 4]; 2],
    /// The occluders' boxes as f64, for the runs' test.
    boxes64: [[f64; 4]; 2],
    base: i32x8,
    /// Rounded relative coordinates inside the image: `[−a, size − a)`.
    bounds: [f32; 4],
    win: &'w [f32; W],
    ctx: &'a Ctx<'a>,
    force_fallback: bool,
}

/// What the fallback needs to redo a chunk in f64: the parts, their boxes, the part and
/// the spacing, the image bounds of the f64 test.
struct Ctx<'p> {
    parts: &'p Projected,
    boxes: &'p [[f64; 4]; 3],
    i: usize,
    step: f64,
    wh: [f64; 2],
}

/// The f32 loop fed by [`Prepared::sample_outline`]: each run is sampled as it comes.
struct Stream<'l, 'a, 'w, 'b, 'c, const INSIDE: bool, const NOCC: usize, const W: usize> {
    simd: V3,
    a: [f64; 2],
    pl: &'l PartLoop<'a, 'w, W>,
    acc: &'b mut Acc<'c>,
    /// Index of the next run.
    k: usize,
}

impl<const INSIDE: bool, const NOCC: usize, const W: usize> super::OutlineSink
    for Stream<'_, '_, '_, '_, '_, INSIDE, NOCC, W>
{
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn line(&mut self, p: Vector2<f64>, q: Vector2<f64>, n: usize) {
        let run = Run32::line(self.a, p, q, n);
        run_v3::<INSIDE, NOCC, W>(self.simd, &run, self.k, self.pl, self.acc);
        self.k += 1;
    }

    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn trig(
        &mut self,
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
        circle: bool,
    ) {
        let run = Run32::trig(self.simd, self.a, c, u, w, theta, n, circle);
        run_v3::<INSIDE, NOCC, W>(self.simd, &run, self.k, self.pl, self.acc);
        self.k += 1;
    }
}

impl pulp::NullaryFnOnce for Nearest<'_> {
    type Output = (f64, usize);

    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn call(self) -> (f64, usize) {
        let s = self.simd;
        let parts = self.parts;
        let (wf, hf) = (f64::from(self.width) - 0.5, f64::from(self.height) - 0.5);
        let boxes = part_boxes(parts);
        let np = parts.n.min(3);
        // One anchor for the whole pose: the rounded centre of the parts' boxes.
        let mut ub = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for b in &boxes[..np] {
            ub = [
                ub[0].min(b[0]),
                ub[1].min(b[1]),
                ub[2].max(b[2]),
                ub[3].max(b[3]),
            ];
        }
        let a = [
            (0.5 * (ub[0] + ub[2])).round(),
            (0.5 * (ub[1] + ub[3])).round(),
        ];
        let m = inf(ub[2] - a[0], ub[3] - a[1]).max(inf(a[0] - ub[0], a[1] - ub[1]));
        let mut t = 0.0f64;
        for part in parts.iter() {
            t = t.max(tolerance_bound(part, m, self.step));
        }
        let t = t + 2e-6 + 1e-6 * m;
        let mut shapes = [Shape32::Never; 3];
        for (sh, part) in shapes.iter_mut().zip(parts.iter()) {
            *sh = Shape32::of_part(part, a, t);
        }
        let mut acc = Acc {
            simd: s,
            data: self.data,
            stride: s.splat_f64s(self.stride as f64),
            stride_f: s.splat_f32s(self.stride as f32),
            sum: s.splat_f64s(0.0),
            n: 0,
        };
        let overlap = |a: &[f64; 4], b: &[f64; 4]| {
            a[0] <= b[2] && b[0] <= a[2] && a[1] <= b[3] && b[1] <= a[3]
        };
        let base = (a[1] * self.stride as f64 + a[0]) as i32;
        // Pixel indices relative to the anchor, `(v − a_v)·stride + (u − a_u)`, are
        // integers below 2²⁴ in magnitude for every pixel of the image (and so exact in
        // f32) unless the parts reach far outside a large image (then the f64 loop).
        let exact = (a[1].abs() + f64::from(self.height) + 1.0) * self.stride as f64
            + a[0].abs()
            + f64::from(self.width)
            < f64::from(1u32 << 24);
        let bounds = [
            -a[0] as f32,
            -a[1] as f32,
            (f64::from(self.width) - a[0]) as f32,
            (f64::from(self.height) - a[1]) as f32,
        ];
        for (i, part) in parts.iter().enumerate() {
            // As `occluders`: the part's box in the image, inside it, the overlapping parts.
            let bb = boxes[i];
            if bb[2] < -0.5 || bb[3] < -0.5 || bb[0] >= wf || bb[1] >= hf {
                continue;
            }
            let mg = super::INSIDE_MARGIN;
            let inside =
                bb[0] - mg >= -0.5 && bb[1] - mg >= -0.5 && bb[2] + mg < wf && bb[3] + mg < hf;
            let (mut oi, mut no) = ([0usize; 2], 0);
            for k in 0..np {
                if k != i && no < 2 && overlap(&bb, &boxes[k]) {
                    oi[no] = k;
                    no += 1;
                }
            }
            let ctx = Ctx {
                parts,
                boxes: &boxes,
                i,
                step: self.step,
                wh: [wf, hf],
            };
            // The rows the part's samples may round to, and a window of G of a power-of-two
            // length that holds them: the reads need no bounds checks (index & (len − 1)).
            let y0 = (bb[1] - 1.0).floor().max(0.0);
            let y1 = (bb[3] + 2.0).floor().min(f64::from(self.height));
            let rows = (y1 - y0).max(0.0) * self.stride as f64;
            let lo = y0 as u32 as usize * self.stride;
            let fits = |w: usize| exact && self.data.len() >= w && rows <= w as f64;
            let shrink = |k: usize| {
                let b = &boxes[oi[k]];
                [
                    (b[0] - a[0] + 0.4),
                    (b[1] - a[1] + 0.4),
                    (b[2] - a[0] - 0.4),
                    (b[3] - a[1] - 0.4),
                ]
            };
            let b64 = [shrink(0), shrink(1)];
            let sp = |b: &[f64; 4]| b.map(|x| s.splat_f32s(x as f32));
            macro_rules! go {
                ($w:expr) => {{
                    let start = lo.min(self.data.len() - $w);
                    let win: &[f32; $w] = self.data[start..start + $w].try_into().unwrap();
                    let pl = PartLoop {
                        shapes: [&shapes[oi[0]], &shapes[oi[1]]],
                        boxes: [sp(&b64[0]), sp(&b64[1])],
                        boxes64: b64,
                        base: pulp::cast([base - start as i32; L8]),
                        bounds,
                        win,
                        ctx: &ctx,
                        force_fallback: self.force_fallback,
                    };
                    match (inside, no) {
                        (true, 0) => stream::<true, 0, { $w }>(s, part, a, &pl, &mut acc),
                        (true, 1) => stream::<true, 1, { $w }>(s, part, a, &pl, &mut acc),
                        (true, _) => stream::<true, 2, { $w }>(s, part, a, &pl, &mut acc),
                        (false, 0) => stream::<false, 0, { $w }>(s, part, a, &pl, &mut acc),
                        (false, 1) => stream::<false, 1, { $w }>(s, part, a, &pl, &mut acc),
                        (false, _) => stream::<false, 2, { $w }>(s, part, a, &pl, &mut acc),
                    }
                }};
            }
            // The smallest window that holds the part's rows and fits in the image, so small
            // images take the f32 loop too.
            if fits(W16) {
                go!(W16);
            } else if fits(W17) {
                go!(W17);
            } else if fits(W18) {
                go!(W18);
            } else if fits(W20) {
                go!(W20);
            } else {
                // Tiny images or parts taller than the windows: the f64 loop.
                let (e2, k) = part_f64(s, &ctx, &acc);
                acc.sum = e2;
                acc.n += k;
            }
        }
        let sum: [f64; LANES] = pulp::cast(acc.sum);
        ((sum[0] + sum[1]) + (sum[2] + sum[3]), acc.n)
    }
}

/// Samples `part` into the f32 loop, with AVX2 (by pulp).
///
/// Out of line: each of the loop's specialisations (inside the image or not, occluders,
/// window length) is a function of its own rather than one more copy in [`Nearest`]'s body,
/// which keeps the kernel's code and its compile time linear in the number of specialisations.
#[inline(never)]
fn stream<const INSIDE: bool, const NOCC: usize, const W: usize>(
    s: V3,
    part: &Prepared,
    a: [f64; 2],
    pl: &PartLoop<'_, '_, W>,
    acc: &mut Acc<'_>,
) {
    s.vectorize(StreamCall::<INSIDE, NOCC, W> {
        simd: s,
        part,
        a,
        pl,
        acc,
    });
}

/// The body of [`stream`].
struct StreamCall<'p, 'l, 'a, 'w, 'b, 'c, const INSIDE: bool, const NOCC: usize, const W: usize> {
    simd: V3,
    part: &'p Prepared,
    a: [f64; 2],
    pl: &'l PartLoop<'a, 'w, W>,
    acc: &'b mut Acc<'c>,
}

impl<const INSIDE: bool, const NOCC: usize, const W: usize> pulp::NullaryFnOnce
    for StreamCall<'_, '_, '_, '_, '_, '_, INSIDE, NOCC, W>
{
    type Output = ();

    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn call(self) {
        let mut st = Stream::<INSIDE, NOCC, W> {
            simd: self.simd,
            a: self.a,
            pl: self.pl,
            acc: self.acc,
            k: 0,
        };
        self.part.sample_outline(self.pl.ctx.step, &mut st);
    }
}

/// The f64 occluders of the context's part (as the portable sampler has them).
fn with_occluders<R>(c: &Ctx<'_>, f: impl FnOnce(&Occluders<'_>) -> R) -> R {
    let mut shapes = [Inside::Never; 3];
    for (sh, part) in shapes.iter_mut().zip(c.parts.iter()) {
        *sh = Inside::new(part);
    }
    let (occ, _) = occluders(c.parts.n, c.boxes, &shapes, c.i, c.wh[0], c.wh[1])
        .expect("the part is in the image");
    f(&occ)
}

/// The whole part by the f64 loop (sum continued from `acc.sum`, count of its samples).
#[allow(clippy::inline_always)]
#[inline(always)]
fn part_f64(s: V3, c: &Ctx<'_>, acc: &Acc<'_>) -> (f64x4, usize) {
    let part = c.parts.iter().nth(c.i).expect("part");
    let (runs, nr) = part.sample_runs(c.step);
    with_occluders(c, |occ| {
        let (mut sum, mut n) = (acc.sum, 0);
        for run in &runs[..nr] {
            run.for_each_chunk(
                #[inline(always)]
                |u, v, ok| {
                    let ok: m64x4 = pulp::cast(ok.map(|b| if b { u64::MAX } else { 0 }));
                    let (e2, k) = chunk::<false, 2>(
                        pulp::cast(u),
                        pulp::cast(v),
                        ok,
                        occ,
                        c.wh[0],
                        c.wh[1],
                        acc,
                    );
                    sum = s.add_f64s(sum, e2);
                    n += k;
                },
            );
        }
        (sum, n)
    })
}

/// The f32 positions of `run`'s samples relative to the anchor, eight per chunk (the
/// chunk's lanes hold samples `8j + l`; lanes past the run are set too), passed to `f`
/// with the chunk index and whether it is the tail chunk.
#[allow(clippy::inline_always)]
#[inline(always)]
fn for_each_chunk32<F: FnMut(usize, f32x8, f32x8, bool)>(s: V3, run: &Run32, mut f: F) {
    let (full, tail) = (run.n / L8, run.n % L8);
    let sp = |x: f32| s.splat_f32s(x);
    match run.samples {
        Gen32::Line { p, s: st } => {
            let (px, py) = (sp(p[0]), sp(p[1]));
            let (sx, sy) = (sp(st[0]), sp(st[1]));
            let eight = s.splat_f32s(L8 as f32);
            let mut k = f32x8(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
            for j in 0..full {
                f(
                    j,
                    s.mul_add_e_f32s(k, sx, px),
                    s.mul_add_e_f32s(k, sy, py),
                    false,
                );
                k = s.add_f32s(k, eight);
            }
            if tail > 0 {
                f(
                    full,
                    s.mul_add_e_f32s(k, sx, px),
                    s.mul_add_e_f32s(k, sy, py),
                    true,
                );
            }
        }
        Gen32::Arc {
            c,
            mut rx,
            mut ry,
            c8,
            s8,
        } => {
            let (cx, cy) = (sp(c[0]), sp(c[1]));
            let (c8, s8, ns8) = (sp(c8), sp(s8), sp(-s8));
            for j in 0..full {
                f(j, s.add_f32s(cx, rx), s.add_f32s(cy, ry), false);
                (rx, ry) = (
                    s.mul_add_e_f32s(c8, rx, s.mul_f32s(s8, ry)),
                    s.mul_add_e_f32s(c8, ry, s.mul_f32s(ns8, rx)),
                );
            }
            if tail > 0 {
                f(full, s.add_f32s(cx, rx), s.add_f32s(cy, ry), true);
            }
        }
        Gen32::Trig {
            c,
            u,
            w,
            mut co,
            mut si,
            c8,
            s8,
        } => {
            let (cx, cy) = (sp(c[0]), sp(c[1]));
            let (ux, uy, wx, wy) = (sp(u[0]), sp(u[1]), sp(w[0]), sp(w[1]));
            let (c8, s8, ns8) = (sp(c8), sp(s8), sp(-s8));
            for j in 0..full {
                let x = s.mul_add_e_f32s(ux, co, s.mul_add_e_f32s(wx, si, cx));
                let y = s.mul_add_e_f32s(uy, co, s.mul_add_e_f32s(wy, si, cy));
                f(j, x, y, false);
                (co, si) = (
                    s.mul_add_e_f32s(co, c8, s.mul_f32s(si, ns8)),
                    s.mul_add_e_f32s(si, c8, s.mul_f32s(co, s8)),
                );
            }
            if tail > 0 {
                let x = s.mul_add_e_f32s(ux, co, s.mul_add_e_f32s(wx, si, cx));
                let y = s.mul_add_e_f32s(uy, co, s.mul_add_e_f32s(wy, si, cy));
                f(full, x, y, true);
            }
        }
    }
}

/// The f64 positions of the four samples `4q … 4q + 3` of `run`: those of the f64 loop
/// (the portable sampler's operations, the rotations repeated `q` times).
#[allow(clippy::inline_always)]
#[inline(always)]
fn chunk64(s: V3, run: &Run, q: usize) -> (f64x4, f64x4) {
    match *run {
        Run::Line { p, s: st, .. } => {
            let b = (LANES * q) as f64;
            let k = f64x4(b, b + 1.0, b + 2.0, b + 3.0);
            (
                s.add_f64s(s.splat_f64s(p.x), s.mul_f64s(k, s.splat_f64s(st.x))),
                s.add_f64s(s.splat_f64s(p.y), s.mul_f64s(k, s.splat_f64s(st.y))),
            )
        }
        Run::Arc {
            c, rx, ry, cl, sl, ..
        } => {
            let (cl, sl) = (s.splat_f64s(cl), s.splat_f64s(sl));
            let mut rx: f64x4 = pulp::cast(rx);
            let mut ry: f64x4 = pulp::cast(ry);
            for _ in 0..q {
                (rx, ry) = (
                    s.add_f64s(s.mul_f64s(cl, rx), s.mul_f64s(sl, ry)),
                    s.sub_f64s(s.mul_f64s(cl, ry), s.mul_f64s(sl, rx)),
                );
            }
            (
                s.add_f64s(s.splat_f64s(c.x), rx),
                s.add_f64s(s.splat_f64s(c.y), ry),
            )
        }
        Run::Trig {
            c,
            u,
            w,
            co,
            si,
            cl,
            sl,
            ..
        } => {
            let (cl, sl) = (s.splat_f64s(cl), s.splat_f64s(sl));
            let mut co: f64x4 = pulp::cast(co);
            let mut si: f64x4 = pulp::cast(si);
            for _ in 0..q {
                (co, si) = (
                    s.sub_f64s(s.mul_f64s(co, cl), s.mul_f64s(si, sl)),
                    s.add_f64s(s.mul_f64s(si, cl), s.mul_f64s(co, sl)),
                );
            }
            let sp = |x: f64| s.splat_f64s(x);
            (
                s.add_f64s(
                    s.add_f64s(sp(c.x), s.mul_f64s(sp(u.x), co)),
                    s.mul_f64s(sp(w.x), si),
                ),
                s.add_f64s(
                    s.add_f64s(sp(c.y), s.mul_f64s(sp(u.y), co)),
                    s.mul_f64s(sp(w.y), si),
                ),
            )
        }
    }
}

/// The f64 loop's two chunks of four samples for the f32 chunk `j` of a run, when one of
/// its decisions was too close to call in f32 (rare): compiled once, out of the f32 loops.
struct Fallback<'c, 'p, 'a, 'b> {
    ctx: &'c Ctx<'p>,
    /// The run (index among the part's runs) and its f32 chunk.
    run: usize,
    j: usize,
    acc: &'a Acc<'b>,
}

impl pulp::NullaryFnOnce for Fallback<'_, '_, '_, '_> {
    /// The two chunks' `(1 − G)²` (zero in lanes without a sample) and their count.
    type Output = ([f64x4; 2], usize);

    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn call(self) -> ([f64x4; 2], usize) {
        let s = self.acc.simd;
        let c = self.ctx;
        let part = c.parts.iter().nth(c.i).expect("part");
        let (runs, _) = part.sample_runs(c.step);
        let run = &runs[self.run];
        let n = run.len();
        with_occluders(c, |occ| {
            let mut out = ([s.splat_f64s(0.0); 2], 0);
            for (h, q) in [2 * self.j, 2 * self.j + 1].into_iter().enumerate() {
                if LANES * q >= n {
                    break;
                }
                let (u, v) = chunk64(s, run, q);
                let ok: m64x4 = pulp::cast(core::array::from_fn::<u64, LANES, _>(|l| {
                    if LANES * q + l < n { u64::MAX } else { 0 }
                }));
                // Two occluder slots (an unused one holds an empty box) and the image
                // test: the same decisions as the specialised f64 loops.
                let (e2, k) = chunk::<false, 2>(u, v, ok, occ, c.wh[0], c.wh[1], self.acc);
                out.0[h] = e2;
                out.1 += k;
            }
            out
        })
    }
}

/// Runs the [`Fallback`] out of line (compiled once with AVX2, by pulp).
#[inline(never)]
fn fallback(f: Fallback<'_, '_, '_, '_>) -> ([f64x4; 2], usize) {
    let s = f.acc.simd;
    s.vectorize(f)
}

/// The f32 sample loop over one run. Per chunk of eight samples: the rounded pixel, the
/// image test (unless `INSIDE`), the occluder tests; a chunk with a decision within the
/// error bound of flipping is redone by the f64 loop ([`Fallback`]), so the same samples
/// pass as in the portable f64 sampler, and their `(1 − G)²` are summed in the same lanes
/// and order (lanes 0–3 are the f64 loop's chunk 2j, lanes 4–7 its chunk 2j + 1).
#[allow(clippy::inline_always)]
#[inline(always)]
fn run_v3<const INSIDE: bool, const NOCC: usize, const W: usize>(
    s: V3,
    run: &Run32,
    ri: usize,
    pl: &PartLoop<'_, '_, W>,
    out: &mut Acc<'_>,
) {
    let lane = i32x8(0, 1, 2, 3, 4, 5, 6, 7);
    let all: m32x8 = pulp::cast([u32::MAX; L8]);
    let (n, tol) = (run.n, run.tol);
    // The sums in registers (the fallback gets no pointer to them). Every sample counts
    // unless a test below drops it.
    let (mut sum, mut count) = (out.sum, out.n + n);
    let acc = &*out;
    let half = s.splat_f32s(if pl.force_fallback {
        -1.0
    } else {
        (0.5 - tol) as f32
    });
    let tail_ok: m32x8 = pulp::cast(
        s.avx2
            ._mm256_cmpgt_epi32(pulp::cast([(n % L8) as i32; L8]), pulp::cast(lane)),
    );
    // The occluders whose (shrunk) box the run's box meets.
    let rb = run.bx;
    let meets = |b: &[f64; 4]| b[0] <= rb[2] && rb[0] <= b[2] && b[1] <= rb[3] && rb[1] <= b[3];
    let use_occ = [
        NOCC >= 1 && meets(&pl.boxes64[0]),
        NOCC >= 2 && meets(&pl.boxes64[1]),
    ];
    let (win, base) = (pl.win, pl.base);
    // The shift that puts an index modulo W in the top bits of its lane.
    let shift: core::arch::x86_64::__m128i = pulp::cast([u64::from(32 - W.trailing_zeros()), 0u64]);
    for_each_chunk32(
        s,
        run,
        #[inline(always)]
        |j, u, v, is_tail| {
            // Lanes holding a sample of the run.
            let mut ok = if is_tail { tail_ok } else { all };
            let mut dropped = is_tail;
            let (ru, rv) = (s.round_f32x8(u), s.round_f32x8(v));
            // |x − round(x)| near ½: the f64 rounding may go either way.
            let du = abs(s, s.sub_f32s(u, ru));
            let dv = abs(s, s.sub_f32s(v, rv));
            let mut amb = s.and_m32s(ok, s.greater_than_f32s(s.max_f32s(du, dv), half));
            if !INSIDE {
                let b = pl.bounds;
                let inx = s.and_m32s(
                    s.greater_than_or_equal_f32s(ru, s.splat_f32s(b[0])),
                    s.less_than_f32s(ru, s.splat_f32s(b[2])),
                );
                let iny = s.and_m32s(
                    s.greater_than_or_equal_f32s(rv, s.splat_f32s(b[1])),
                    s.less_than_f32s(rv, s.splat_f32s(b[3])),
                );
                let inside = s.and_m32s(ok, s.and_m32s(inx, iny));
                count -= (bits(s, ok) ^ bits(s, inside)).count_ones() as usize;
                ok = inside;
                dropped = true;
            }
            for k in 0..NOCC {
                if !use_occ[k] {
                    continue;
                }
                let ob = &pl.boxes[k];
                let inx = s.and_m32s(
                    s.greater_than_or_equal_f32s(u, ob[0]),
                    s.less_than_or_equal_f32s(u, ob[2]),
                );
                let iny = s.and_m32s(
                    s.greater_than_or_equal_f32s(v, ob[1]),
                    s.less_than_or_equal_f32s(v, ob[3]),
                );
                if bits(s, s.and_m32s(ok, s.and_m32s(inx, iny))) != 0 {
                    let (not_deep, not_out) = pl.shapes[k].test_not(s, u, v);
                    amb = s.or_m32s(amb, s.and_m32s(ok, s.and_m32s(not_deep, not_out)));
                    // Dropped: the lanes that passed so far and are surely deep.
                    let kept = s.and_m32s(ok, not_deep);
                    count -= (bits(s, ok) ^ bits(s, kept)).count_ones() as usize;
                    ok = kept;
                    dropped = true;
                }
            }
            if bits(s, amb) != 0 {
                // Undo this chunk's count; the f64 loop counts it.
                count -= bits(s, ok).count_ones() as usize;
                let ([lo, hi], k) = fallback(Fallback {
                    ctx: pl.ctx,
                    run: ri,
                    j,
                    acc,
                });
                sum = s.add_f64s(s.add_f64s(sum, lo), hi);
                count += k;
                return;
            }
            // The index relative to the anchor in f32: exact for every lane in the image
            // (integers below 2²⁴, see `exact`), one conversion.
            let rel = s.mul_add_e_f32s(rv, acc.stride_f, ru);
            let idx = s
                .avx2
                ._mm256_add_epi32(s.avx._mm256_cvttps_epi32(pulp::cast(rel)), pulp::cast(base));
            // Lanes that passed are in the window; the others read some G in it, which
            // is dropped. Each index modulo the window length W = 2^(32 − k) sits in the
            // top bits of its 32-bit lane (one vector shift left by k), and the indices
            // leave the register as four 64-bit pairs: the low lane's index is the low
            // 32 bits shifted right by k, the high lane's the pair shifted right by 32 + k,
            // both below W without a mask (no lane extracts, no bounds checks).
            let idx = s.avx2._mm256_sll_epi32(pulp::cast(idx), shift);
            let idx: [u64; L8 / 2] = pulp::cast(idx);
            let k = 32 - W.trailing_zeros();
            let at_lo = |x: u64| win[((x as u32) >> k) as usize];
            let at_hi = |x: u64| win[(x >> (32 + k)) as usize];
            // The two halves built apart (no 256-bit insert and extract).
            let lo = f32x4(at_lo(idx[0]), at_hi(idx[0]), at_lo(idx[1]), at_hi(idx[1]));
            let hi = f32x4(at_lo(idx[2]), at_hi(idx[2]), at_lo(idx[3]), at_hi(idx[3]));
            // Lanes without a sample read G = 1, i.e. add (1 − 1)² = +0, as the f64 loop.
            let (lo, hi) = if dropped {
                let [mlo, mhi]: [pulp::m32x4; 2] = pulp::cast(ok);
                let one = s.splat_f32x4(1.0);
                (s.select_f32x4(mlo, lo, one), s.select_f32x4(mhi, hi, one))
            } else {
                (lo, hi)
            };
            let c = s.splat_f64s(1.0);
            let e = s.sub_f64s(c, s.convert_f32x4_to_f64x4(lo));
            sum = s.add_f64s(sum, s.mul_f64s(e, e));
            let e = s.sub_f64s(c, s.convert_f32x4_to_f64x4(hi));
            sum = s.add_f64s(sum, s.mul_f64s(e, e));
        },
    );
    out.sum = sum;
    out.n = count;
}

#[allow(clippy::inline_always, clippy::too_many_arguments)]
#[inline(always)]
fn chunk<const INSIDE: bool, const NOCC: usize>(
    u: f64x4,
    v: f64x4,
    ok: m64x4,
    occ: &Occluders<'_>,
    wf: f64,
    hf: f64,
    acc: &Acc<'_>,
) -> (f64x4, usize) {
    let s = acc.simd;
    let mut ok = ok;
    if !INSIDE {
        let lo = s.splat_f64s(-0.5);
        let a = s.and_m64s(
            s.greater_than_or_equal_f64s(u, lo),
            s.greater_than_or_equal_f64s(v, lo),
        );
        let b = s.and_m64s(
            s.less_than_f64s(u, s.splat_f64s(wf)),
            s.less_than_f64s(v, s.splat_f64s(hf)),
        );
        ok = s.and_m64s(ok, s.and_m64s(a, b));
    }
    for (shape, ob) in occ.shapes.iter().zip(&occ.boxes).take(NOCC) {
        let a = s.and_m64s(
            s.greater_than_or_equal_f64s(u, s.splat_f64s(ob[0])),
            s.less_than_or_equal_f64s(u, s.splat_f64s(ob[2])),
        );
        let b = s.and_m64s(
            s.greater_than_or_equal_f64s(v, s.splat_f64s(ob[1])),
            s.less_than_or_equal_f64s(v, s.splat_f64s(ob[3])),
        );
        let inbox = s.and_m64s(ok, s.and_m64s(a, b));
        if any(inbox) {
            let deep = deep(s, shape, u, v);
            ok = s.and_m64s(ok, s.not_m64s(s.and_m64s(inbox, deep)));
        }
    }
    let zero = s.splat_f64s(0.0);
    let half = s.splat_f64s(0.5);
    let uu = s.select_f64s(ok, s.add_f64s(u, half), zero);
    let vv = s.select_f64s(ok, s.add_f64s(v, half), zero);
    // Lanes that passed have u + ½, v + ½ ∈ [0, 2³¹) (in the image): truncation is the
    // rounded pixel, and the index is exact in f64.
    let fi = s.add_f64s(
        s.mul_f64s(s.truncate_f64x4(vv), acc.stride),
        s.truncate_f64x4(uu),
    );
    let idx: [i32; LANES] = pulp::cast(s.convert_f64x4_to_i32x4(fi));
    let d = acc.data;
    let g = s.convert_f32x4_to_f64x4(f32x4(
        d[idx[0] as usize],
        d[idx[1] as usize],
        d[idx[2] as usize],
        d[idx[3] as usize],
    ));
    let e = s.sub_f64s(s.splat_f64s(1.0), g);
    let n = s.avx._mm256_movemask_pd(pulp::cast(ok)).count_ones() as usize;
    (s.select_f64s(ok, s.mul_f64s(e, e), zero), n)
}

/// [`Inside::deep`] on four lanes.
#[allow(clippy::inline_always)]
#[inline(always)]
fn deep(s: V3, shape: &Inside, x: f64x4, y: f64x4) -> m64x4 {
    let sp = |a: f64| s.splat_f64s(a);
    let dot = |ax: f64x4, ay: f64x4, bx: f64, by: f64| {
        s.add_f64s(s.mul_f64s(ax, sp(bx)), s.mul_f64s(ay, sp(by)))
    };
    let norm2 = |ax: f64x4, ay: f64x4| s.add_f64s(s.mul_f64s(ax, ax), s.mul_f64s(ay, ay));
    match *shape {
        Inside::Never => pulp::cast([0u64; LANES]),
        Inside::Disc { c, r2 } => {
            let (dx, dy) = (s.sub_f64s(x, sp(c.x)), s.sub_f64s(y, sp(c.y)));
            s.less_than_f64s(norm2(dx, dy), sp(r2))
        }
        Inside::Capsule {
            c0,
            c1,
            d,
            n,
            lo,
            hi,
            r0sq,
            r1sq,
            sin_a,
            cos_a,
            lim,
        } => {
            let (rx, ry) = (s.sub_f64s(x, sp(c0.x)), s.sub_f64s(y, sp(c0.y)));
            let (qx, qy) = (s.sub_f64s(x, sp(c1.x)), s.sub_f64s(y, sp(c1.y)));
            let sd = dot(rx, ry, d.x, d.y);
            let side = s.less_than_f64s(
                s.add_f64s(
                    s.mul_f64s(sd, sp(sin_a)),
                    s.mul_f64s(abs64(s, dot(rx, ry, n.x, n.y)), sp(cos_a)),
                ),
                sp(lim),
            );
            let cap0 = s.less_than_f64s(norm2(rx, ry), sp(r0sq));
            let cap1 = s.less_than_f64s(norm2(qx, qy), sp(r1sq));
            let below = s.less_than_f64s(sd, sp(lo));
            let above = s.greater_than_f64s(sd, sp(hi));
            let mid = s.and_m64s(s.not_m64s(above), side);
            let upper = s.or_m64s(s.and_m64s(above, cap1), mid);
            s.or_m64s(
                s.and_m64s(below, cap0),
                s.and_m64s(s.not_m64s(below), upper),
            )
        }
        Inside::Ellipse { c, ea, eb, k2 } => {
            let (rx, ry) = (s.sub_f64s(x, sp(c.x)), s.sub_f64s(y, sp(c.y)));
            let (xa, xb) = (dot(rx, ry, ea.x, ea.y), dot(rx, ry, eb.x, eb.y));
            s.less_than_f64s(norm2(xa, xb), sp(k2))
        }
    }
}

#[cfg(test)]
mod tests;
