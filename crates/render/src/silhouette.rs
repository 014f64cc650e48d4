//! How much of a binary foreground mask a pose's union silhouette covers, row by row: each
//! part is convex, so it cuts a pixel row in one interval; the intervals of a row are merged and
//! the foreground under them is read from per-row prefix counts. The cost is proportional to the
//! silhouette's height, not its area.

use nalgebra::Vector2;

use crate::RenderError;
use crate::contour::{Part2, Prepared};

/// The most parts [`ForegroundCounts::overlap`] takes (the arm has three).
pub const MAX_SILHOUETTE_PARTS: usize = 8;

/// Pixels of a silhouette, and how many of them are foreground.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Overlap {
    /// Pixels (centres at integer coordinates) inside the union of the parts, in the image.
    pub area: u64,
    /// Of those, the pixels marked foreground.
    pub foreground: u64,
}

/// Row-wise prefix counts of a binary foreground mask (built once per frame and view, then
/// read by every particle).
#[derive(Clone, Debug, Default)]
pub struct ForegroundCounts {
    width: usize,
    height: usize,
    /// `height` rows of `width + 1` running counts, each row starting at 0.
    prefix: Vec<u32>,
    total: u64,
}

impl ForegroundCounts {
    /// Counts the pixels of `mask` (row-major, `width × height`) for which `is_foreground`
    /// holds. The buffers are reused.
    ///
    /// # Errors
    /// [`RenderError::InvalidImage`] if the mask does not have `width × height` values.
    pub fn set<T: Copy>(
        &mut self,
        mask: &[T],
        width: u32,
        height: u32,
        is_foreground: impl Fn(T) -> bool,
    ) -> Result<(), RenderError> {
        let (w, h) = (width as usize, height as usize);
        if mask.len() != w * h {
            return Err(RenderError::InvalidImage(format!(
                "foreground counts: a {width}×{height} mask needs {} values, got {}",
                w * h,
                mask.len()
            )));
        }
        self.width = w;
        self.height = h;
        self.prefix.clear();
        self.prefix.reserve((w + 1) * h);
        let mut total = 0u64;
        for row in mask.chunks_exact(w.max(1)).take(h) {
            let mut run = 0u32;
            self.prefix.push(0);
            for &x in row {
                run += u32::from(is_foreground(x));
                self.prefix.push(run);
            }
            total += u64::from(run);
        }
        self.total = total;
        Ok(())
    }

    /// Foreground pixels in the whole mask.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The mask's size (width, height).
    #[must_use]
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The union silhouette of `parts` (pixel centres with signed distance ≤ 0 to some part,
    /// inside the mask) and the foreground under it. Non-finite parts cover nothing.
    ///
    /// # Errors
    /// [`RenderError::InvalidParameter`] for more than [`MAX_SILHOUETTE_PARTS`] parts.
    pub fn overlap(&self, parts: &[Part2]) -> Result<Overlap, RenderError> {
        if parts.len() > MAX_SILHOUETTE_PARTS {
            return Err(RenderError::InvalidParameter(format!(
                "silhouette overlap: at most {MAX_SILHOUETTE_PARTS} parts, got {}",
                parts.len()
            )));
        }
        let mut spans = [Span::EMPTY; MAX_SILHOUETTE_PARTS];
        let mut n = 0;
        let (mut v0, mut v1) = (f64::INFINITY, f64::NEG_INFINITY);
        for part in parts {
            if !finite(part) {
                continue;
            }
            let p = Prepared::new(part);
            let b = p.bbox();
            if !b.iter().all(|x| x.is_finite()) {
                continue;
            }
            if let Some(s) = Span::new(&p) {
                v0 = v0.min(b[1]);
                v1 = v1.max(b[3]);
                spans[n] = s;
                n += 1;
            }
        }
        let mut out = Overlap::default();
        if n == 0 || self.width == 0 {
            return Ok(out);
        }
        let spans = &spans[..n];
        let first = v0.ceil().max(0.0);
        let last = v1.floor().min(self.height as f64 - 1.0);
        if first > last {
            return Ok(out);
        }
        let wmax = self.width as f64 - 1.0;
        let mut cuts = [(0i64, -1i64); MAX_SILHOUETTE_PARTS];
        for v in first as usize..=last as usize {
            let y = v as f64;
            let mut k = 0;
            for s in spans {
                if let Some((lo, hi)) = s.cut(y) {
                    let (lo, hi) = (lo.ceil().max(0.0), hi.floor().min(wmax));
                    if lo <= hi {
                        cuts[k] = (lo as i64, hi as i64);
                        k += 1;
                    }
                }
            }
            let row = &mut cuts[..k];
            row.sort_unstable();
            let prefix = &self.prefix[v * (self.width + 1)..(v + 1) * (self.width + 1)];
            let mut open: Option<(i64, i64)> = None;
            let close = |(lo, hi): (i64, i64), out: &mut Overlap| {
                out.area += (hi - lo + 1) as u64;
                out.foreground += u64::from(prefix[hi as usize + 1] - prefix[lo as usize]);
            };
            for &(lo, hi) in row.iter() {
                open = match open {
                    Some((a, b)) if lo <= b + 1 => Some((a, b.max(hi))),
                    Some(done) => {
                        close(done, &mut out);
                        Some((lo, hi))
                    }
                    None => Some((lo, hi)),
                };
            }
            if let Some(done) = open {
                close(done, &mut out);
            }
        }
        Ok(out)
    }
}

/// Every number of the part is finite (a NaN can hide from the bounding box's min and max).
fn finite(part: &Part2) -> bool {
    match *part {
        Part2::Capsule { c0, c1, r0, r1 } => {
            c0.iter().chain(&c1).chain(&[r0, r1]).all(|x| x.is_finite())
        }
        Part2::Ellipse { c, a, b, angle } => c.iter().chain(&[a, b, angle]).all(|x| x.is_finite()),
    }
}

/// A part in the form of its cut with a pixel row: a convex shape is the union of convex
/// pieces whose cuts overlap, so the row's interval is the hull of the pieces' intervals.
#[derive(Clone, Copy, Debug)]
enum Span {
    Empty,
    Disc {
        c: Vector2<f64>,
        r: f64,
    },
    /// The hull of two discs: the discs and the quadrilateral of the four tangent points.
    Capsule {
        d0: (Vector2<f64>, f64),
        d1: (Vector2<f64>, f64),
        quad: [Vector2<f64>; 4],
    },
    /// `A·du² + B·dy·du + C·dy² ≤ 1` around `c` (du = u − c.u, dy = v − c.v).
    Ellipse {
        c: Vector2<f64>,
        a: f64,
        b: f64,
        cc: f64,
    },
}

impl Span {
    const EMPTY: Self = Self::Empty;

