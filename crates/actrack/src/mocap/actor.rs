//! The actor frame of DESIGN.md: origin at the acting shoulder landmark of the static trial,
//! axes of the table (y away from the actor, z up, x = y × z), a left arm mirrored onto the right.
//!
//! The table's axes are the lab's, turned about z by the actor's heading. The heading is either
//! given (degrees) or detected from the static trial: the direction from the actor's left to
//! right shoulder markers, snapped to the nearest multiple of 90° (the table's axes), so the
//! shoulder line's own ±5° of noise never enters the frame.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{ArmSide, ArmTrajectory};

/// How the actor's heading (rotation of the table axes about lab z) is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Heading {
    /// From the static trial's shoulder line, snapped to a multiple of 90°.
    #[default]
    Auto,
    /// Given, in degrees: 0 when the actor faces lab +y, 180 when facing −y.
    Degrees(f64),
}

/// A rigid map lab → actor frame (plus the optional left→right mirror).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ActorFrame {
    /// Lab-frame origin (the acting shoulder landmark of the static trial), metres.
    pub origin: [f64; 3],
    /// Heading in degrees: the actor frame's x axis is the lab x axis turned by this about z.
    pub heading_deg: f64,
    /// Mirror x → −x (a left arm onto the right).
    pub mirror: bool,
}

impl ActorFrame {
    /// The frame for an arm whose static shoulder is `origin`, with the heading chosen by
    /// `heading` from `right_direction` (lab direction from the actor's left to right side).
    pub fn new(
        origin: Vector3<f64>,
        side: ArmSide,
        heading: Heading,
        right_direction: Option<Vector3<f64>>,
    ) -> ActorFrame {
        let heading_deg = match (heading, right_direction) {
            (Heading::Degrees(d), _) => d,
            (Heading::Auto, Some(v)) if v.x.hypot(v.y) > 1e-6 => {
                let deg = v.y.atan2(v.x).to_degrees();
                ((deg / 90.0).round() * 90.0).rem_euclid(360.0)
            }
            (Heading::Auto, _) => 0.0,
        };
        ActorFrame {
            origin: origin.into(),
            heading_deg,
            mirror: side == ArmSide::Left,
        }
    }

    /// A lab-frame point in the actor frame.
    pub fn to_actor(&self, v: &Vector3<f64>) -> Vector3<f64> {
        let d = v - Vector3::from(self.origin);
        let (s, c) = self.heading_deg.to_radians().sin_cos();
        let x = c * d.x + s * d.y;
        let y = -s * d.x + c * d.y;
        Vector3::new(if self.mirror { -x } else { x }, y, d.z)
    }

    /// An actor-frame point in the lab frame (inverse of [`ActorFrame::to_actor`]).
    pub fn to_lab(&self, v: &Vector3<f64>) -> Vector3<f64> {
        let x = if self.mirror { -v.x } else { v.x };
        let (s, c) = self.heading_deg.to_radians().sin_cos();
        Vector3::new(c * x - s * v.y, s * x + c * v.y, v.z) + Vector3::from(self.origin)
    }

    /// The whole trajectory in the actor frame.
    pub fn apply(&self, arm: &ArmTrajectory) -> ArmTrajectory {
        let map = |v: &Vec<Vector3<f64>>| v.iter().map(|p| self.to_actor(p)).collect();
        ArmTrajectory {
            rate: arm.rate,
            p: map(&arm.p),
            q: map(&arm.q),
            w: map(&arm.w),
            r: map(&arm.r),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heading_snaps_and_roundtrips() {
        let f = ActorFrame::new(
            Vector3::new(-0.23, 0.75, 0.3),
            ArmSide::Right,
            Heading::Auto,
            Some(Vector3::new(-0.35, 0.03, 0.0)),
        );
        assert!((f.heading_deg - 180.0).abs() < 1e-12);
        // Facing −y: a point further along −y is "away from the actor" (+y in the actor frame).
        let p = f.to_actor(&Vector3::new(-0.23, 0.25, 0.0));
        assert!((p.y - 0.5).abs() < 1e-12 && p.x.abs() < 1e-12 && (p.z + 0.3).abs() < 1e-12);
        let q = Vector3::new(0.1, -0.2, 0.3);
        assert!((f.to_lab(&f.to_actor(&q)) - q).norm() < 1e-12);
        let m = ActorFrame::new(Vector3::zeros(), ArmSide::Left, Heading::Degrees(0.0), None);
        assert!(
            (m.to_actor(&Vector3::new(0.1, 0.2, 0.3)) - Vector3::new(-0.1, 0.2, 0.3)).norm()
                < 1e-12
        );
        assert!((m.to_lab(&m.to_actor(&q)) - q).norm() < 1e-12);
    }
}
