//! The raster contour: the union silhouette filled by tiny-skia and its inner 4-neighbour
//! boundary.

use tiny_skia::{FillRule, Mask, Transform};

use super::{Projected, RenderScratch};

/// Raster contour: fills the union silhouette into the scratch mask (tight bounding box,
/// non-zero winding, no anti-aliasing) and calls `visit(u, v)` for every pixel of the inner
/// 4-neighbour boundary that lies inside the `width × height` image.
pub(crate) fn raster_contour<F: FnMut(usize, usize)>(
    parts: &Projected,
    width: u32,
    height: u32,
    scratch: &mut RenderScratch,
    mut visit: F,
) {
    if parts.is_empty() {
        return;
    }
    let mut bb = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in parts.iter() {
        let b = p.bbox();
        bb = [
            bb[0].min(b[0]),
            bb[1].min(b[1]),
            bb[2].max(b[2]),
            bb[3].max(b[3]),
        ];
    }
    // Image pixels to scan (inclusive), then the mask covers one more pixel on each side.
    let (w, h) = (i64::from(width), i64::from(height));
    let sx0 = ((bb[0].floor() as i64) - 1).max(0);
    let sy0 = ((bb[1].floor() as i64) - 1).max(0);
    let sx1 = ((bb[2].ceil() as i64) + 1).min(w - 1);
    let sy1 = ((bb[3].ceil() as i64) + 1).min(h - 1);
    if sx0 > sx1 || sy0 > sy1 {
        return;
    }
    let (ox, oy) = (sx0 - 1, sy0 - 1);
    let mw = (sx1 - sx0 + 3) as u32;
    let mh = (sy1 - sy0 + 3) as u32;
    let need_new = scratch
        .mask
        .as_ref()
        .is_none_or(|m| m.width() < mw || m.height() < mh);
    if need_new {
        let (cw, ch) = scratch
            .mask
            .as_ref()
            .map_or((0, 0), |m| (m.width(), m.height()));
        scratch.mask = Mask::new(mw.max(cw), mh.max(ch));
    }
    let Some(mask) = scratch.mask.as_mut() else {
        return;
    };
    let mut pb = scratch.builder.take().unwrap_or_default();
    // Mask pixel (i, j) ↔ image pixel (ox+i, oy+j), whose centre is mask point (i+½, j+½).
    let (tx, ty) = (0.5 - ox as f64, 0.5 - oy as f64);
    for part in parts.iter() {
        let mut first = true;
        part.walk_outline(1.0, true, |x| {
            let (px, py) = ((x.x + tx) as f32, (x.y + ty) as f32);
            if first {
                pb.move_to(px, py);
                first = false;
            } else {
                pb.line_to(px, py);
            }
        });
        pb.close();
    }
    let stride = mask.width() as usize;
    let Some(path) = pb.finish() else {
        return;
    };
    mask.fill_path(&path, FillRule::Winding, false, Transform::identity());
    // Region that the fill may have touched, to restore the all-zero invariant afterwards.
    let pbb = path.bounds();
    let clear = [
        (f64::from(pbb.left()).floor() as i64 - 1).clamp(0, i64::from(mask.width())) as usize,
        (f64::from(pbb.top()).floor() as i64 - 1).clamp(0, i64::from(mask.height())) as usize,
        (f64::from(pbb.right()).ceil() as i64 + 1).clamp(0, i64::from(mask.width())) as usize,
        (f64::from(pbb.bottom()).ceil() as i64 + 1).clamp(0, i64::from(mask.height())) as usize,
    ];
    scratch.builder = Some(path.clear());
    let data = mask.data_mut();
    let (mw, mh) = (mw as usize, mh as usize);
    let word = |s: &[u8], at: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&s[at..at + 8]);
        u64::from_le_bytes(b)
    };
    for j in 1..mh - 1 {
        let up = &data[(j - 1) * stride..(j - 1) * stride + mw];
        let cur = &data[j * stride..j * stride + mw];
        let dn = &data[(j + 1) * stride..(j + 1) * stride + mw];
        let v = (oy + j as i64) as usize;
        // Eight pixels at a time: a non-AA fill writes only 0 and 255, so the boundary bytes
        // are `cur & !(left & right & up & down)`; all-empty and all-interior words are skipped.
        let mut i = 1;
        while i + 9 <= mw {
            let c = word(cur, i);
            if c != 0 {
                let all = word(cur, i - 1) & word(cur, i + 1) & word(up, i) & word(dn, i);
                let mut b = c & !all;
                while b != 0 {
                    let k = (b.trailing_zeros() / 8) as usize;
                    visit((ox + (i + k) as i64) as usize, v);
                    b &= !(0xFFu64 << (8 * k));
                }
            }
            i += 8;
        }
        while i < mw - 1 {
            if cur[i] != 0 && (cur[i - 1] == 0 || cur[i + 1] == 0 || up[i] == 0 || dn[i] == 0) {
                visit((ox + i as i64) as usize, v);
            }
            i += 1;
        }
    }
    if clear[0] < clear[2] {
        for j in clear[1]..clear[3] {
            data[j * stride + clear[0]..j * stride + clear[2]].fill(0);
        }
    }
}

/// Rasterised silhouette of the parts as a full-image 0/1 mask (row-major `u8`), for tests and
/// overlays.
#[cfg(test)]
pub(crate) fn silhouette(parts: &Projected, width: u32, height: u32) -> Vec<u8> {
    let mut out = vec![0u8; width as usize * height as usize];
    let Some(size) = tiny_skia::IntSize::from_wh(width, height) else {
        return out;
    };
    let Some(mut mask) = Mask::new(size.width(), size.height()) else {
        return out;
    };
    let mut pb = tiny_skia::PathBuilder::new();
    for part in parts.iter() {
        let mut first = true;
        part.walk_outline(1.0, true, |x| {
            let (px, py) = ((x.x + 0.5) as f32, (x.y + 0.5) as f32);
            if first {
                pb.move_to(px, py);
                first = false;
            } else {
                pb.line_to(px, py);
            }
        });
        pb.close();
    }
    if let Some(path) = pb.finish() {
        mask.fill_path(&path, FillRule::Winding, false, Transform::identity());
    }
    for (o, &m) in out.iter_mut().zip(mask.data()) {
        *o = u8::from(m != 0);
    }
    out
}
