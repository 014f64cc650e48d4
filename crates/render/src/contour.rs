//! Projection of the arm into 2-D parts, the raster silhouette contour (tiny-skia) and the
//! analytic contour sampler (SPEC §4.2).

use nalgebra::{Vector2, Vector3};
use tiny_skia::{FillRule, Mask, PathBuilder, Transform};

use crate::{ArmGeometry, Camera, RenderError, camera::NEAR_PLANE};

/// Largest projected coordinate (pixels) a part may have; parts beyond this (points within
/// millimetres of the camera plane) are skipped rather than rasterised.
const MAX_COORD: f64 = 1.0e6;
/// Maximal sagitta (pixels) of the polygons approximating arcs in the raster silhouette.
const SAGITTA: f64 = 0.15;
/// Analytic samples deeper than this (pixels) inside another part are not on the union outline.
pub(crate) const INSIDE_TOL: f64 = 0.5;

/// How the contour C of a pose is obtained (SPEC §4.2). Record which one was used: the scores
/// differ slightly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ContourMethod {
    /// Rasterise the union silhouette S (tiny-skia, no anti-aliasing) and take the inner
    /// boundary `C = {pixels in S with a 4-neighbour outside S}` (the normative method).
    #[default]
    Raster,
    /// Sample points every Δ pixels (default 2) along each part's projected outline, drop those
    /// inside another part (bodytrack style; much cheaper).
    Analytic,
}

/// One projected arm part in pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Part2 {
    /// The convex hull of two discs (a truncated cone seen from the side, with round caps).
    Capsule {
        /// Centre of the first disc (u, v).
        c0: [f64; 2],
        /// Centre of the second disc.
        c1: [f64; 2],
        /// Radius of the first disc, pixels.
        r0: f64,
        /// Radius of the second disc, pixels.
        r1: f64,
    },
    /// An ellipse (the projected hand ellipsoid).
    Ellipse {
        /// Centre (u, v).
        c: [f64; 2],
        /// Semi-major axis, pixels.
        a: f64,
        /// Semi-minor axis, pixels.
        b: f64,
        /// Angle of the major axis from +u toward +v, radians.
        angle: f64,
    },
}

/// A part with everything the contour routines need precomputed.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Prepared {
    Circle {
        c: Vector2<f64>,
        r: f64,
    },
    Capsule {
        c0: Vector2<f64>,
        c1: Vector2<f64>,
        r0: f64,
        r1: f64,
        len: f64,
        d: Vector2<f64>,
        n: Vector2<f64>,
        sin_a: f64,
        cos_a: f64,
    },
    Ellipse {
        c: Vector2<f64>,
        a: f64,
        b: f64,
        ea: Vector2<f64>,
        eb: Vector2<f64>,
    },
}

impl Prepared {
    pub(crate) fn new(part: &Part2) -> Self {
        match *part {
            Part2::Capsule { c0, c1, r0, r1 } => {
                let (c0, c1) = (Vector2::from(c0), Vector2::from(c1));
                let delta = c1 - c0;
                let len = delta.norm();
                if len <= (r0 - r1).abs() + 1e-9 {
                    return if r0 >= r1 {
                        Self::Circle { c: c0, r: r0 }
                    } else {
                        Self::Circle { c: c1, r: r1 }
                    };
                }
                let d = delta / len;
                let sin_a = (r0 - r1) / len;
                let cos_a = (1.0 - sin_a * sin_a).max(0.0).sqrt();
                Self::Capsule {
                    c0,
                    c1,
                    r0,
                    r1,
                    len,
                    d,
                    n: Vector2::new(-d.y, d.x),
                    sin_a,
                    cos_a,
                }
            }
            Part2::Ellipse { c, a, b, angle } => {
                let (s, co) = angle.sin_cos();
                Self::Ellipse {
                    c: Vector2::from(c),
                    a,
                    b,
                    ea: Vector2::new(co, s),
                    eb: Vector2::new(-s, co),
                }
            }
        }
    }

    /// Whether `x` is more than [`INSIDE_TOL`] pixels inside the part (no square roots): the
    /// scalar reference of the sampler's four-lane test ([`Inside::deep`]).
    #[cfg(test)]
    fn deep_inside(&self, x: Vector2<f64>) -> bool {
        let within = |d2: f64, r: f64| r > INSIDE_TOL && d2 < (r - INSIDE_TOL) * (r - INSIDE_TOL);
        match *self {
            Self::Circle { c, r } => within((x - c).norm_squared(), r),
            Self::Capsule {
                c0,
                c1,
                r0,
                r1,
                len,
                d,
                n,
                sin_a,
                cos_a,
            } => {
                let rel = x - c0;
                let s = rel.dot(&d);
                if s < r0 * sin_a {
                    within(rel.norm_squared(), r0)
                } else if s > len + r1 * sin_a {
                    within((x - c1).norm_squared(), r1)
                } else {
                    s * sin_a + rel.dot(&n).abs() * cos_a < r0 - INSIDE_TOL
                }
            }
            Self::Ellipse { c, a, b, ea, eb } => {
                if b <= INSIDE_TOL {
                    return false;
                }
                let rel = x - c;
                let (xa, xb) = (rel.dot(&ea) / a, rel.dot(&eb) / b);
                let k = 1.0 - INSIDE_TOL / b;
                xa * xa + xb * xb < k * k
            }
        }
    }

    /// Signed distance (exact for discs and capsules, approximate for ellipses), negative
    /// inside.
    fn signed_distance(&self, x: Vector2<f64>) -> f64 {
        match *self {
            Self::Circle { c, r } => (x - c).norm() - r,
            Self::Capsule {
                c0,
                c1,
                r0,
                r1,
                len,
                d,
                n,
                sin_a,
                cos_a,
            } => {
                let rel = x - c0;
                let s = rel.dot(&d);
                if s < r0 * sin_a {
                    rel.norm() - r0
                } else if s > len + r1 * sin_a {
                    (x - c1).norm() - r1
                } else {
                    s * sin_a + rel.dot(&n).abs() * cos_a - r0
                }
            }
            Self::Ellipse { c, a, b, ea, eb } => {
                if b <= 1e-9 {
                    return f64::INFINITY;
                }
                let rel = x - c;
                let (xa, xb) = (rel.dot(&ea) / a, rel.dot(&eb) / b);
                (xa.hypot(xb) - 1.0) * b
            }
        }
    }

    /// Axis-aligned bounding box (min u, min v, max u, max v).
    pub(crate) fn bbox(&self) -> [f64; 4] {
        match *self {
            Self::Circle { c, r } => [c.x - r, c.y - r, c.x + r, c.y + r],
            Self::Capsule { c0, c1, r0, r1, .. } => [
                (c0.x - r0).min(c1.x - r1),
                (c0.y - r0).min(c1.y - r1),
                (c0.x + r0).max(c1.x + r1),
                (c0.y + r0).max(c1.y + r1),
            ],
            Self::Ellipse { c, a, b, ea, .. } => {
                let ex = (a * a * ea.x * ea.x + b * b * ea.y * ea.y).sqrt();
                let ey = (a * a * ea.y * ea.y + b * b * ea.x * ea.x).sqrt();
                [c.x - ex, c.y - ey, c.x + ex, c.y + ey]
            }
        }
    }

