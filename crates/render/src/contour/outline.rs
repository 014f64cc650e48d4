//! The 2-D parts with their precomputed outline: the signed distance and inside tests, the
//! outline walk, and the runs of samples (lines, arcs) the analytic sampler generates.

use nalgebra::Vector2;

#[cfg(test)]
use super::INSIDE_TOL;
use super::{Part2, SAGITTA};

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
    pub(super) fn deep_inside(&self, x: Vector2<f64>) -> bool {
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

    /// Signed distance, negative inside: exact for discs and capsules; for an ellipse
    /// b·(ρ − 1), with ρ the ellipse's radial coordinate (exact along the b axis, a/b as far
    /// along the a axis).
    pub(super) fn signed_distance(&self, x: Vector2<f64>) -> f64 {
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
                let (s, t) = (rel.dot(&d), rel.dot(&n).abs());
                // The outline's straight side touches each disc where the disc's normal
                // (sin α, cos α) in (axis, across) coordinates does; the nearest point is on a
                // cap behind the normal through its centre and on the side between them.
                if s * cos_a < t * sin_a {
                    rel.norm() - r0
                } else if (s - len) * cos_a > t * sin_a {
                    (x - c1).norm() - r1
                } else {
                    s * sin_a + t * cos_a - r0
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

    /// A bound on how fast [`Self::signed_distance`] changes: |sd(x) − sd(y)| ≤ L·|x − y|. The
    /// exact distances of discs and capsules have L = 1; the ellipse's b·(ρ − 1) has
    /// L = b / min(a, b).
    pub(super) fn lipschitz(&self) -> f64 {
        match *self {
            Self::Circle { .. } | Self::Capsule { .. } => 1.0,
            Self::Ellipse { a, b, .. } => (b / a.min(b)).max(1.0),
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
    pub(super) fn walk_outline<F: FnMut(Vector2<f64>)>(&self, step: f64, polygon: bool, mut f: F) {
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
pub(super) const LANES: usize = 4;
/// One value per lane.
pub(super) type Lanes = [f64; LANES];
/// The sample index of each lane in the first chunk of a run.
pub(super) const LANE_INDEX: Lanes = [0.0, 1.0, 2.0, 3.0];

/// `f(l)` for every lane `l`.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn lanes<T: Copy + Default, F: Fn(usize) -> T>(f: F) -> [T; LANES] {
    let mut out = [T::default(); LANES];
    for (l, o) in out.iter_mut().enumerate() {
        *o = f(l);
    }
    out
}

/// `(sin θ, cos θ)`; for |θ| ≤ ½ (the arcs of every part wider than a few pixels) by the
/// Taylor polynomials to θ¹³ / θ¹⁴ (truncation < 1e-16), otherwise by libm.
pub(super) fn sin_cos(theta: f64) -> (f64, f64) {
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
pub(super) enum Run {
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
    pub(super) fn line(p: Vector2<f64>, q: Vector2<f64>, m: usize) -> Self {
        Self::Line {
            p,
            s: (q - p) / m as f64,
            n: m,
        }
    }

    /// The `n` points `c + u·cos kθ + w·sin kθ`, k = 0 … n−1.
    pub(super) fn trig(
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
    ) -> Self {
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
    pub(super) fn circle(
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
    ) -> Self {
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
    pub(super) fn for_each_chunk<F: FnMut(Lanes, Lanes, [bool; LANES])>(self, mut f: F) {
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
    pub(super) fn len(&self) -> usize {
        match *self {
            Self::Line { n, .. } | Self::Arc { n, .. } | Self::Trig { n, .. } => n,
        }
    }

    /// Calls `f` with every point of the run, in order.
    #[cfg(test)]
    pub(super) fn for_each<F: FnMut(Vector2<f64>)>(self, mut f: F) {
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
/// geometry of the samples, shared by the CPU sampler ([`Run`]) and the GPU port (`gpu/pieces.rs`), so
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
pub(super) struct RunSink {
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
    pub(super) fn sample_runs(&self, step: f64) -> ([Run; 4], usize) {
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
