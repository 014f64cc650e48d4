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

    /// Whether `x` is more than [`INSIDE_TOL`] pixels inside the part (no square roots).
    // Measured: with plain `#[inline]` LLVM keeps this out of line once the sample loop has six
    // specialisations: +1.3k Ir per likelihood call and ~2 % slower (perf example).
    #[allow(clippy::inline_always)]
    #[inline(always)]
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

/// One run of analytic outline samples. [`Prepared::sample_runs`] yields, run after run, exactly
/// the points (same arithmetic, same order) of `walk_outline(step, false, …)`, but as plain data
/// that a caller can loop over without nested closures, so that its accumulators stay in
/// registers.
#[derive(Debug, Clone, Copy)]
enum Run {
    /// `n` points `c + v`, with `v` rotated clockwise by the angle of (co, s) after each point.
    Arc {
        c: Vector2<f64>,
        v: Vector2<f64>,
        co: f64,
        s: f64,
        n: usize,
    },
    /// `n` points `c + ea·(a·cos t) + eb·(b·sin t)`, t decreasing by the angle of (cd, sd).
    Ellipse {
        c: Vector2<f64>,
        a: f64,
        b: f64,
        ea: Vector2<f64>,
        eb: Vector2<f64>,
        cd: f64,
        sd: f64,
        n: usize,
    },
    /// `m` points `p + (q − p)·k/m`, k = 0 … m−1.
    Line {
        p: Vector2<f64>,
        q: Vector2<f64>,
        m: usize,
    },
}

impl Run {
    /// Calls `f` with every point of the run.
    // Measured: with plain `#[inline]` LLVM keeps this out of line and the analytic likelihood is
    // ~12 % slower (perf example, same run).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn for_each<F: FnMut(Vector2<f64>)>(self, mut f: F) {
        match self {
            Self::Arc { c, mut v, co, s, n } => {
                for _ in 0..n {
                    f(c + v);
                    v = Vector2::new(co * v.x + s * v.y, -s * v.x + co * v.y);
                }
            }
            Self::Ellipse {
                c,
                a,
                b,
                ea,
                eb,
                cd,
                sd,
                n,
            } => {
                let (mut co, mut s) = (1.0f64, 0.0f64);
                for _ in 0..n {
                    f(c + ea * (a * co) + eb * (b * s));
                    (co, s) = (co * cd + s * sd, s * cd - co * sd);
                }
            }
            Self::Line { p, q, m } => {
                // k as an f64 counter: exact (k < 2⁵³), so the same points as `k as f64`
                // without a u64 → f64 conversion per point.
                let (d, mf) = (q - p, m as f64);
                let mut kf = 0.0f64;
                for _ in 0..m {
                    f(p + d * (kf / mf));
                    kf += 1.0;
                }
            }
        }
    }
}