    /// Walks the outline clockwise (in u-right, v-up terms; one fixed orientation for every
    /// part), calling `f` with points no further apart than `step` pixels along arcs and lines.
    /// `closed_polygon` selects vertex placement for rasterisation (arcs by sagitta) instead of
    /// uniform sampling.
    fn walk_outline<F: FnMut(Vector2<f64>)>(&self, step: f64, polygon: bool, mut f: F) {
        // Number of pieces for an arc of radius r and the given sweep.
        let arc_n = |r: f64, sweep: f64| -> usize {
            let n = if polygon {
                let dt = if r > SAGITTA {
                    2.0 * (1.0 - SAGITTA / r).acos()
                } else {
                    1.0
                };
                (sweep / dt).ceil()
            } else {
                (r * sweep / step).ceil()
            };
            (n as usize).clamp(if polygon { 2 } else { 1 }, 4096)
        };
        // Clockwise arc: from angle `from` decreasing by `sweep`, excluding the end point.
        let arc = |c: Vector2<f64>, r: f64, from: Vector2<f64>, sweep: f64, f: &mut F| {
            let n = arc_n(r, sweep);
            let (s, co) = (sweep / n as f64).sin_cos();
            let mut v = from * r;
            for _ in 0..n {
                f(c + v);
                // rotate by −dt
                v = Vector2::new(co * v.x + s * v.y, -s * v.x + co * v.y);
            }
        };
        match *self {
            Self::Circle { c, r } => arc(c, r, Vector2::x(), std::f64::consts::TAU, &mut f),
            Self::Ellipse { c, a, b, ea, eb } => {
                let n = arc_n(a, std::f64::consts::TAU);
                // Angle decreasing by dt per point, by rotation (no sin/cos per point).
                let (sd, cd) = (std::f64::consts::TAU / n as f64).sin_cos();
                let (mut co, mut s) = (1.0f64, 0.0f64);
                for _ in 0..n {
                    f(c + ea * (a * co) + eb * (b * s));
                    (co, s) = (co * cd + s * sd, s * cd - co * sd);
                }
            }
            Self::Capsule {
                c0,
                c1,
                r0,
                r1,
                len,
                d,
                n,
                sin_a,
                cos_a,
            } => {
                let np = d * sin_a + n * cos_a;
                let nm = d * sin_a - n * cos_a;
                let tangent = len * cos_a;
                let line = |a: Vector2<f64>, b: Vector2<f64>, f: &mut F| {
                    if polygon {
                        f(a);
                    } else {
                        let m = ((tangent / step).ceil() as usize).clamp(1, 1 << 16);
                        for k in 0..m {
                            f(a + (b - a) * (k as f64 / m as f64));
                        }
                    }
                };
                let half = std::f64::consts::PI;
                let alpha = sin_a.asin();
                line(c0 + np * r0, c1 + np * r1, &mut f);
                arc(c1, r1, np, half - 2.0 * alpha, &mut f);
                line(c1 + nm * r1, c0 + nm * r0, &mut f);
                arc(c0, r0, nm, half + 2.0 * alpha, &mut f);
            }
        }
    }
}

/// Lanes of the analytic sampler: samples are generated, tested and summed four at a time
/// (four f64 lanes: one AVX2 register, two SSE2 registers).
const LANES: usize = 4;
/// One value per lane.
type Lanes = [f64; LANES];
/// The sample index of each lane in the first chunk of a run.
const LANE_INDEX: Lanes = [0.0, 1.0, 2.0, 3.0];

/// `f(l)` for every lane `l`.
#[allow(clippy::inline_always)]
#[inline(always)]
fn lanes<T: Copy + Default, F: Fn(usize) -> T>(f: F) -> [T; LANES] {
    let mut out = [T::default(); LANES];
    for (l, o) in out.iter_mut().enumerate() {
        *o = f(l);
    }
    out
}

/// `(sin θ, cos θ)`; for |θ| ≤ ½ (the arcs of every part wider than a few pixels) by the
/// Taylor polynomials to θ¹³ / θ¹⁴ (truncation < 1e-16), otherwise by libm.
fn sin_cos(theta: f64) -> (f64, f64) {
    if theta.abs() > 0.5 {
        return theta.sin_cos();
    }
    let z = theta * theta;
    let s = theta
        * (1.0
            + z * (-1.0 / 6.0
                + z * (1.0 / 120.0
                    + z * (-1.0 / 5040.0
                        + z * (1.0 / 362_880.0
                            + z * (-1.0 / 39_916_800.0 + z * (1.0 / 6_227_020_800.0)))))));
    let c = 1.0
        + z * (-0.5
            + z * (1.0 / 24.0
                + z * (-1.0 / 720.0
                    + z * (1.0 / 40_320.0
                        + z * (-1.0 / 3_628_800.0
                            + z * (1.0 / 479_001_600.0 + z * (-1.0 / 87_178_291_200.0)))))));
    (s, c)
}

/// One run of analytic outline samples, generated [`LANES`] at a time. The points are those of
/// `walk_outline(step, false, …)` (same count and order, equal up to rounding).
#[derive(Debug, Clone, Copy)]
enum Run {
    /// `n` points `p + k·s`, k = 0 … n−1.
    Line {
        p: Vector2<f64>,
        s: Vector2<f64>,
        n: usize,
    },
    /// `n` points `c + r_k` on a circle, `r_k` = `r_0` rotated clockwise by kθ. `rx`, `ry`:
    /// r_k in the lanes of the first chunk (k = 0 … 3); `cl`, `sl`: cos and sin of 4θ, the
    /// rotation from one chunk to the next.
    Arc {
        c: Vector2<f64>,
        rx: Lanes,
        ry: Lanes,
        cl: f64,
        sl: f64,
        n: usize,
    },
    /// `n` points `c + u·cos kθ + w·sin kθ`, k = 0 … n−1 (the ellipse). `co`, `si`: cos and
    /// sin of kθ in the lanes of the first chunk (k = 0 … 3); `cl`, `sl`: cos and sin of 4θ.
    Trig {
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        co: Lanes,
        si: Lanes,
        cl: f64,
        sl: f64,
        n: usize,
    },
}

impl Run {
    /// The `m` points `p + (q − p)·k/m`, k = 0 … m−1.
    fn line(p: Vector2<f64>, q: Vector2<f64>, m: usize) -> Self {
        Self::Line {
            p,
            s: (q - p) / m as f64,
            n: m,
        }
    }

    /// The `n` points `c + u·cos kθ + w·sin kθ`, k = 0 … n−1.
    fn trig(c: Vector2<f64>, u: Vector2<f64>, w: Vector2<f64>, theta: f64, n: usize) -> Self {
        let (s1, c1) = sin_cos(theta);
        let (c2, s2) = (c1 * c1 - s1 * s1, 2.0 * c1 * s1);
        let (c3, s3) = (c2 * c1 - s2 * s1, s2 * c1 + c2 * s1);
        Self::Trig {
            c,
            u,
            w,
            co: [1.0, c1, c2, c3],
            si: [0.0, s1, s2, s3],
            cl: c2 * c2 - s2 * s2,
            sl: 2.0 * c2 * s2,
            n,
        }
    }

    /// The `n` points `c + u·cos kθ + w·sin kθ` of a circular arc (|u| = |w|, u ⟂ w), generated
    /// by rotating the radius vectors instead of through cos/sin lanes.
    fn circle(c: Vector2<f64>, u: Vector2<f64>, w: Vector2<f64>, theta: f64, n: usize) -> Self {
        let Self::Trig {
            u,
            w,
            co,
            si,
            cl,
            sl,
            ..
        } = Self::trig(c, u, w, theta, n)
        else {
            unreachable!("trig gives a Trig run")
        };
        Self::Arc {
            c,
            rx: lanes(|l| u.x * co[l] + w.x * si[l]),
            ry: lanes(|l| u.y * co[l] + w.y * si[l]),
            cl,
            sl,
            n,
        }
    }

