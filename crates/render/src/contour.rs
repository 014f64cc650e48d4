//! Projection of the arm into 2-D parts, the raster silhouette contour (tiny-skia) and the
//! analytic contour sampler (SPEC §4.2).

use nalgebra::{Vector2, Vector3};
use tiny_skia::{FillRule, Mask, PathBuilder, Transform};

use crate::{ArmGeometry, Camera, camera::NEAR_PLANE};

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
    fn new(part: &Part2) -> Self {
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
    #[cfg(test)]
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
        let arc_n = |r: f64, sweep: f64| ((r * sweep / step).ceil() as usize).clamp(1, 4096);
        // A clockwise arc (u right, v down: decreasing angle) of radius `r` around `c` from the
        // unit direction `from`, the end point excluded.
        let arc = |sink: &mut S, c: Vector2<f64>, r: f64, from: Vector2<f64>, sweep: f64| {
            let n = arc_n(r, sweep);
            let w = Vector2::new(from.y, -from.x) * r;
            sink.trig(c, from * r, w, sweep / n as f64, n, true);
        };
        match *self {
            Self::Circle { c, r } => arc(sink, c, r, Vector2::x(), std::f64::consts::TAU),
            Self::Ellipse { c, a, b, ea, eb } => {
                let n = arc_n(a, std::f64::consts::TAU);
                // x = c + ea·a·cos t + eb·b·sin t with t = −kθ.
                sink.trig(
                    c,
                    ea * a,
                    -eb * b,
                    std::f64::consts::TAU / n as f64,
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
                let m = ((len * cos_a / step).ceil() as usize).clamp(1, 1 << 16);
                let half = std::f64::consts::PI;
                let alpha = sin_a.asin();
                sink.line(c0 + np * r0, c1 + np * r1, m);
                arc(sink, c1, r1, np, half - 2.0 * alpha);
                sink.line(c1 + nm * r1, c0 + nm * r0, m);
                arc(sink, c0, r0, nm, half + 2.0 * alpha);
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

/// A truncated cone from a to b (camera frame) clipped to the near plane, as a 2-D capsule.
fn project_cone(cam: &Camera, a: Vector3<f64>, b: Vector3<f64>, ra: f64, rb: f64) -> Option<Part2> {
    let zmin = NEAR_PLANE * 1.000_001;
    let (mut a, mut b, mut ra, mut rb) = (a, b, ra, rb);
    let behind = |z: f64| z.is_nan() || z < zmin;
    if behind(a.z) && behind(b.z) {
        return None;
    }
    if behind(a.z) {
        let t = (zmin - a.z) / (b.z - a.z);
        a += (b - a) * t;
        a.z = zmin;
        ra += (rb - ra) * t;
    } else if behind(b.z) {
        let t = (zmin - b.z) / (a.z - b.z);
        b += (a - b) * t;
        b.z = zmin;
        rb += (ra - rb) * t;
    }
    let pa = cam.project_camera(&a)?;
    let pb = cam.project_camera(&b)?;
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
fn ellipse_shape(
    cam: &Camera,
    centre: Vector3<f64>,
    axes: &[Vector3<f64>; 3],
) -> Option<(Vector2<f64>, f64, f64, [f64; 3])> {
    let reach = axes.iter().map(nalgebra::Vector3::norm).fold(0.0, f64::max);
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

/// Projects the three parts of a pose (upper arm, forearm, hand) into the camera. Parts behind
/// the near plane are clipped (cones) or dropped (the hand). A non-finite pose gives none.
pub(crate) fn project_prepared(cam: &Camera, geometry: &ArmGeometry, pose: &[f64; 9]) -> Projected {
    let mut out = Projected::default();
    let Some(parts) = geometry.parts(pose) else {
        return out;
    };
    let (p, q, r0, r1) = parts.upper;
    if let Some(part) = project_cone(cam, cam.to_camera(&p), cam.to_camera(&q), r0, r1) {
        out.push(Prepared::new(&part));
    }
    let (q, w, r0, r1) = parts.forearm;
    if let Some(part) = project_cone(cam, cam.to_camera(&q), cam.to_camera(&w), r0, r1) {
        out.push(Prepared::new(&part));
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
    let (p, q, r0, r1) = parts.upper;
    out.extend(project_cone(
        camera,
        camera.to_camera(&p),
        camera.to_camera(&q),
        r0,
        r1,
    ));
    let (q, w, r0, r1) = parts.forearm;
    out.extend(project_cone(
        camera,
        camera.to_camera(&q),
        camera.to_camera(&w),
        r0,
        r1,
    ));
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
/// `V3` token, no `unsafe` in our code): the same IEEE operations in the same order as the
/// portable four-lane loop ([`sample_parts`]), so the same points pass, and the pixel index,
/// the read of G and `(1 − G)²` of four samples at a time.
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use pulp::{Simd, f32x4, f64x4, m64x4, x86::V3};

    use super::{Inside, LANES, Occluders, Projected, Run, occluders, part_boxes};

    /// Whether any lane of `m` is set.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn any(m: m64x4) -> bool {
        let a: [u64; LANES] = pulp::cast(m);
        (a[0] | a[1] | a[2] | a[3]) != 0
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
    }

    /// Accumulators and constants of the loop.
    struct Acc<'a> {
        simd: V3,
        data: &'a [f32],
        stride: f64x4,
        sum: f64x4,
        count: f64x4,
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
            let mut shapes = [Inside::Never; 3];
            for (sh, part) in shapes.iter_mut().zip(parts.iter()) {
                *sh = Inside::new(part);
            }
            let mut acc = Acc {
                simd: s,
                data: self.data,
                stride: s.splat_f64s(self.stride as f64),
                sum: s.splat_f64s(0.0),
                count: s.splat_f64s(0.0),
            };
            for (i, part) in parts.iter().enumerate() {
                let Some((occ, inside)) = occluders(parts.n, &boxes, &shapes, i, wf, hf) else {
                    continue;
                };
                let (runs, nr) = part.sample_runs(self.step);
                let (r, a) = (&runs[..nr], &mut acc);
                match (inside, occ.n) {
                    (true, 0) => runs_v3::<true, 0>(r, &occ, wf, hf, a),
                    (true, 1) => runs_v3::<true, 1>(r, &occ, wf, hf, a),
                    (true, _) => runs_v3::<true, 2>(r, &occ, wf, hf, a),
                    (false, 0) => runs_v3::<false, 0>(r, &occ, wf, hf, a),
                    (false, 1) => runs_v3::<false, 1>(r, &occ, wf, hf, a),
                    (false, _) => runs_v3::<false, 2>(r, &occ, wf, hf, a),
                }
            }
            let sum: [f64; LANES] = pulp::cast(acc.sum);
            let count: [f64; LANES] = pulp::cast(acc.count);
            (
                (sum[0] + sum[1]) + (sum[2] + sum[3]),
                ((count[0] + count[1]) + (count[2] + count[3])) as usize,
            )
        }
    }

    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn runs_v3<const INSIDE: bool, const NOCC: usize>(
        runs: &[Run],
        occ: &Occluders<'_>,
        wf: f64,
        hf: f64,
        acc: &mut Acc<'_>,
    ) {
        let s = acc.simd;
        let four = s.splat_f64s(LANES as f64);
        let all: m64x4 = pulp::cast([u64::MAX; LANES]);
        for run in runs {
            let (full, tail) = (run.len() / LANES, run.len() % LANES);
            let tail_ok: m64x4 =
                pulp::cast([0, 1, 2, 3].map(|l| if l < tail { u64::MAX } else { 0 }));
            match *run {
                Run::Line { p, s: st, .. } => {
                    let (px, py) = (s.splat_f64s(p.x), s.splat_f64s(p.y));
                    let (sx, sy) = (s.splat_f64s(st.x), s.splat_f64s(st.y));
                    let mut k = f64x4(0.0, 1.0, 2.0, 3.0);
                    for _ in 0..full {
                        let u = s.add_f64s(px, s.mul_f64s(k, sx));
                        let v = s.add_f64s(py, s.mul_f64s(k, sy));
                        chunk::<INSIDE, NOCC>(u, v, all, occ, wf, hf, acc);
                        k = s.add_f64s(k, four);
                    }
                    if tail > 0 {
                        let u = s.add_f64s(px, s.mul_f64s(k, sx));
                        let v = s.add_f64s(py, s.mul_f64s(k, sy));
                        chunk::<INSIDE, NOCC>(u, v, tail_ok, occ, wf, hf, acc);
                    }
                }
                Run::Arc {
                    c, rx, ry, cl, sl, ..
                } => {
                    let (cx, cy) = (s.splat_f64s(c.x), s.splat_f64s(c.y));
                    let (cl, sl) = (s.splat_f64s(cl), s.splat_f64s(sl));
                    let mut rx: f64x4 = pulp::cast(rx);
                    let mut ry: f64x4 = pulp::cast(ry);
                    for _ in 0..full {
                        chunk::<INSIDE, NOCC>(
                            s.add_f64s(cx, rx),
                            s.add_f64s(cy, ry),
                            all,
                            occ,
                            wf,
                            hf,
                            acc,
                        );
                        (rx, ry) = (
                            s.add_f64s(s.mul_f64s(cl, rx), s.mul_f64s(sl, ry)),
                            s.sub_f64s(s.mul_f64s(cl, ry), s.mul_f64s(sl, rx)),
                        );
                    }
                    if tail > 0 {
                        let (u, v) = (s.add_f64s(cx, rx), s.add_f64s(cy, ry));
                        chunk::<INSIDE, NOCC>(u, v, tail_ok, occ, wf, hf, acc);
                    }
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
                    let (cx, cy) = (s.splat_f64s(c.x), s.splat_f64s(c.y));
                    let (ux, uy) = (s.splat_f64s(u.x), s.splat_f64s(u.y));
                    let (wx, wy) = (s.splat_f64s(w.x), s.splat_f64s(w.y));
                    let (cl, sl) = (s.splat_f64s(cl), s.splat_f64s(sl));
                    let mut co: f64x4 = pulp::cast(co);
                    let mut si: f64x4 = pulp::cast(si);
                    for k in 0..full + usize::from(tail > 0) {
                        let x = s.add_f64s(s.add_f64s(cx, s.mul_f64s(ux, co)), s.mul_f64s(wx, si));
                        let y = s.add_f64s(s.add_f64s(cy, s.mul_f64s(uy, co)), s.mul_f64s(wy, si));
                        let ok = if k < full { all } else { tail_ok };
                        chunk::<INSIDE, NOCC>(x, y, ok, occ, wf, hf, acc);
                        (co, si) = (
                            s.sub_f64s(s.mul_f64s(co, cl), s.mul_f64s(si, sl)),
                            s.add_f64s(s.mul_f64s(si, cl), s.mul_f64s(co, sl)),
                        );
                    }
                }
            }
        }
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
        acc: &mut Acc<'_>,
    ) {
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
        acc.sum = s.add_f64s(acc.sum, s.select_f64s(ok, s.mul_f64s(e, e), zero));
        acc.count = s.add_f64s(acc.count, s.select_f64s(ok, s.splat_f64s(1.0), zero));
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
                        s.mul_f64s(s.abs_f64s(dot(rx, ry, n.x, n.y)), sp(cos_a)),
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
}

/// `Σ (1 − G(c))²` over the analytic contour samples `c` at their rounded pixels (`data`:
/// G row-major with `stride` values per row; the image is at least `width × height`) and
/// their number: the same points and values as `analytic_sum` with the nearest-pixel cost, with
/// AVX2 when the CPU has it (the lanes are summed separately: the sum differs by rounding).
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
        });
    }
    analytic_sum(parts, width, height, step, nearest_cost(data, stride))
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
        n: 0,
    };
    for k in 0..n.min(3) {
        if k != i && out.n < 2 && overlap(&bb, &boxes[k]) {
            out.shapes[out.n] = &shapes[k];
            out.boxes[out.n] = boxes[k];
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
