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
//! comparisons per pixel and pass, independent of R).

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

/// Running maximum over windows `[i − r, i + r]` (clamped to the line) of `n` values read with
/// stride `step` from `src`, written with the same stride into `dst`.
fn window_max(
    src: &[f32],
    dst: &mut [f32],
    start: usize,
    step: usize,
    n: usize,
    r: usize,
    (prefix, suffix): (&mut Vec<f32>, &mut Vec<f32>),
) {
    let block = 2 * r + 1;
    prefix.clear();
    suffix.clear();
    prefix.resize(n, 0.0);
    suffix.resize(n, 0.0);
    let at = |i: usize| src[start + i * step];
    for i in 0..n {
        prefix[i] = if i % block == 0 {
            at(i)
        } else {
            prefix[i - 1].max(at(i))
        };
    }
    for i in (0..n).rev() {
        suffix[i] = if i % block == block - 1 || i == n - 1 {
            at(i)
        } else {
            suffix[i + 1].max(at(i))
        };
    }
    for i in 0..n {
        let lo = i.saturating_sub(r);
        let hi = (i + r).min(n - 1);
        // [lo, hi] spans at most two blocks: the suffix of lo's block and the prefix of hi's.
        let m = if lo / block == hi / block {
            // Inside one block (only at the ends of the line): scan.
            (lo..=hi).map(at).fold(f32::NEG_INFINITY, f32::max)
        } else {
            suffix[lo].max(prefix[hi])
        };
        dst[start + i * step] = m;
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
    for y in 0..h {
        window_max(src, rows, y * w, 1, w, radius, (prefix, suffix));
    }
    out.clear();
    out.resize(w * h, 0.0);
    for x in 0..w {
        window_max(rows, out, x, w, h, radius, (prefix, suffix));
    }
    Ok(())
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
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 40) as f32 / (1u64 << 24) as f32
        };
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