    /// Calls `f(u, v, ok)` for every chunk of [`LANES`] points; `ok` marks the lanes that hold
    /// a point of the run (all but the tail of the last chunk).
    // Measured: with plain `#[inline]` LLVM keeps this out of line and the analytic likelihood is
    // ~12 % slower (perf example, same run).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn for_each_chunk<F: FnMut(Lanes, Lanes, [bool; LANES])>(self, mut f: F) {
        // Full chunks, then the tail (lanes l < n mod 4).
        let (full, tail) = (self.len() / LANES, self.len() % LANES);
        let tail_ok = lanes(|l| l < tail);
        let step = LANES as f64;
        match self {
            Self::Line { p, s, .. } => {
                let mut k = LANE_INDEX;
                let mut chunk = |k: &Lanes, ok| {
                    f(lanes(|l| p.x + k[l] * s.x), lanes(|l| p.y + k[l] * s.y), ok);
                };
                for _ in 0..full {
                    chunk(&k, [true; LANES]);
                    k = lanes(|l| k[l] + step);
                }
                if tail > 0 {
                    chunk(&k, tail_ok);
                }
            }
            Self::Arc {
                c,
                mut rx,
                mut ry,
                cl,
                sl,
                ..
            } => {
                for _ in 0..full {
                    f(
                        lanes(|l| c.x + rx[l]),
                        lanes(|l| c.y + ry[l]),
                        [true; LANES],
                    );
                    (rx, ry) = (
                        lanes(|l| cl * rx[l] + sl * ry[l]),
                        lanes(|l| cl * ry[l] - sl * rx[l]),
                    );
                }
                if tail > 0 {
                    f(lanes(|l| c.x + rx[l]), lanes(|l| c.y + ry[l]), tail_ok);
                }
            }
            Self::Trig {
                c,
                u,
                w,
                mut co,
                mut si,
                cl,
                sl,
                ..
            } => {
                for k in 0..full + usize::from(tail > 0) {
                    f(
                        lanes(|l| c.x + u.x * co[l] + w.x * si[l]),
                        lanes(|l| c.y + u.y * co[l] + w.y * si[l]),
                        if k < full { [true; LANES] } else { tail_ok },
                    );
                    (co, si) = (
                        lanes(|l| co[l] * cl - si[l] * sl),
                        lanes(|l| si[l] * cl + co[l] * sl),
                    );
                }
            }
        }
    }

    /// The number of points of the run.
    fn len(&self) -> usize {
        match *self {
            Self::Line { n, .. } | Self::Arc { n, .. } | Self::Trig { n, .. } => n,
        }
    }

    /// Calls `f` with every point of the run, in order.
    #[cfg(test)]
    fn for_each<F: FnMut(Vector2<f64>)>(self, mut f: F) {
        self.for_each_chunk(|u, v, ok| {
            for l in 0..LANES {
                if ok[l] {
                    f(Vector2::new(u[l], v[l]));
                }
            }
        });
    }
}

/// Receives the pieces of a part's analytic outline from [`Prepared::sample_outline`]: the
/// geometry of the samples, shared by the CPU sampler ([`Run`]) and the GPU port (`gpu.rs`), so
/// that both sample the same points.
pub(crate) trait OutlineSink {
    /// `n` points `p + (q − p)·k/n`, k = 0 … n−1.
    fn line(&mut self, p: Vector2<f64>, q: Vector2<f64>, n: usize);
    /// `n` points `c + u·cos kθ + w·sin kθ`, k = 0 … n−1; `circle`: a circular arc (|u| = |w|,
    /// w = u turned clockwise by a right angle), otherwise an ellipse.
    fn trig(
        &mut self,
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
        circle: bool,
    );
}

/// At most four [`Run`]s of one part.
struct RunSink {
    runs: [Run; 4],
    n: usize,
}

impl OutlineSink for RunSink {
    #[inline]
    fn line(&mut self, p: Vector2<f64>, q: Vector2<f64>, n: usize) {
        self.runs[self.n & 3] = Run::line(p, q, n);
        self.n += 1;
    }
    #[inline]
    fn trig(
        &mut self,
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
        circle: bool,
    ) {
        self.runs[self.n & 3] = if circle {
            Run::circle(c, u, w, theta, n)
        } else {
            Run::trig(c, u, w, theta, n)
        };
        self.n += 1;
    }
}

impl Prepared {
    /// The analytic samples every `step` pixels along the outline as at most four pieces, in
    /// order, into `sink`. The sample counts are those of `walk_outline`.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    pub(crate) fn sample_outline<S: OutlineSink>(&self, step: f64, sink: &mut S) {
        // Functions, not closures: a closure's body stays out of line here, and the AVX2 sink
        // must be inlined into the dispatched function.
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn arc_n(r: f64, sweep: f64, step: f64) -> usize {
            // Clamped in f64 (NaN gives 1, as the saturating conversion and the integer
            // `clamp` did; f64 `clamp` would keep NaN), so the conversion is a plain one.
            #[allow(clippy::manual_clamp)]
            let n = (r * sweep / step).ceil().max(1.0).min(4096.0);
            n as u32 as usize
        }
        // A clockwise arc (u right, v down: decreasing angle) of radius `r` around `c` from the
        // unit direction `from`, the end point excluded.
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn arc<S: OutlineSink>(
            sink: &mut S,
            step: f64,
            c: Vector2<f64>,
            r: f64,
            from: Vector2<f64>,
            sweep: f64,
        ) {
            let n = arc_n(r, sweep, step);
            let w = Vector2::new(from.y, -from.x) * r;
            sink.trig(c, from * r, w, sweep / f64::from(n as u32), n, true);
        }
        match *self {
            Self::Circle { c, r } => arc(sink, step, c, r, Vector2::x(), std::f64::consts::TAU),
            Self::Ellipse { c, a, b, ea, eb } => {
                let n = arc_n(a, std::f64::consts::TAU, step);
                // x = c + ea·a·cos t + eb·b·sin t with t = −kθ.
                sink.trig(
                    c,
                    ea * a,
                    -eb * b,
                    std::f64::consts::TAU / f64::from(n as u32),
                    n,
                    false,
                );
            }
            Self::Capsule {
                c0,
                c1,
                r0,
                r1,
                len,
                d,
                n,
                sin_a,
                cos_a,
            } => {
                let np = d * sin_a + n * cos_a;
                let nm = d * sin_a - n * cos_a;
                // As `arc_n`: NaN gives 1.
                #[allow(clippy::manual_clamp)]
                let m = (len * cos_a / step).ceil().max(1.0).min(65_536.0) as u32 as usize;
                let half = std::f64::consts::PI;
                let alpha = sin_a.asin();
                sink.line(c0 + np * r0, c1 + np * r1, m);
                arc(sink, step, c1, r1, np, half - 2.0 * alpha);
                sink.line(c1 + nm * r1, c0 + nm * r0, m);
                arc(sink, step, c0, r0, nm, half + 2.0 * alpha);
            }
        }
    }

    /// [`Prepared::sample_outline`] as [`Run`]s: the runs and their number.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn sample_runs(&self, step: f64) -> ([Run; 4], usize) {
        let none = Run::Line {
            p: Vector2::zeros(),
            s: Vector2::zeros(),
            n: 0,
        };
        let mut sink = RunSink {
            runs: [none; 4],
            n: 0,
        };
        self.sample_outline(step, &mut sink);
        (sink.runs, sink.n)
    }
}
/// Per-thread scratch for rasterising silhouettes: a mask that only grows, and a reusable path
/// builder. Reusing one per thread means no allocation per particle in our code (tiny-skia
/// itself still allocates a small edge list per fill).
#[derive(Default)]
pub struct RenderScratch {
    mask: Option<Mask>,
    builder: Option<PathBuilder>,
}

impl std::fmt::Debug for RenderScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let size = self.mask.as_ref().map(|m| (m.width(), m.height()));
        f.debug_struct("RenderScratch")
            .field("mask", &size)
            .finish_non_exhaustive()
    }
}

impl RenderScratch {
    /// An empty scratch; buffers grow on first use.
    pub fn new() -> Self {
        Self::default()
    }
}

/// The projected parts of a pose in one view (at most three).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Projected {
    parts: [Option<Prepared>; 3],
    n: usize,
}

