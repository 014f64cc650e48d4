//! The tracking session end to end on a small generated video: every key of the method changes
//! the track, a shrunk frame tracks as its small self, the table floor, bad frames and the
//! centred report.

// Test fixtures: a failure is a panic with the error.
#![allow(clippy::unwrap_used)]

use actrack::ActionModel;
use actrack::Scene;
use actrack::TrackConfig;
use actrack::config::FloorSetting;
use actrack::demo::train_generator_model;
use actrack::scene::default_scene;
use actrack::session::{FrameResult, PoseReport, Session, shrink_factor};
use actrack::synth::{MotionSource, random_targets, render_frames, sequence};
use image::RgbImage;

struct Small {
    scene: Scene,
    model: ActionModel,
    frames: Vec<RgbImage>,
}

fn small() -> Small {
    let scene = default_scene(160, 120);
    let (model, _) = train_generator_model(&scene, &["point", "push"], 2, 8, 3).unwrap();
    let targets = random_targets(&scene, &["point", "push"], 4);
    let seq = sequence(&scene, MotionSource::Generator, &targets, 30.0, 5).unwrap();
    let world: Vec<[f64; 9]> = seq.truth.rows.iter().take(24).map(|r| r.pose).collect();
    let frames = render_frames(&scene, &world, seq.lengths, 6).unwrap();
    Small {
        scene,
        model,
        frames,
    }
}

fn run(s: &Small, config: &TrackConfig) -> Vec<FrameResult> {
    let mut session = Session::new(&s.model, &s.scene, config).unwrap();
    s.frames
        .iter()
        .enumerate()
        .map(|(i, f)| session.step_rgb(i, &[f]).unwrap())
        .collect()
}

fn config(set: &[&str]) -> TrackConfig {
    let mut c = TrackConfig::default();
    c.set("filter.particles=120").unwrap();
    for kv in set {
        c.set(kv).unwrap();
    }
    c
}

fn best(r: &[FrameResult]) -> Vec<[f64; 9]> {
    r.iter().map(|x| x.best_world).collect()
}

#[test]
fn every_key_of_the_method_changes_the_track_and_stays_finite() {
    let s = small();
    let base = run(&s, &config(&[]));
    assert_eq!(best(&base), best(&run(&s, &config(&[]))), "deterministic");
    for kv in [
        "observation.short_contour_penalty.enabled=false",
        "observation.foreground_gate.enabled=false",
        "observation.foreground_gate.radius=6",
        "actor.fingertip_floor=off",
        "filter.max_stay=1.0",
        "filter.action_floor=0.25",
        // The training prior without its padding (with it, this small video's training targets
        // cover the whole table: the same region as `prior.theta = "scene"`).
        "prior.theta_pad=0.0",
        "observation.contour=\"raster\"",
        "prior.height_scale=0.9",
        "observation.max_width=80",
        "observation.edge_region=\"frame\"",
    ] {
        let other = run(&s, &config(&[kv]));
        assert_ne!(best(&other), best(&base), "{kv} changed nothing");
        for r in &other {
            assert!(r.best_world.iter().all(|v| v.is_finite()), "{kv}");
            assert!(r.estimate.action_posterior.iter().all(|p| p.is_finite()));
        }
    }
    // Local normalisation: this small clean video's edges are saturated near the arm, so with
    // the default radius and floor it has nothing to change; a 2 px window and a low floor raise
    // the weak edges (checked without the gate, which would damp them again).
    let wide = config(&["observation.foreground_gate.enabled=false"]);
    let normalised = config(&[
        "observation.foreground_gate.enabled=false",
        "observation.local_norm.enabled=true",
        "observation.local_norm.radius=2",
        "observation.local_norm.floor=0.01",
    ]);
    assert_ne!(best(&run(&s, &normalised)), best(&run(&s, &wide)));
    // The paper's preset runs too.
    let mut paper = TrackConfig::preset("paper").unwrap();
    paper.filter.particles = 120;
    assert_eq!(run(&s, &paper).len(), s.frames.len());
}

#[test]
fn every_scored_contour_lies_in_the_computed_edge_region() {
    let s = small();
    for contour in ["analytic", "raster"] {
        let cfg = config(&[&format!("observation.contour=\"{contour}\"")]);
        let method = match contour {
            "raster" => actrack::render::ContourMethod::Raster,
            _ => actrack::render::ContourMethod::Analytic,
        };
        let mut session = Session::new(&s.model, &s.scene, &cfg).unwrap();
        let cam = &s.scene.cameras[0].model;
        let mut smaller = 0;
        for (i, f) in s.frames.iter().enumerate() {
            session.step_rgb(i, &[f]).unwrap();
            let rect = session.edge_region(0).unwrap();
            smaller += usize::from(rect.area() < u64::from(cam.width * cam.height));
            let edges = &session.edges()[0];
            for (k, &g) in edges.data().iter().enumerate() {
                let (u, v) = ((k % 160) as u32, (k / 160) as u32);
                let inside = (rect.x0..rect.x1).contains(&u) && (rect.y0..rect.y1).contains(&v);
                assert!(
                    inside || g == 0.0,
                    "frame {i}: G = {g} at ({u}, {v}) outside {rect:?}"
                );
            }
            for pose in session.tracker().samples() {
                let world = s.scene.pose_to_world(pose);
                for [u, v] in
                    actrack::render::contour_points(cam, session.geometry(), &world, method)
                {
                    // Bilinear reads touch the next pixel too; points beyond the image's
                    // border are not read.
                    let lo = |p: f64, lo: u32| lo == 0 || p.floor() >= f64::from(lo);
                    let hi = |p: f64, hi: u32, n: u32| hi == n || p.floor() + 1.0 < f64::from(hi);
                    assert!(
                        lo(u, rect.x0)
                            && lo(v, rect.y0)
                            && hi(u, rect.x1, 160)
                            && hi(v, rect.y1, 120),
                        "frame {i}: contour point ({u}, {v}) outside {rect:?}"
                    );
                }
            }
        }
        assert!(smaller > 0, "the region never left out any pixel");
    }
}

