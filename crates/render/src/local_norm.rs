//! Local normalisation of an edge image (an extension, not SPEC §4.1).
//!
//! SPEC's G is normalised by its global maximum, so an edge of low contrast (skin on wood, a
//! sleeve over a shirt of similar colour) stays weak wherever a strong edge elsewhere in the
//! frame sets the scale. Dividing G by the maximum of G over a square window around each pixel
//! (with a floor, so that flat regions and noise are not blown up) makes every edge that is
//! the strongest in its neighbourhood count as 1:
//!
//! `G'(x) = min(1, G(x) / max(floor, max_{‖y − x‖∞ ≤ R} G(y)))`.
//!
//! The window maximum is computed with the van Herk / Gil–Werman algorithm (separable, three
//! comparisons per pixel and pass, independent of R; the vertical pass works on whole rows).

use crate::{EdgeImage, RenderError};

/// Settings of [`local_normalise`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LocalNorm {
    /// Half-width R of the square window in pixels (≥ 1).
    pub radius: u32,
    /// Floor of the divisor, in (0, 1]: where the local maximum is below it, G is divided by
    /// the floor instead.
    pub floor: f32,
}

impl LocalNorm {
    /// Checks R ≥ 1 and floor ∈ (0, 1].
    pub fn validate(&self) -> Result<(), RenderError> {
        if self.radius == 0 || self.radius > 10_000 {
            return Err(RenderError::InvalidParameter(format!(
                "local normalisation radius must be in [1, 10000] px, got {}",
                self.radius
            )));
        }
        if !(self.floor.is_finite() && self.floor > 0.0 && self.floor <= 1.0) {
            return Err(RenderError::InvalidParameter(format!(
                "local normalisation floor must be in (0, 1], got {}",
                self.floor
            )));
        }
        Ok(())
    }
}

/// Scratch buffers of [`local_normalise`] (no allocation after the first frame of a size).
#[derive(Debug, Default, Clone)]
pub struct LocalNormScratch {
    rows: Vec<f32>,
    prefix: Vec<f32>,
    suffix: Vec<f32>,
}

/// The output index's window `[i − r, i + r]` clamped to `0..n` as the van Herk / Gil–Werman
/// combination of a block prefix (`P`, running maximum from the start of each block of
/// `2r + 1`) and a block suffix (`S`, running maximum to the end of each block, the last block
/// ending at `n − 1`): a full window spans two adjacent blocks, or is one whole block, so it is
/// `max(S[lo], P[hi])`; a window clamped at the start lies in the first block (`P[hi]`); one
/// clamped at the end is `S[lo]` when `lo` is in the last block, else `max(S[lo], P[n − 1])`.
#[derive(Clone, Copy)]
enum Window {
    Prefix(usize),
    Suffix(usize),
    Both(usize, usize),
}

/// [`Window`] of output index `i` in a line of `n` values whose last block starts at `last`.
#[inline]
fn window(i: usize, n: usize, r: usize, last: usize) -> Window {
    let hi = (i + r).min(n - 1);
    if i <= r {
        Window::Prefix(hi)
    } else {
        let lo = i - r;
        if hi == n - 1 && lo >= last {
            Window::Suffix(lo)
        } else {
            Window::Both(lo, hi)
        }
    }
}

/// Running maximum over the windows `[i − r, i + r]` (clamped to the line) of the contiguous
/// line `src`, into `dst` (same length).
fn line_max(src: &[f32], dst: &mut [f32], r: usize, prefix: &mut Vec<f32>, suffix: &mut Vec<f32>) {
    let n = src.len();
    if n == 0 {
        return;
    }
    let block = 2 * r + 1;
    prefix.clear();
    prefix.resize(n, 0.0);
    suffix.clear();
    suffix.resize(n, 0.0);
    for ((p, s), x) in prefix
        .chunks_mut(block)
        .zip(suffix.chunks_mut(block))
        .zip(src.chunks(block))
    {
        let mut m = f32::NEG_INFINITY;
        for (p, &x) in p.iter_mut().zip(x) {
            m = m.max(x);
            *p = m;
        }
        let mut m = f32::NEG_INFINITY;
        for (s, &x) in s.iter_mut().zip(x).rev() {
            m = m.max(x);
            *s = m;
        }
    }
    let last = (n - 1) / block * block;
    for (i, d) in dst.iter_mut().enumerate() {
        *d = match window(i, n, r, last) {
            Window::Prefix(hi) => prefix[hi],
            Window::Suffix(lo) => suffix[lo],
            Window::Both(lo, hi) => suffix[lo].max(prefix[hi]),
        };
    }
}