impl Projected {
    fn push(&mut self, p: Prepared) {
        if self.n < 3 {
            self.parts[self.n] = Some(p);
            self.n += 1;
        }
    }

    pub(crate) fn iter(&self) -> impl Iterator<Item = &Prepared> {
        self.parts[..self.n].iter().flatten()
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.n == 0
    }
}

fn finite_coords(v: &Vector2<f64>) -> bool {
    v.x.abs() < MAX_COORD && v.y.abs() < MAX_COORD
}

/// A camera-frame point and its projection ([`Camera::project_camera`]).
type Projection = (Vector3<f64>, Option<Vector2<f64>>);

/// `p` in the camera frame and projected.
#[allow(clippy::inline_always)] // Outlined, the calls and by-value copies cost ~100 Ir per pose.
#[inline(always)]
fn projection(cam: &Camera, p: &Vector3<f64>) -> Projection {
    let c = cam.to_camera(p);
    (c, cam.project_camera(&c))
}

/// A truncated cone from a to b (camera frame, with their projections) clipped to the near
/// plane, as a 2-D capsule.
#[allow(clippy::inline_always)] // Outlined, the calls and by-value copies cost ~100 Ir per pose.
#[inline(always)]
fn project_cone(cam: &Camera, a: Projection, b: Projection, ra: f64, rb: f64) -> Option<Part2> {
    let zmin = NEAR_PLANE * 1.000_001;
    let ((mut a, mut pa), (mut b, mut pb), mut ra, mut rb) = (a, b, ra, rb);
    let behind = |z: f64| z.is_nan() || z < zmin;
    if behind(a.z) && behind(b.z) {
        return None;
    }
    if behind(a.z) {
        let t = (zmin - a.z) / (b.z - a.z);
        a += (b - a) * t;
        a.z = zmin;
        ra += (rb - ra) * t;
        pa = cam.project_camera(&a);
    } else if behind(b.z) {
        let t = (zmin - b.z) / (a.z - b.z);
        b += (a - b) * t;
        b.z = zmin;
        rb += (ra - rb) * t;
        pb = cam.project_camera(&b);
    }
    let (pa, pb) = (pa?, pb?);
    if !(finite_coords(&pa) && finite_coords(&pb)) {
        return None;
    }
    let f = cam.mean_focal();
    let (r0, r1) = (ra * f / a.z, rb * f / b.z);
    (r0.abs() < MAX_COORD && r1.abs() < MAX_COORD).then_some(Part2::Capsule {
        c0: [pa.x, pa.y],
        c1: [pb.x, pb.y],
        r0: r0.max(0.0),
        r1: r1.max(0.0),
    })
}

/// The hand ellipsoid as a 2-D ellipse, by the local affine approximation of the projection at
/// its centre (exact up to perspective foreshortening across the hand).
fn project_ellipsoid(
    cam: &Camera,
    centre: Vector3<f64>,
    axes: &[Vector3<f64>; 3],
) -> Option<Part2> {
    let (c, a, b, [s00, s01, s11]) = ellipse_shape(cam, centre, axes)?;
    let angle = 0.5 * (2.0 * s01).atan2(s00 - s11);
    Some(Part2::Ellipse {
        c: [c.x, c.y],
        a,
        b,
        angle,
    })
}

/// The projected hand as prepared for the contour routines: [`project_ellipsoid`] with the
/// axis directions from the shape matrix by the half-angle formulas (no `atan2`, `sin_cos`).
fn project_ellipsoid_prepared(
    cam: &Camera,
    centre: Vector3<f64>,
    axes: &[Vector3<f64>; 3],
) -> Option<Prepared> {
    let (c, a, b, [s00, s01, s11]) = ellipse_shape(cam, centre, axes)?;
    // (cos 2φ, sin 2φ) ∝ (s00 − s11, 2 s01), φ ∈ [−π/2, π/2] as `0.5·atan2`; the larger of
    // cos φ, |sin φ| by a square root, the other from sin 2φ = 2 sin φ cos φ. The norm of
    // (c2, s2) is 2·dev = a² − b² (no `hypot`: |s_ij| < 1e12 px², the squares cannot overflow).
    let (c2, s2) = (s00 - s11, 2.0 * s01);
    #[allow(clippy::imprecise_flops)] // `hypot` is a libm call, and no accuracy is lost here.
    let h = (c2 * c2 + s2 * s2).sqrt();
    let ea = if h > 0.0 {
        let (c2, s2) = (c2 / h, s2 / h);
        if c2 >= 0.0 {
            let co = (0.5 * (1.0 + c2)).sqrt();
            Vector2::new(co, s2 / (2.0 * co))
        } else {
            let si = (0.5 * (1.0 - c2)).sqrt().copysign(s2);
            Vector2::new(s2 / (2.0 * si), si)
        }
    } else {
        Vector2::x()
    };
    Some(Prepared::Ellipse {
        c,
        a,
        b,
        ea,
        eb: Vector2::new(-ea.y, ea.x),
    })
}

/// Centre, semi-axes and shape matrix `S = Σ_k (J a_k)(J a_k)ᵀ` (s00, s01, s11) of the
/// projected hand.
#[allow(clippy::inline_always)] // Outlined, the calls and by-value copies cost ~100 Ir per pose.
#[inline(always)]
fn ellipse_shape(
    cam: &Camera,
    centre: Vector3<f64>,
    axes: &[Vector3<f64>; 3],
) -> Option<(Vector2<f64>, f64, f64, [f64; 3])> {
    // The largest norm (one square root: √ is monotonic and correctly rounded, so this is the
    // largest of the three `norm`s).
    let reach = axes
        .iter()
        .map(nalgebra::Vector3::norm_squared)
        .fold(0.0, f64::max)
        .sqrt();
    if centre.z.is_nan() || centre.z - reach <= NEAR_PLANE {
        return None;
    }
    let c = cam.project_camera(&centre)?;
    if !finite_coords(&c) {
        return None;
    }
    let j = cam.project_camera_jacobian(&centre)?;
    let (mut s00, mut s01, mut s11) = (0.0, 0.0, 0.0);
    for a in axes {
        let v = j * a;
        s00 += v.x * v.x;
        s01 += v.x * v.y;
        s11 += v.y * v.y;
    }
    let mean = 0.5 * (s00 + s11);
    let dev = (0.25 * (s00 - s11) * (s00 - s11) + s01 * s01).sqrt();
    let a = (mean + dev).max(0.0).sqrt();
    let b = (mean - dev).max(0.0).sqrt();
    (a.is_finite() && b.is_finite() && a < MAX_COORD).then_some((c, a, b, [s00, s01, s11]))
}

/// The upper arm and the forearm as 2-D capsules (the elbow, their shared end, is projected
/// once).
#[allow(clippy::inline_always)] // Outlined, the calls and by-value copies cost ~100 Ir per pose.
#[inline(always)]
fn project_cones(cam: &Camera, parts: &crate::arm::ArmParts) -> [Option<Part2>; 2] {
    let (p, q, r0, r1) = parts.upper;
    let (_, w, f0, f1) = parts.forearm;
    let (p, q, w) = (
        projection(cam, &p),
        projection(cam, &q),
        projection(cam, &w),
    );
    [
        project_cone(cam, p, q, r0, r1),
        project_cone(cam, q, w, f0, f1),
    ]
}

/// Projects the three parts of a pose (upper arm, forearm, hand) into the camera. Parts behind
/// the near plane are clipped (cones) or dropped (the hand). A non-finite pose gives none.
pub(crate) fn project_prepared(cam: &Camera, geometry: &ArmGeometry, pose: &[f64; 9]) -> Projected {
    let mut out = Projected::default();
    let Some(parts) = geometry.parts(pose) else {
        return out;
    };
    let [upper, forearm] = project_cones(cam, &parts);
    for part in upper.iter().chain(&forearm) {
        out.push(Prepared::new(part));
    }
    let rot = cam.rotation_matrix();
    let axes = parts.hand_axes.map(|a| rot * a);
    if let Some(part) = project_ellipsoid_prepared(cam, cam.to_camera(&parts.hand_centre), &axes) {
        out.push(part);
    }
    out
}

