//! The analytic contour sampler: samples every Δ px along each part's outline that are not
//! inside another part, visited or summed four lanes at a time.

use nalgebra::Vector2;

use super::{INSIDE_TOL, LANES, Lanes, Prepared, Projected, Run, avx2, lanes};

/// A part in the form of the per-sample "more than [`INSIDE_TOL`] inside" test, four lanes at
/// a time (no square roots, no divisions, no branches per lane).
#[derive(Debug, Clone, Copy)]
pub(super) enum Inside {
    /// Contains no point deeper than the tolerance.
    Never,
    /// `|x − c|² < r2`.
    Disc { c: Vector2<f64>, r2: f64 },
    /// The capsule test of `Prepared::deep_inside`: cap at c0 for `s < lo`, at c1 for
    /// `s > hi`, the side lines between. `r0sq`, `r1sq`: squared cap radii less the tolerance
    /// (−1 for caps too small to contain a point that deep).
    Capsule {
        c0: Vector2<f64>,
        c1: Vector2<f64>,
        d: Vector2<f64>,
        n: Vector2<f64>,
        lo: f64,
        hi: f64,
        r0sq: f64,
        r1sq: f64,
        sin_a: f64,
        cos_a: f64,
        lim: f64,
    },
    /// `(rel·ea/a)² + (rel·eb/b)² < k2`.
    Ellipse {
        c: Vector2<f64>,
        ea: Vector2<f64>,
        eb: Vector2<f64>,
        k2: f64,
    },
}

impl Inside {
    pub(super) fn new(part: &Prepared) -> Self {
        let sq = |r: f64| {
            if r > INSIDE_TOL {
                (r - INSIDE_TOL) * (r - INSIDE_TOL)
            } else {
                -1.0
            }
        };
        match *part {
            Prepared::Circle { c, r } => Self::Disc { c, r2: sq(r) },
            Prepared::Capsule {
                c0,
                c1,
                r0,
                r1,
                len,
                d,
                n,
                sin_a,
                cos_a,
            } => Self::Capsule {
                c0,
                c1,
                d,
                n,
                lo: r0 * sin_a,
                hi: len + r1 * sin_a,
                r0sq: sq(r0),
                r1sq: sq(r1),
                sin_a,
                cos_a,
                lim: r0 - INSIDE_TOL,
            },
            Prepared::Ellipse { c, a, b, ea, eb } => {
                if b <= INSIDE_TOL {
                    return Self::Never;
                }
                let k = 1.0 - INSIDE_TOL / b;
                Self::Ellipse {
                    c,
                    ea: ea / a,
                    eb: eb / b,
                    k2: k * k,
                }
            }
        }
    }

    /// Per lane: whether the point is more than [`INSIDE_TOL`] inside the part.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    pub(super) fn deep(&self, x: Lanes, y: Lanes) -> [bool; LANES] {
        match *self {
            Self::Never => [false; LANES],
            Self::Disc { c, r2 } => lanes(|l| {
                let (dx, dy) = (x[l] - c.x, y[l] - c.y);
                dx * dx + dy * dy < r2
            }),
            Self::Capsule {
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
            } => lanes(|l| {
                let (rx, ry) = (x[l] - c0.x, y[l] - c0.y);
                let (qx, qy) = (x[l] - c1.x, y[l] - c1.y);
                let s = rx * d.x + ry * d.y;
                let side = s * sin_a + (rx * n.x + ry * n.y).abs() * cos_a < lim;
                let cap0 = rx * rx + ry * ry < r0sq;
                let cap1 = qx * qx + qy * qy < r1sq;
                if s < lo {
                    cap0
                } else if s > hi {
                    cap1
                } else {
                    side
                }
            }),
            Self::Ellipse { c, ea, eb, k2 } => lanes(|l| {
                let (rx, ry) = (x[l] - c.x, y[l] - c.y);
                let (xa, xb) = (rx * ea.x + ry * ea.y, rx * eb.x + ry * eb.y);
                xa * xa + xb * xb < k2
            }),
        }
    }
}

