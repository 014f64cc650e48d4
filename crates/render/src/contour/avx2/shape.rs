//! The f32 forms of the occluder test ([`Shape32`]) and of the sample runs ([`Run32`]), with
//! the bounds of their error against the f64 loop, and the small vector helpers they share.

use pulp::{Simd, f32x8, f64x4, m32x8, x86::V3};

use nalgebra::Vector2;

use super::super::{INSIDE_TOL, LANES, Prepared, sin_cos};
use super::L8;
/// The "more than [`INSIDE_TOL`] inside" test of an occluder in f32, in coordinates relative
/// to the anchor of the part whose samples it tests, with every threshold moved by the error
/// bound `t` both ways: lanes below the lower threshold are deep in the f64 test
/// ([`Inside::deep`](super::super::Inside::deep) at the f64 positions), lanes above the upper one are not, the rest are
/// ambiguous. `[lo, hi]` pairs are these two thresholds.
#[derive(Clone, Copy)]
pub(super) enum Shape32 {
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
pub(super) fn pair(x: f64, t: f64) -> [f32; 2] {
    [(x - t) as f32, (x + t) as f32]
}

/// A point relative to the anchor `a`, in f32.
pub(super) fn rel(p: nalgebra::Vector2<f64>, a: [f64; 2]) -> [f32; 2] {
    [(p.x - a[0]) as f32, (p.y - a[1]) as f32]
}

pub(super) fn f32s(v: nalgebra::Vector2<f64>) -> [f32; 2] {
    [v.x as f32, v.y as f32]
}

impl Shape32 {
    /// Per lane: (surely deep, surely not deep) in the f64 test.
    #[cfg(test)]
    #[allow(clippy::inline_always)]
    #[inline(always)]
    pub(super) fn test(&self, s: V3, x: f32x8, y: f32x8) -> (m32x8, m32x8) {
        let (nd, no) = self.test_not(s, x, y);
        (s.not_m32s(nd), s.not_m32s(no))
    }

    /// Per lane: (not surely deep, not surely outside) in the f64 test, i.e. the
    /// complements of `Shape32::test` (the loop uses them as they are: fewer
    /// negations).
    #[allow(clippy::inline_always)]
    #[inline(always)]
    pub(super) fn test_not(&self, s: V3, x: f32x8, y: f32x8) -> (m32x8, m32x8) {
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
pub(super) fn abs(s: V3, x: f32x8) -> f32x8 {
    s.and_f32s(x, pulp::cast([0x7fff_ffff_u32; L8]))
}

/// `|x|` per lane, f64.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn abs64(s: V3, x: f64x4) -> f64x4 {
    s.and_f64s(x, pulp::cast([0x7fff_ffff_ffff_ffff_u64; LANES]))
}

/// `a·b` of two-vector lanes and a constant.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn dot(s: V3, ax: f32x8, ay: f32x8, b: &[f32; 2]) -> f32x8 {
    s.mul_add_e_f32s(ax, s.splat_f32s(b[0]), s.mul_f32s(ay, s.splat_f32s(b[1])))
}

/// `|a|²` of two-vector lanes.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn norm2(s: V3, ax: f32x8, ay: f32x8) -> f32x8 {
    s.mul_add_e_f32s(ax, ax, s.mul_f32s(ay, ay))
}

/// `(q < lo, q > hi)` per lane.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn below_above(s: V3, q: f32x8, th: &[f32; 2]) -> (m32x8, m32x8) {
    (
        s.less_than_f32s(q, s.splat_f32s(th[0])),
        s.greater_than_f32s(q, s.splat_f32s(th[1])),
    )
}

/// How a [`Run32`] generates its samples.
#[derive(Clone, Copy)]
pub(super) enum Gen32 {
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

/// A [`Run`](super::super::Run) for the f32 loop, relative to the anchor: `n` samples, the bound `tol` of
/// their error against the f64 positions, and a box (f64) that holds them.
#[derive(Clone, Copy)]
pub(super) struct Run32 {
    pub(super) samples: Gen32,
    pub(super) n: usize,
    pub(super) tol: f64,
    pub(super) bx: [f64; 4],
}

/// The larger magnitude of a vector's coordinates.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn inf(x: f64, y: f64) -> f64 {
    let (x, y) = (x.abs(), y.abs());
    if x > y { x } else { y }
}

/// Two f64x4 as one f32x8.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn to_f32x8(s: V3, lo: f64x4, hi: f64x4) -> f32x8 {
    pulp::cast([s.convert_f64x4_to_f32x4(lo), s.convert_f64x4_to_f32x4(hi)])
}

/// `uc·co + wc·si`.
#[allow(clippy::inline_always)]
#[inline(always)]
pub(super) fn comb(s: V3, co: f64x4, si: f64x4, uc: f64, wc: f64) -> f64x4 {
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
    pub(super) fn line(a: [f64; 2], p: Vector2<f64>, q: Vector2<f64>, n: usize) -> Self {
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
    pub(super) fn trig(
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
        let (s1, c1) = sin_cos(theta);
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
pub(super) fn tolerance_bound(part: &Prepared, m: f64, step: f64) -> f64 {
    // Arcs: |u|₁ + |w|₁ ≤ 2√2·r, at most 2πr/Δ samples; lines at most as long as the part.
    let arcs = |r: f64| {
        let big = 2.9 * r;
        2e-6 + 4e-7 * (m + big + 1.0) + 4e-7 * big * (r * std::f64::consts::TAU / step / 8.0 + 3.0)
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
    /// The part's test ([`Inside::new`](super::super::Inside::new) of it) relative to the anchor `a`; `t`: bound
    /// (pixels) of the error of the f32 sample positions and of this test's arithmetic.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    pub(super) fn of_part(part: &Prepared, a: [f64; 2], t: f64) -> Self {
        let pair_sq = |r: f64| {
            if r <= INSIDE_TOL {
                return [-1.0f32, -1.0];
            }
            let r = r - INSIDE_TOL;
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
                lim: pair(r0 - INSIDE_TOL, 1.5 * t),
            },
            Prepared::Ellipse {
                c,
                a: ra,
                b,
                ea,
                eb,
            } => {
                if b <= INSIDE_TOL {
                    return Self::Never;
                }
                // Normalised coordinates move by at most 1/b ≥ 1/a times the error.
                let k = 1.0 - INSIDE_TOL / b;
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
