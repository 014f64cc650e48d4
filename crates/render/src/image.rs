//! Small image types: borrowed input frames and an owned RGB8 image.

use crate::RenderError;

/// A borrowed frame, row-major, no padding between rows.
#[derive(Debug, Clone, Copy)]
pub enum ImageView<'a> {
    /// Interleaved RGB, 8 bits per channel (`3·w·h` bytes).
    Rgb8 {
        /// Pixel data.
        data: &'a [u8],
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// Grey, 8 bits (`w·h` bytes).
    Grey8 {
        /// Pixel data.
        data: &'a [u8],
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// Grey, f32 (`w·h` values, any scale).
    GreyF32 {
        /// Pixel data.
        data: &'a [f32],
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
}

fn check(len: usize, channels: usize, width: u32, height: u32) -> Result<(), RenderError> {
    if width == 0 || height == 0 {
        return Err(RenderError::InvalidImage(format!(
            "zero-size image {width}×{height}"
        )));
    }
    let need = (width as usize)
        .checked_mul(height as usize)
        .and_then(|n| n.checked_mul(channels))
        .ok_or_else(|| RenderError::InvalidImage("image size overflows".to_owned()))?;
    if len != need {
        return Err(RenderError::InvalidImage(format!(
            "{width}×{height}×{channels} image needs {need} values, got {len}"
        )));
    }
    Ok(())
}

impl<'a> ImageView<'a> {
    /// An RGB8 view; checks that `data.len() == 3·w·h` and the size is non-zero.
    pub fn rgb8(data: &'a [u8], width: u32, height: u32) -> Result<Self, RenderError> {
        check(data.len(), 3, width, height)?;
        Ok(Self::Rgb8 {
            data,
            width,
            height,
        })
    }

    /// A grey8 view; checks that `data.len() == w·h` and the size is non-zero.
    pub fn grey8(data: &'a [u8], width: u32, height: u32) -> Result<Self, RenderError> {
        check(data.len(), 1, width, height)?;
        Ok(Self::Grey8 {
            data,
            width,
            height,
        })
    }

    /// A grey f32 view; checks that `data.len() == w·h` and the size is non-zero.
    pub fn grey_f32(data: &'a [f32], width: u32, height: u32) -> Result<Self, RenderError> {
        check(data.len(), 1, width, height)?;
        Ok(Self::GreyF32 {
            data,
            width,
            height,
        })
    }

    /// (width, height).
    pub fn size(&self) -> (u32, u32) {
        match *self {
            Self::Rgb8 { width, height, .. }
            | Self::Grey8 { width, height, .. }
            | Self::GreyF32 { width, height, .. } => (width, height),
        }
    }

    /// Re-checks the buffer length (the variants have public fields).
    pub fn validate(&self) -> Result<(), RenderError> {
        match *self {
            Self::Rgb8 {
                data,
                width,
                height,
            } => check(data.len(), 3, width, height),
            Self::Grey8 {
                data,
                width,
                height,
            } => check(data.len(), 1, width, height),
            Self::GreyF32 {
                data,
                width,
                height,
            } => check(data.len(), 1, width, height),
        }
    }
}

/// Buffers of [`downscale`] (reused across frames).
#[derive(Debug, Default)]
pub struct DownscaleBuf {
    bytes: Vec<u8>,
    floats: Vec<f32>,
    sums: Vec<u32>,
    /// The last output's size and channels (3: RGB8, 1: grey8, 0: grey f32).
    last: Option<(u32, u32, u8)>,
}

impl DownscaleBuf {
    /// The image the last [`downscale`] into this buffer returned.
    pub fn last(&self) -> Option<ImageView<'_>> {
        let (w, h, c) = self.last?;
        match c {
            3 => ImageView::rgb8(&self.bytes, w, h).ok(),
            1 => ImageView::grey8(&self.bytes, w, h).ok(),
            _ => ImageView::grey_f32(&self.floats, w, h).ok(),
        }
    }
}

/// `view` shrunk by the integer `factor`: every output pixel is the mean of a `factor`² block
/// (rounded for 8-bit images); the last `width mod factor` columns and `height mod factor` rows
/// are dropped. Output pixel j's centre is input coordinate `factor·j + (factor − 1)/2`, which
/// [`crate::Camera::downscaled`] follows.
///
/// # Errors
/// [`RenderError::InvalidImage`] when `factor` is 0 or larger than a side of the image.
pub fn downscale<'b>(
    view: ImageView<'_>,
    factor: u32,
    buf: &'b mut DownscaleBuf,
) -> Result<ImageView<'b>, RenderError> {
    view.validate()?;
    let (w, h) = view.size();
    if factor == 0 || factor > w || factor > h {
        return Err(RenderError::InvalidImage(format!(
            "cannot shrink a {w}×{h} image by {factor}"
        )));
    }
    buf.last = None;
    let (f, w, h) = (factor as usize, w as usize, h as usize);
    let (ow, oh) = (w / f, h / f);
    let channels = match view {
        ImageView::Rgb8 { .. } => 3,
        _ => 1,
    };
    let n = (f * f) as u32;
    match view {
        ImageView::Rgb8 { data, .. } | ImageView::Grey8 { data, .. } => {
            buf.bytes.clear();
            buf.bytes.reserve(ow * oh * channels);
            for oy in 0..oh {
                buf.sums.clear();
                buf.sums.resize(ow * channels, 0);
                for y in oy * f..oy * f + f {
                    let row = &data[y * w * channels..(y * w + ow * f) * channels];
                    // One output pixel's `f` input pixels at a time.
                    for (sums, block) in buf
                        .sums
                        .chunks_exact_mut(channels)
                        .zip(row.chunks_exact(f * channels))
                    {
                        for px in block.chunks_exact(channels) {
                            for (s, &v) in sums.iter_mut().zip(px) {
                                *s += u32::from(v);
                            }
                        }
                    }
                }
                // Rounded to nearest; the mean of bytes fits a byte.
                #[allow(clippy::cast_possible_truncation)]
                buf.bytes
                    .extend(buf.sums.iter().map(|&s| ((s + n / 2) / n) as u8));
            }
            let (ow, oh) = (ow as u32, oh as u32);
            buf.last = Some((ow, oh, channels as u8));
            if channels == 3 {
                ImageView::rgb8(&buf.bytes, ow, oh)
            } else {
                ImageView::grey8(&buf.bytes, ow, oh)
            }
        }
        ImageView::GreyF32 { data, .. } => {
            buf.floats.clear();
            buf.floats.resize(ow * oh, 0.0);
            for oy in 0..oh {
                let out = &mut buf.floats[oy * ow..(oy + 1) * ow];
                for y in oy * f..oy * f + f {
                    for (o, block) in out
                        .iter_mut()
                        .zip(data[y * w..y * w + ow * f].chunks_exact(f))
                    {
                        *o += block.iter().sum::<f32>();
                    }
                }
            }
            let inv = 1.0 / n as f32;
            for v in &mut buf.floats {
                *v *= inv;
            }
            buf.last = Some((ow as u32, oh as u32, 0));
            ImageView::grey_f32(&buf.floats, ow as u32, oh as u32)
        }
    }
}