/// The parts that may hide analytic samples of one part: those whose bounding box overlaps
/// the part's box (at most two), with their boxes. Unused slots hold an empty box that no
/// sample lies in.
#[derive(Clone, Copy)]
pub(super) struct Occluders<'a> {
    pub(super) shapes: [&'a Inside; 2],
    pub(super) boxes: [[f64; 4]; 2],
    /// The parts in the used slots.
    pub(super) idx: [usize; 2],
    /// Number of used slots.
    pub(super) n: usize,
}

/// A box that contains no point.
pub(super) const EMPTY_BOX: [f64; 4] = [
    f64::INFINITY,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
];

/// Margin (pixels) between a part's bounding box and the image border below which the
/// per-sample image test is kept: the samples lie on the outline up to rounding (~1e-12 px).
pub(super) const INSIDE_MARGIN: f64 = 1e-3;

/// What the sample loop does with a chunk of samples that passed the image and occluder tests
/// (`ok` marks them).
pub(super) trait Sink {
    fn take(&mut self, u: Lanes, v: Lanes, ok: [bool; LANES]);
}

/// Calls `visit` for every point that passed, in order.
pub(super) struct Visit<F>(F);

impl<F: FnMut(f64, f64)> Sink for Visit<F> {
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn take(&mut self, u: Lanes, v: Lanes, ok: [bool; LANES]) {
        for l in 0..LANES {
            if ok[l] {
                (self.0)(u[l], v[l]);
            }
        }
    }
}

/// Σ cost over the points that passed, one accumulator per lane, and their number. `cost` is
/// evaluated on every lane (at (0, 0) for lanes that did not pass, whose result is dropped),
/// so there is no branch per sample.
pub(super) struct Sum<'c, C> {
    cost: &'c C,
    acc: Lanes,
    count: usize,
}

impl<C: Fn(f64, f64) -> f64> Sink for Sum<'_, C> {
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn take(&mut self, u: Lanes, v: Lanes, ok: [bool; LANES]) {
        let u = lanes(|l| if ok[l] { u[l] } else { 0.0 });
        let v = lanes(|l| if ok[l] { v[l] } else { 0.0 });
        for l in 0..LANES {
            let c = (self.cost)(u[l], v[l]);
            self.acc[l] += if ok[l] { c } else { 0.0 };
        }
        self.count += ok.iter().map(|&b| usize::from(b)).sum::<usize>();
    }
}

/// The analytic sample loop over every part: points every `step` pixels along each part's
/// outline that are not more than half a pixel inside another part and whose rounded pixel is
/// inside the `width × height` image go to `sink`, in outline order.
///
/// Per part, only the other parts whose bounding box overlaps this part's box can hide any of
/// its samples, and the inside test against such a part runs only for chunks with a sample in
/// that part's box, so most chunks cost no inside test at all. A part whose box lies inside
/// the image skips the per-sample image test.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn sample_parts<S: Sink>(
    parts: &Projected,
    width: u32,
    height: u32,
    step: f64,
    sink: &mut S,
) {
    let (wf, hf) = (f64::from(width) - 0.5, f64::from(height) - 0.5);
    let boxes = part_boxes(parts);
    let mut shapes = [Inside::Never; 3];
    for (s, part) in shapes.iter_mut().zip(parts.iter()) {
        *s = Inside::new(part);
    }
    for (i, part) in parts.iter().enumerate() {
        let Some((occ, inside)) = occluders(parts.n, &boxes, &shapes, i, wf, hf) else {
            continue;
        };
        let (runs, nr) = part.sample_runs(step);
        // Six copies of the sample loop: without and with the image test, for 0, 1 and 2
        // occluders.
        let r = &runs[..nr];
        match (inside, occ.n) {
            (true, 0) => sample_runs_into::<true, 0, S>(r, &occ, wf, hf, sink),
            (true, 1) => sample_runs_into::<true, 1, S>(r, &occ, wf, hf, sink),
            (true, _) => sample_runs_into::<true, 2, S>(r, &occ, wf, hf, sink),
            (false, 0) => sample_runs_into::<false, 0, S>(r, &occ, wf, hf, sink),
            (false, 1) => sample_runs_into::<false, 1, S>(r, &occ, wf, hf, sink),
            (false, _) => sample_runs_into::<false, 2, S>(r, &occ, wf, hf, sink),
        }
    }
}

