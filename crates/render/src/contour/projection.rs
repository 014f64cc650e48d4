//! Projection of the arm into 2-D parts (pinhole + Brown, capsules and an ellipse) and the
//! coverage of parts on a mask.

use nalgebra::{Vector2, Vector3};
use tiny_skia::{Mask, PathBuilder};

use super::{MAX_COORD, Part2, Prepared};
use crate::{ArmGeometry, Camera, PixelRect, RenderError, camera::NEAR_PLANE};

/// Per-thread scratch for rasterising silhouettes: a mask that only grows, and a reusable path
/// builder. Reusing one per thread means no allocation per particle in our code (tiny-skia
/// itself still allocates a small edge list per fill).
#[derive(Default)]
pub struct RenderScratch {
    pub(super) mask: Option<Mask>,
    pub(super) builder: Option<PathBuilder>,
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
    pub(super) parts: [Option<Prepared>; 3],
    pub(super) n: usize,
}

impl Projected {
    pub(super) fn push(&mut self, p: Prepared) {
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

pub(super) fn finite_coords(v: &Vector2<f64>) -> bool {
    v.x.abs() < MAX_COORD && v.y.abs() < MAX_COORD
}

/// A camera-frame point and its projection ([`Camera::project_camera`]).
pub(super) type Projection = (Vector3<f64>, Option<Vector2<f64>>);

/// `p` in the camera frame and projected.
#[allow(clippy::inline_always)] // Outlined, the calls and by-value copies cost ~100 Ir per pose.
#[inline(always)]
pub(super) fn projection(cam: &Camera, p: &Vector3<f64>) -> Projection {
    let c = cam.to_camera(p);
    (c, cam.project_camera(&c))
}

/// A truncated cone from a to b (camera frame, with their projections) clipped to the near
/// plane, as a 2-D capsule.
#[allow(clippy::inline_always)] // Outlined, the calls and by-value copies cost ~100 Ir per pose.
#[inline(always)]
pub(super) fn project_cone(
    cam: &Camera,
    a: Projection,
    b: Projection,
    ra: f64,
    rb: f64,
) -> Option<Part2> {
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
pub(super) fn project_ellipsoid(
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
pub(super) fn project_ellipsoid_prepared(
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
pub(super) fn ellipse_shape(
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
pub(super) fn project_cones(cam: &Camera, parts: &crate::arm::ArmParts) -> [Option<Part2>; 2] {
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
/// capsules; an ellipse's inside is exact and its growth is `grow` along its b axis and a/b
/// times that along its a axis, within its bounding box grown by `grow`). Other pixels are
/// left as they are. A non-finite part or `grow` covers nothing. Returns the smallest
/// rectangle that holds every pixel it set (empty when it set none), so that a caller can clear
/// just that.
///
/// # Errors
/// [`RenderError::InvalidImage`] if `mask` does not hold `width · height` values.
pub fn cover_parts(
    parts: &[Part2],
    grow: f64,
    width: u32,
    height: u32,
    mask: &mut [u8],
) -> Result<PixelRect, RenderError> {
    let (w, h) = (width as usize, height as usize);
    if mask.len() != w * h {
        return Err(RenderError::InvalidImage(format!(
            "cover_parts: a {width}×{height} mask needs {} values, got {}",
            w * h,
            mask.len()
        )));
    }
    let mut set = PixelRect::default();
    if !grow.is_finite() {
        return Ok(set);
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
        // A part grown by `grow` is convex, so it covers one run of every row: found from
        // both ends, then filled. Each end is found by stepping over pixels that cannot be
        // inside: the signed distance changes by at most L per pixel, so from a pixel `e` outside
        // (e = sd − grow > 0) the next e / L pixels are outside too (shortened by a relative
        // 1e-9 against rounding).
        let lip = p.lipschitz();
        let excess =
            |u: usize, v: usize| p.signed_distance(Vector2::new(u as f64, v as f64)) - grow;
        let skip = |e: f64| (e / lip * (1.0 - 1e-9)).ceil().max(1.0) as usize;
        let (u0, u1) = (lo(b[0]), u1 as usize);
        // The runs of the last two rows. The part and its bounding box are convex, so a run's
        // first pixel is a convex function of the row and its last a concave one, up to the
        // rounding to pixels (1 px each): a row's run starts at or after 2a₁ − a₂ − 2 and ends
        // at or before 2z₁ − z₂ + 2, where the searches begin.
        let mut last: [Option<(usize, usize)>; 2] = [None, None];
        for v in lo(b[1])..=v1 as usize {
            let row = &mut mask[v * w..(v + 1) * w];
            let (from, to) = match last {
                [Some((a1, z1)), Some((a2, z2))] => (
                    (2 * a1).saturating_sub(a2 + 2).max(u0),
                    (2 * z1 + 2).saturating_sub(z2).min(u1),
                ),
                _ => (u0, u1),
            };
            let mut a = from;
            while a <= u1 {
                let e = excess(a, v);
                if e <= 0.0 {
                    break;
                }
                a = a.saturating_add(skip(e));
            }
            if a > u1 {
                last = [None, None];
                continue;
            }
            let mut z = to.max(a);
            while z > a {
                let e = excess(z, v);
                if e <= 0.0 {
                    break;
                }
                z = z.saturating_sub(skip(e)).max(a);
            }
            row[a..=z].fill(1);
            last = [Some((a, z)), last[0]];
            #[allow(clippy::cast_possible_truncation)] // within the image's u32 size
            let run = PixelRect {
                x0: a as u32,
                y0: v as u32,
                x1: z as u32 + 1,
                y1: v as u32 + 1,
            };
            set = set.union(&run);
        }
    }
    Ok(set)
}
