//! The contour likelihood of SPEC §4.3 and its multi-view sum (§4.4).

use std::cell::RefCell;

use rayon::prelude::*;

use crate::{
    ArmGeometry, Camera, ContourMethod, EdgeImage, RenderError,
    contour::{
        RenderScratch, analytic_sum, analytic_sum_nearest, project_prepared, raster_contour,
    },
};

/// How G is read at an analytic contour point (raster contour points are whole pixels).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum SamplingMode {
    /// G at the rounded pixel (SPEC §4.3 default).
    #[default]
    Nearest,
    /// Bilinear interpolation of G.
    Bilinear,
}

thread_local! {
    static SCRATCH: RefCell<RenderScratch> = RefCell::new(RenderScratch::new());
}

/// The observation model: cameras (one per view), the rendered arm, γ and the contour method.
///
/// `log P(I | x̃) = −(1/(2γ²)) Σ_v ε̄_v`, `ε̄_v = (1/|C_v|) Σ_{c∈C_v} (1 − G_v(c))²`, with
/// `ε̄_v = 1` when the contour is empty in view v (arm out of view or behind the camera). The
/// range is `[−V/(2γ²), 0]`; a pose with a non-finite coordinate scores the minimum
/// `−V/(2γ²)`. Poses are in the world frame and are rendered as given: correct them first
/// with [`crate::correct_arm`].
///
/// Eq. 4 sums per-view means, so the likelihood sharpens with the number of views V (SPEC
/// E19); pass e.g. γ·√V as `gamma` to keep the single-view sharpness.
#[derive(Debug, Clone)]
pub struct LikelihoodModel {
    cameras: Vec<Camera>,
    geometry: ArmGeometry,
    gamma: f64,
    contour: ContourMethod,
    sampling: SamplingMode,
    spacing: f64,
}

impl LikelihoodModel {
    /// Validates the cameras (at least one), the geometry and γ > 0.
    pub fn new(
        cameras: Vec<Camera>,
        geometry: ArmGeometry,
        gamma: f64,
        contour: ContourMethod,
    ) -> Result<Self, RenderError> {
        if cameras.is_empty() {
            return Err(RenderError::InvalidParameter(
                "at least one camera is needed".into(),
            ));
        }
        for c in &cameras {
            c.validate()?;
        }
        geometry.validate()?;
        if !(gamma.is_finite() && gamma > 0.0) {
            return Err(RenderError::InvalidParameter(format!(
                "gamma must be > 0, got {gamma}"
            )));
        }
        Ok(Self {
            cameras,
            geometry,
            gamma,
            contour,
            sampling: SamplingMode::Nearest,
            spacing: 2.0,
        })
    }

    /// Sets how G is read at analytic contour points (default nearest pixel).
    #[must_use]
    pub fn with_sampling(mut self, sampling: SamplingMode) -> Self {
        self.sampling = sampling;
        self
    }

    /// Sets the spacing Δ of analytic contour samples in pixels (default 2; clamped to
    /// [0.25, 100]).
    #[must_use]
    pub fn with_spacing(mut self, spacing: f64) -> Self {
        self.spacing = if spacing.is_finite() {
            spacing.clamp(0.25, 100.0)
        } else {
            2.0
        };
        self
    }

    /// Sets the contour method.
    #[must_use]
    pub fn with_contour(mut self, contour: ContourMethod) -> Self {
        self.contour = contour;
        self
    }

    /// The cameras, one per view.
    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    /// The arm geometry.
    pub fn geometry(&self) -> &ArmGeometry {
        &self.geometry
    }

    /// γ.
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The contour method.
    pub fn contour(&self) -> ContourMethod {
        self.contour
    }

    /// The lowest possible score, `−V/(2γ²)` (every view without contour or without edges).
    pub fn min_log_likelihood(&self) -> f64 {
        -(self.cameras.len() as f64) / (2.0 * self.gamma * self.gamma)
    }

    /// Checks that there is one edge image per camera with the camera's size.
    pub fn check_edges(&self, edges: &[EdgeImage]) -> Result<(), RenderError> {
        if edges.len() != self.cameras.len() {
            return Err(RenderError::ViewCount {
                expected: self.cameras.len(),
                got: edges.len(),
            });
        }
        for (view, (c, e)) in self.cameras.iter().zip(edges).enumerate() {
            if (c.width, c.height) != (e.width(), e.height()) {
                return Err(RenderError::ViewSize {
                    view,
                    width: c.width,
                    height: c.height,
                    got_w: e.width(),
                    got_h: e.height(),
                });
            }
        }
        Ok(())
    }

    /// The mean squared edge distance ε̄_v ∈ [0, 1] of a pose in one view (1 when the
    /// contour is empty or the pose is not finite).
    pub fn view_error(
        &self,
        view: usize,
        edge: &EdgeImage,
        pose: &[f64; 9],
        scratch: &mut RenderScratch,
    ) -> f64 {
        let (sum, count) = self.view_sum(view, edge, pose, scratch);
        if count == 0 {
            1.0
        } else {
            (sum / count as f64).clamp(0.0, 1.0)
        }
    }