/// The sample loop of [`sample_parts`] for one part; `INSIDE`: the part's box is inside the
/// image, so the image test is left out.
// `&` on the lanes' booleans: branch-free, so LLVM can keep the four lanes together.
#[allow(clippy::inline_always, clippy::needless_bitwise_bool)]
#[inline(always)]
pub(super) fn sample_runs_into<const INSIDE: bool, const NOCC: usize, S: Sink>(
    runs: &[Run],
    occ: &Occluders<'_>,
    wf: f64,
    hf: f64,
    sink: &mut S,
) {
    for run in runs {
        run.for_each_chunk(
            #[inline(always)]
            |u, v, ok| {
                let mut ok = ok;
                if !INSIDE {
                    ok = lanes(|l| {
                        ok[l] & (u[l] >= -0.5) & (v[l] >= -0.5) & (u[l] < wf) & (v[l] < hf)
                    });
                }
                for (shape, ob) in occ.shapes.iter().zip(&occ.boxes).take(NOCC) {
                    let inbox = lanes(|l| {
                        ok[l]
                            & (u[l] >= ob[0])
                            & (u[l] <= ob[2])
                            & (v[l] >= ob[1])
                            & (v[l] <= ob[3])
                    });
                    if inbox.iter().any(|&b| b) {
                        let deep = shape.deep(u, v);
                        ok = lanes(|l| ok[l] & !(inbox[l] & deep[l]));
                    }
                }
                sink.take(u, v, ok);
            },
        );
    }
}

/// Analytic contour: calls `visit(u, v)` for points every `step` pixels along each part's
/// outline that are not more than half a pixel inside another part and whose rounded pixel is
/// inside the `width × height` image (the points that [`analytic_sum`] sums over, in the same
/// order).
pub(crate) fn analytic_contour<F: FnMut(f64, f64)>(
    parts: &Projected,
    width: u32,
    height: u32,
    step: f64,
    visit: F,
) {
    sample_parts(parts, width, height, step, &mut Visit(visit));
}

/// Σ cost(u, v) over the analytic contour samples (the points of [`analytic_contour`]) and
/// their number. `cost` must accept (0, 0) (it is also evaluated there, for lanes without a
/// sample, and the result dropped). The loop is compiled twice, for baseline x86-64 and with
/// AVX2, and the variant the CPU supports runs (pulp, no `unsafe` in our code); the four
/// lanes are summed separately, so the order of the sum differs from the point order (by
/// rounding only).
pub(crate) fn analytic_sum<C: Fn(f64, f64) -> f64>(
    parts: &Projected,
    width: u32,
    height: u32,
    step: f64,
    cost: C,
) -> (f64, usize) {
    pulp::Arch::new().dispatch(SumOp {
        parts,
        width,
        height,
        step,
        cost,
    })
}

/// [`analytic_sum`] as a [`pulp::WithSimd`] operation (see `edge.rs`: a closure's shim would
/// not be inlined into the dispatched function, this is).
pub(super) struct SumOp<'p, C> {
    parts: &'p Projected,
    width: u32,
    height: u32,
    step: f64,
    cost: C,
}

impl<C: Fn(f64, f64) -> f64> pulp::WithSimd for SumOp<'_, C> {
    type Output = (f64, usize);

    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> (f64, usize) {
        let mut sink = Sum {
            cost: &self.cost,
            acc: [0.0; LANES],
            count: 0,
        };
        sample_parts(self.parts, self.width, self.height, self.step, &mut sink);
        let s = sink.acc;
        ((s[0] + s[1]) + (s[2] + s[3]), sink.count)
    }
}

