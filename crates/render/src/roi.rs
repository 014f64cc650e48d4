//! Regions of interest: the part of an image that a set of arm poses can project into, and the
//! crop and paste that let the edge image be computed there only.
//!
//! The likelihood reads the edge image G at the contour points of the poses it scores, and
//! nowhere else; the contour of a pose lies inside the projection of its arm. [`arm_bounds`]
//! bounds that projection for a whole particle set, so that a caller can compute G on
//! [`crop`]ped pixels (with the halo its filters need) and [`paste`] it into a frame-sized image
//! whose other pixels are 0.

use nalgebra::Vector3;

use crate::{ArmGeometry, Camera, EdgeImage, ImageView, NEAR_PLANE, RenderError};

/// The pixels `[x0, x1) × [y0, y1)` of an image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PixelRect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl PixelRect {
    /// Every pixel of a `width`×`height` image.
    pub fn full(width: u32, height: u32) -> Self {
        Self {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    /// Columns.
    pub fn width(&self) -> u32 {
        self.x1.saturating_sub(self.x0)
    }

    /// Rows.
    pub fn height(&self) -> u32 {
        self.y1.saturating_sub(self.y0)
    }

    /// Whether the rectangle holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.width() == 0 || self.height() == 0
    }

    /// Pixels.
    pub fn area(&self) -> u64 {
        u64::from(self.width()) * u64::from(self.height())
    }

    /// The rectangle grown by `by` pixels on every side and clipped to a `width`×`height`
    /// image (an empty rectangle stays empty).
    #[must_use]
    pub fn grown(&self, by: u32, width: u32, height: u32) -> Self {
        if self.is_empty() {
            return Self::default();
        }
        Self {
            x0: self.x0.saturating_sub(by),
            y0: self.y0.saturating_sub(by),
            x1: self.x1.saturating_add(by).min(width),
            y1: self.y1.saturating_add(by).min(height),
        }
    }

    /// The smallest rectangle that holds both (an empty one adds nothing).
    #[must_use]
    pub fn union(&self, other: &Self) -> Self {
        match (self.is_empty(), other.is_empty()) {
            (true, true) => Self::default(),
            (true, false) => *other,
            (false, true) => *self,
            (false, false) => Self {
                x0: self.x0.min(other.x0),
                y0: self.y0.min(other.y0),
                x1: self.x1.max(other.x1),
                y1: self.y1.max(other.y1),
            },
        }
    }

    /// Whether `other` lies inside this rectangle.
    pub fn contains(&self, other: &Self) -> bool {
        other.is_empty()
            || (self.x0 <= other.x0
                && self.y0 <= other.y0
                && other.x1 <= self.x1
                && other.y1 <= self.y1)
    }
}

/// Points sampled along each side of the normalised rectangle to bound its distorted image.
const SIDE_SAMPLES: usize = 16;