impl Prepared {
    /// The analytic samples every `step` pixels along the outline as at most four runs (see
    /// [`Run`]); returns the runs and their number.
    fn sample_runs(&self, step: f64) -> ([Run; 4], usize) {
        let arc_n = |r: f64, sweep: f64| ((r * sweep / step).ceil() as usize).clamp(1, 4096);
        let arc = |c: Vector2<f64>, r: f64, from: Vector2<f64>, sweep: f64| {
            let n = arc_n(r, sweep);
            let (s, co) = (sweep / n as f64).sin_cos();
            Run::Arc {
                c,
                v: from * r,
                co,
                s,
                n,
            }
        };
        let none = Run::Line {
            p: Vector2::zeros(),
            q: Vector2::zeros(),
            m: 0,
        };
        match *self {
            Self::Circle { c, r } => (
                [
                    arc(c, r, Vector2::x(), std::f64::consts::TAU),
                    none,
                    none,
                    none,
                ],
                1,
            ),
            Self::Ellipse { c, a, b, ea, eb } => {
                let n = arc_n(a, std::f64::consts::TAU);
                let (sd, cd) = (std::f64::consts::TAU / n as f64).sin_cos();
                (
                    [
                        Run::Ellipse {
                            c,
                            a,
                            b,
                            ea,
                            eb,
                            cd,
                            sd,
                            n,
                        },
                        none,
                        none,
                        none,
                    ],
                    1,
                )
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
                (
                    [
                        Run::Line {
                            p: c0 + np * r0,
                            q: c1 + np * r1,
                            m,
                        },
                        arc(c1, r1, np, half - 2.0 * alpha),
                        Run::Line {
                            p: c1 + nm * r1,
                            q: c0 + nm * r0,
                            m,
                        },
                        arc(c0, r0, nm, half + 2.0 * alpha),
                    ],
                    4,
                )
            }
        }
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
    let reach = axes.iter().map(nalgebra::Vector3::norm).fold(0.0, f64::max);
    if centre.z.is_nan() || centre.z - reach <= NEAR_PLANE {
        return None;
    }
    let c = cam.project_camera(&centre)?;
    if !finite_coords(&c) {
        return None;
    }
    let j = cam.project_camera_jacobian(&centre)?;
    // Shape matrix S = Σ_k (J a_k)(J a_k)ᵀ.
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
    let angle = 0.5 * (2.0 * s01).atan2(s00 - s11);
    (a.is_finite() && b.is_finite() && a < MAX_COORD).then_some(Part2::Ellipse {
        c: [c.x, c.y],
        a,
        b,
        angle,
    })
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
    if let Some(part) = project_ellipsoid(cam, cam.to_camera(&parts.hand_centre), &axes) {
        out.push(Prepared::new(&part));
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

/// The parts that may hide analytic samples of one part: those whose bounding box overlaps
/// the part's box (at most two), with their boxes. Unused slots hold an empty box, so the
/// per-sample test is two unrolled box tests without a loop or a count.
#[derive(Clone, Copy)]
struct Occluders<'a> {
    parts: [Option<&'a Prepared>; 2],
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

/// Analytic contour: calls `visit(u, v)` for points every `step` pixels along each part's
/// outline that are not more than half a pixel inside another part and whose rounded pixel is
/// inside the `width × height` image.
///
/// Per part, only the other parts whose bounding box overlaps this part's box can hide any of
/// its samples, and a sample is tested against such a part only when it lies in that part's box
/// (four comparisons), so most samples cost no inside test at all. A part whose box lies inside
/// the image skips the per-sample image test.
pub(crate) fn analytic_contour<F: FnMut(f64, f64)>(
    parts: &Projected,
    width: u32,
    height: u32,
    step: f64,
    mut visit: F,
) {
    let (wf, hf) = (f64::from(width) - 0.5, f64::from(height) - 0.5);
    let boxes = part_boxes(parts);
    for (i, part) in parts.iter().enumerate() {
        let Some((occ, inside)) = occluders(parts, &boxes, i, wf, hf) else {
            continue;
        };
        let (runs, nr) = part.sample_runs(step);
        for run in &runs[..nr] {
            run.for_each(|x| {
                if (inside || in_image(x, wf, hf)) && !occluded::<2>(x, &occ) {
                    visit(x.x, x.y);
                }
            });
        }
    }
}

/// Σ cost(u, v) and the number of analytic contour samples (the points of
/// [`analytic_contour`], in the same order), with one accumulator kept in a register: `cost`
/// has no mutable state, and the loops over [`Run`]s have no nested closures.
// Measured: with plain `#[inline]` LLVM keeps this out of line and the analytic likelihood is
// ~12 % slower (perf example, same run).
#[allow(clippy::inline_always)]
#[inline(always)]
pub(crate) fn analytic_sum<C: Fn(f64, f64) -> f64>(
    parts: &Projected,
    width: u32,
    height: u32,
    step: f64,
    cost: C,
) -> (f64, usize) {
    let (wf, hf) = (f64::from(width) - 0.5, f64::from(height) - 0.5);
    let boxes = part_boxes(parts);
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for (i, part) in parts.iter().enumerate() {
        let Some((occ, inside)) = occluders(parts, &boxes, i, wf, hf) else {
            continue;
        };
        let (runs, nr) = part.sample_runs(step);
        // Six copies of the sample loop: without and with the image test, for 0, 1 and 2
        // occluders.
        let (r, c, s, n) = (&runs[..nr], &cost, &mut sum, &mut count);
        match (inside, occ.n) {
            (true, 0) => sum_runs::<true, 0, C>(r, &occ, wf, hf, c, s, n),
            (true, 1) => sum_runs::<true, 1, C>(r, &occ, wf, hf, c, s, n),
            (true, _) => sum_runs::<true, 2, C>(r, &occ, wf, hf, c, s, n),
            (false, 0) => sum_runs::<false, 0, C>(r, &occ, wf, hf, c, s, n),
            (false, 1) => sum_runs::<false, 1, C>(r, &occ, wf, hf, c, s, n),
            (false, _) => sum_runs::<false, 2, C>(r, &occ, wf, hf, c, s, n),
        }
    }
    (sum, count)
}

/// The sample loop of [`analytic_sum`] for one part; `INSIDE`: the part's box is inside the
/// image, so the image test is left out. Adds to `sum` in sample order.
#[allow(clippy::inline_always)]
#[inline(always)]
fn sum_runs<const INSIDE: bool, const NOCC: usize, C: Fn(f64, f64) -> f64>(
    runs: &[Run],
    occ: &Occluders<'_>,
    wf: f64,
    hf: f64,
    cost: &C,
    sum: &mut f64,
    count: &mut usize,
) {
    let (mut s, mut n) = (*sum, *count);
    for run in runs {
        run.for_each(
            #[inline(always)]
            |x| {
                if (INSIDE || in_image(x, wf, hf)) && !occluded::<NOCC>(x, occ) {
                    s += cost(x.x, x.y);
                    n += 1;
                }
            },
        );
    }
    (*sum, *count) = (s, n);
}

/// Bounding boxes of the parts (unused slots zero).
fn part_boxes(parts: &Projected) -> [[f64; 4]; 3] {
    let mut boxes = [[0.0f64; 4]; 3];
    for (b, part) in boxes.iter_mut().zip(parts.iter()) {
        *b = part.bbox();
    }
    boxes
}

/// The occluders of part `i` and whether its box lies inside the image, or `None` when the
/// part is entirely outside the image.
fn occluders<'a>(
    parts: &'a Projected,
    boxes: &[[f64; 4]; 3],
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
        parts: [None; 2],
        boxes: [EMPTY_BOX; 2],
        n: 0,
    };
    for (k, other) in parts.iter().enumerate() {
        if k != i && out.n < 2 && overlap(&bb, &boxes[k]) {
            out.parts[out.n] = Some(other);
            out.boxes[out.n] = boxes[k];
            out.n += 1;
        }
    }
    Some((out, inside))
}

/// Whether the rounded pixel of an analytic sample is in the image.
#[allow(clippy::inline_always)]
#[inline(always)]
fn in_image(x: Vector2<f64>, wf: f64, hf: f64) -> bool {
    x.x >= -0.5 && x.y >= -0.5 && x.x < wf && x.y < hf
}

/// Whether an analytic sample is deep inside one of the first `NOCC` occluders (tested only
/// when it lies in the occluder's box).
// Measured: with plain `#[inline]` LLVM keeps this out of line and the analytic likelihood is
// ~12 % slower (perf example, same run).
#[allow(clippy::inline_always)]
#[inline(always)]
fn occluded<const NOCC: usize>(x: Vector2<f64>, occ: &Occluders<'_>) -> bool {
    for (other, ob) in occ.parts.iter().zip(&occ.boxes).take(NOCC) {
        if x.x >= ob[0]
            && x.x <= ob[2]
            && x.y >= ob[1]
            && x.y <= ob[3]
            && let Some(other) = other
            && other.deep_inside(x)
        {
            return true;
        }
    }
    false
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
        // The runs of the likelihood's sampler give exactly (bit for bit, same order) the
        // points of the reference outline walk, for every part kind and several spacings.
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
                assert_eq!(walk, runs);
            }
        }
    }

    #[test]
    fn analytic_sum_visits_the_contour_points_in_order() {
        // The specialised loops of `analytic_sum` (part inside / cut by the image border, 0–2
        // occluders) give exactly the points of `analytic_contour`, in the same order, so the
        // sums agree bit for bit. Cameras of several sizes cut parts at the border.
        let g = ArmGeometry::default();
        let mut occluder_counts = [0usize; 3];
        let mut cut = 0;
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
                let (wf, hf) = (f64::from(w) - 0.5, f64::from(h) - 0.5);
                for i in 0..parts.n {
                    if let Some((occ, inside)) = occluders(&parts, &boxes, i, wf, hf) {
                        occluder_counts[occ.n] += 1;
                        cut += usize::from(!inside);
                    }
                }
                let cost = |u: f64, v: f64| (u * 0.37 + v * 1.3).sin();
                let (mut sum, mut count) = (0.0, 0usize);
                analytic_contour(&parts, w, h, 2.0, |u, v| {
                    sum += cost(u, v);
                    count += 1;
                });
                let (s2, n2) = analytic_sum(&parts, w, h, 2.0, cost);
                assert_eq!(
                    (sum.to_bits(), count),
                    (s2.to_bits(), n2),
                    "{w}×{h} {pose:?}"
                );
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
        for i in 0..apart.n {
            let (occ, inside) = occluders(&apart, &boxes, i, 639.5, 479.5).unwrap();
            occluder_counts[occ.n] += 1;
            cut += usize::from(!inside);
        }
        let cost = |u: f64, v: f64| (u * 0.37 + v * 1.3).sin();
        let (mut sum, mut count) = (0.0, 0usize);
        analytic_contour(&apart, 640, 480, 2.0, |u, v| {
            sum += cost(u, v);
            count += 1;
        });
        let (s2, n2) = analytic_sum(&apart, 640, 480, 2.0, cost);
        assert_eq!((sum.to_bits(), count), (s2.to_bits(), n2));
        assert!(count > 100);
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