/// Row `y` of a `w`-wide image.
#[inline]
fn row(v: &[f32], w: usize, y: usize) -> &[f32] {
    &v[y * w..(y + 1) * w]
}

/// Running maximum over the windows of rows `[y − r, y + r]` (clamped to the image) of the
/// `w`-wide rows of `src`, into `dst`: the same blocks as [`line_max`], each step a whole row
/// (element-wise, so it vectorises and reads memory in order).
fn column_max(
    src: &[f32],
    dst: &mut [f32],
    w: usize,
    r: usize,
    prefix: &mut Vec<f32>,
    suffix: &mut Vec<f32>,
) {
    let n = src.len().checked_div(w).unwrap_or(0);
    if n == 0 {
        return;
    }
    let block = 2 * r + 1;
    prefix.clear();
    prefix.resize(src.len(), 0.0);
    suffix.clear();
    suffix.resize(src.len(), 0.0);
    let stride = block * w;
    for ((p, s), x) in prefix
        .chunks_mut(stride)
        .zip(suffix.chunks_mut(stride))
        .zip(src.chunks(stride))
    {
        let rows = x.len() / w;
        p[..w].copy_from_slice(&x[..w]);
        for k in 1..rows {
            let (done, next) = p.split_at_mut(k * w);
            let prev = &done[(k - 1) * w..];
            for ((o, &a), &b) in next[..w].iter_mut().zip(prev).zip(&x[k * w..(k + 1) * w]) {
                *o = a.max(b);
            }
        }
        let end = (rows - 1) * w;
        s[end..].copy_from_slice(&x[end..]);
        for k in (0..rows - 1).rev() {
            let (this, done) = s.split_at_mut((k + 1) * w);
            for ((o, &a), &b) in this[k * w..]
                .iter_mut()
                .zip(&done[..w])
                .zip(&x[k * w..(k + 1) * w])
            {
                *o = a.max(b);
            }
        }
    }
    let last = (n - 1) / block * block;
    for (y, d) in dst.chunks_mut(w).enumerate() {
        match window(y, n, r, last) {
            Window::Prefix(hi) => d.copy_from_slice(row(prefix, w, hi)),
            Window::Suffix(lo) => d.copy_from_slice(row(suffix, w, lo)),
            Window::Both(lo, hi) => {
                for ((o, &a), &b) in d.iter_mut().zip(row(suffix, w, lo)).zip(row(prefix, w, hi)) {
                    *o = a.max(b);
                }
            }
        }
    }
}

/// The maximum of `src` (`width` × `height`, row-major) over the square window of half-width
/// `radius` around each pixel (clamped at the borders), into `out` (resized). For a 0/1 mask
/// this is its dilation by the square.
pub fn max_filter(
    src: &[f32],
    (width, height): (usize, usize),
    radius: usize,
    scratch: &mut LocalNormScratch,
    out: &mut Vec<f32>,
) -> Result<(), RenderError> {
    if width.checked_mul(height) != Some(src.len()) {
        return Err(RenderError::InvalidImage(format!(
            "max filter: {width}×{height} image needs {} values, got {}",
            width.saturating_mul(height),
            src.len()
        )));
    }
    let (w, h) = (width, height);
    let LocalNormScratch {
        rows,
        prefix,
        suffix,
    } = scratch;
    rows.clear();
    rows.resize(w * h, 0.0);
    if w == 0 {
        out.clear();
        return Ok(());
    }
    for (s, d) in src.chunks(w).zip(rows.chunks_mut(w)) {
        line_max(s, d, radius, prefix, suffix);
    }
    out.clear();
    out.resize(w * h, 0.0);
    column_max(rows, out, w, radius, prefix, suffix);
    Ok(())
}