/// `Σ (1 − G(c))²` over the analytic contour samples `c` at their rounded pixels (`data`:
/// G row-major with `stride` values per row; the image is at least `width × height`) and
/// their number: the same points and values as `analytic_sum` with the nearest-pixel cost, with
/// AVX2 when the CPU has it (f32 lanes with an exact f64 fallback, see `avx2`; the sum is the
/// portable loop's bit for bit, its four lanes summed separately, i.e. it differs from the
/// sum in point order by rounding).
pub(crate) fn analytic_sum_nearest(
    parts: &Projected,
    width: u32,
    height: u32,
    step: f64,
    data: &[f32],
    stride: usize,
) -> (f64, usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        return simd.vectorize(avx2::Nearest {
            simd,
            parts,
            width,
            height,
            step,
            data,
            stride,
            force_fallback: false,
        });
    }
    analytic_sum(parts, width, height, step, nearest_cost(data, stride))
}

/// [`analytic_sum_nearest`] with every chunk of the AVX2 loop redone by its f64 fallback
/// (`None` without AVX2).
#[cfg(all(test, target_arch = "x86_64"))]
pub(crate) fn analytic_sum_nearest_by_fallback(
    parts: &Projected,
    width: u32,
    height: u32,
    step: f64,
    data: &[f32],
    stride: usize,
) -> Option<(f64, usize)> {
    let simd = pulp::x86::V3::try_new()?;
    Some(simd.vectorize(avx2::Nearest {
        simd,
        parts,
        width,
        height,
        step,
        data,
        stride,
        force_fallback: true,
    }))
}

/// The nearest-pixel cost `(1 − G)²` at an analytic sample (whose rounded pixel is in the
/// image, so u + ½, v + ½ ∈ [0, 2³¹): the cheap f64 → i32 conversion suffices), and at (0, 0).
#[allow(clippy::inline_always)]
#[inline(always)]
pub(crate) fn nearest_cost(data: &[f32], stride: usize) -> impl Fn(f64, f64) -> f64 + '_ {
    #[inline(always)]
    move |u: f64, v: f64| {
        let i = (v + 0.5) as i32 as usize * stride + (u + 0.5) as i32 as usize;
        let e = 1.0 - f64::from(data[i]);
        e * e
    }
}

/// Bounding boxes of the parts (unused slots zero).
pub(super) fn part_boxes(parts: &Projected) -> [[f64; 4]; 3] {
    let mut boxes = [[0.0f64; 4]; 3];
    for (b, part) in boxes.iter_mut().zip(parts.iter()) {
        *b = part.bbox();
    }
    boxes
}

/// The occluders of part `i` (of `n`) and whether its box lies inside the image, or `None`
/// when the part is entirely outside the image.
pub(super) fn occluders<'a>(
    n: usize,
    boxes: &[[f64; 4]; 3],
    shapes: &'a [Inside; 3],
    i: usize,
    wf: f64,
    hf: f64,
) -> Option<(Occluders<'a>, bool)> {
    let bb = boxes[i];
    if bb[2] < -0.5 || bb[3] < -0.5 || bb[0] >= wf || bb[1] >= hf {
        return None;
    }
    let m = INSIDE_MARGIN;
    let inside = bb[0] - m >= -0.5 && bb[1] - m >= -0.5 && bb[2] + m < wf && bb[3] + m < hf;
    let overlap =
        |a: &[f64; 4], b: &[f64; 4]| a[0] <= b[2] && b[0] <= a[2] && a[1] <= b[3] && b[1] <= a[3];
    let mut out = Occluders {
        shapes: [&Inside::Never; 2],
        boxes: [EMPTY_BOX; 2],
        idx: [0; 2],
        n: 0,
    };
    for k in 0..n.min(3) {
        if k != i && out.n < 2 && overlap(&bb, &boxes[k]) {
            out.shapes[out.n] = &shapes[k];
            out.boxes[out.n] = boxes[k];
            out.idx[out.n] = k;
            out.n += 1;
        }
    }
    Some((out, inside))
}
