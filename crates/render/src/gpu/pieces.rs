//! The CPU half of a job: a projected part as the shader's inside-test record ([`GpuPart`]) and
//! its outline as lines and arcs ([`GpuPiece`]), each relative to an integer pixel anchor so
//! that f32 keeps sub-pixel precision, with the error bound of the positions the GPU computes.

use bytemuck::{Pod, Zeroable};
use nalgebra::Vector2;

use crate::contour::{INSIDE_TOL, OutlineSink, Prepared};

/// One line or arc of a part's outline, relative to an integer pixel anchor.
///
/// Line: `x_k = anchor + base + u·(k/n)`. Arc: `x_k = anchor + base + u·cos(kθ) + w·sin(kθ)`
/// with θ = `dt_hi + dt_lo`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub(super) struct GpuPiece {
    /// kind (1 line, 2 arc), index of its part in the job, number of samples n, unused.
    head: [u32; 4],
    anchor: [i32; 2],
    base: [f32; 2],
    u: [f32; 2],
    w: [f32; 2],
    dt_hi: f32,
    dt_lo: f32,
    /// Positions are within this many pixels of the f64 positions.
    tol: f32,
    _pad: f32,
}

/// A part for the inside test, relative to an integer anchor.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
pub(super) struct GpuPart {
    /// kind (0 never inside, 1 disc, 2 capsule, 3 ellipse), cap flags (bit 0: disc at c0 can
    /// contain points, bit 1: disc at c1), unused ×2.
    head: [u32; 4],
    anchor: [i32; 2],
    /// Disc / capsule start / ellipse centre, relative to the anchor.
    c0: [f32; 2],
    /// Capsule end minus start.
    c1: [f32; 2],
    /// Capsule direction, or the ellipse major axis direction.
    d: [f32; 2],
    /// Capsule normal, or the ellipse minor axis direction.
    n: [f32; 2],
    /// Disc: r, capsule: r0, ellipse: a.
    r0: f32,
    /// Capsule: r1, ellipse: b.
    r1: f32,
    /// Capsule: length, ellipse: 1 − INSIDE_TOL / b.
    len: f32,
    sin_a: f32,
    cos_a: f32,
    /// Magnitude of the part's coordinates (pixels), for the error bound.
    scale: f32,
    _pad: [f32; 4],
}

// The WGSL layouts of `Piece` and `Part` (16-byte aligned structs).
const _: () = assert!(size_of::<GpuPiece>() == 64 && size_of::<GpuPart>() == 96);

impl Prepared {
    /// The part for the inside test.
    pub(super) fn gpu_part(&self) -> GpuPart {
        let mut g = GpuPart::default();
        match *self {
            Self::Circle { c, r } => {
                let (anchor, c0) = anchored(c);
                g.head = [u32::from(r > INSIDE_TOL), 0, 0, 0];
                g.anchor = anchor;
                g.c0 = c0;
                g.r0 = r as f32;
                g.scale = r as f32;
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
                let (anchor, base) = anchored(c0);
                let caps = u32::from(r0 > INSIDE_TOL) | (u32::from(r1 > INSIDE_TOL) << 1);
                g.head = [2, caps, 0, 0];
                g.anchor = anchor;
                g.c0 = base;
                g.c1 = f32x2(c1 - c0);
                g.d = f32x2(d);
                g.n = f32x2(n);
                g.r0 = r0 as f32;
                g.r1 = r1 as f32;
                g.len = len as f32;
                g.sin_a = sin_a as f32;
                g.cos_a = cos_a as f32;
                g.scale = (len + r0 + r1) as f32;
            }
            Self::Ellipse { c, a, b, ea, eb } => {
                let (anchor, base) = anchored(c);
                g.head = [if b > INSIDE_TOL { 3 } else { 0 }, 0, 0, 0];
                g.anchor = anchor;
                g.c0 = base;
                g.d = f32x2(ea);
                g.n = f32x2(eb);
                g.r0 = a as f32;
                g.r1 = b as f32;
                g.len = (1.0 - INSIDE_TOL / b) as f32;
                g.scale = a as f32;
            }
        }
        g
    }

    /// Appends the pieces of the outline: the CPU sampler's ([`Prepared::sample_outline`]), in
    /// its order and with its sample counts.
    pub(super) fn pieces(&self, part: u32, step: f64, out: &mut Vec<GpuPiece>) {
        self.sample_outline(step, &mut PieceSink { part, out });
    }
}

/// Collects a part's outline as GPU pieces.
struct PieceSink<'a> {
    part: u32,
    out: &'a mut Vec<GpuPiece>,
}

impl OutlineSink for PieceSink<'_> {
    fn line(&mut self, p: Vector2<f64>, q: Vector2<f64>, n: usize) {
        self.out.push(line_piece(self.part, n, p, q));
    }
    fn trig(
        &mut self,
        c: Vector2<f64>,
        u: Vector2<f64>,
        w: Vector2<f64>,
        theta: f64,
        n: usize,
        _circle: bool,
    ) {
        self.out.push(arc_piece(self.part, n, c, u, w, theta));
    }
}

fn f32x2(v: Vector2<f64>) -> [f32; 2] {
    [v.x as f32, v.y as f32]
}

/// An integer anchor near `x` (its floor) and `x` relative to it, in [0, 1)².
fn anchored(x: Vector2<f64>) -> ([i32; 2], [f32; 2]) {
    let (fx, fy) = (x.x.floor(), x.y.floor());
    // |x| < 1e6 for every projected part (the projection rejects larger coordinates).
    (
        [fx as i32, fy as i32],
        [(x.x - fx) as f32, (x.y - fy) as f32],
    )
}

/// Error bound (pixels) of GPU positions built from vectors of total length `magnitude`.
///
/// Worst case per coordinate of an arc of radius r (|u| = |w| = r, magnitude ≈ 2r): u and w
/// rounded to f32 (r·6e-8 each), cos/sin within 2e-7, two products and two sums rounded
/// (r·1.2e-7 each): ≈ r·7e-7 + 1e-7. Lines: k/n within 2.5 ulp (Vulkan), so ≈ |u|·3e-7.
/// The bound below is about twice that; measured errors are more than 100× smaller (the
/// tests pass with the bound divided by 100).
fn position_tol(magnitude: f64) -> f32 {
    (2e-6 + 6e-7 * magnitude) as f32
}

fn line_piece(part: u32, n: usize, a: Vector2<f64>, b: Vector2<f64>) -> GpuPiece {
    let (anchor, base) = anchored(a);
    let u = b - a;
    GpuPiece {
        head: [1, part, n as u32, 0],
        anchor,
        base,
        u: f32x2(u),
        tol: position_tol(u.norm() + 1.0),
        ..GpuPiece::default()
    }
}

fn arc_piece(
    part: u32,
    n: usize,
    c: Vector2<f64>,
    u: Vector2<f64>,
    w: Vector2<f64>,
    dt: f64,
) -> GpuPiece {
    let (anchor, base) = anchored(c);
    // dt = dt_hi + dt_lo with dt_hi of 11 significant bits, so k·dt_hi is exact in f32 for
    // k < 2¹³ (arcs have at most 4096 samples).
    let dt_hi = f32::from_bits((dt as f32).to_bits() & 0xFFFF_E000);
    let dt_lo = (dt - f64::from(dt_hi)) as f32;
    GpuPiece {
        head: [2, part, n as u32, 0],
        anchor,
        base,
        u: f32x2(u),
        w: f32x2(w),
        dt_hi,
        dt_lo,
        tol: position_tol(u.norm() + w.norm() + 1.0),
        _pad: 0.0,
    }
}
