//! Projection of the arm into 2-D parts, the raster silhouette contour (tiny-skia) and the
//! analytic contour sampler (SPEC §4.2).
//!
//! * `projection`: arm pose → 2-D parts ([`Part2`]), coverage of parts on a mask;
//! * `outline`: the parts' precomputed form, their outline walk and sample runs;
//! * `raster`: the union silhouette and its inner boundary (tiny-skia);
//! * `analytic`: the portable analytic sampler (visit or sum, four lanes);
//! * `avx2`: the same sum with AVX2 f32 lanes and an exact f64 fallback.

use crate::{ArmGeometry, Camera};

mod analytic;
#[cfg(target_arch = "x86_64")]
mod avx2;
mod outline;
mod projection;
mod raster;
#[cfg(test)]
mod tests;

pub(crate) use analytic::*;
pub(crate) use outline::*;
pub(crate) use projection::*;
pub use projection::{RenderScratch, cover_parts, project_parts};
pub(crate) use raster::*;

/// Largest projected coordinate (pixels) a part may have; parts beyond this (points within
/// millimetres of the camera plane) are skipped rather than rasterised.
const MAX_COORD: f64 = 1.0e6;
/// Maximal sagitta (pixels) of the polygons approximating arcs in the raster silhouette.
const SAGITTA: f64 = 0.15;
/// Analytic samples deeper than this (pixels) inside another part are not on the union outline.
pub(crate) const INSIDE_TOL: f64 = 0.5;

/// How the contour C of a pose is obtained (SPEC §4.2). Record which one was used: the scores
/// differ slightly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum ContourMethod {
    /// Rasterise the union silhouette S (tiny-skia, no anti-aliasing) and take the inner
    /// boundary `C = {pixels in S with a 4-neighbour outside S}` (the normative method).
    #[default]
    Raster,
    /// Sample points every Δ pixels (default 2) along each part's projected outline, drop those
    /// inside another part (bodytrack style; much cheaper).
    Analytic,
}

/// One projected arm part in pixel coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Part2 {
    /// The convex hull of two discs (a truncated cone seen from the side, with round caps).
    Capsule {
        /// Centre of the first disc (u, v).
        c0: [f64; 2],
        /// Centre of the second disc.
        c1: [f64; 2],
        /// Radius of the first disc, pixels.
        r0: f64,
        /// Radius of the second disc, pixels.
        r1: f64,
    },
    /// An ellipse (the projected hand ellipsoid).
    Ellipse {
        /// Centre (u, v).
        c: [f64; 2],
        /// Semi-major axis, pixels.
        a: f64,
        /// Semi-minor axis, pixels.
        b: f64,
        /// Angle of the major axis from +u toward +v, radians.
        angle: f64,
    },
}

/// The contour of a pose in one view, for overlays: raster contour pixels or analytic sample
/// points (Δ = 2 px), in pixel coordinates, only points inside the image.
pub fn contour_points(
    camera: &Camera,
    geometry: &ArmGeometry,
    pose: &[f64; 9],
    method: ContourMethod,
) -> Vec<[f64; 2]> {
    let parts = project_prepared(camera, geometry, pose);
    let mut out = Vec::new();
    match method {
        ContourMethod::Raster => {
            let mut scratch = RenderScratch::new();
            raster_contour(&parts, camera.width, camera.height, &mut scratch, |u, v| {
                out.push([u as f64, v as f64]);
            });
        }
        ContourMethod::Analytic => {
            analytic_contour(&parts, camera.width, camera.height, 2.0, |u, v| {
                out.push([u, v]);
            });
        }
    }
    out
}