/// A rectangle of pixels that holds the projection of every finite pose's arm (the cones and
/// the hand of `geometry` around p, q and r; world frame) in `camera`'s image, grown by
/// `margin` pixels and clipped to the image. Poses that are not finite are skipped (they are
/// not rendered); with none left the rectangle is empty. When a pose comes within the arm's
/// largest radius of the camera's near plane the whole image is returned.
///
/// The bound is conservative: every point of an arm lies within ρ, the largest cone radius or
/// cross half-axis of the hand, of the convex hull of p, q, r and the two ends c ± a₀e₀ of the
/// hand ellipsoid's long axis (a point of the ellipsoid lies within its largest cross
/// half-axis of that axis; the cones lie within their radii of p–q and q–r). Perspective maps
/// the hull into the convex hull of the projected vertices, and a ball of radius ρ at depth
/// z ≥ z_min, seen at most tan α off the axis, projects within
/// ρ(1 + tan²α) / (√(z_min² − ρ²) − ρ tan α) of its centre (normalised units). With lens
/// distortion the normalised rectangle's sides are sampled and distorted, which bounds it for
/// the monotonic distortions of calibrated lenses.
pub fn arm_bounds(
    camera: &Camera,
    geometry: &ArmGeometry,
    poses: &[[f64; 9]],
    margin: f64,
) -> PixelRect {
    let full = PixelRect::full(camera.width, camera.height);
    let rho = geometry
        .upper_radii
        .iter()
        .chain(&geometry.forearm_radii)
        .chain(&geometry.hand_half_axes[1..])
        .fold(0.0f64, |a, &b| a.max(b));
    let rot = camera.rotation_matrix();
    let t = camera.translation_vector();
    let (mut xa, mut xb, mut ya, mut yb) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut z_min = f64::MAX;
    let mut any = false;
    for pose in poses {
        let Some(parts) = geometry.parts(pose) else {
            continue;
        };
        let (c, a) = (parts.hand_centre, parts.hand_axes[0]);
        let joints = [0, 1, 2].map(|j| Vector3::new(pose[3 * j], pose[3 * j + 1], pose[3 * j + 2]));
        for x in joints.into_iter().chain([c - a, c + a]) {
            let c = rot * x + t;
            if c.z <= NEAR_PLANE + rho {
                return full;
            }
            let (x, y) = (c.x / c.z, c.y / c.z);
            xa = xa.min(x);
            xb = xb.max(x);
            ya = ya.min(y);
            yb = yb.max(y);
            z_min = z_min.min(c.z);
            any = true;
        }
    }
    if !any {
        return PixelRect::default();
    }
    let tan_a = xa.abs().max(xb.abs()).hypot(ya.abs().max(yb.abs()));
    let denom = (z_min * z_min - rho * rho).sqrt() - rho * tan_a;
    if !(denom > 0.0 && tan_a.is_finite()) {
        return full;
    }
    let d = rho * (1.0 + tan_a * tan_a) / denom;
    let (xa, xb, ya, yb) = (xa - d, xb + d, ya - d, yb + d);
    // Pixel bounds of the normalised rectangle's image.
    let (mut ua, mut ub, mut va, mut vb) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut add = |x: f64, y: f64| {
        let (xd, yd) = camera.distort(x, y);
        let (u, v) = (camera.fx * xd + camera.cx, camera.fy * yd + camera.cy);
        ua = ua.min(u);
        ub = ub.max(u);
        va = va.min(v);
        vb = vb.max(v);
    };
    if camera.distortion.iter().all(|&k| k == 0.0) {
        add(xa, ya);
        add(xb, yb);
    } else {
        for i in 0..=SIDE_SAMPLES {
            let s = i as f64 / SIDE_SAMPLES as f64;
            let (x, y) = (xa + s * (xb - xa), ya + s * (yb - ya));
            add(x, ya);
            add(x, yb);
            add(xa, y);
            add(xb, y);
        }
    }
    let (ua, ub, va, vb) = (ua - margin, ub + margin, va - margin, vb + margin);
    if ![ua, ub, va, vb].iter().all(|v| v.is_finite()) {
        return full;
    }
    let clip = |v: f64, hi: u32| v.clamp(0.0, f64::from(hi)) as u32;
    let rect = PixelRect {
        x0: clip(ua.floor(), camera.width),
        y0: clip(va.floor(), camera.height),
        x1: clip(ub.ceil() + 1.0, camera.width),
        y1: clip(vb.ceil() + 1.0, camera.height),
    };
    if rect.is_empty() {
        PixelRect::default()
    } else {
        rect
    }
}

/// The buffer of [`crop`] (reused across frames).
#[derive(Debug, Default)]
pub struct CropBuf {
    bytes: Vec<u8>,
    floats: Vec<f32>,
}