#[test]
fn a_frame_wider_than_max_width_is_tracked_as_its_shrunk_self() {
    // Every frame blown up ×2 by pixel replication, with its camera: shrunk back by 2, the
    // session sees exactly the original frames and camera, so the track is bit-identical.
    let s = small();
    let mut big = Small {
        scene: s.scene.clone(),
        model: s.model.clone(),
        frames: s
            .frames
            .iter()
            .map(|f| {
                image::imageops::resize(
                    f,
                    2 * f.width(),
                    2 * f.height(),
                    image::imageops::FilterType::Nearest,
                )
            })
            .collect(),
    };
    let cam = &mut big.scene.cameras[0].model;
    cam.width *= 2;
    cam.height *= 2;
    cam.fx *= 2.0;
    cam.fy *= 2.0;
    cam.cx = 2.0 * cam.cx + 0.5;
    cam.cy = 2.0 * cam.cy + 0.5;
    let c = config(&["observation.max_width=160"]);
    assert_eq!(best(&run(&big, &c)), best(&run(&s, &c)));
    let mut session = Session::new(&big.model, &big.scene, &c).unwrap();
    session.step_rgb(0, &[&big.frames[0]]).unwrap();
    assert_eq!(session.edges()[0].width(), 160);
    // A frame the factor would shrink to nothing is refused naming the key.
    let flat = default_scene(400, 4);
    let e = Session::new(&s.model, &flat, &config(&["observation.max_width=32"]))
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("observation.max_width") && e.contains("400×4"),
        "{e}"
    );
    assert_eq!(shrink_factor(1280, 640), 2);
    assert_eq!(shrink_factor(1281, 640), 3);
    assert_eq!(shrink_factor(1920, 0), 1);
}

#[test]
fn the_table_floor_is_the_scenes_table_height() {
    let s = small();
    let z = s.scene.table_height();
    let table = run(&s, &config(&["actor.fingertip_floor=\"table\""]));
    let given = run(&s, &config(&[&format!("actor.fingertip_floor={z}")]));
    assert_eq!(best(&table), best(&given));
    let c = config(&[]);
    assert_eq!(c.actor.fingertip_floor, FloorSetting::Table);
}

#[test]
fn images_that_do_not_fit_the_scene_name_the_frame() {
    let s = small();
    let mut session = Session::new(&s.model, &s.scene, &config(&[])).unwrap();
    let e = session.step_rgb(3, &[]).unwrap_err().to_string();
    assert!(e.contains("frame 3") && e.contains("1 camera"), "{e}");
    let e = session
        .step_rgb(4, &[&s.frames[0], &s.frames[1]])
        .unwrap_err()
        .to_string();
    assert!(e.contains("frame 4") && e.contains("2 image"), "{e}");
    let wrong = RgbImage::new(100, 100);
    let e = session.step_rgb(5, &[&wrong]).unwrap_err().to_string();
    assert!(e.contains("frame 5") && e.contains("100×100"), "{e}");
    let mut bad = config(&[]);
    bad.filter.particles = 0;
    let e = Session::new(&s.model, &s.scene, &bad)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("filter.particles"), "{e}");
}

#[test]
fn the_centred_report_is_the_centred_median_of_the_best_poses() {
    let s = small();
    let c = config(&["output.median=\"centred\"", "output.median_window=5"]);
    let results = run(&s, &c);
    let mut report = PoseReport::new(&c.output).unwrap();
    let mut out = Vec::new();
    for (i, r) in results.iter().enumerate() {
        if let Some((j, pose)) = report.push(i, r.estimate.best_pose, r.estimate.smoothed_pose) {
            assert_eq!(j + 2, i, "frames leave two frames later");
            out.push((j, pose));
        }
    }
    out.extend(report.finish());
    let frames: Vec<usize> = out.iter().map(|x| x.0).collect();
    assert_eq!(frames, (0..results.len()).collect::<Vec<_>>());
    let bests: Vec<[f64; 9]> = results.iter().map(|r| r.estimate.best_pose).collect();
    let expected = actrack_pf::centred_median(&bests, 5).unwrap();
    let got: Vec<[f64; 9]> = out.iter().map(|x| x.1).collect();
    assert_eq!(got, expected);
    // Causal: each frame at once with the filter's own median.
    let causal = config(&["output.median=\"causal\"", "output.median_window=5"]);
    let mut report = PoseReport::new(&causal.output).unwrap();
    let e = &results[0].estimate;
    let (i, pose) = report.push(7usize, e.best_pose, e.smoothed_pose).unwrap();
    assert_eq!((i, pose), (7, results[0].estimate.smoothed_pose));
    assert!(report.finish().is_empty());
}
