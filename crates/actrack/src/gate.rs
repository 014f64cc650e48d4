//! The foreground gate of the edge image (not in SPEC §4.1): G is multiplied by a mask of the
//! pixels that differ from a background the tracker keeps, so that the edges of what does not
//! move (a torso's outline, clutter on the table) stop attracting the arm's contour.
//!
//! A pixel is foreground where its grey value differs from the background by more than a
//! threshold; the mask is dilated by a square of half-width `radius` and
//! G' = G · (floor + (1 − floor) · mask). The background is causal: the first frame, then after
//! each frame's step B ← B + rate · (I − B) at every pixel farther than `margin` pixels from the
//! tracked arm's silhouette, so the arm is not learnt as background while the track follows it
//! (a cup held at the mouth stays foreground).

use actrack_render::{ArmGeometry, Camera, DilateScratch, EdgeImage, ImageView};

use crate::config::GateConfig;
use crate::error::{Error, Result};

/// The gate of one view: its background and buffers (no allocation after the first frame of a
/// size).
#[derive(Debug, Default)]
pub struct ForegroundGate {
    background: Vec<f32>,
    chan: Vec<f32>,
    /// The grey values of the frame `apply` gated last, for `update` of the same frame.
    grey: Vec<f32>,
    /// Whether `grey` holds the frame that `update` is given next.
    fresh: bool,
    foreground: Vec<u8>,
    covered: Vec<u8>,
    dilate: DilateScratch,
    mask: Vec<u8>,
}

impl ForegroundGate {
    /// The background (grey values, row-major); `None` before the first frame.
    pub fn background(&self) -> Option<&[f32]> {
        (!self.background.is_empty()).then_some(self.background.as_slice())
    }

    /// Gates `g`, the edge image of `view`: starts the background from `view` on the first
    /// frame, then G ← G · (floor + (1 − floor) · mask).
    ///
    /// # Errors
    /// When `view`, the background and `g` differ in size.
    pub fn apply(
        &mut self,
        cfg: &GateConfig,
        view: ImageView<'_>,
        g: &mut EdgeImage,
    ) -> Result<()> {
        let (w, h) = view.size();
        if self.background.is_empty() {
            actrack_render::grey_image(view, &mut self.chan, &mut self.background);
        }
        if self.background.len() != w as usize * h as usize || g.width() != w || g.height() != h {
            return Err(Error::Config(format!(
                "foreground gate: a {w}×{h} frame against a background of {} pixels",
                self.background.len()
            )));
        }
        actrack_render::grey_image(view, &mut self.chan, &mut self.grey);
        self.fresh = true;
        self.foreground.clear();
        self.foreground.extend(
            self.grey
                .iter()
                .zip(&self.background)
                .map(|(&i, &b)| u8::from((i - b).abs() > cfg.threshold)),
        );
        actrack_render::dilate_mask(
            &self.foreground,
            (w as usize, h as usize),
            cfg.radius as usize,
            &mut self.dilate,
            &mut self.mask,
        )
        .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
        // The factor floor + (1 − floor)·m for m = 1 and m = 0.
        let (on, off) = (cfg.floor + (1.0 - cfg.floor), cfg.floor);
        let mut data = std::mem::take(g).into_data();
        for (d, &m) in data.iter_mut().zip(&self.mask) {
            *d *= if m != 0 { on } else { off };
        }
        *g = EdgeImage::from_vec(w, h, data)
            .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
        Ok(())
    }

    /// After a frame's step: blends `view` into the background at `cfg.rate` away from the
    /// silhouettes of the `tracked` poses (world) grown by `cfg.margin` pixels. `view` is the
    /// frame last given to [`apply`](Self::apply), if any (its grey values are reused).
    ///
    /// # Errors
    /// When `view` and the background differ in size.
    pub fn update(
        &mut self,
        cfg: &GateConfig,
        view: ImageView<'_>,
        camera: &Camera,
        geometry: &ArmGeometry,
        tracked: &[&[f64; 9]],
    ) -> Result<()> {
        let (w, h) = view.size();
        if self.background.is_empty() {
            actrack_render::grey_image(view, &mut self.chan, &mut self.background);
        }
        // The grey frame of `apply` when this is the frame it gated.
        if !std::mem::take(&mut self.fresh) || self.grey.len() != w as usize * h as usize {
            actrack_render::grey_image(view, &mut self.chan, &mut self.grey);
        }
        if self.grey.len() != self.background.len() {
            return Err(Error::Config(format!(
                "foreground gate: a {w}×{h} frame against a background of {} pixels",
                self.background.len()
            )));
        }
        self.covered.clear();
        self.covered.resize(self.grey.len(), 0);
        for pose in tracked {
            if !pose.iter().all(|x| x.is_finite()) {
                continue;
            }
            let parts = actrack_render::project_parts(camera, geometry, pose);
            actrack_render::cover_parts(&parts, f64::from(cfg.margin), w, h, &mut self.covered)
                .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
        }
        blend(&mut self.background, &self.grey, &self.covered, cfg.rate);
        Ok(())
    }
}

/// B ← B + rate · (I − B) where `covered` is 0 (equal sizes).
pub fn blend(background: &mut [f32], grey: &[f32], covered: &[u8], rate: f32) {
    for ((b, &g), &c) in background.iter_mut().zip(grey).zip(covered) {
        if c == 0 {
            *b += rate * (g - *b);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blend_skips_covered_pixels() {
        let mut b = vec![0.0, 0.0, 10.0];
        blend(&mut b, &[10.0, 10.0, 20.0], &[0, 1, 0], 0.5);
        assert_eq!(b, vec![5.0, 0.0, 15.0]);
    }

    #[test]
    fn gate_keeps_edges_that_move_and_damps_the_rest() {
        let cfg = GateConfig {
            radius: 0,
            ..GateConfig::default()
        };
        let (w, h) = (4u32, 1u32);
        let first = vec![50u8; (w * h * 3) as usize];
        let mut second = first.clone();
        second[0..3].copy_from_slice(&[200, 200, 200]);
        let mut gate = ForegroundGate::default();
        let mut g = EdgeImage::from_vec(w, h, vec![1.0; 4]).unwrap();
        gate.apply(&cfg, ImageView::rgb8(&first, w, h).unwrap(), &mut g)
            .unwrap();
        // Nothing moved against the first frame: every pixel is damped to the floor.
        assert!(g.data().iter().all(|&x| (x - cfg.floor).abs() < 1e-6));
        let mut g = EdgeImage::from_vec(w, h, vec![1.0; 4]).unwrap();
        gate.apply(&cfg, ImageView::rgb8(&second, w, h).unwrap(), &mut g)
            .unwrap();
        assert!((g.data()[0] - 1.0).abs() < 1e-6);
        assert!((g.data()[1] - cfg.floor).abs() < 1e-6);
    }
}