/// The pixels of `rect` of `view`, copied into `buf` as an image of their own.
///
/// # Errors
/// [`RenderError::InvalidImage`] when `rect` is empty or does not lie inside the image.
pub fn crop<'b>(
    view: ImageView<'_>,
    rect: PixelRect,
    buf: &'b mut CropBuf,
) -> Result<ImageView<'b>, RenderError> {
    view.validate()?;
    let (w, h) = view.size();
    if rect.is_empty() || !PixelRect::full(w, h).contains(&rect) {
        return Err(RenderError::InvalidImage(format!(
            "cannot crop [{}, {}) × [{}, {}) from a {w}×{h} image",
            rect.x0, rect.x1, rect.y0, rect.y1
        )));
    }
    let (x0, x1, w) = (rect.x0 as usize, rect.x1 as usize, w as usize);
    let rows = rect.y0 as usize..rect.y1 as usize;
    match view {
        ImageView::Rgb8 { data, .. } | ImageView::Grey8 { data, .. } => {
            let c = if matches!(view, ImageView::Rgb8 { .. }) {
                3
            } else {
                1
            };
            buf.bytes.clear();
            for y in rows {
                buf.bytes
                    .extend_from_slice(&data[(y * w + x0) * c..(y * w + x1) * c]);
            }
            if c == 3 {
                ImageView::rgb8(&buf.bytes, rect.width(), rect.height())
            } else {
                ImageView::grey8(&buf.bytes, rect.width(), rect.height())
            }
        }
        ImageView::GreyF32 { data, .. } => {
            buf.floats.clear();
            for y in rows {
                buf.floats.extend_from_slice(&data[y * w + x0..y * w + x1]);
            }
            ImageView::grey_f32(&buf.floats, rect.width(), rect.height())
        }
    }
}