/// The dilation of the 0/1 mask `src` (`width` × `height`, row-major; any non-zero value is 1)
/// by the square of half-width `radius` (clamped at the borders), as 0/1 into `out` (resized):
/// the same as [`max_filter`] on a 0/1 image, in bytes and linear time for any radius — the
/// columns by a running count per column over the window's rows, then the rows by filling
/// each run of set pixels grown by the radius.
pub fn dilate_mask(
    src: &[u8],
    (width, height): (usize, usize),
    radius: usize,
    scratch: &mut DilateScratch,
    out: &mut Vec<u8>,
) -> Result<(), RenderError> {
    if width.checked_mul(height) != Some(src.len()) {
        return Err(RenderError::InvalidImage(format!(
            "dilation: {width}×{height} mask needs {} values, got {}",
            width.saturating_mul(height),
            src.len()
        )));
    }
    let (w, h) = (width, height);
    let DilateScratch { cols, counts } = scratch;
    if radius <= DIRECT_RADIUS && w > 0 && h > 0 {
        // Every value is written below: no clearing.
        cols.resize(w * h, 0);
        out.resize(w * h, 0);
        dilate_direct(src, (w, h), radius, &mut cols[..w * h], out);
        return Ok(());
    }
    cols.clear();
    cols.resize(w * h, 0);
    out.clear();
    out.resize(w * h, 0);
    if w == 0 || h == 0 {
        return Ok(());
    }
    // Columns: the number of set pixels in rows [y − r, y + r] of each column.
    counts.clear();
    counts.resize(w, 0);
    for row in src.chunks_exact(w).take(radius.min(h - 1) + 1) {
        for (c, &v) in counts.iter_mut().zip(row) {
            *c += u32::from(v != 0);
        }
    }
    for y in 0..h {
        for (o, &c) in cols[y * w..(y + 1) * w].iter_mut().zip(counts.iter()) {
            *o = u8::from(c > 0);
        }
        if y + radius + 1 < h {
            let add = &src[(y + radius + 1) * w..(y + radius + 2) * w];
            for (c, &v) in counts.iter_mut().zip(add) {
                *c += u32::from(v != 0);
            }
        }
        if y >= radius {
            let sub = &src[(y - radius) * w..(y - radius + 1) * w];
            for (c, &v) in counts.iter_mut().zip(sub) {
                *c -= u32::from(v != 0);
            }
        }
    }
    // Rows: each run of set pixels [start, end) fills [start − r, end + r), every pixel once.
    for (s, d) in cols.chunks_exact(w).zip(out.chunks_exact_mut(w)) {
        let (mut x, mut filled) = (0, 0);
        while x < w {
            // Skip zeros eight at a time.
            while let Some(word) = s.get(x..x + 8)
                && word.iter().all(|&v| v == 0)
            {
                x += 8;
            }
            while x < w && s[x] == 0 {
                x += 1;
            }
            if x == w {
                break;
            }
            let start = x;
            while x < w && s[x] != 0 {
                x += 1;
            }
            let (lo, hi) = (
                start.saturating_sub(radius).max(filled),
                (x + radius).min(w),
            );
            d[lo..hi].fill(1);
            filled = hi;
        }
    }
    Ok(())
}

/// Radii up to this are dilated by OR-ing the 2r + 1 shifted rows and columns
/// ([`dilate_direct`]): a few byte operations per pixel that vectorise, cheaper than the
/// running counts for the small radii of the foreground gate.
const DIRECT_RADIUS: usize = 4;