/// An owned RGB8 image (interleaved, row-major), e.g. a synthesised frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageRgb8 {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `3·w·h` bytes.
    pub data: Vec<u8>,
}

impl ImageRgb8 {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![0; 3 * width as usize * height as usize],
        }
    }

    /// A borrowed view for [`crate::EdgeWorkspace::compute`].
    pub fn view(&self) -> ImageView<'_> {
        ImageView::Rgb8 {
            data: &self.data,
            width: self.width,
            height: self.height,
        }
    }

    /// The pixel at (u, v), `None` outside.
    pub fn get(&self, u: u32, v: u32) -> Option<[u8; 3]> {
        if u >= self.width || v >= self.height {
            return None;
        }
        let i = 3 * (v as usize * self.width as usize + u as usize);
        Some([self.data[i], self.data[i + 1], self.data[i + 2]])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn downscale_averages_blocks_and_drops_the_remainder() {
        // 5×3 RGB: shrunk by 2 to 2×1 (the last column and row are dropped).
        let data: Vec<u8> = (0..45u8).collect();
        let mut buf = DownscaleBuf::default();
        let out = downscale(ImageView::rgb8(&data, 5, 3).unwrap(), 2, &mut buf).unwrap();
        assert_eq!(out.size(), (2, 1));
        let out = buf.last().unwrap();
        let ImageView::Rgb8 { data: got, .. } = out else {
            panic!("not RGB");
        };
        // Brute force: the rounded mean of each block's channel.
        let px = |x: usize, y: usize, c: usize| u32::from(data[3 * (y * 5 + x) + c]);
        for ox in 0..2 {
            for c in 0..3 {
                let s: u32 = (0..2)
                    .flat_map(|dy| (0..2).map(move |dx| (2 * ox + dx, dy)))
                    .map(|(x, y)| px(x, y, c))
                    .sum();
                assert_eq!(u32::from(got[3 * ox + c]), (s + 2) / 4);
            }
        }
        let grey: Vec<f32> = (0..12).map(|v| v as f32).collect();
        let out = downscale(ImageView::grey_f32(&grey, 4, 3).unwrap(), 3, &mut buf).unwrap();
        let ImageView::GreyF32 { data: got, .. } = out else {
            panic!("not f32");
        };
        assert_eq!(
            got,
            &[(0.0 + 1.0 + 2.0 + 4.0 + 5.0 + 6.0 + 8.0 + 9.0 + 10.0) / 9.0]
        );
    }

    #[test]
    fn downscale_rejects_factors_that_leave_nothing() {
        let data = [0u8; 12];
        let mut buf = DownscaleBuf::default();
        for f in [0, 5] {
            assert!(downscale(ImageView::grey8(&data, 4, 3).unwrap(), f, &mut buf).is_err());
        }
    }
}