/// The projected 2-D parts of a pose in one view (upper arm, forearm, hand, in that order;
/// parts behind the camera are clipped or left out), for overlays and tests.
pub fn project_parts(camera: &Camera, geometry: &ArmGeometry, pose: &[f64; 9]) -> Vec<Part2> {
    let Some(parts) = geometry.parts(pose) else {
        return Vec::new();
    };
    let mut out = Vec::with_capacity(3);
    out.extend(project_cones(camera, &parts).into_iter().flatten());
    let rot = camera.rotation_matrix();
    let axes = parts.hand_axes.map(|a| rot * a);
    out.extend(project_ellipsoid(
        camera,
        camera.to_camera(&parts.hand_centre),
        &axes,
    ));
    out
}

/// The raster polygon of a part (pixel coordinates, the same vertices as the silhouette),
/// appended to `out`.
pub(crate) fn part_polygon(part: &Part2, out: &mut Vec<[f64; 2]>) {
    Prepared::new(part).walk_outline(1.0, true, |x| out.push([x.x, x.y]));
}

/// Sets `mask[v · width + u] = 1` for every pixel whose centre (u, v) lies in one of `parts` or
/// within `grow` pixels of it: the union silhouette grown by `grow` (exact for discs and
/// capsules; for an ellipse the inside is exact and the growth is measured along its minor
/// axis, so it reaches less far along the major one). Other pixels are left as they are. A
/// non-finite part or `grow` covers nothing.
///
/// # Errors
/// [`RenderError::InvalidImage`] if `mask` does not hold `width · height` values.
pub fn cover_parts(
    parts: &[Part2],
    grow: f64,
    width: u32,
    height: u32,
    mask: &mut [u8],
) -> Result<(), RenderError> {
    let (w, h) = (width as usize, height as usize);
    if mask.len() != w * h {
        return Err(RenderError::InvalidImage(format!(
            "cover_parts: a {width}×{height} mask needs {} values, got {}",
            w * h,
            mask.len()
        )));
    }
    if !grow.is_finite() {
        return Ok(());
    }
    for part in parts {
        let p = Prepared::new(part);
        let b = p.bbox();
        if !b.iter().all(|x| x.is_finite()) {
            continue;
        }
        let lo = |x: f64| (x - grow).ceil().max(0.0) as usize;
        let hi = |x: f64, n: usize| ((x + grow).floor().min(n as f64 - 1.0)).max(-1.0);
        let (u1, v1) = (hi(b[2], w), hi(b[3], h));
        if u1 < 0.0 || v1 < 0.0 {
            continue;
        }
        for v in lo(b[1])..=v1 as usize {
            for u in lo(b[0])..=u1 as usize {
                if p.signed_distance(Vector2::new(u as f64, v as f64)) <= grow {
                    mask[v * w + u] = 1;
                }
            }
        }
    }
    Ok(())
}

/// A part in the form of the per-sample "more than [`INSIDE_TOL`] inside" test, four lanes at
/// a time (no square roots, no divisions, no branches per lane).
#[derive(Debug, Clone, Copy)]
enum Inside {
    /// Contains no point deeper than the tolerance.
    Never,
    /// `|x − c|² < r2`.
    Disc { c: Vector2<f64>, r2: f64 },
    /// The capsule test of [`Prepared::deep_inside`]: cap at c0 for `s < lo`, at c1 for
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
    fn new(part: &Prepared) -> Self {
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
    fn deep(&self, x: Lanes, y: Lanes) -> [bool; LANES] {
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
struct Occluders<'a> {
    shapes: [&'a Inside; 2],
    boxes: [[f64; 4]; 2],
    /// The parts in the used slots.
    idx: [usize; 2],
    /// Number of used slots.
    n: usize,
}

/// A box that contains no point.
const EMPTY_BOX: [f64; 4] = [
    f64::INFINITY,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
];

/// Margin (pixels) between a part's bounding box and the image border below which the
/// per-sample image test is kept: the samples lie on the outline up to rounding (~1e-12 px).
const INSIDE_MARGIN: f64 = 1e-3;

/// What the sample loop does with a chunk of samples that passed the image and occluder tests
/// (`ok` marks them).
trait Sink {
    fn take(&mut self, u: Lanes, v: Lanes, ok: [bool; LANES]);
}

/// Calls `visit` for every point that passed, in order.
struct Visit<F>(F);

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
struct Sum<'c, C> {
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
fn sample_parts<S: Sink>(parts: &Projected, width: u32, height: u32, step: f64, sink: &mut S) {
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
fn sample_runs_into<const INSIDE: bool, const NOCC: usize, S: Sink>(
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
struct SumOp<'p, C> {
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

/// The analytic sample loop of [`analytic_sum_nearest`] with explicit AVX2 vectors (pulp's
/// `V3` token, no `unsafe` in our code): eight samples per register in f32, relative to an
/// integer anchor, with a bound of their error against the f64 samples of the portable loop
/// ([`sample_parts`]); a chunk of eight with a decision (rounded pixel, image bounds, inside
/// another part) within that bound of flipping is redone by the f64 loop (the same IEEE
/// operations in the same order as the portable loop). So the same points pass, and their
/// `(1 − G)²` are summed in f64 in the portable loop's lanes and order: bit-identical sums.
#[cfg(target_arch = "x86_64")]
mod avx2 {
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

    /// The "more than [`super::INSIDE_TOL`] inside" test of an occluder in f32, in coordinates relative
    /// to the anchor of the part whose samples it tests, with every threshold moved by the error
    /// bound `t` both ways: lanes below the lower threshold are deep in the f64 test
    /// ([`Inside::deep`] at the f64 positions), lanes above the upper one are not, the rest are
    /// ambiguous. `[lo, hi]` pairs are these two thresholds.
    #[derive(Clone, Copy)]
    enum Shape32 {
        Never,
        Disc {
            c: [f32; 2],
            r2: [f32; 2],
        },
        Capsule {
            c0: [f32; 2],
            c1: [f32; 2],
            d: [f32; 2],
            n: [f32; 2],
            /// The cap-at-c0 region is `s < lo` (f64), the cap-at-c1 region `s > hi`.
            lo: [f32; 2],
            hi: [f32; 2],
            r0sq: [f32; 2],
            r1sq: [f32; 2],
            sin_a: f32,
            cos_a: f32,
            lim: [f32; 2],
        },
        Ellipse {
            c: [f32; 2],
            ea: [f32; 2],
            eb: [f32; 2],
            k2: [f32; 2],
        },
    }

    /// `[x − t, x + t]` in f32.
    fn pair(x: f64, t: f64) -> [f32; 2] {
        [(x - t) as f32, (x + t) as f32]
    }

    /// A point relative to the anchor `a`, in f32.
    fn rel(p: nalgebra::Vector2<f64>, a: [f64; 2]) -> [f32; 2] {
        [(p.x - a[0]) as f32, (p.y - a[1]) as f32]
    }

    fn f32s(v: nalgebra::Vector2<f64>) -> [f32; 2] {
        [v.x as f32, v.y as f32]
    }

    impl Shape32 {
        /// Per lane: (surely deep, surely not deep) in the f64 test.
        #[cfg(test)]
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn test(&self, s: V3, x: f32x8, y: f32x8) -> (m32x8, m32x8) {
            let (nd, no) = self.test_not(s, x, y);
            (s.not_m32s(nd), s.not_m32s(no))
        }

        /// Per lane: (not surely deep, not surely outside) in the f64 test, i.e. the
        /// complements of [`Shape32::test`] (the loop uses them as they are: fewer
        /// negations).
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn test_not(&self, s: V3, x: f32x8, y: f32x8) -> (m32x8, m32x8) {
            let sp = |a: f32| s.splat_f32s(a);
            // `(q ≥ lo, q ≤ hi)`: not below the lower threshold, not above the upper one.
            let not_below_above = |q: f32x8, th: &[f32; 2]| {
                (
                    s.greater_than_or_equal_f32s(q, sp(th[0])),
                    s.less_than_or_equal_f32s(q, sp(th[1])),
                )
            };
            // `m ∧ ¬d` (one `vandnps`).
            let andnot = |d: m32x8, m: m32x8| -> m32x8 {
                pulp::cast(s.avx._mm256_andnot_ps(pulp::cast(d), pulp::cast(m)))
            };
            match self {
                Self::Never => (pulp::cast([u32::MAX; L8]), pulp::cast([0u32; L8])),
                Self::Disc { c, r2 } => {
                    let (dx, dy) = (s.sub_f32s(x, sp(c[0])), s.sub_f32s(y, sp(c[1])));
                    not_below_above(norm2(s, dx, dy), r2)
                }
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
                } => {
                    let (rx, ry) = (s.sub_f32s(x, sp(c0[0])), s.sub_f32s(y, sp(c0[1])));
                    let (qx, qy) = (s.sub_f32s(x, sp(c1[0])), s.sub_f32s(y, sp(c1[1])));
                    let sd = dot(s, rx, ry, d);
                    let f = s.mul_add_e_f32s(
                        sd,
                        sp(*sin_a),
                        s.mul_f32s(abs(s, dot(s, rx, ry, n)), sp(*cos_a)),
                    );
                    let (side_deep, side_out) = below_above(s, f, lim);
                    let (cap0_deep, cap0_out) = below_above(s, norm2(s, rx, ry), r0sq);
                    let (cap1_deep, cap1_out) = below_above(s, norm2(s, qx, qy), r1sq);
                    // Regions the f64 test may select: cap 0 (s < lo), side, cap 1 (s > hi).
                    let maybe0 = s.less_than_f32s(sd, sp(lo[1]));
                    let maybe1 = s.greater_than_f32s(sd, sp(hi[0]));
                    let maybe_side = s.and_m32s(
                        s.greater_than_or_equal_f32s(sd, sp(lo[0])),
                        s.less_than_or_equal_f32s(sd, sp(hi[1])),
                    );
                    // Sure when it holds in every region that may be selected: not sure when
                    // some region may be selected in which it does not hold.
                    let not_deep = s.or_m32s(
                        s.or_m32s(andnot(cap0_deep, maybe0), andnot(side_deep, maybe_side)),
                        andnot(cap1_deep, maybe1),
                    );
                    let not_out = s.or_m32s(
                        s.or_m32s(andnot(cap0_out, maybe0), andnot(side_out, maybe_side)),
                        andnot(cap1_out, maybe1),
                    );
                    (not_deep, not_out)
                }
                Self::Ellipse { c, ea, eb, k2 } => {
                    let (rx, ry) = (s.sub_f32s(x, sp(c[0])), s.sub_f32s(y, sp(c[1])));
                    let (xa, xb) = (dot(s, rx, ry, ea), dot(s, rx, ry, eb));
                    not_below_above(norm2(s, xa, xb), k2)
                }
            }
        }
    }

    /// `|x|` per lane (the sign bits cleared). pulp's `abs_f32s` is only `#[inline]`, and LLVM
    /// may keep it (and the intrinsics in it) out of line, i.e. without AVX2.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn abs(s: V3, x: f32x8) -> f32x8 {
        s.and_f32s(x, pulp::cast([0x7fff_ffff_u32; L8]))
    }

    /// `|x|` per lane, f64.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn abs64(s: V3, x: f64x4) -> f64x4 {
        s.and_f64s(x, pulp::cast([0x7fff_ffff_ffff_ffff_u64; LANES]))
    }

    /// `a·b` of two-vector lanes and a constant.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn dot(s: V3, ax: f32x8, ay: f32x8, b: &[f32; 2]) -> f32x8 {
        s.mul_add_e_f32s(ax, s.splat_f32s(b[0]), s.mul_f32s(ay, s.splat_f32s(b[1])))
    }

    /// `|a|²` of two-vector lanes.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn norm2(s: V3, ax: f32x8, ay: f32x8) -> f32x8 {
        s.mul_add_e_f32s(ax, ax, s.mul_f32s(ay, ay))
    }