/// [`dilate_mask`] for small radii (`src` and `cols`: `w · h` values, `out` as well): each row
/// the OR of the rows y − r … y + r (clamped), then each pixel the OR of columns x − r … x + r
/// (clamped) of that, normalised to 0/1.
fn dilate_direct(src: &[u8], (w, h): (usize, usize), r: usize, cols: &mut [u8], out: &mut [u8]) {
    for (y, dst) in cols.chunks_exact_mut(w).enumerate() {
        let (lo, hi) = (y.saturating_sub(r), (y + r).min(h - 1));
        dst.copy_from_slice(&src[lo * w..(lo + 1) * w]);
        for row in src[(lo + 1) * w..(hi + 1) * w].chunks_exact(w) {
            for (d, &v) in dst.iter_mut().zip(row) {
                *d |= v;
            }
        }
    }
    for (s, d) in cols.chunks_exact(w).zip(out.chunks_exact_mut(w)) {
        if w > 2 * r {
            let n = w - 2 * r;
            let inner = &mut d[r..r + n];
            inner.copy_from_slice(&s[..n]);
            for j in 1..=2 * r {
                for (o, &v) in inner.iter_mut().zip(&s[j..j + n]) {
                    *o |= v;
                }
            }
        }
        // The columns within r of either border (all of them in a row narrower than 2r + 1).
        for x in (0..r.min(w)).chain(w.saturating_sub(r).max(r.min(w))..w) {
            d[x] = s[x.saturating_sub(r)..=(x + r).min(w - 1)]
                .iter()
                .fold(0, |a, &v| a | v);
        }
        for o in d.iter_mut() {
            *o = u8::from(*o != 0);
        }
    }
}

/// Buffers of [`dilate_mask`] (reused between frames).
#[derive(Debug, Clone, Default)]
pub struct DilateScratch {
    cols: Vec<u8>,
    counts: Vec<u32>,
}