    fn new(p: &Prepared) -> Option<Self> {
        match *p {
            Prepared::Circle { c, r } => (r >= 0.0).then_some(Self::Disc { c, r }),
            Prepared::Capsule {
                c0,
                c1,
                r0,
                r1,
                d,
                n,
                sin_a,
                cos_a,
                ..
            } => {
                if !(r0 >= 0.0 && r1 >= 0.0) {
                    return None;
                }
                let (mp, mm) = (d * sin_a + n * cos_a, d * sin_a - n * cos_a);
                Some(Self::Capsule {
                    d0: (c0, r0),
                    d1: (c1, r1),
                    quad: [c0 + mp * r0, c1 + mp * r1, c1 + mm * r1, c0 + mm * r0],
                })
            }
            Prepared::Ellipse { c, a, b, ea, eb } => {
                if !(a > 1e-9 && b > 1e-9) {
                    return None;
                }
                // ((x·ea)/a)² + ((x·eb)/b)² with x = (du, dy).
                let (ia, ib) = (1.0 / (a * a), 1.0 / (b * b));
                Some(Self::Ellipse {
                    c,
                    a: ea.x * ea.x * ia + eb.x * eb.x * ib,
                    b: 2.0 * (ea.x * ea.y * ia + eb.x * eb.y * ib),
                    cc: ea.y * ea.y * ia + eb.y * eb.y * ib,
                })
            }
        }
    }

