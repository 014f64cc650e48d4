//! The foreground gate of the edge image (not in SPEC §4.1): G is multiplied by a mask of the
//! pixels that differ from a background the tracker keeps, so that the edges of what does not
//! move (a torso's outline, clutter on the table) stop attracting the arm's contour.
//!
//! A pixel is foreground where its grey value differs from the background by more than a
//! threshold; the mask is dilated by a square of half-width `radius` and
//! G' = G · (floor + (1 − floor) · mask). The background is causal: the first frame, then after
//! each frame's step B ← B + rate · (I − B) at every pixel farther than `margin` pixels from the
//! tracked arm's silhouette, so the arm is not learnt as background while the track follows it
//! (a cup held at the mouth stays foreground). When the edge image is computed in a region only
//! (`observation.edge_region`), the gate works in that region, which is blended every frame; the
//! rest of the background is blended one row in [`SWEEP`] per frame at the compounded rate.

use actrack_render::{ArmGeometry, Camera, DilateScratch, EdgeImage, ImageView, PixelRect};

use crate::config::GateConfig;
use crate::error::{Error, Result};

/// The gate of one view: its background and buffers (no allocation after the first frame of a
/// size).
#[derive(Debug, Default)]
pub struct ForegroundGate {
    background: Vec<f32>,
    /// The grey values of the region `apply` gated last, for `update` of the same frame.
    grey: Vec<f32>,
    /// The region whose grey values `grey` holds, when they are of the frame `update` is
    /// given next.
    fresh: Option<PixelRect>,
    /// One row's grey values.
    row: Vec<f32>,
    /// The rows of the next frame's turn outside the gated region (`SWEEP`).
    sweep: usize,
    foreground: Vec<u8>,
    covered: Vec<u8>,
    /// The rectangle of `covered`'s set pixels.
    set: PixelRect,
    /// The frame size `covered` was made for.
    covered_size: (u32, u32),
    dilate: DilateScratch,
    mask: Vec<u8>,
}

impl ForegroundGate {
    /// The background (grey values, row-major); `None` before the first frame.
    pub fn background(&self) -> Option<&[f32]> {
        (!self.background.is_empty()).then_some(self.background.as_slice())
    }

    /// Gates `g`, the edge image of the pixels `rect` of `view` (`pixels` holds them, see
    /// `actrack_render::crop`; the whole frame: `rect` = the frame, `pixels` = `view`): starts
    /// the background from `view` on the first frame, then G ← G · (floor + (1 − floor) · mask)
    /// with the mask found inside `rect`.
    ///
    /// # Errors
    /// When `view` and the background differ in size, or `rect` is empty or `rect`, `pixels`
    /// and `g` do not fit.
    pub fn apply(
        &mut self,
        cfg: &GateConfig,
        view: ImageView<'_>,
        rect: PixelRect,
        pixels: ImageView<'_>,
        g: &mut EdgeImage,
    ) -> Result<()> {
        let (w, h) = view.size();
        if self.background.is_empty() {
            actrack_render::grey_image(view, &mut self.background);
        }
        let (rw, rh) = (rect.width(), rect.height());
        if self.background.len() != w as usize * h as usize
            || rect.is_empty()
            || !PixelRect::full(w, h).contains(&rect)
            || pixels.size() != (rw, rh)
            || (g.width(), g.height()) != (rw, rh)
        {
            return Err(Error::Config(format!(
                "foreground gate: a {w}×{h} frame against a background of {} pixels",
                self.background.len()
            )));
        }
        actrack_render::grey_image(pixels, &mut self.grey);
        self.fresh = Some(rect);
        self.foreground.resize(self.grey.len(), 0);
        let (x0, x1) = (rect.x0 as usize, rect.x1 as usize);
        let rows = self.grey.chunks_exact(rw as usize);
        let fg = self.foreground.chunks_exact_mut(rw as usize);
        for ((y, grey), fg) in (rect.y0 as usize..).zip(rows).zip(fg) {
            let back = &self.background[y * w as usize + x0..y * w as usize + x1];
            actrack_render::foreground_mask(grey, back, cfg.threshold, fg);
        }
        actrack_render::dilate_mask(
            &self.foreground,
            (rw as usize, rh as usize),
            cfg.radius as usize,
            &mut self.dilate,
            &mut self.mask,
        )
        .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
        // The factor floor + (1 − floor)·m for m = 1 and m = 0.
        let (on, off) = (cfg.floor + (1.0 - cfg.floor), cfg.floor);
        let mut data = std::mem::take(g).into_data();
        actrack_render::scale_by_mask(&mut data, &self.mask, on, off);
        *g = EdgeImage::from_vec(rw, rh, data)
            .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
        Ok(())
    }