    /// Σ (1 − G)² over the pose's contour points in one view and their number (the parts of
    /// [`LikelihoodModel::view_error`]; `(0, 0)` for a missing view), for likelihoods that
    /// weigh the contour's length differently from SPEC's mean.
    pub fn view_sum(
        &self,
        view: usize,
        edge: &EdgeImage,
        pose: &[f64; 9],
        scratch: &mut RenderScratch,
    ) -> (f64, usize) {
        let Some(cam) = self.cameras.get(view) else {
            return (0.0, 0);
        };
        let (w, h) = (cam.width.min(edge.width()), cam.height.min(edge.height()));
        let parts = project_prepared(cam, &self.geometry, pose);
        let mut sum = 0.0f64;
        let mut count = 0usize;
        match self.contour {
            ContourMethod::Raster => {
                let data = edge.data();
                let stride = edge.width() as usize;
                raster_contour(&parts, w, h, scratch, |u, v| {
                    let e = 1.0 - f64::from(data[v * stride + u]);
                    sum += e * e;
                    count += 1;
                });
            }
            ContourMethod::Analytic => {
                let data = edge.data();
                let stride = edge.width() as usize;
                (sum, count) = match self.sampling {
                    SamplingMode::Nearest => {
                        analytic_sum_nearest(&parts, w, h, self.spacing, data, stride)
                    }
                    SamplingMode::Bilinear => analytic_sum(&parts, w, h, self.spacing, |u, v| {
                        let g = edge.sample_bilinear(u, v).unwrap_or(0.0);
                        let e = 1.0 - f64::from(g);
                        e * e
                    }),
                };
            }
        }
        (sum, count)
    }

    /// log P(I | x̃) with an explicit scratch (no validation of `edges`; call
    /// [`LikelihoodModel::check_edges`] once per frame).
    pub fn log_likelihood_with(
        &self,
        scratch: &mut RenderScratch,
        edges: &[EdgeImage],
        pose: &[f64; 9],
    ) -> f64 {
        let factor = 1.0 / (2.0 * self.gamma * self.gamma);
        if !pose.iter().all(|v| v.is_finite()) {
            return self.min_log_likelihood();
        }
        let total: f64 = edges
            .iter()
            .enumerate()
            .take(self.cameras.len())
            .map(|(v, e)| self.view_error(v, e, pose, scratch))
            .sum();
        // Missing views count as "no contour".
        let missing = self.cameras.len().saturating_sub(edges.len()) as f64;
        -(total + missing) * factor
    }

    /// log P(I | x̃) of one pose (SPEC Eq. 3/4), using a per-thread scratch.
    pub fn log_likelihood(&self, edges: &[EdgeImage], pose: &[f64; 9]) -> Result<f64, RenderError> {
        self.check_edges(edges)?;
        Ok(SCRATCH.with(|s| self.log_likelihood_with(&mut s.borrow_mut(), edges, pose)))
    }

