//! The running background of a static camera's view: B ← B + rate · (I − B), away from the
//! pixels a tracked body covers (the foreground gate of the `actrack` crate).

use crate::{ImageView, RenderError};

/// Blends the grey values of `pixels` (converted as [`crate::grey_image`] converts them) into
/// `background`: B ← B + rate · (I − B) wherever `covered` is 0. `background` and `covered`
/// hold one value per pixel of `pixels`, in its row-major order. One pass over the pixels,
/// without a branch (a covered pixel adds 0 · rate · (I − B) = 0), compiled for the best
/// instruction set the CPU has.
///
/// # Errors
/// [`RenderError::InvalidImage`] if the lengths differ from the number of pixels.
pub fn blend_background(
    background: &mut [f32],
    pixels: ImageView<'_>,
    covered: &[u8],
    rate: f32,
) -> Result<(), RenderError> {
    let (w, h) = pixels.size();
    let n = w as usize * h as usize;
    if background.len() != n || covered.len() != n {
        return Err(RenderError::InvalidImage(format!(
            "background blend: {w}×{h} pixels against a background of {} and a mask of {}",
            background.len(),
            covered.len()
        )));
    }
    pulp::Arch::new().dispatch(Blend {
        background,
        pixels,
        covered,
        rate,
    });
    Ok(())
}

struct Blend<'a> {
    background: &'a mut [f32],
    pixels: ImageView<'a>,
    covered: &'a [u8],
    rate: f32,
}

impl pulp::WithSimd for Blend<'_> {
    type Output = ();

    // Inlined into the dispatched function.
    #[allow(clippy::inline_always)]
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let Self {
            background,
            pixels,
            covered,
            rate,
        } = self;
        let step = |b: &mut f32, g: f32, c: u8| *b += rate * (g - *b) * f32::from(u8::from(c == 0));
        match pixels {
            ImageView::Rgb8 { data, .. } => {
                let (px, _) = data.as_chunks::<3>();
                for ((b, p), &c) in background.iter_mut().zip(px).zip(covered) {
                    let g =
                        0.299 * f32::from(p[0]) + 0.587 * f32::from(p[1]) + 0.114 * f32::from(p[2]);
                    step(b, g, c);
                }
            }
            ImageView::Grey8 { data, .. } => {
                for ((b, &p), &c) in background.iter_mut().zip(data).zip(covered) {
                    step(b, f32::from(p), c);
                }
            }
            ImageView::GreyF32 { data, .. } => {
                for ((b, &p), &c) in background.iter_mut().zip(data).zip(covered) {
                    step(b, if p.is_finite() { p } else { 0.0 }, c);
                }
            }
        }
    }
}

/// The pixels that differ from the background: `out[i] = 1` where
/// `|grey[i] − background[i]| > threshold`, else 0 (equal lengths; the shortest decides). Compiled for the best
/// instruction set the CPU has.
pub fn foreground_mask(grey: &[f32], background: &[f32], threshold: f32, out: &mut [u8]) {
    struct Op<'a> {
        grey: &'a [f32],
        background: &'a [f32],
        threshold: f32,
        out: &'a mut [u8],
    }
    impl pulp::WithSimd for Op<'_> {
        type Output = ();

        // Inlined into the dispatched function.
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) {
            for ((o, &i), &b) in self.out.iter_mut().zip(self.grey).zip(self.background) {
                *o = u8::from((i - b).abs() > self.threshold);
            }
        }
    }
    pulp::Arch::new().dispatch(Op {
        grey,
        background,
        threshold,
        out,
    });
}

/// Scales each value by `on` where `mask` is non-zero and by `off` elsewhere (equal lengths;
/// the shortest decides). Compiled for the best instruction set the CPU has.
pub fn scale_by_mask(values: &mut [f32], mask: &[u8], on: f32, off: f32) {
    struct Op<'a> {
        values: &'a mut [f32],
        mask: &'a [u8],
        on: f32,
        off: f32,
    }
    impl pulp::WithSimd for Op<'_> {
        type Output = ();

        // Inlined into the dispatched function.
        #[allow(clippy::inline_always)]
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _simd: S) {
            for (v, &m) in self.values.iter_mut().zip(self.mask) {
                *v *= if m != 0 { self.on } else { self.off };
            }
        }
    }
    pulp::Arch::new().dispatch(Op {
        values,
        mask,
        on,
        off,
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grey_image;

    /// The fused blend of pixels equals the grey conversion followed by the blend of grey
    /// values, bit for bit, for every kind of image, and skips covered pixels.
    #[test]
    fn blending_pixels_equals_blending_their_grey_values() {
        let (w, h) = (37u32, 5u32);
        let n = (w * h) as usize;
        let rgb: Vec<u8> = (0..3 * n).map(|i| ((i * 97 + i / 5) % 256) as u8).collect();
        let grey8: Vec<u8> = rgb.iter().step_by(3).copied().collect();
        let mut f32s: Vec<f32> = grey8.iter().map(|&v| f32::from(v) * 0.7).collect();
        f32s[3] = f32::NAN;
        let covered: Vec<u8> = (0..n).map(|i| u8::from(i % 7 == 0)).collect();
        let start: Vec<f32> = (0..n).map(|i| (i % 251) as f32 * 0.9).collect();
        for view in [
            ImageView::rgb8(&rgb, w, h).unwrap(),
            ImageView::grey8(&grey8, w, h).unwrap(),
            ImageView::grey_f32(&f32s, w, h).unwrap(),
        ] {
            let mut fused = start.clone();
            blend_background(&mut fused, view, &covered, 0.1).unwrap();
            let mut grey = Vec::new();
            grey_image(view, &mut grey);
            let mut want = start.clone();
            for ((b, &g), &c) in want.iter_mut().zip(&grey).zip(&covered) {
                if c == 0 {
                    *b += 0.1 * (g - *b) * 1.0;
                }
            }
            let mut two = start.clone();
            let grey_view = ImageView::grey_f32(&grey, w, h).unwrap();
            blend_background(&mut two, grey_view, &covered, 0.1).unwrap();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&fused), bits(&want));
            assert_eq!(bits(&two), bits(&want));
            assert!(blend_background(&mut fused[1..], view, &covered, 0.1).is_err());
        }
    }

    /// The mask and the scaling give what the plain per-pixel expressions give.
    #[test]
    fn foreground_mask_and_scaling_are_the_per_pixel_expressions() {
        let grey: Vec<f32> = (0..67).map(|i| (i * 37 % 101) as f32).collect();
        let back: Vec<f32> = (0..67).map(|i| (i * 53 % 97) as f32 + 0.5).collect();
        let mut mask = vec![7u8; 67];
        foreground_mask(&grey, &back, 10.0, &mut mask);
        for ((&m, &i), &b) in mask.iter().zip(&grey).zip(&back) {
            assert_eq!(m, u8::from((i - b).abs() > 10.0));
        }
        assert!(mask.contains(&0) && mask.contains(&1));
        let mut values: Vec<f32> = (0..67).map(|i| i as f32 / 67.0).collect();
        let want: Vec<f32> = values
            .iter()
            .zip(&mask)
            .map(|(&v, &m)| v * if m != 0 { 1.0 } else { 0.1 })
            .collect();
        scale_by_mask(&mut values, &mask, 1.0, 0.1);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&values), bits(&want));
    }
}
