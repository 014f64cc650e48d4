//! Arm geometry (SPEC §4.2) and the arm-length correction (SPEC §3.4).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::RenderError;

/// The rendered arm: segment lengths and the shapes of the three parts (SPEC §4.2). Metres.
///
/// * Upper arm: truncated cone from the shoulder p to the elbow q, radii `upper_radii`
///   (at p, at q).
/// * Forearm: truncated cone from q to the wrist `w = q + forearm_fraction·(r − q)`, radii
///   `forearm_radii` (at q, at w).
/// * Hand: an ellipsoid centred halfway between w and the fingertip r, half-axes
///   `hand_half_axes` = (along w→r, across the hand, thickness). The "across" axis is
///   horizontal (perpendicular to the hand axis and to world z; world x if the hand is
///   vertical), so a hand pointing over a table lies flat.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ArmGeometry {
    /// Upper-arm length L1 = |p − q|.
    pub l1: f64,
    /// Elbow-to-fingertip length L2 = |q − r| (forearm plus hand, SPEC E20).
    pub l2: f64,
    /// Upper-arm radii at the shoulder and at the elbow.
    pub upper_radii: [f64; 2],
    /// Forearm radii at the elbow and at the wrist.
    pub forearm_radii: [f64; 2],
    /// Forearm length as a fraction of L2 (L_fa = 0.6·L2).
    pub forearm_fraction: f64,
    /// Hand ellipsoid half-axes: along the hand, across, thickness.
    pub hand_half_axes: [f64; 3],
}

impl Default for ArmGeometry {
    /// SPEC §4.2 defaults in metres: radii 5/4 cm and 4/3 cm, hand 9 × 4.5 × 1.5 cm,
    /// L_fa = 0.6·L2; L1 = 0.30 m, L2 = 0.45 m.
    fn default() -> Self {
        Self {
            l1: 0.30,
            l2: 0.45,
            upper_radii: [0.05, 0.04],
            forearm_radii: [0.04, 0.03],
            forearm_fraction: 0.6,
            hand_half_axes: [0.09, 0.045, 0.015],
        }
    }
}

impl ArmGeometry {
    /// Default radii with the given arm lengths.
    pub fn with_lengths(l1: f64, l2: f64) -> Self {
        Self {
            l1,
            l2,
            ..Self::default()
        }
    }

    /// Checks that lengths are positive and finite, radii non-negative and the forearm
    /// fraction in (0, 1].
    pub fn validate(&self) -> Result<(), RenderError> {
        let bad = |m: String| Err(RenderError::InvalidParameter(m));
        if !(self.l1.is_finite() && self.l1 > 0.0 && self.l2.is_finite() && self.l2 > 0.0) {
            return bad(format!(
                "arm lengths must be positive (L1={}, L2={})",
                self.l1, self.l2
            ));
        }
        if !self
            .upper_radii
            .iter()
            .chain(&self.forearm_radii)
            .chain(&self.hand_half_axes)
            .all(|r| r.is_finite() && *r >= 0.0)
        {
            return bad("radii and hand half-axes must be finite and ≥ 0".to_owned());
        }
        if !(self.forearm_fraction > 0.0 && self.forearm_fraction <= 1.0) {
            return bad(format!(
                "forearm_fraction must be in (0, 1], got {}",
                self.forearm_fraction
            ));
        }
        Ok(())
    }

    /// The 3-D parts of a (corrected) pose. `None` when the pose is not finite.
    pub fn parts(&self, pose: &[f64; 9]) -> Option<ArmParts> {
        if !pose.iter().all(|v| v.is_finite()) {
            return None;
        }
        let p = Vector3::new(pose[0], pose[1], pose[2]);
        let q = Vector3::new(pose[3], pose[4], pose[5]);
        let r = Vector3::new(pose[6], pose[7], pose[8]);
        let w = q + self.forearm_fraction * (r - q);
        let centre = 0.5 * (w + r);
        let [a0, a1, a2] = self.hand_half_axes;
        let (e0, e1, e2) = hand_frame(&(r - w));
        Some(ArmParts {
            upper: (p, q, self.upper_radii[0], self.upper_radii[1]),
            forearm: (q, w, self.forearm_radii[0], self.forearm_radii[1]),
            hand_centre: centre,
            hand_axes: [a0 * e0, a1 * e1, a2 * e2],
        })
    }
}

/// Orthonormal hand frame: along the hand, across (horizontal), thickness.
fn hand_frame(axis: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let e0 = axis.try_normalize(1e-12).unwrap_or_else(Vector3::x);
    let e1 = e0
        .cross(&Vector3::z())
        .try_normalize(1e-6)
        .or_else(|| e0.cross(&Vector3::x()).try_normalize(1e-6))
        .unwrap_or_else(Vector3::y);
    let e2 = e0.cross(&e1);
    (e0, e1, e2)
}