    /// After a frame's step: blends `view` into the background at `cfg.rate` away from the
    /// silhouettes of the `tracked` poses (world) grown by `cfg.margin` pixels. `rect` is the
    /// region [`apply`](Self::apply) gated (the whole frame when it gated all of it): its
    /// pixels are blended every frame, with the grey values `apply` found for this frame; the
    /// others, which the gate did not read, one row in [`SWEEP`] per frame in turn at the rate
    /// that compounds to `SWEEP` frames, 1 − (1 − rate)^SWEEP, so a static background is learnt
    /// as fast as by blending every pixel every frame.
    ///
    /// # Errors
    /// When `view` and the background differ in size or `rect` does not lie in the frame.
    pub fn update(
        &mut self,
        cfg: &GateConfig,
        view: ImageView<'_>,
        rect: PixelRect,
        camera: &Camera,
        geometry: &ArmGeometry,
        tracked: &[&[f64; 9]],
    ) -> Result<()> {
        let (w, h) = view.size();
        if self.background.is_empty() {
            actrack_render::grey_image(view, &mut self.background);
        }
        let n = w as usize * h as usize;
        if self.background.len() != n || !PixelRect::full(w, h).contains(&rect) {
            return Err(Error::Config(format!(
                "foreground gate: a {w}×{h} frame against a background of {} pixels",
                self.background.len()
            )));
        }
        // The grey values of `rect` from `apply` when this is the frame and region it gated.
        let (rw, rh) = (rect.width() as usize, rect.height() as usize);
        if self.fresh.take() != Some(rect) || self.grey.len() != rw * rh {
            self.grey.clear();
            for y in rect.y0..rect.y1 {
                let row = row_view(view, y, rect.x0, rect.x1)?;
                actrack_render::grey_image(row, &mut self.row);
                self.grey.extend_from_slice(&self.row);
            }
        }
        // Only the pixels the last frame covered need clearing, when it was of this size.
        if self.covered_size == (w, h) && self.covered.len() == n {
            let c = self.set;
            for y in c.y0 as usize..c.y1 as usize {
                self.covered[y * w as usize + c.x0 as usize..y * w as usize + c.x1 as usize]
                    .fill(0);
            }
        } else {
            self.covered.clear();
            self.covered.resize(n, 0);
            self.covered_size = (w, h);
        }
        self.set = PixelRect::default();
        for pose in tracked {
            if !pose.iter().all(|x| x.is_finite()) {
                continue;
            }
            let parts = actrack_render::project_parts(camera, geometry, pose);
            let set =
                actrack_render::cover_parts(&parts, f64::from(cfg.margin), w, h, &mut self.covered)
                    .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
            self.set = self.set.union(&set);
        }
        let w = w as usize;
        let (x0, x1) = (rect.x0 as usize, rect.x1 as usize);
        if rw > 0 {
            for (y, grey) in (rect.y0 as usize..).zip(self.grey.chunks_exact(rw)) {
                let at = y * w + x0..y * w + x1;
                // The grey values are finite, so the f32 view passes them as they are.
                #[allow(clippy::cast_possible_truncation)] // the region's width
                let grey = ImageView::grey_f32(grey, rw as u32, 1)
                    .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
                actrack_render::blend_background(
                    &mut self.background[at.clone()],
                    grey,
                    &self.covered[at],
                    cfg.rate,
                )
                .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
            }
        }
        if rect == PixelRect::full(w as u32, h) {
            return Ok(());
        }
        // The rows of this frame's turn, outside `rect`.
        let rate = 1.0 - (1.0 - cfg.rate).powi(SWEEP as i32);
        let phase = self.sweep;
        self.sweep = (self.sweep + 1) % SWEEP;
        for y in (phase..h as usize).step_by(SWEEP) {
            let inside = (rect.y0 as usize..rect.y1 as usize).contains(&y) && rw > 0;
            let spans = if inside {
                [(0, x0), (x1, w)]
            } else {
                [(0, w), (w, w)]
            };
            for (a, b) in spans {
                if a == b {
                    continue;
                }
                #[allow(clippy::cast_possible_truncation)] // both are at most the width
                let row = row_view(view, y as u32, a as u32, b as u32)?;
                let at = y * w + a..y * w + b;
                actrack_render::blend_background(
                    &mut self.background[at.clone()],
                    row,
                    &self.covered[at],
                    rate,
                )
                .map_err(|e| Error::Config(format!("foreground gate: {e}")))?;
            }
        }
        Ok(())
    }
}

/// Rows outside the gated region are blended into the background once every `SWEEP` frames.
pub const SWEEP: usize = 4;