    /// `(q < lo, q > hi)` per lane.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn below_above(s: V3, q: f32x8, th: &[f32; 2]) -> (m32x8, m32x8) {
        (
            s.less_than_f32s(q, s.splat_f32s(th[0])),
            s.greater_than_f32s(q, s.splat_f32s(th[1])),
        )
    }

    /// How a [`Run32`] generates its samples.
    #[derive(Clone, Copy)]
    enum Gen32 {
        /// `p + k·s`.
        Line { p: [f32; 2], s: [f32; 2] },
        /// `c + r_k`: radius vectors of the first chunk, rotated by 8θ per chunk.
        Arc {
            c: [f32; 2],
            rx: f32x8,
            ry: f32x8,
            c8: f32,
            s8: f32,
        },
        /// `c + u·cos kθ + w·sin kθ`: cos and sin of the first chunk, rotated by 8θ.
        Trig {
            c: [f32; 2],
            u: [f32; 2],
            w: [f32; 2],
            co: f32x8,
            si: f32x8,
            c8: f32,
            s8: f32,
        },
    }

    /// A [`Run`] for the f32 loop, relative to the anchor: `n` samples, the bound `tol` of
    /// their error against the f64 positions, and a box (f64) that holds them.
    #[derive(Clone, Copy)]
    struct Run32 {
        samples: Gen32,
        n: usize,
        tol: f64,
        bx: [f64; 4],
    }

    /// The larger magnitude of a vector's coordinates.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn inf(x: f64, y: f64) -> f64 {
        let (x, y) = (x.abs(), y.abs());
        if x > y { x } else { y }
    }

    /// Two f64x4 as one f32x8.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn to_f32x8(s: V3, lo: f64x4, hi: f64x4) -> f32x8 {
        pulp::cast([s.convert_f64x4_to_f32x4(lo), s.convert_f64x4_to_f32x4(hi)])
    }

    /// `uc·co + wc·si`.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn comb(s: V3, co: f64x4, si: f64x4, uc: f64, wc: f64) -> f64x4 {
        s.add_f64s(
            s.mul_f64s(s.splat_f64s(uc), co),
            s.mul_f64s(s.splat_f64s(wc), si),
        )
    }

    // The tolerances: a few f32 roundings of the magnitudes involved, and for the rotations
    // one per step of 8θ (test `f32_positions_are_within_the_bound` checks them with a margin).
    impl Run32 {
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn line(a: [f64; 2], p: Vector2<f64>, q: Vector2<f64>, n: usize) -> Self {
            let (x0, y0) = (p.x - a[0], p.y - a[1]);
            let (x1, y1) = (q.x - a[0], q.y - a[1]);
            let st = (q - p) / f64::from(n as u32);
            let m = 1e-3;
            Self {
                samples: Gen32::Line {
                    p: [x0 as f32, y0 as f32],
                    s: [st.x as f32, st.y as f32],
                },
                n,
                tol: 2e-6 + 4e-7 * (inf(x0, y0) + inf(x1 - x0, y1 - y0) + 1.0),
                bx: [
                    x0.min(x1) - m,
                    y0.min(y1) - m,
                    x0.max(x1) + m,
                    y0.max(y1) + m,
                ],
            }
        }

        #[allow(clippy::inline_always, clippy::many_single_char_names)]
        #[inline(always)]
        fn trig(
            s: V3,
            a: [f64; 2],
            c: Vector2<f64>,
            u: Vector2<f64>,
            w: Vector2<f64>,
            theta: f64,
            n: usize,
            circle: bool,
        ) -> Self {
            let (cx, cy) = (c.x - a[0], c.y - a[1]);
            // cos kθ, sin kθ for k = 0 … 7 (the f64 run's products for k ≤ 3, then 4θ on).
            let (s1, c1) = super::sin_cos(theta);
            let (c2, s2) = (c1 * c1 - s1 * s1, 2.0 * c1 * s1);
            let (c3, s3) = (c2 * c1 - s2 * s1, s2 * c1 + c2 * s1);
            let (c4, s4) = (c2 * c2 - s2 * s2, 2.0 * c2 * s2);
            let (co0, si0) = (f64x4(1.0, c1, c2, c3), f64x4(0.0, s1, s2, s3));
            let (c4v, s4v) = (s.splat_f64s(c4), s.splat_f64s(s4));
            let co1 = s.sub_f64s(s.mul_f64s(co0, c4v), s.mul_f64s(si0, s4v));
            let si1 = s.add_f64s(s.mul_f64s(si0, c4v), s.mul_f64s(co0, s4v));
            let (c8, s8) = ((c4 * c4 - s4 * s4) as f32, (2.0 * c4 * s4) as f32);
            let r = u.x.abs() + u.y.abs() + w.x.abs() + w.y.abs();
            let steps = f64::from((n / L8 + 2) as u32);
            let samples = if circle {
                Gen32::Arc {
                    c: [cx as f32, cy as f32],
                    rx: to_f32x8(s, comb(s, co0, si0, u.x, w.x), comb(s, co1, si1, u.x, w.x)),
                    ry: to_f32x8(s, comb(s, co0, si0, u.y, w.y), comb(s, co1, si1, u.y, w.y)),
                    c8,
                    s8,
                }
            } else {
                Gen32::Trig {
                    c: [cx as f32, cy as f32],
                    u: [u.x as f32, u.y as f32],
                    w: [w.x as f32, w.y as f32],
                    co: to_f32x8(s, co0, co1),
                    si: to_f32x8(s, si0, si1),
                    c8,
                    s8,
                }
            };
            let (ex, ey) = (u.x.abs() + w.x.abs() + 1e-3, u.y.abs() + w.y.abs() + 1e-3);
            Self {
                samples,
                n,
                tol: 2e-6 + 4e-7 * (inf(cx, cy) + r + 1.0) + 4e-7 * r * steps,
                bx: [cx - ex, cy - ey, cx + ex, cy + ey],
            }
        }
    }

    /// A bound of [`Run32::tol`] over every run of `part`'s outline (spacing `step`), whose
    /// coordinates relative to the anchor are at most `m`.
    fn tolerance_bound(part: &Prepared, m: f64, step: f64) -> f64 {
        // Arcs: |u|₁ + |w|₁ ≤ 2√2·r, at most 2πr/Δ samples; lines at most as long as the part.
        let arcs = |r: f64| {
            let big = 2.9 * r;
            2e-6 + 4e-7 * (m + big + 1.0)
                + 4e-7 * big * (r * std::f64::consts::TAU / step / 8.0 + 3.0)
        };
        match *part {
            Prepared::Circle { r, .. } => arcs(r),
            Prepared::Capsule { r0, r1, len, .. } => {
                arcs(r0.max(r1)).max(2e-6 + 4e-7 * (m + len + 1.0))
            }
            Prepared::Ellipse { a, b, .. } => {
                let big = 1.5 * (a + b);
                2e-6 + 4e-7 * (m + big + 1.0)
                    + 4e-7 * big * (a * std::f64::consts::TAU / step / 8.0 + 3.0)
            }
        }
    }

    impl Shape32 {
        /// The part's test ([`Inside::new`] of it) relative to the anchor `a`; `t`: bound
        /// (pixels) of the error of the f32 sample positions and of this test's arithmetic.
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn of_part(part: &Prepared, a: [f64; 2], t: f64) -> Self {
            let pair_sq = |r: f64| {
                if r <= super::INSIDE_TOL {
                    return [-1.0f32, -1.0];
                }
                let r = r - super::INSIDE_TOL;
                let lo = if r > t { (r - t) * (r - t) } else { -1.0 };
                [lo as f32, ((r + t) * (r + t)) as f32]
            };
            match *part {
                Prepared::Circle { c, r } => Self::Disc {
                    c: rel(c, a),
                    r2: pair_sq(r),
                },
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
                    c0: rel(c0, a),
                    c1: rel(c1, a),
                    d: f32s(d),
                    n: f32s(n),
                    lo: pair(r0 * sin_a, t),
                    hi: pair(len + r1 * sin_a, t),
                    r0sq: pair_sq(r0),
                    r1sq: pair_sq(r1),
                    sin_a: sin_a as f32,
                    cos_a: cos_a as f32,
                    // |s·sin α + |t|·cos α| moves by at most √2 times the position error.
                    lim: pair(r0 - super::INSIDE_TOL, 1.5 * t),
                },
                Prepared::Ellipse {
                    c,
                    a: ra,
                    b,
                    ea,
                    eb,
                } => {
                    if b <= super::INSIDE_TOL {
                        return Self::Never;
                    }
                    // Normalised coordinates move by at most 1/b ≥ 1/a times the error.
                    let k = 1.0 - super::INSIDE_TOL / b;
                    let tn = 1.5 * t / b;
                    let lo = if k > tn { (k - tn) * (k - tn) } else { -1.0 };
                    Self::Ellipse {
                        c: rel(c, a),
                        ea: f32s(ea / ra),
                        eb: f32s(eb / b),
                        k2: [lo as f32, ((k + tn) * (k + tn)) as f32],
                    }
                }
            }
        }
    }

    /// Window lengths (f32 values) of G for the loops without bounds checks.
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
                if fits(W18) {
                    go!(W18);
                } else if fits(W20) {
                    go!(W20);
                } else {
                    // Small images or parts taller than the windows: the f64 loop.
                    let (e2, k) = part_f64(s, &ctx, &acc);
                    acc.sum = e2;
                    acc.n += k;
                }
            }
            let sum: [f64; LANES] = pulp::cast(acc.sum);
            ((sum[0] + sum[1]) + (sum[2] + sum[3]), acc.n)
        }
    }

    /// Samples `part` into the f32 loop.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn stream<const INSIDE: bool, const NOCC: usize, const W: usize>(
        s: V3,
        part: &Prepared,
        a: [f64; 2],
        pl: &PartLoop<'_, '_, W>,
        acc: &mut Acc<'_>,
    ) {
        let mut st = Stream::<INSIDE, NOCC, W> {
            simd: s,
            a,
            pl,
            acc,
            k: 0,
        };
        part.sample_outline(pl.ctx.step, &mut st);
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
        let shift: core::arch::x86_64::__m128i =
            pulp::cast([u64::from(32 - W.trailing_zeros()), 0u64]);
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
    mod tests {
        use nalgebra::Vector3;
        use rand::{Rng, SeedableRng};

        use super::*;
        use crate::{ArmGeometry, Camera, contour::project_prepared};

        /// Random poses around the arm's rest pose, seen by cameras from far to close (parts
        /// from a few pixels to a few hundred across), at 640×480 and 1920×1080.
        fn scenes() -> Vec<(Camera, [f64; 9])> {
            let g = ArmGeometry::default();
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
            let mut out = Vec::new();
            for &(w, h) in &[(640u32, 480u32), (1920, 1080)] {
                for &dist in &[0.6, 1.0, 1.8, 4.0] {
                    let eye = Vector3::new(0.1, -dist, 1.3);
                    let c =
                        Camera::look_at(eye, Vector3::new(0.1, 0.3, 1.0), Vector3::z(), w, h, 1.0)
                            .unwrap();
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
                let fast =
                    crate::contour::analytic_sum_nearest(&parts, w, h, 2.0, &data, w as usize);
                let Some(slow) = crate::contour::analytic_sum_nearest_by_fallback(
                    &parts, w, h, 2.0, &data, w as usize,
                ) else {
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
fn part_boxes(parts: &Projected) -> [[f64; 4]; 3] {
    let mut boxes = [[0.0f64; 4]; 3];
    for (b, part) in boxes.iter_mut().zip(parts.iter()) {
        *b = part.bbox();
    }
    boxes
}

/// The occluders of part `i` (of `n`) and whether its box lies inside the image, or `None`
/// when the part is entirely outside the image.
fn occluders<'a>(
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
/// Raster contour: fills the union silhouette into the scratch mask (tight bounding box,
/// non-zero winding, no anti-aliasing) and calls `visit(u, v)` for every pixel of the inner
/// 4-neighbour boundary that lies inside the `width × height` image.
pub(crate) fn raster_contour<F: FnMut(usize, usize)>(
    parts: &Projected,
    width: u32,
    height: u32,
    scratch: &mut RenderScratch,
    mut visit: F,
) {
    if parts.is_empty() {
        return;
    }
    let mut bb = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in parts.iter() {
        let b = p.bbox();
        bb = [
            bb[0].min(b[0]),
            bb[1].min(b[1]),
            bb[2].max(b[2]),
            bb[3].max(b[3]),
        ];
    }
    // Image pixels to scan (inclusive), then the mask covers one more pixel on each side.
    let (w, h) = (i64::from(width), i64::from(height));
    let sx0 = ((bb[0].floor() as i64) - 1).max(0);
    let sy0 = ((bb[1].floor() as i64) - 1).max(0);
    let sx1 = ((bb[2].ceil() as i64) + 1).min(w - 1);
    let sy1 = ((bb[3].ceil() as i64) + 1).min(h - 1);
    if sx0 > sx1 || sy0 > sy1 {
        return;
    }
    let (ox, oy) = (sx0 - 1, sy0 - 1);
    let mw = (sx1 - sx0 + 3) as u32;
    let mh = (sy1 - sy0 + 3) as u32;
    let need_new = scratch
        .mask
        .as_ref()
        .is_none_or(|m| m.width() < mw || m.height() < mh);
    if need_new {
        let (cw, ch) = scratch
            .mask
            .as_ref()
            .map_or((0, 0), |m| (m.width(), m.height()));
        scratch.mask = Mask::new(mw.max(cw), mh.max(ch));
    }
    let Some(mask) = scratch.mask.as_mut() else {
        return;
    };
    let mut pb = scratch.builder.take().unwrap_or_default();
    // Mask pixel (i, j) ↔ image pixel (ox+i, oy+j), whose centre is mask point (i+½, j+½).
    let (tx, ty) = (0.5 - ox as f64, 0.5 - oy as f64);
    for part in parts.iter() {
        let mut first = true;
        part.walk_outline(1.0, true, |x| {
            let (px, py) = ((x.x + tx) as f32, (x.y + ty) as f32);
            if first {
                pb.move_to(px, py);
                first = false;
            } else {
                pb.line_to(px, py);
            }
        });
        pb.close();
    }
    let stride = mask.width() as usize;
    let Some(path) = pb.finish() else {
        return;
    };
    mask.fill_path(&path, FillRule::Winding, false, Transform::identity());
    // Region that the fill may have touched, to restore the all-zero invariant afterwards.
    let pbb = path.bounds();
    let clear = [
        (f64::from(pbb.left()).floor() as i64 - 1).clamp(0, i64::from(mask.width())) as usize,
        (f64::from(pbb.top()).floor() as i64 - 1).clamp(0, i64::from(mask.height())) as usize,
        (f64::from(pbb.right()).ceil() as i64 + 1).clamp(0, i64::from(mask.width())) as usize,
        (f64::from(pbb.bottom()).ceil() as i64 + 1).clamp(0, i64::from(mask.height())) as usize,
    ];
    scratch.builder = Some(path.clear());
    let data = mask.data_mut();
    let (mw, mh) = (mw as usize, mh as usize);
    let word = |s: &[u8], at: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&s[at..at + 8]);
        u64::from_le_bytes(b)
    };
    for j in 1..mh - 1 {
        let up = &data[(j - 1) * stride..(j - 1) * stride + mw];
        let cur = &data[j * stride..j * stride + mw];
        let dn = &data[(j + 1) * stride..(j + 1) * stride + mw];
        let v = (oy + j as i64) as usize;
        // Eight pixels at a time: a non-AA fill writes only 0 and 255, so the boundary bytes
        // are `cur & !(left & right & up & down)`; all-empty and all-interior words are skipped.
        let mut i = 1;
        while i + 9 <= mw {
            let c = word(cur, i);
            if c != 0 {
                let all = word(cur, i - 1) & word(cur, i + 1) & word(up, i) & word(dn, i);
                let mut b = c & !all;
                while b != 0 {
                    let k = (b.trailing_zeros() / 8) as usize;
                    visit((ox + (i + k) as i64) as usize, v);
                    b &= !(0xFFu64 << (8 * k));
                }
            }
            i += 8;
        }
        while i < mw - 1 {
            if cur[i] != 0 && (cur[i - 1] == 0 || cur[i + 1] == 0 || up[i] == 0 || dn[i] == 0) {
                visit((ox + i as i64) as usize, v);
            }
            i += 1;
        }
    }
    if clear[0] < clear[2] {
        for j in clear[1]..clear[3] {
            data[j * stride + clear[0]..j * stride + clear[2]].fill(0);
        }
    }
}

/// The contour of a pose in one view, for overlays: raster contour pixels or analytic sample
/// points (Δ = 2 px), in pixel coordinates, only points inside the image.
pub fn contour_points(
    camera: &Camera,
    geometry: &ArmGeometry,
    pose: &[f64; 9],
    method: ContourMethod,
) -> Vec<[f64; 2]> {
    let parts = project_prepared(camera, geometry, pose);
    let mut out = Vec::new();
    match method {
        ContourMethod::Raster => {
            let mut scratch = RenderScratch::new();
            raster_contour(&parts, camera.width, camera.height, &mut scratch, |u, v| {
                out.push([u as f64, v as f64]);
            });
        }
        ContourMethod::Analytic => {
            analytic_contour(&parts, camera.width, camera.height, 2.0, |u, v| {
                out.push([u, v]);
            });
        }
    }
    out
}

/// Rasterised silhouette of the parts as a full-image 0/1 mask (row-major `u8`), for tests and
/// overlays.
#[cfg(test)]
pub(crate) fn silhouette(parts: &Projected, width: u32, height: u32) -> Vec<u8> {
    let mut out = vec![0u8; width as usize * height as usize];
    let Some(size) = tiny_skia::IntSize::from_wh(width, height) else {
        return out;
    };
    let Some(mut mask) = Mask::new(size.width(), size.height()) else {
        return out;
    };
    let mut pb = PathBuilder::new();
    for part in parts.iter() {
        let mut first = true;
        part.walk_outline(1.0, true, |x| {
            let (px, py) = ((x.x + 0.5) as f32, (x.y + 0.5) as f32);
            if first {
                pb.move_to(px, py);
                first = false;
            } else {
                pb.line_to(px, py);
            }
        });
        pb.close();
    }
    if let Some(path) = pb.finish() {
        mask.fill_path(&path, FillRule::Winding, false, Transform::identity());
    }
    for (o, &m) in out.iter_mut().zip(mask.data()) {
        *o = u8::from(m != 0);
    }
    out
}

#[cfg(test)]
mod tests {
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
                        let x: Lanes = lanes(|l| {
                            bb[0] - 3.0 + (bb[2] - bb[0] + 6.0) * (4 * i + l) as f64 / 39.0
                        });
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
}