/// G divided by its local maximum ([`LocalNorm`]), into `out` (resized; its previous contents
/// are replaced). Values stay in [0, 1]; a G of zeros stays zero.
pub fn local_normalise(
    g: &EdgeImage,
    settings: &LocalNorm,
    scratch: &mut LocalNormScratch,
    out: &mut EdgeImage,
) -> Result<(), RenderError> {
    settings.validate()?;
    let (w, h) = (g.width() as usize, g.height() as usize);
    let src = g.data();
    let mut data = std::mem::take(out).into_data();
    max_filter(src, (w, h), settings.radius as usize, scratch, &mut data)?;
    for (d, &v) in data.iter_mut().zip(src) {
        let m = d.max(settings.floor);
        *d = (v / m).clamp(0.0, 1.0);
    }
    *out = EdgeImage::from_vec(g.width(), g.height(), data)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform values in [0, 1) from a 64-bit linear congruential generator seeded by `s`.
    fn lcg(mut s: u64) -> impl FnMut() -> f32 {
        move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    fn brute(g: &[f32], w: usize, h: usize, r: usize, floor: f32) -> Vec<f32> {
        let mut out = vec![0.0; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut m = f32::NEG_INFINITY;
                for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
                    for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                        m = m.max(g[yy * w + xx]);
                    }
                }
                out[y * w + x] = (g[y * w + x] / m.max(floor)).clamp(0.0, 1.0);
            }
        }
        out
    }

    #[test]
    fn equals_brute_force() {
        let mut rnd = lcg(12345);
        let mut scratch = LocalNormScratch::default();
        let mut out = EdgeImage::default();
        for (w, h) in [(1, 1), (7, 5), (23, 17), (64, 3)] {
            let data: Vec<f32> = (0..w * h).map(|_| rnd()).collect();
            let g = EdgeImage::from_vec(w as u32, h as u32, data.clone()).unwrap();
            for r in [1, 2, 3, 8, 40] {
                for floor in [0.05, 0.5, 1.0] {
                    let ln = LocalNorm { radius: r, floor };
                    local_normalise(&g, &ln, &mut scratch, &mut out).unwrap();
                    let want = brute(&data, w, h, r as usize, floor);
                    assert_eq!(out.data(), &want[..], "{w}x{h} r {r} floor {floor}");
                }
            }
        }
    }

    /// The dilation itself against a brute-force window maximum, radius 0 included, for lines,
    /// columns and images whose sides are and are not multiples of the block 2R + 1.
    #[test]
    #[allow(clippy::float_cmp)] // a maximum is exact: bit-identical values are the claim
    fn max_filter_equals_brute_force() {
        let mut rnd = {
            let mut u = lcg(99);
            move || u() - 0.5
        };
        let mut scratch = LocalNormScratch::default();
        let mut out = Vec::new();
        for (w, h) in [(1, 9), (9, 1), (13, 13), (31, 29), (50, 7)] {
            let data: Vec<f32> = (0..w * h).map(|_| rnd()).collect();
            for r in [0, 1, 2, 6, 13, 60] {
                max_filter(&data, (w, h), r, &mut scratch, &mut out).unwrap();
                for y in 0..h {
                    for x in 0..w {
                        let mut m = f32::NEG_INFINITY;
                        for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
                            for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                                m = m.max(data[yy * w + xx]);
                            }
                        }
                        assert_eq!(out[y * w + x], m, "{w}x{h} r {r} at ({x}, {y})");
                    }
                }
            }
        }
        assert!(max_filter(&[0.0; 5], (2, 2), 1, &mut scratch, &mut out).is_err());
        max_filter(&[], (0, 4), 1, &mut scratch, &mut out).unwrap();
        assert!(out.is_empty());
    }

    /// The byte dilation against [`max_filter`] on the same 0/1 masks.
    #[test]
    fn dilate_mask_equals_max_filter() {
        let mut u = lcg(7);
        let (mut s1, mut s2) = (LocalNormScratch::default(), DilateScratch::default());
        let (mut want, mut got) = (Vec::new(), Vec::new());
        for (w, h) in [(1, 9), (9, 1), (13, 13), (31, 29), (50, 7)] {
            for density in [0.02, 0.2, 0.7] {
                let bits: Vec<u8> = (0..w * h).map(|_| u8::from(u() < density)).collect();
                let f: Vec<f32> = bits.iter().map(|&b| f32::from(b)).collect();
                for r in [0, 1, 2, 6, 13, 60] {
                    max_filter(&f, (w, h), r, &mut s1, &mut want).unwrap();
                    dilate_mask(&bits, (w, h), r, &mut s2, &mut got).unwrap();
                    let want: Vec<u8> = want.iter().map(|&v| u8::from(v > 0.5)).collect();
                    assert_eq!(got, want, "{w}x{h} r {r} density {density}");
                }
            }
        }
        assert!(dilate_mask(&[0; 5], (2, 2), 1, &mut s2, &mut got).is_err());
        dilate_mask(&[], (0, 4), 1, &mut s2, &mut got).unwrap();
        assert!(got.is_empty());
    }

    #[test]
    fn isolated_weak_edge_becomes_one_and_zero_stays_zero() {
        let (w, h) = (40, 10);
        let mut data = vec![0.0f32; w * h];
        for y in 0..h {
            data[y * w + 5] = 0.25; // weak edge, far from the strong one
            data[y * w + 35] = 1.0;
        }
        let g = EdgeImage::from_vec(w as u32, h as u32, data).unwrap();
        let mut out = EdgeImage::default();
        let ln = LocalNorm {
            radius: 8,
            floor: 0.1,
        };
        local_normalise(&g, &ln, &mut LocalNormScratch::default(), &mut out).unwrap();
        assert_eq!(out.get(5, 3), Some(1.0));
        assert_eq!(out.get(35, 3), Some(1.0));
        assert_eq!(out.get(20, 3), Some(0.0));
        let zero = EdgeImage::constant(9, 4, 0.0).unwrap();
        local_normalise(&zero, &ln, &mut LocalNormScratch::default(), &mut out).unwrap();
        assert!(out.data().iter().all(|&v| v == 0.0));
    }

    #[test]
    fn bad_settings_are_errors() {
        let g = EdgeImage::constant(4, 4, 0.5).unwrap();
        let mut out = EdgeImage::default();
        for ln in [
            LocalNorm {
                radius: 0,
                floor: 0.1,
            },
            LocalNorm {
                radius: 3,
                floor: 0.0,
            },
            LocalNorm {
                radius: 3,
                floor: f32::NAN,
            },
            LocalNorm {
                radius: 3,
                floor: 1.5,
            },
        ] {
            assert!(local_normalise(&g, &ln, &mut LocalNormScratch::default(), &mut out).is_err());
        }
    }
}
