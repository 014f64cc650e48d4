//! A built-in generator of human-like arm movements for demonstrations and synthetic tests.
//!
//! The fingertip follows minimum-jerk profiles (Flash & Hogan 1985: s(τ) = 10τ³ − 15τ⁴ + 6τ⁵,
//! the smoothest point-to-point movement, which matches the bell-shaped speed of human reaching)
//! from a rest position beside the body to a target on the table and back, with an arc in height
//! (peaking mid-way). The elbow is placed by inverse kinematics on the admissible elbow circle
//! (upper arm L1, elbow → fingertip L2), hanging down and swivelled outward by a per-trial angle;
//! the shoulder leans forward a little on far targets. Poses are 9-D (shoulder p, elbow q,
//! fingertip r) in the actor frame (DESIGN.md): origin at the acting shoulder at rest, x to the
//! actor's right, y across the table, z up; metres.
//!
//! Actions:
//! * `point` — the extended index finger touches the target, a short hold, back.
//! * `reach` — the hand goes to the target on a higher arc and holds it (a grasp), back.
//! * `push`  — the hand goes to the target, pushes ~10 cm forward along the table, back.
//!
//! Trial-to-trial variability: durations (±15 %), peak height (±25 %), elbow swivel (±8°),
//! push distance and a few rest frames at both ends.

use nalgebra::{DMatrix, Vector3};
use rand::Rng;

/// The actions the generator knows.
pub const ACTIONS: [&str; 3] = ["point", "reach", "push"];

/// Parameters of the generated arm.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionParams {
    /// Upper-arm length L1 (metres).
    pub upper_arm: f64,
    /// Elbow → fingertip length L2 (metres).
    pub forearm_hand: f64,
    /// Height of the table surface in the actor frame (negative: below the shoulder).
    pub table_z: f64,
    /// Fingertip at rest (actor frame).
    pub rest: [f64; 3],
    /// Frames per second.
    pub fps: f64,
}

impl Default for MotionParams {
    fn default() -> Self {
        Self {
            upper_arm: 0.29,
            forearm_hand: 0.45,
            table_z: -0.35,
            rest: [0.2, 0.2, -0.33],
            fps: 30.0,
        }
    }
}

/// One generated movement.
#[derive(Clone, Debug)]
pub struct Movement {
    /// Action name.
    pub action: String,
    /// θ: the target's (x, y) in the actor frame.
    pub theta: [f64; 2],
    /// Poses, one row per frame (T × 9).
    pub poses: DMatrix<f64>,
}

fn min_jerk(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
}

/// Elbow on the admissible circle for shoulder `p`, fingertip `r`, swivel `phi` (radians, 0 =
/// lowest point, positive = outward to +x); `r` is pulled in if out of reach.
pub fn elbow_ik(
    p: Vector3<f64>,
    r: Vector3<f64>,
    l1: f64,
    l2: f64,
    phi: f64,
) -> (Vector3<f64>, Vector3<f64>) {
    let mut d = r - p;
    let mut dist = d.norm().max(1e-9);
    let max = 0.995 * (l1 + l2);
    let min = (l1 - l2).abs() * 1.01 + 1e-6;
    if dist > max {
        d *= max / dist;
        dist = max;
    } else if dist < min {
        d *= min / dist;
        dist = min;
    }
    let u = d / dist;
    let s = (dist * dist + l1 * l1 - l2 * l2) / (2.0 * dist);
    let rho = (l1 * l1 - s * s).max(0.0).sqrt();
    let down = -Vector3::z();
    let e1 = (down - u * down.dot(&u))
        .try_normalize(1e-9)
        .unwrap_or_else(Vector3::x);
    let e2 = e1.cross(&u);
    let q = p + u * s + (e1 * phi.cos() + e2 * phi.sin()) * rho;
    (q, p + d)
}

