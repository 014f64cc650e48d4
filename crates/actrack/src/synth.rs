//! Synthetic test sequences with known truth: arm movements from the built-in generator
//! ([`crate::motion`]) or sampled from an action model, several actions in a row, rendered with
//! `actrack-render`'s scene synthesis (textured clutter, table, torso, head, shaded arm, noise)
//! through the scene's first camera, plus the ground-truth CSV.

use std::path::{Path, PathBuf};

use actrack_render::correct_arm;
use actrack_render::synth::{Body, SceneSynth, Table};
use image::RgbImage;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::model::ActionModel;
use crate::motion::{MotionParams, generate};
use crate::scene::Scene;
use crate::scene::render_arm;
use crate::track_csv::{TrajRow, Trajectory};

/// Where the movements come from.
#[derive(Clone, Copy, Debug)]
pub enum MotionSource<'a> {
    /// The built-in minimum-jerk generator (arm lengths 0.29 / 0.45 m).
    Generator,
    /// Samples of an action model's parametric HMMs (corrected to its arm lengths).
    Model(&'a ActionModel),
}

/// A synthetic sequence: poses and truth.
#[derive(Clone, Debug)]
pub struct Sequence {
    /// Poses in the actor frame, one per frame.
    pub poses_actor: Vec<[f64; 9]>,
    /// The ground truth (world poses, θ in the actor frame).
    pub truth: Trajectory,
    /// Arm lengths (L1, L2) of the movements.
    pub lengths: [f64; 2],
}

/// Generator parameters fitted to a scene (table height relative to the shoulder).
pub fn motion_params(scene: &Scene, fps: f64) -> MotionParams {
    let table_z = scene.table.placement.origin.z - scene.actor.origin.z;
    MotionParams {
        table_z,
        rest: [0.2, 0.2, table_z + 0.02],
        fps,
        ..MotionParams::default()
    }
}

/// Makes a sequence of `actions` (name, θ) in a row.
pub fn sequence(
    scene: &Scene,
    source: MotionSource<'_>,
    actions: &[(String, [f64; 2])],
    fps: f64,
    seed: u64,
) -> Result<Sequence> {
    if actions.is_empty() {
        return Err(Error::Config("synth: give at least one action".into()));
    }
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let params = motion_params(scene, fps);
    let mut poses_actor = Vec::new();
    let mut truth = Trajectory::default();
    let lengths = match source {
        MotionSource::Generator => [params.upper_arm, params.forearm_hand],
        MotionSource::Model(m) => [m.arm_lengths.upper_arm, m.arm_lengths.forearm_hand],
    };
    let geometry = render_arm(scene, lengths);
    for (name, theta) in actions {
        let x = match source {
            MotionSource::Generator => {
                generate(name, *theta, &params, &mut rng)
                    .ok_or_else(|| {
                        Error::Config(format!(
                            "synth: the built-in generator knows {:?}, not `{name}`",
                            crate::motion::ACTIONS
                        ))
                    })?
                    .poses
            }
            MotionSource::Model(m) => {
                let a = m.action(name).ok_or_else(|| {
                    Error::Config(format!(
                        "synth: the model has actions {:?}, not `{name}`",
                        m.action_names()
                    ))
                })?;
                a.phmm.sample(theta, None, &mut rng).0
            }
        };
        for t in 0..x.nrows() {
            let mut pose = [0.0; 9];
            for c in 0..9 {
                pose[c] = x[(t, c)];
            }
            if matches!(source, MotionSource::Model(_)) {
                correct_arm(&geometry, &mut pose, None);
            }
            let frame = poses_actor.len();
            truth.rows.push(TrajRow::truth(
                frame,
                frame as f64 / fps,
                name,
                *theta,
                scene.pose_to_world(&pose),
            ));
            poses_actor.push(pose);
        }
    }
    Ok(Sequence {
        poses_actor,
        truth,
        lengths,
    })
}

/// The renderer of a scene's synthetic frames.
pub fn scene_synth(scene: &Scene, lengths: [f64; 2]) -> SceneSynth {
    let t = &scene.table;
    let table = Table {
        center: t.placement.origin.into(),
        half_extents: [t.half_extents[0] + 0.15, t.half_extents[1] + 0.12],
        yaw: t.placement.yaw,
        thickness: 0.03,
    };
    let facing = scene.actor.rotation().column(1).into_owned();
    let body = Body::for_shoulder(
        scene.actor.origin.into(),
        [facing.x, facing.y],
        scene.side == crate::scene::Side::Right,
    );
    SceneSynth::new(render_arm(scene, lengths), Some(table), Some(body))
}

/// Renders the frames of world poses through the scene's first camera (the background is the
/// same in every frame: one seed; the sensor noise changes from frame to frame,
/// [`actrack_render::synth::SceneSynth::render_frame`]).
pub fn render_frames(
    scene: &Scene,
    poses_world: &[[f64; 9]],
    lengths: [f64; 2],
    seed: u64,
) -> Result<Vec<RgbImage>> {
    let synth = scene_synth(scene, lengths);
    let cam = scene.cameras[0].model.clone();
    poses_world
        .par_iter()
        .enumerate()
        .map_init(
            actrack_render::synth::SynthCache::default,
            |cache, (i, p)| {
                let img = synth
                    .render_frame(cache, &cam, p, seed, i as u64)
                    .map_err(|e| Error::Config(format!("synth: frame {i}: {e}")))?;
                RgbImage::from_raw(img.width, img.height, img.data)
                    .ok_or_else(|| Error::Config(format!("synth: frame {i}: bad image buffer")))
            },
        )
        .collect()
}

/// Writes frames as `dir/frame_00000.png …` (creating `dir`).
pub fn save_frames(frames: &[RgbImage], dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::write(dir, e))?;
    frames
        .par_iter()
        .enumerate()
        .map(|(i, f)| {
            let p = dir.join(format!("frame_{i:05}.png"));
            f.save(&p)
                .map_err(|e| Error::write(&p, std::io::Error::other(e.to_string())))?;
            Ok(p)
        })
        .collect()
}

/// Random targets inside the scene's θ region (shrunk to 80 %), one per action.
pub fn random_targets(scene: &Scene, actions: &[&str], seed: u64) -> Vec<(String, [f64; 2])> {
    use rand::Rng;
    let mut rng = Pcg64Mcg::seed_from_u64(seed ^ 0x007a_26e7);
    let (c, h) = scene.theta_region();
    actions
        .iter()
        .map(|a| {
            let u: f64 = rng.random_range(-0.8..0.8);
            let v: f64 = rng.random_range(-0.8..0.8);
            ((*a).to_string(), [c[0] + u * h[0], c[1] + v * h[1]])
        })
        .collect()
}