/// The three 3-D parts of an arm pose, world frame, metres.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmParts {
    /// Upper arm: (start, end, radius at start, radius at end).
    pub upper: (Vector3<f64>, Vector3<f64>, f64, f64),
    /// Forearm: (elbow, wrist, radius at elbow, radius at wrist).
    pub forearm: (Vector3<f64>, Vector3<f64>, f64, f64),
    /// Centre of the hand ellipsoid.
    pub hand_centre: Vector3<f64>,
    /// The hand ellipsoid's three half-axis vectors (along, across, thickness).
    pub hand_axes: [Vector3<f64>; 3],
}

/// The arm-length correction of SPEC §3.4, in place on `pose = (p, q, r)`.
///
/// Keeps p, keeps r whenever it is reachable, and moves q to the nearest point of the
/// admissible elbow circle, so that `|q'−p| = L1` and `|r'−q'| = L2`:
///
/// * overstretched (`|r−p| ≥ L1+L2`): straight arm from p toward r;
/// * too short (`|r−p| ≤ |L1−L2|`): r is pushed outward along `u = (r−p)/|r−p|` to
///   `|L1−L2| + 1e-6` (u = −z when r = p), then the general case;
/// * q on the arm axis (bend plane undefined): the bend direction is `prev_bend` projected
///   orthogonally to u, else the projection of −z, else of +x.
///
/// Returns the unit bend direction used (from the circle's centre toward q'), which the caller
/// may keep and pass as `prev_bend` next frame; `None` for a straight (overstretched) arm.
/// A pose with a non-finite coordinate, or a geometry with non-positive lengths, is left
/// unchanged and gives `None`.
pub fn correct_arm(
    geometry: &ArmGeometry,
    pose: &mut [f64; 9],
    prev_bend: Option<Vector3<f64>>,
) -> Option<Vector3<f64>> {
    let (l1, l2) = (geometry.l1, geometry.l2);
    if !(pose.iter().all(|v| v.is_finite()) && l1 > 0.0 && l2 > 0.0) {
        return None;
    }
    let p = Vector3::new(pose[0], pose[1], pose[2]);
    let q = Vector3::new(pose[3], pose[4], pose[5]);
    let mut r = Vector3::new(pose[6], pose[7], pose[8]);
    let mut d = (r - p).norm();
    let u = if d < 1e-9 { -Vector3::z() } else { (r - p) / d };
    let write = |pose: &mut [f64; 9], q: &Vector3<f64>, r: &Vector3<f64>| {
        pose[3..6].copy_from_slice(q.as_slice());
        pose[6..9].copy_from_slice(r.as_slice());
    };
    if d >= l1 + l2 {
        let q2 = p + l1 * u;
        let r2 = p + (l1 + l2) * u;
        write(pose, &q2, &r2);
        return None;
    }
    if d <= (l1 - l2).abs() {
        d = (l1 - l2).abs() + 1e-6;
        r = p + d * u;
    }
    let s = (d * d + l1 * l1 - l2 * l2) / (2.0 * d);
    let rho = (l1 * l1 - s * s).max(0.0).sqrt();
    let c = p + s * u;
    let orth = |v: Vector3<f64>| v - v.dot(&u) * u;
    let v = orth(q - c);
    let dir = v
        .try_normalize(1e-9)
        .or_else(|| prev_bend.and_then(|b| orth(b).try_normalize(1e-9)))
        .or_else(|| orth(-Vector3::z()).try_normalize(1e-9))
        .or_else(|| orth(Vector3::x()).try_normalize(1e-9))
        .unwrap_or_else(|| orth(Vector3::y()).normalize());
    let q2 = c + rho * dir;
    write(pose, &q2, &r);
    Some(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    fn v(pose: &[f64; 9], i: usize) -> Vector3<f64> {
        Vector3::new(pose[3 * i], pose[3 * i + 1], pose[3 * i + 2])
    }

    /// Brute force: the point of the admissible circle nearest to q.
    fn brute_force(
        p: Vector3<f64>,
        r: Vector3<f64>,
        q: Vector3<f64>,
        l1: f64,
        l2: f64,
    ) -> Vector3<f64> {
        let d = (r - p).norm();
        let u = (r - p) / d;
        let s = (d * d + l1 * l1 - l2 * l2) / (2.0 * d);
        let rho = (l1 * l1 - s * s).sqrt();
        let c = p + s * u;
        let a = u.cross(&Vector3::new(0.3, -0.7, 0.64)).normalize();
        let b = u.cross(&a);
        let n = 200_000;
        let mut best = (f64::INFINITY, c);
        for k in 0..n {
            let t = std::f64::consts::TAU * f64::from(k) / f64::from(n);
            let x = c + rho * (t.cos() * a + t.sin() * b);
            let dist = (x - q).norm();
            if dist < best.0 {
                best = (dist, x);
            }
        }
        best.1
    }

    #[test]
    fn spec_test_8_arm_correction() {
        let g = ArmGeometry::with_lengths(30.0, 45.0);
        let mut rng = Pcg64Mcg::seed_from_u64(8);
        let mut n_feasible = 0;
        let mut n_over = 0;
        let mut n_short = 0;
        for trial in 0..400 {
            let mut pose = [0.0; 9];
            for x in &mut pose {
                *x = rng.random_range(-60.0..60.0);
            }
            if trial % 5 == 0 {
                // Short reaches: r near p.
                for k in 0..3 {
                    pose[6 + k] = pose[k] + rng.random_range(-8.0..8.0);
                }
            }
            let orig = pose;
            let (p0, q0, r0) = (v(&orig, 0), v(&orig, 1), v(&orig, 2));
            correct_arm(&g, &mut pose, None);
            let (p, q, r) = (v(&pose, 0), v(&pose, 1), v(&pose, 2));
            assert!(((q - p).norm() - 30.0).abs() < 1e-9);
            assert!(((r - q).norm() - 45.0).abs() < 1e-9);
            assert_eq!(p, p0);
            let d = (r0 - p0).norm();
            if d >= 75.0 {
                n_over += 1;
                // Collinear output, toward r.
                assert!((q - p).cross(&(r - p)).norm() < 1e-9 * 75.0 * 30.0);
                assert!((r - p).normalize().dot(&(r0 - p0).normalize()) > 1.0 - 1e-12);
            } else {
                if d > 15.0 {
                    n_feasible += 1;
                    assert_eq!(r, r0, "feasible r must not move");
                } else {
                    n_short += 1;
                    assert!(((r - p).norm() - 15.0).abs() < 1e-5);
                }
                // Coplanar with the original p, q, r.
                let n = (q0 - p0).cross(&(r0 - p0)).normalize();
                assert!((q - p0).dot(&n).abs() < 1e-9, "not coplanar");
                let bf = brute_force(p, r, q0, 30.0, 45.0);
                assert!(
                    (bf - q).norm() < 1e-3,
                    "{} from brute force",
                    (bf - q).norm()
                );
            }
        }
        assert!(
            n_feasible > 50 && n_over > 20 && n_short > 10,
            "{n_feasible} {n_over} {n_short}"
        );
    }

    #[test]
    fn degenerate_cases() {
        let g = ArmGeometry::with_lengths(0.30, 0.45);
        // q on the axis: previous bend direction is used.
        let mut pose = [0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.5, 0.0];
        let bend = correct_arm(&g, &mut pose, Some(Vector3::new(1.0, 0.3, 0.0))).unwrap();
        assert!((bend - Vector3::x()).norm() < 1e-12);
        assert!(pose[3] > 0.0 && pose[5].abs() < 1e-12);
        // No previous bend: projection of −z.
        let mut pose = [0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.5, 0.0];
        let bend = correct_arm(&g, &mut pose, None).unwrap();
        assert!((bend + Vector3::z()).norm() < 1e-12);
        // Vertical arm axis, previous bend along the axis: fall back to +x.
        let mut pose = [0.0, 0.0, 1.0, 0.0, 0.0, 0.8, 0.0, 0.0, 0.5];
        let bend = correct_arm(&g, &mut pose, Some(Vector3::z())).unwrap();
        assert!((bend - Vector3::x()).norm() < 1e-12);
        // r = p: u = −z, r pushed down to |L1 − L2|.
        let mut pose = [0.1, 0.2, 1.0, 0.3, 0.2, 1.0, 0.1, 0.2, 1.0];
        correct_arm(&g, &mut pose, None);
        assert!((pose[8] - (1.0 - 0.15 - 1e-6)).abs() < 1e-12);
        // Everything at one point.
        let mut pose = [0.5; 9];
        correct_arm(&g, &mut pose, None);
        let (p, q, r) = (v(&pose, 0), v(&pose, 1), v(&pose, 2));
        assert!(((q - p).norm() - 0.30).abs() < 1e-9 && ((r - q).norm() - 0.45).abs() < 1e-9);
        // Non-finite input is left untouched.
        let mut pose = [f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert!(correct_arm(&g, &mut pose, None).is_none());
        assert!(pose[0].is_nan() && pose[1] == 0.0);
        // Equal lengths: r at p would be degenerate, pushed out by 1e-6.
        let g = ArmGeometry::with_lengths(0.3, 0.3);
        let mut pose = [0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0];
        correct_arm(&g, &mut pose, None);
        let (p, q, r) = (v(&pose, 0), v(&pose, 1), v(&pose, 2));
        assert!(((q - p).norm() - 0.3).abs() < 1e-9 && ((r - q).norm() - 0.3).abs() < 1e-9);
    }

    #[test]
    fn parts_and_validation() {
        let g = ArmGeometry::default();
        g.validate().unwrap();
        let pose = [0.0, 0.0, 1.0, 0.0, 0.0, 0.7, 0.0, 0.45, 0.7];
        let parts = g.parts(&pose).unwrap();
        assert!((parts.forearm.1 - Vector3::new(0.0, 0.27, 0.7)).norm() < 1e-12);
        assert!((parts.hand_centre - Vector3::new(0.0, 0.36, 0.7)).norm() < 1e-12);
        assert!(parts.hand_axes[1].z.abs() < 1e-12);
        assert!(g.parts(&[f64::INFINITY; 9]).is_none());
        let mut bad = g.clone();
        bad.l1 = -1.0;
        assert!(bad.validate().is_err());
        let mut bad = g;
        bad.forearm_fraction = 1.5;
        assert!(bad.validate().is_err());
    }
}