/// Writes the pixels of `part` (an edge image of the crop `from`) that fall in `keep` into
/// `out`, a `width`×`height` image, and sets every other pixel of `out` to 0. `clear` is the
/// rectangle `out` may hold non-zero pixels in (what the last paste kept; the whole image when
/// unknown): only it is cleared, so a frame costs the rectangles' area, not the image's.
///
/// # Errors
/// [`RenderError::InvalidImage`] when `part` is not `from`'s size, `from` or `clear` does not
/// lie in the image or `keep` does not lie in `from`.
pub fn paste(
    part: &EdgeImage,
    from: PixelRect,
    keep: PixelRect,
    clear: PixelRect,
    (width, height): (u32, u32),
    out: &mut EdgeImage,
) -> Result<(), RenderError> {
    let full = PixelRect::full(width, height);
    if (part.width(), part.height()) != (from.width(), from.height())
        || !full.contains(&from)
        || !full.contains(&clear)
        || !from.contains(&keep)
    {
        return Err(RenderError::InvalidImage(format!(
            "cannot paste a {}×{} edge image of [{}, {}) × [{}, {}) into {width}×{height}",
            part.width(),
            part.height(),
            from.x0,
            from.x1,
            from.y0,
            from.y1
        )));
    }
    let w = width as usize;
    let mut data = if (out.width(), out.height()) == (width, height) {
        let mut d = std::mem::take(out).into_data();
        // The pixels of `clear` that `keep` does not overwrite below.
        for y in clear.y0..clear.y1 {
            let row = &mut d[y as usize * w..(y as usize + 1) * w];
            if (keep.y0..keep.y1).contains(&y) && !keep.is_empty() {
                row[clear.x0 as usize..clear.x1.min(keep.x0).max(clear.x0) as usize].fill(0.0);
                row[clear.x0.max(keep.x1).min(clear.x1) as usize..clear.x1 as usize].fill(0.0);
            } else {
                row[clear.x0 as usize..clear.x1 as usize].fill(0.0);
            }
        }
        d
    } else {
        vec![0.0; w * height as usize]
    };
    let (pw, src) = (from.width() as usize, part.data());
    for y in keep.y0..keep.y1 {
        let (sy, y) = ((y - from.y0) as usize, y as usize);
        let sx = (keep.x0 - from.x0) as usize;
        let n = keep.width() as usize;
        data[y * w + keep.x0 as usize..y * w + keep.x0 as usize + n]
            .copy_from_slice(&src[sy * pw + sx..sy * pw + sx + n]);
    }
    *out = EdgeImage::from_vec(width, height, data)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::project_parts;

    fn camera(distortion: [f64; 5]) -> Camera {
        let mut c = Camera::look_at(
            Vector3::new(0.3, -1.6, 1.5),
            Vector3::new(0.0, 0.3, 0.9),
            Vector3::z(),
            640,
            480,
            60f64.to_radians(),
        )
        .unwrap();
        c.distortion = distortion;
        c
    }

    /// Poses around a reach, some far to the side.
    fn poses() -> Vec<[f64; 9]> {
        let mut out = Vec::new();
        for i in 0..50 {
            let s = f64::from(i) / 49.0;
            out.push([
                0.0,
                0.0,
                1.2,
                0.1 - 0.2 * s,
                0.15,
                0.95,
                0.3 * s - 0.1,
                0.45 + 0.1 * s,
                0.85 + 0.2 * s,
            ]);
        }
        out
    }

    #[test]
    fn arm_bounds_hold_every_projected_part() {
        let geom = ArmGeometry::default();
        for dist in [[0.0; 5], [-0.25, 0.08, 0.001, -0.001, 0.0]] {
            let cam = camera(dist);
            let ps = poses();
            let rect = arm_bounds(&cam, &geom, &ps, 0.0);
            assert!(!rect.is_empty() && rect.area() < PixelRect::full(640, 480).area());
            // Brute force: points on the outline of every 3-D part, densely sampled.
            let mut tight = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
            for p in &ps {
                let parts = geom.parts(p).unwrap();
                let seg = |a: Vector3<f64>, b: Vector3<f64>, ra: f64, rb: f64| {
                    (0..=20).flat_map(move |i| {
                        let s = f64::from(i) / 20.0;
                        let c = a + s * (b - a);
                        let r = ra + s * (rb - ra);
                        (0..64).flat_map(move |k| {
                            (0..32).map(move |l| {
                                let (th, ph) = (
                                    f64::from(k) * std::f64::consts::TAU / 64.0,
                                    f64::from(l) * std::f64::consts::PI / 31.0,
                                );
                                c + r * Vector3::new(
                                    th.cos() * ph.sin(),
                                    th.sin() * ph.sin(),
                                    ph.cos(),
                                )
                            })
                        })
                    })
                };
                let (p0, q0, a, b) = parts.upper;
                let (q1, w1, c, d) = parts.forearm;
                let hand = (0..64).flat_map(|k| {
                    (0..32).map(move |l| {
                        let (th, ph) = (
                            f64::from(k) * std::f64::consts::TAU / 64.0,
                            f64::from(l) * std::f64::consts::PI / 31.0,
                        );
                        let [e0, e1, e2] = parts.hand_axes;
                        parts.hand_centre
                            + th.cos() * ph.sin() * e0
                            + th.sin() * ph.sin() * e1
                            + ph.cos() * e2
                    })
                });
                for x in seg(p0, q0, a, b).chain(seg(q1, w1, c, d)).chain(hand) {
                    let uv = cam.project(&x).unwrap();
                    tight.0 = tight.0.min(uv.x);
                    tight.1 = tight.1.max(uv.x);
                    tight.2 = tight.2.min(uv.y);
                    tight.3 = tight.3.max(uv.y);
                }
                assert!(!project_parts(&cam, &geom, p).is_empty());
            }
            let (x0, x1, y0, y1) = tight;
            assert!(
                f64::from(rect.x0) <= x0.max(0.0).floor(),
                "{rect:?} {tight:?}"
            );
            assert!(
                f64::from(rect.y0) <= y0.max(0.0).floor(),
                "{rect:?} {tight:?}"
            );
            assert!(
                f64::from(rect.x1) >= (x1.ceil() + 1.0).min(640.0),
                "{rect:?} {tight:?}"
            );
            assert!(
                f64::from(rect.y1) >= (y1.ceil() + 1.0).min(480.0),
                "{rect:?} {tight:?}"
            );
            // Not much looser than the tight box (a few tens of pixels).
            assert!(
                f64::from(rect.width()) < (x1 - x0) + 80.0,
                "{rect:?} {tight:?}"
            );
            assert!(
                f64::from(rect.height()) < (y1 - y0) + 80.0,
                "{rect:?} {tight:?}"
            );
        }
    }

    #[test]
    fn arm_bounds_of_nothing_is_empty_and_near_the_camera_is_everything() {
        let (cam, geom) = (camera([0.0; 5]), ArmGeometry::default());
        assert!(arm_bounds(&cam, &geom, &[], 0.0).is_empty());
        assert!(arm_bounds(&cam, &geom, &[[f64::NAN; 9]], 0.0).is_empty());
        let eye = cam.center();
        let mut near = poses()[0];
        near[..3].copy_from_slice(eye.as_slice());
        assert_eq!(
            arm_bounds(&cam, &geom, &[near], 0.0),
            PixelRect::full(640, 480)
        );
    }

    #[test]
    fn crop_and_paste_round_trip() {
        let data: Vec<u8> = (0..5 * 4 * 3).map(|v| v as u8).collect();
        let view = ImageView::rgb8(&data, 5, 4).unwrap();
        let rect = PixelRect {
            x0: 1,
            y0: 1,
            x1: 4,
            y1: 3,
        };
        let mut buf = CropBuf::default();
        let ImageView::Rgb8 { data: got, .. } = crop(view, rect, &mut buf).unwrap() else {
            panic!("not RGB");
        };
        let want: Vec<u8> = (1..3)
            .flat_map(|y| {
                (1..4).flat_map(move |x| (0..3).map(move |c| (3 * (y * 5 + x) + c) as u8))
            })
            .collect();
        assert_eq!(got, &want[..]);
        assert!(crop(view, PixelRect::full(6, 4), &mut buf).is_err());
        assert!(crop(view, PixelRect::default(), &mut buf).is_err());
        // Paste a 3×2 part, keeping its middle column, into an image full of 7s.
        let part = EdgeImage::from_vec(3, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let mut out = EdgeImage::constant(5, 4, 7.0).unwrap();
        let keep = PixelRect {
            x0: 2,
            y0: 1,
            x1: 3,
            y1: 3,
        };
        paste(&part, rect, keep, PixelRect::full(5, 4), (5, 4), &mut out).unwrap();
        let mut want = [0.0; 20];
        want[5 + 2] = 2.0;
        want[10 + 2] = 5.0;
        assert_eq!(out.data(), &want[..]);
        assert!(paste(&part, rect, PixelRect::full(5, 4), rect, (5, 4), &mut out).is_err());
        // Every placement of the cleared rectangle against the kept one: the cleared pixels are
        // 0 unless kept, the kept ones the part's, the rest untouched.
        let r = |x0, y0, x1, y1| PixelRect { x0, y0, x1, y1 };
        let from = r(1, 1, 5, 4);
        let part = EdgeImage::from_vec(4, 3, (1..=12).map(|v| v as f32).collect()).unwrap();
        for keep in [r(1, 1, 5, 4), r(2, 1, 4, 3), r(3, 2, 4, 3)] {
            for clear in [
                r(0, 0, 6, 5),
                r(0, 0, 3, 2),
                r(4, 3, 6, 5),
                r(2, 0, 3, 5),
                r(0, 0, 0, 0),
            ] {
                let mut out = EdgeImage::constant(6, 5, 7.0).unwrap();
                paste(&part, from, keep, clear, (6, 5), &mut out).unwrap();
                for y in 0..5u32 {
                    for x in 0..6u32 {
                        let inside =
                            |q: PixelRect| (q.x0..q.x1).contains(&x) && (q.y0..q.y1).contains(&y);
                        let want = if inside(keep) {
                            ((y - 1) * 4 + (x - 1) + 1) as f32
                        } else if inside(clear) {
                            0.0
                        } else {
                            7.0
                        };
                        let got = out.data()[(y * 6 + x) as usize];
                        assert_eq!(
                            got.to_bits(),
                            want.to_bits(),
                            "({x}, {y}) keep {keep:?} clear {clear:?}"
                        );
                    }
                }
            }
        }
    }
}