    /// The interval of u where row `y` is inside, if any.
    fn cut(&self, y: f64) -> Option<(f64, f64)> {
        fn disc(c: Vector2<f64>, r: f64, y: f64) -> Option<(f64, f64)> {
            let dy = y - c.y;
            let q = r * r - dy * dy;
            (q >= 0.0).then(|| {
                let h = q.sqrt();
                (c.x - h, c.x + h)
            })
        }
        fn hull(a: Option<(f64, f64)>, b: Option<(f64, f64)>) -> Option<(f64, f64)> {
            match (a, b) {
                (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
                (a, None) => a,
                (None, b) => b,
            }
        }
        match *self {
            Self::Empty => None,
            Self::Disc { c, r } => disc(c, r, y),
            Self::Capsule { d0, d1, quad } => {
                let mut q: Option<(f64, f64)> = None;
                for i in 0..4 {
                    let (p, r) = (quad[i], quad[(i + 1) % 4]);
                    let (lo, hi) = if p.y <= r.y { (p, r) } else { (r, p) };
                    if y < lo.y || y > hi.y {
                        continue;
                    }
                    let x = if hi.y - lo.y > 1e-12 {
                        lo.x + (y - lo.y) * (hi.x - lo.x) / (hi.y - lo.y)
                    } else {
                        lo.x
                    };
                    q = hull(q, Some((x, x)));
                    if hi.y - lo.y <= 1e-12 {
                        // A horizontal edge on the row: all of it.
                        q = hull(q, Some((lo.x.min(hi.x), lo.x.max(hi.x))));
                    }
                }
                hull(hull(disc(d0.0, d0.1, y), disc(d1.0, d1.1, y)), q)
            }
            Self::Ellipse { c, a, b, cc } => {
                // a·du² + b·dy·du + cc·dy² − 1 ≤ 0.
                let dy = y - c.y;
                let (bb, k) = (b * dy, cc * dy * dy - 1.0);
                let disc = bb * bb - 4.0 * a * k;
                (disc >= 0.0).then(|| {
                    let s = disc.sqrt();
                    (c.x + (-bb - s) / (2.0 * a), c.x + (-bb + s) / (2.0 * a))
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::{ForegroundCounts, MAX_SILHOUETTE_PARTS, Overlap};
    use crate::Part2;

    /// Brute force, independent of the row cuts: a capsule is the union of the discs
    /// c(t), r(t) for t ∈ [0, 1] (sampled), an ellipse its implicit inequality. The distance
    /// in pixels, negative inside (an approximation away from the outline, exact in sign).
    fn distance(part: &Part2, x: [f64; 2]) -> f64 {
        match *part {
            Part2::Capsule { c0, c1, r0, r1 } => (0..=800)
                .map(|i| {
                    let t = f64::from(i) / 800.0;
                    let c = [c0[0] + t * (c1[0] - c0[0]), c0[1] + t * (c1[1] - c0[1])];
                    (x[0] - c[0]).hypot(x[1] - c[1]) - (r0 + t * (r1 - r0))
                })
                .fold(f64::INFINITY, f64::min),
            Part2::Ellipse { c, a, b, angle } => {
                let (dx, dy) = (x[0] - c[0], x[1] - c[1]);
                let (s, co) = angle.sin_cos();
                let (xa, xb) = ((dx * co + dy * s) / a, (-dx * s + dy * co) / b);
                // Scaled so that the tolerance below is about a pixel's fraction.
                (xa.hypot(xb) - 1.0) * b
            }
        }
    }

    /// The overlap counted pixel by pixel, and the number of pixels within `tol` of an
    /// outline (where the two counts may differ by rounding).
    fn brute(parts: &[Part2], mask: &[u8], w: u32, h: u32, tol: f64) -> (Overlap, u64) {
        let (mut out, mut unsure) = (Overlap::default(), 0);
        for v in 0..h {
            for u in 0..w {
                let x = [f64::from(u), f64::from(v)];
                let d = parts
                    .iter()
                    .map(|p| distance(p, x))
                    .fold(f64::INFINITY, f64::min);
                if d.abs() <= tol {
                    unsure += 1;
                }
                if d <= 0.0 {
                    out.area += 1;
                    out.foreground += u64::from(mask[(v * w + u) as usize]);
                }
            }
        }
        (out, unsure)
    }

    fn pattern(w: u32, h: u32, seed: u64) -> Vec<u8> {
        // A fixed pseudo-random mask (SplitMix64 bits), about half foreground.
        (0..u64::from(w * h))
            .map(|i| {
                let mut z = (i + seed).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                u8::from((z ^ (z >> 31)) & 1 == 1)
            })
            .collect()
    }

    fn check(parts: &[Part2], w: u32, h: u32, seed: u64) {
        let mask = pattern(w, h, seed);
        let mut counts = ForegroundCounts::default();
        counts.set(&mask, w, h, |x| x == 1).unwrap();
        assert_eq!(
            counts.total(),
            mask.iter().map(|&x| u64::from(x)).sum::<u64>()
        );
        let got = counts.overlap(parts).unwrap();
        let (want, unsure) = brute(parts, &mask, w, h, 0.02);
        assert!(
            got.area.abs_diff(want.area) <= unsure
                && got.foreground.abs_diff(want.foreground) <= unsure,
            "{parts:?}: {got:?} against {want:?} (±{unsure})"
        );
        // Every pixel of the mask foreground: the overlap is the area.
        let full = vec![1u8; (w * h) as usize];
        counts.set(&full, w, h, |x| x == 1).unwrap();
        let o = counts.overlap(parts).unwrap();
        assert_eq!(o.area, o.foreground);
    }

    #[test]
    fn overlap_matches_brute_force() {
        let (w, h) = (120u32, 90u32);
        let upper = Part2::Capsule {
            c0: [20.0, 30.0],
            c1: [95.0, 55.0],
            r0: 12.0,
            r1: 6.0,
        };
        let cases: Vec<Vec<Part2>> = vec![
            vec![upper],
            // Tapering the other way, nearly vertical.
            vec![Part2::Capsule {
                c0: [60.0, 10.0],
                c1: [62.0, 80.0],
                r0: 4.0,
                r1: 9.5,
            }],
            // Cut by the border.
            vec![Part2::Capsule {
                c0: [-20.0, 40.0],
                c1: [30.0, 100.0],
                r0: 8.0,
                r1: 8.0,
            }],
            // One disc holds the other.
            vec![Part2::Capsule {
                c0: [50.0, 50.0],
                c1: [51.0, 50.5],
                r0: 10.0,
                r1: 3.0,
            }],
            // Exactly horizontal (horizontal quadrilateral edges).
            vec![Part2::Capsule {
                c0: [10.0, 20.0],
                c1: [90.0, 20.0],
                r0: 5.0,
                r1: 5.0,
            }],
            vec![Part2::Ellipse {
                c: [70.0, 40.0],
                a: 18.0,
                b: 7.0,
                angle: 0.6,
            }],
            // A whole arm: overlapping parts are counted once.
            vec![
                upper,
                Part2::Capsule {
                    c0: [95.0, 55.0],
                    c1: [70.0, 20.0],
                    r0: 6.0,
                    r1: 4.0,
                },
                Part2::Ellipse {
                    c: [66.0, 14.0],
                    a: 9.0,
                    b: 5.0,
                    angle: 2.0,
                },
            ],
            // Outside the image, and a part of zero size.
            vec![
                Part2::Capsule {
                    c0: [-50.0, -50.0],
                    c1: [-30.0, -40.0],
                    r0: 5.0,
                    r1: 5.0,
                },
                Part2::Capsule {
                    c0: [40.0, 40.0],
                    c1: [40.0, 40.0],
                    r0: 0.0,
                    r1: 0.0,
                },
            ],
        ];
        for (i, parts) in cases.iter().enumerate() {
            check(parts, w, h, i as u64);
        }
        let arm = &cases[6];
        let counts = {
            let mut c = ForegroundCounts::default();
            c.set(&pattern(w, h, 1), w, h, |x| x == 1).unwrap();
            c
        };
        let union = counts.overlap(arm).unwrap();
        let sum: u64 = arm
            .iter()
            .map(|p| counts.overlap(std::slice::from_ref(p)).unwrap().area)
            .sum();
        assert!(union.area < sum, "the parts overlap: {union:?} < {sum}");
    }

    #[test]
    fn overlap_bad_input() {
        let mut counts = ForegroundCounts::default();
        assert!(counts.set(&[0u8; 5], 2, 3, |x| x == 1).is_err());
        // Before any mask, and for an empty mask: nothing.
        let part = Part2::Capsule {
            c0: [1.0, 1.0],
            c1: [5.0, 5.0],
            r0: 2.0,
            r1: 2.0,
        };
        assert_eq!(counts.overlap(&[part]).unwrap(), Overlap::default());
        counts.set::<u8>(&[], 0, 0, |x| x == 1).unwrap();
        assert_eq!(counts.overlap(&[part]).unwrap(), Overlap::default());
        counts.set(&[1u8; 100], 10, 10, |x| x == 1).unwrap();
        // NaN and infinite parts cover nothing; negative radii neither.
        for bad in [
            Part2::Capsule {
                c0: [f64::NAN, 1.0],
                c1: [5.0, 5.0],
                r0: 2.0,
                r1: 2.0,
            },
            Part2::Capsule {
                c0: [1.0, 1.0],
                c1: [5.0, 5.0],
                r0: f64::INFINITY,
                r1: 2.0,
            },
            Part2::Capsule {
                c0: [1.0, 1.0],
                c1: [5.0, 5.0],
                r0: -2.0,
                r1: -2.0,
            },
            Part2::Ellipse {
                c: [5.0, 5.0],
                a: 3.0,
                b: 0.0,
                angle: 0.0,
            },
        ] {
            assert_eq!(
                counts.overlap(&[bad]).unwrap(),
                Overlap::default(),
                "{bad:?}"
            );
        }
        assert!(counts.overlap(&[part; MAX_SILHOUETTE_PARTS + 1]).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

        #[test]
        fn random_arms_match_brute_force(
            c in prop::array::uniform8(-20.0f64..100.0),
            r in prop::array::uniform4(0.5f64..15.0),
            angle in 0.0f64..6.3,
            seed in 0u64..1000,
        ) {
            let parts = [
                Part2::Capsule { c0: [c[0], c[1]], c1: [c[2], c[3]], r0: r[0], r1: r[1] },
                Part2::Capsule { c0: [c[2], c[3]], c1: [c[4], c[5]], r0: r[1], r1: r[2] },
                Part2::Ellipse { c: [c[6], c[7]], a: r[3] + 3.0, b: r[3], angle },
            ];
            check(&parts, 80, 60, seed);
        }
    }
}
