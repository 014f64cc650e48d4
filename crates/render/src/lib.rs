//! The observation model of actrack (SPEC.md §4): camera, arm geometry, silhouette and contour
//! rendering, the edge image and the contour likelihood, plus scene synthesis for synthetic
//! experiments. It does no I/O: images come in and go out as slices with a width and a height.
//!
//! # Architecture
//!
//! ```text
//! frame (RGB8 / grey8 / f32) ──EdgeWorkspace::compute──▶ EdgeImage G (§4.1), once per view+frame
//!
//! pose [p q r] (9 × f64, metres, world) ──correct_arm (§3.4)──▶ x̃
//!      │
//!      ├─ per view: Camera::project (pinhole + Brown) ──▶ 2-D parts (two capsules + an ellipse)
//!      │      ├─ ContourMethod::Raster:   tiny-skia fill of the union into a tight Mask,
//!      │      │                           inner 4-neighbour boundary C (§4.2)
//!      │      └─ ContourMethod::Analytic: points every Δ px along each part's outline that are
//!      │                                  not inside another part (bodytrack style)
//!      └─ ε̄_v = mean_{c∈C_v} (1 − G_v(c))²;  log P = −Σ_v ε̄_v / (2γ²)   (§4.3, §4.4)
//! ```
//!
//! * [`Camera`]: OpenCV-compatible pinhole camera (K, Brown k1 k2 p1 p2 k3, X_c = R X_w + t).
//! * [`ArmGeometry`] and [`correct_arm`]: segment lengths and radii, the arm-length correction.
//! * [`EdgeParams`], [`EdgeWorkspace`], [`EdgeImage`]: the edge image G.
//! * [`LikelihoodModel`]: the likelihood of one pose or of a batch of poses (rayon), with
//!   [`ContourMethod`] choosing the raster or the analytic contour.
//! * [`contour_points`]: the contour of a pose in one view, for overlays.
//! * [`synth::SceneSynth`]: renders an RGB frame of a given arm pose (textured clutter, table,
//!   torso, head, shaded arm, sensor noise) from a seed.
//!
//! # Dependencies
//!
//! nalgebra (small vectors and rotations), tiny-skia (aliasing-free rasterisation of silhouettes
//! into masks, and the anti-aliased drawing of synthetic scenes), rayon (batches of particles),
//! rand / rand_distr / rand_pcg (scene synthesis with the seed as the only source of randomness),
//! serde (cameras and geometry are part of the scene file), thiserror (the error enum).
//!
//! # Example
//!
//! ```
//! use actrack_render::{ArmGeometry, Camera, ContourMethod, EdgeParams, EdgeWorkspace,
//!     ImageView, LikelihoodModel};
//! use nalgebra::Vector3;
//!
//! let cam = Camera::look_at(Vector3::new(0.0, -1.5, 1.6), Vector3::new(0.0, 0.3, 0.9),
//!     Vector3::z(), 320, 240, 60f64.to_radians()).unwrap();
//! let model = LikelihoodModel::new(vec![cam.clone()], ArmGeometry::default(), 0.15,
//!     ContourMethod::Raster).unwrap();
//! let frame = vec![128u8; 320 * 240 * 3];
//! let mut ws = EdgeWorkspace::new();
//! let g = ws.compute(ImageView::rgb8(&frame, 320, 240).unwrap(), &EdgeParams::default())
//!     .unwrap().clone();
//! let pose = [0.0, 0.0, 1.2, 0.05, 0.1, 0.92, 0.1, 0.5, 0.85];
//! let lp = model.log_likelihood(&[g], &pose).unwrap();
//! assert!((-22.23..=0.0).contains(&lp));
//! ```

mod arm;
mod background;
mod camera;
mod contour;
mod edge;
mod error;
#[doc(hidden)]
pub mod fixtures;
#[cfg(feature = "gpu")]
pub mod gpu;
mod image;
mod likelihood;
mod local_norm;
mod roi;
mod silhouette;
pub mod synth;

pub use arm::{ArmGeometry, ArmParts, correct_arm};
pub use background::{blend_background, foreground_mask, scale_by_mask};
pub use camera::{Camera, NEAR_PLANE};
pub use contour::{
    ContourMethod, Part2, RenderScratch, contour_points, cover_parts, project_parts,
};
pub use edge::{EdgeImage, EdgeParams, EdgeWorkspace, grey_image};
pub use error::RenderError;
#[cfg(feature = "gpu")]
pub use gpu::{GpuError, GpuLikelihood};
pub use image::{DownscaleBuf, ImageRgb8, ImageView, downscale};
pub use likelihood::{LikelihoodModel, SamplingMode};
pub use local_norm::{
    DilateScratch, LocalNorm, LocalNormScratch, dilate_mask, local_normalise, max_filter,
};
pub use roi::{CropBuf, PixelRect, arm_bounds, crop, paste};
pub use silhouette::{ForegroundCounts, MAX_SILHOUETTE_PARTS, Overlap};

/// An arm pose as it crosses crate boundaries: (p shoulder xyz, q elbow xyz, r fingertip xyz),
/// metres, world frame.
pub type Pose = [f64; 9];

#[cfg(test)]
mod tests;