/// Generates one movement of `action` towards θ = `target` (actor frame x, y).
/// Returns `None` for an unknown action.
pub fn generate<R: Rng>(
    action: &str,
    target: [f64; 2],
    params: &MotionParams,
    rng: &mut R,
) -> Option<Movement> {
    let jitter = |rng: &mut R, rel: f64| 1.0 + rel * (2.0 * rng.random::<f64>() - 1.0);
    let (approach, hold, peak, contact_z, push, swivel0) = match action {
        "point" => (0.85, 0.15, 0.07, 0.005, 0.0, 0.25),
        "reach" => (1.0, 0.45, 0.13, 0.04, 0.0, 0.55),
        "push" => (0.9, 0.1, 0.05, 0.03, 0.10, 0.05),
        _ => return None,
    };
    let fps = params.fps;
    let approach = approach * jitter(rng, 0.15);
    let back = approach * jitter(rng, 0.1);
    let hold = hold * jitter(rng, 0.3);
    let push_time = if push > 0.0 {
        0.55 * jitter(rng, 0.15)
    } else {
        0.0
    };
    let push = push * jitter(rng, 0.2);
    let peak = peak * jitter(rng, 0.25);
    let swivel = swivel0 + (8.0f64).to_radians() * (2.0 * rng.random::<f64>() - 1.0);
    let rest_before = 3 + rng.random_range(0..4usize);
    let rest_after = 3 + rng.random_range(0..4usize);
    let r0 = Vector3::from(params.rest);
    let t_contact = Vector3::new(target[0], target[1], params.table_z + contact_z);
    let t_pushed = t_contact + Vector3::new(0.0, push, 0.0);
    let frames = |s: f64| (s * fps).round().max(1.0) as usize;
    let (na, nh, np, nb) = (
        frames(approach),
        frames(hold),
        if push > 0.0 { frames(push_time) } else { 0 },
        frames(back),
    );
    let mut tips: Vec<Vector3<f64>> = Vec::new();
    tips.extend(std::iter::repeat_n(r0, rest_before));
    let arc = |a: Vector3<f64>, b: Vector3<f64>, n: usize, h: f64, tips: &mut Vec<Vector3<f64>>| {
        for i in 1..=n {
            let s = min_jerk(i as f64 / n as f64);
            tips.push(a + (b - a) * s + Vector3::z() * (h * 4.0 * s * (1.0 - s)));
        }
    };
    arc(r0, t_contact, na, peak, &mut tips);
    tips.extend(std::iter::repeat_n(t_contact, nh));
    let end = if np > 0 {
        arc(t_contact, t_pushed, np, 0.0, &mut tips);
        t_pushed
    } else {
        t_contact
    };
    arc(end, r0, nb, peak, &mut tips);
    tips.extend(std::iter::repeat_n(r0, rest_after));
    let far = (t_pushed.xy().norm() - 0.45).max(0.0);
    let mut poses = DMatrix::zeros(tips.len(), 9);
    let (l1, l2) = (params.upper_arm, params.forearm_hand);
    for (t, r) in tips.iter().enumerate() {
        // Shoulder lean: forward and slightly down in proportion to the fingertip's progress.
        let prog =
            ((r.xy() - r0.xy()).norm() / (t_pushed.xy() - r0.xy()).norm().max(1e-6)).min(1.0);
        let lean = 0.02 + 0.5 * far;
        let p = Vector3::new(
            0.1 * lean * prog * r.x.signum(),
            lean * prog,
            -0.3 * lean * prog,
        );
        let (q, r) = elbow_ik(p, *r, l1, l2, swivel);
        for (j, v) in [p, q, r].iter().enumerate() {
            for c in 0..3 {
                poses[(t, 3 * j + c)] = v[c];
            }
        }
    }
    Some(Movement {
        action: action.to_string(),
        theta: target,
        poses,
    })
}

/// Training demonstrations: for each action, `reps` repetitions to each of the region's four
/// corners (centre, half-extents in the actor frame), as in the paper's protocol (4 corners × 5
/// repetitions), with the targets jittered by up to 10 % of the half-extents.
pub fn demonstrations<R: Rng>(
    actions: &[&str],
    centre: [f64; 2],
    half: [f64; 2],
    reps: usize,
    params: &MotionParams,
    rng: &mut R,
) -> Vec<Movement> {
    let mut out = Vec::new();
    for a in actions {
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            for _ in 0..reps {
                let jx = 0.1 * (2.0 * rng.random::<f64>() - 1.0);
                let jy = 0.1 * (2.0 * rng.random::<f64>() - 1.0);
                let t = [
                    centre[0] + half[0] * (sx * 0.9 + jx),
                    centre[1] + half[1] * (sy * 0.9 + jy),
                ];
                if let Some(m) = generate(a, t, params, rng) {
                    out.push(m);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn arm_lengths_and_targets() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        let p = MotionParams::default();
        for a in ACTIONS {
            let m = generate(a, [-0.2, 0.45], &p, &mut rng).unwrap();
            let x = &m.poses;
            assert!(x.nrows() > 40 && x.nrows() < 120, "{a}: {}", x.nrows());
            let mut max_ext = 0.0f64;
            let mut at = 0;
            for t in 0..x.nrows() {
                let v =
                    |j: usize| Vector3::new(x[(t, 3 * j)], x[(t, 3 * j + 1)], x[(t, 3 * j + 2)]);
                assert!(((v(0) - v(1)).norm() - 0.29).abs() < 1e-9);
                assert!(((v(1) - v(2)).norm() - 0.45).abs() < 1e-9);
                let e = (v(2) - v(0)).xy().norm();
                if e > max_ext {
                    max_ext = e;
                    at = t;
                }
            }
            // The fingertip reaches the target (push: beyond it, along +y).
            let r = Vector3::new(x[(at, 6)], x[(at, 7)], x[(at, 8)]);
            assert!((r.x + 0.2).abs() < 0.01, "{a}: {r}");
            if a == "push" {
                assert!(r.y > 0.5, "{a}: {r}");
            } else {
                assert!((r.y - 0.45).abs() < 0.01, "{a}: {r}");
            }
            // Starts and ends at rest.
            assert!(
                (x[(0, 6)] - p.rest[0]).abs() < 1e-9
                    && (x[(x.nrows() - 1, 7)] - p.rest[1]).abs() < 1e-9
            );
        }
        assert!(generate("wave", [0.0, 0.4], &p, &mut rng).is_none());
    }

    #[test]
    fn min_jerk_profile() {
        assert!(min_jerk(0.0).abs() < 1e-15 && (min_jerk(1.0) - 1.0).abs() < 1e-15);
        assert!((min_jerk(0.5) - 0.5).abs() < 1e-12);
        // Zero velocity at both ends (finite difference).
        assert!(min_jerk(1e-4) < 1e-10 && 1.0 - min_jerk(1.0 - 1e-4) < 1e-10);
    }
}
