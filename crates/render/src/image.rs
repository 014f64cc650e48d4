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
