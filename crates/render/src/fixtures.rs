//! The scene that the crate's tests, the observation-model benches (`benches/bench_render.rs`)
//! and the `perf` example share, so that their numbers speak of the same frames. Not part of
//! the API: hidden from the docs, and it may change without notice.
//!
//! A right arm reaching over a table, seen from across the table (a little to the side and
//! above), with a body behind the shoulder.

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use crate::synth::{Body, SceneSynth, Table};
use crate::{ArmGeometry, Camera, EdgeImage, EdgeParams, EdgeWorkspace, Pose, correct_arm};

/// The shoulder, world frame, metres.
pub const SHOULDER: [f64; 3] = [0.2, 0.0, 1.2];

/// The camera centre of [`camera`]: across the table, facing the actor.
pub const EYE: [f64; 3] = [0.7, 1.9, 1.65];

/// A distortion-free camera at `eye` looking at the arm's workspace over the table, 55°
/// horizontal field of view.
///
/// # Panics
/// For a zero image size or an `eye` at the target.
pub fn camera_at(eye: [f64; 3], width: u32, height: u32) -> Camera {
    Camera::look_at(
        Vector3::from(eye),
        Vector3::new(0.1, 0.25, 0.95),
        Vector3::z(),
        width,
        height,
        55f64.to_radians(),
    )
    .expect("a valid fixture camera")
}

/// [`camera_at`] from [`EYE`].
///
/// # Panics
/// For a zero image size.
pub fn camera(width: u32, height: u32) -> Camera {
    camera_at(EYE, width, height)
}

/// The scene: default arm, a table in front, a body behind the shoulder.
pub fn scene() -> SceneSynth {
    SceneSynth::new(
        ArmGeometry::default(),
        Some(Table {
            center: [0.0, 0.5, 0.75],
            half_extents: [0.8, 0.45],
            yaw: 0.0,
            thickness: 0.04,
        }),
        Some(Body::for_shoulder(SHOULDER, [0.0, 1.0], true)),
    )
}

/// The pose the frames show: a reach toward the table, corrected to the default arm.
pub fn true_pose() -> Pose {
    let mut p = [
        SHOULDER[0],
        SHOULDER[1],
        SHOULDER[2],
        0.3,
        0.15,
        0.95,
        0.25,
        0.55,
        0.8,
    ];
    correct_arm(&ArmGeometry::default(), &mut p, None);
    p
}

/// `n` particles around [`true_pose`]: elbow and fingertip moved by up to ±`spread` metres
/// per coordinate (uniform, seeded), then corrected.
///
/// # Panics
/// Unless `spread` > 0.
pub fn poses_around(n: usize, spread: f64, seed: u64) -> Vec<Pose> {
    let g = ArmGeometry::default();
    let base = true_pose();
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let mut p = base;
            for x in &mut p[3..] {
                *x += rng.random_range(-spread..spread);
            }
            correct_arm(&g, &mut p, None);
            p
        })
        .collect()
}

/// The edge image (default parameters) of the scene at [`true_pose`] seen by `cam`, frame
/// noise from `seed`.
///
/// # Panics
/// For a camera the renderer refuses (see [`SceneSynth::render`]).
pub fn edges(cam: &Camera, seed: u64) -> EdgeImage {
    let frame = scene()
        .render(cam, &true_pose(), seed)
        .expect("a fixture frame");
    EdgeWorkspace::new()
        .compute(frame.view(), &EdgeParams::default())
        .expect("the fixture frame's edges")
        .clone()
}