    /// log P(I | x̃) of every pose into `out`, in parallel over poses (rayon). Each pose is
    /// scored independently, so the result does not depend on the number of threads.
    pub fn log_likelihood_batch(
        &self,
        edges: &[EdgeImage],
        poses: &[[f64; 9]],
        out: &mut [f64],
    ) -> Result<(), RenderError> {
        self.check_edges(edges)?;
        if out.len() != poses.len() {
            return Err(RenderError::OutputLength {
                expected: poses.len(),
                got: out.len(),
            });
        }
        out.par_iter_mut()
            .zip(poses.par_iter())
            .with_min_len(8)
            .for_each(|(o, pose)| {
                *o = SCRATCH.with(|s| self.log_likelihood_with(&mut s.borrow_mut(), edges, pose));
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn cam(w: u32, h: u32) -> Camera {
        Camera::look_at(
            Vector3::new(0.1, -1.6, 1.5),
            Vector3::new(0.0, 0.25, 0.85),
            Vector3::z(),
            w,
            h,
            60f64.to_radians(),
        )
        .unwrap()
    }

    const POSE: [f64; 9] = [0.2, 0.0, 1.2, 0.25, 0.1, 0.93, 0.2, 0.52, 0.9];

    #[test]
    fn spec_test_9_bounds() {
        for method in [ContourMethod::Raster, ContourMethod::Analytic] {
            let m = LikelihoodModel::new(vec![cam(320, 240)], ArmGeometry::default(), 0.15, method)
                .unwrap();
            let ones = [EdgeImage::constant(320, 240, 1.0).unwrap()];
            let zeros = [EdgeImage::constant(320, 240, 0.0).unwrap()];
            assert!(m.log_likelihood(&ones, &POSE).unwrap().abs() < 1e-12);
            let lz = m.log_likelihood(&zeros, &POSE).unwrap();
            assert!((lz + 1.0 / (2.0 * 0.15 * 0.15)).abs() < 1e-9, "{lz}");
            assert!((lz + 22.222_222_222_222_22).abs() < 1e-9);
            // Empty contour: ε̄ = 1.
            let off = [50.0, 0.0, 1.0, 50.3, 0.0, 1.0, 50.7, 0.0, 1.0];
            assert!((m.log_likelihood(&ones, &off).unwrap() - lz).abs() < 1e-9);
            // Non-finite pose: the minimum.
            let mut nan = POSE;
            nan[4] = f64::NAN;
            assert!((m.log_likelihood(&ones, &nan).unwrap() - lz).abs() < 1e-9);
        }
    }

    #[test]
    fn spec_test_9_monotone_and_single_view() {
        // Raising G at any one pixel never lowers the score; raising it on a contour pixel raises
        // it strictly.
        let c = cam(160, 120);
        for method in [ContourMethod::Raster, ContourMethod::Analytic] {
            let m = LikelihoodModel::new(vec![c.clone()], ArmGeometry::default(), 0.15, method)
                .unwrap();
            let mut g: Vec<f32> = (0..160 * 120)
                .map(|i| ((i * 37) % 101) as f32 / 100.0)
                .collect();
            let contour = crate::contour_points(&c, &ArmGeometry::default(), &POSE, method);
            assert!(!contour.is_empty());
            let base = m
                .log_likelihood(&[EdgeImage::from_vec(160, 120, g.clone()).unwrap()], &POSE)
                .unwrap();
            let [u, v] = contour[contour.len() / 2];
            let i = v.round() as usize * 160 + u.round() as usize;
            g[i] = (g[i] + 0.5).min(1.0);
            let g_img = EdgeImage::from_vec(160, 120, g.clone()).unwrap();
            let up = m
                .log_likelihood(std::slice::from_ref(&g_img), &POSE)
                .unwrap();
            assert!(up > base, "{up} vs {base}");
            // Eq. 4 with one view = Eq. 3 computed by hand.
            let mut sum = 0.0;
            for p in &contour {
                let e = 1.0 - f64::from(g_img.sample_nearest(p[0], p[1]).unwrap());
                sum += e * e;
            }
            let eq3 = -(sum / contour.len() as f64) / (2.0 * 0.15 * 0.15);
            assert!((up - eq3).abs() < 1e-9, "{up} vs {eq3}");
            // Two identical views: exactly twice the single view (sum of means, §4.4).
            let m2 = LikelihoodModel::new(
                vec![c.clone(), c.clone()],
                ArmGeometry::default(),
                0.15,
                method,
            )
            .unwrap();
            let two = m2
                .log_likelihood(&[g_img.clone(), g_img.clone()], &POSE)
                .unwrap();
            assert!((two - 2.0 * up).abs() < 1e-9);
        }
    }

    #[test]
    fn batch_matches_single_and_errors() {
        let c = cam(200, 150);
        let m = LikelihoodModel::new(vec![c], ArmGeometry::default(), 0.15, ContourMethod::Raster)
            .unwrap();
        let g: Vec<f32> = (0..200 * 150)
            .map(|i| ((i * 13) % 97) as f32 / 96.0)
            .collect();
        let e = [EdgeImage::from_vec(200, 150, g).unwrap()];
        let poses: Vec<[f64; 9]> = (0..64)
            .map(|k| {
                let mut p = POSE;
                p[6] += 0.003 * f64::from(k);
                p[4] -= 0.002 * f64::from(k);
                p
            })
            .collect();
        let mut out = vec![0.0; poses.len()];
        m.log_likelihood_batch(&e, &poses, &mut out).unwrap();
        for (p, o) in poses.iter().zip(&out) {
            assert_eq!(m.log_likelihood(&e, p).unwrap().to_bits(), o.to_bits());
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let mut out1 = vec![0.0; poses.len()];
        pool.install(|| m.log_likelihood_batch(&e, &poses, &mut out1).unwrap());
        assert_eq!(out, out1);
        assert!(m.log_likelihood_batch(&e, &poses, &mut out[..3]).is_err());
        assert!(m.log_likelihood(&[], &POSE).is_err());
        let wrong = [EdgeImage::constant(20, 15, 1.0).unwrap()];
        assert!(m.log_likelihood(&wrong, &POSE).is_err());
        assert!(
            LikelihoodModel::new(vec![], ArmGeometry::default(), 0.15, ContourMethod::Raster)
                .is_err()
        );
        let mut bad = cam(10, 10);
        bad.cx = f64::INFINITY;
        assert!(
            LikelihoodModel::new(
                vec![bad],
                ArmGeometry::default(),
                0.15,
                ContourMethod::Raster
            )
            .is_err()
        );
        assert!(
            LikelihoodModel::new(
                vec![cam(10, 10)],
                ArmGeometry::default(),
                0.0,
                ContourMethod::Raster
            )
            .is_err()
        );
    }
}