/// The pixels `x0 .. x1` of row `y` of `view` as an image of one row.
fn row_view(view: ImageView<'_>, y: u32, x0: u32, x1: u32) -> Result<ImageView<'_>> {
    let w = view.size().0 as usize;
    let (y, x0, x1) = (y as usize, x0 as usize, x1 as usize);
    let width = u32::try_from(x1 - x0).unwrap_or(u32::MAX);
    match view {
        ImageView::Rgb8 { data, .. } => {
            ImageView::rgb8(&data[3 * (y * w + x0)..3 * (y * w + x1)], width, 1)
        }
        ImageView::Grey8 { data, .. } => ImageView::grey8(&data[y * w + x0..y * w + x1], width, 1),
        ImageView::GreyF32 { data, .. } => {
            ImageView::grey_f32(&data[y * w + x0..y * w + x1], width, 1)
        }
    }
    .map_err(|e| Error::Config(format!("foreground gate: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(d: &[u8]) -> ImageView<'_> {
        ImageView::rgb8(d, 8, 8).unwrap()
    }

    #[test]
    fn a_region_and_its_sweep_learn_a_static_background_alike() {
        let cfg = GateConfig::default();
        let (w, h) = (8u32, 8u32);
        let first = vec![50u8; (w * h * 3) as usize];
        let second = vec![90u8; (w * h * 3) as usize];
        let rect = PixelRect {
            x0: 2,
            y0: 3,
            x1: 5,
            y1: 6,
        };
        let (cam, geom) = (
            Camera::look_at(
                nalgebra::Vector3::new(0.0, -2.0, 1.0),
                nalgebra::Vector3::zeros(),
                nalgebra::Vector3::z(),
                w,
                h,
                1.0,
            )
            .unwrap(),
            ArmGeometry::default(),
        );
        let mut gate = ForegroundGate::default();
        gate.update(&cfg, view(&first), rect, &cam, &geom, &[])
            .unwrap();
        // Every pixel starts from the first frame; after SWEEP frames of the second, every
        // pixel has moved by 1 − (1 − rate)^SWEEP of the difference, in the region frame by
        // frame, elsewhere in one step.
        let start = gate.background().unwrap().to_vec();
        for _ in 0..SWEEP {
            gate.update(&cfg, view(&second), rect, &cam, &geom, &[])
                .unwrap();
        }
        let want = 1.0 - (1.0 - cfg.rate).powi(SWEEP as i32);
        for (i, (&b, &s)) in gate.background().unwrap().iter().zip(&start).enumerate() {
            let moved = (b - s) / (90.0 - s);
            assert!((moved - want).abs() < 1e-4, "pixel {i}: {moved} vs {want}");
        }
        // An empty region is refused, not a panic.
        let mut g = EdgeImage::default();
        assert!(
            gate.apply(
                &cfg,
                view(&first),
                PixelRect::default(),
                view(&first),
                &mut g
            )
            .is_err()
        );
    }

    /// A frame of another shape with as many pixels is blended without a panic: the covered
    /// mask is made again for its size rather than cleared where the last frame set it.
    #[test]
    fn a_frame_of_another_shape_remakes_the_covered_mask() {
        let cfg = GateConfig::default();
        let cam = |w: u32, h: u32| {
            Camera::look_at(
                nalgebra::Vector3::new(0.0, -2.0, 1.0),
                nalgebra::Vector3::new(0.0, 0.3, 0.9),
                nalgebra::Vector3::z(),
                w,
                h,
                1.2,
            )
            .unwrap()
        };
        let pose = [0.2, 0.0, 1.2, 0.25, 0.1, 0.93, 0.2, 0.52, 0.9];
        let geom = ArmGeometry::default();
        let mut gate = ForegroundGate::default();
        for (w, h) in [(16u32, 64u32), (64, 16)] {
            let frame = vec![80u8; (w * h * 3) as usize];
            let view = ImageView::rgb8(&frame, w, h).unwrap();
            gate.update(
                &cfg,
                view,
                PixelRect::full(w, h),
                &cam(w, h),
                &geom,
                &[&pose],
            )
            .unwrap();
            assert!(gate.covered.contains(&1), "{w}×{h}");
        }
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
        let all = PixelRect::full(w, h);
        let view = ImageView::rgb8(&first, w, h).unwrap();
        gate.apply(&cfg, view, all, view, &mut g).unwrap();
        // Nothing moved against the first frame: every pixel is damped to the floor.
        assert!(g.data().iter().all(|&x| (x - cfg.floor).abs() < 1e-6));
        let mut g = EdgeImage::from_vec(w, h, vec![1.0; 4]).unwrap();
        let view = ImageView::rgb8(&second, w, h).unwrap();
        gate.apply(&cfg, view, all, view, &mut g).unwrap();
        assert!((g.data()[0] - 1.0).abs() < 1e-6);
        assert!((g.data()[1] - cfg.floor).abs() < 1e-6);
    }
}
