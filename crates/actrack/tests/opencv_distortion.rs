//! The scene camera's lens distortion against OpenCV: `cv2.projectPoints` pixels and
//! `cv2.undistortPoints` normalised coordinates of five cameras (barrel, pincushion, tangential,
//! a strong wide-angle lens, none), written by `scripts/make-opencv-fixtures`. Checks the scene
//! camera's projection, the renderer's camera (what the tracker scores and synth draws with), its
//! inverse, and that a scene file with k1…k3 loads into the same camera.
#![allow(clippy::unwrap_used)]
// Distortion coefficients written to TOML and read back are compared bit for bit.
#![allow(clippy::float_cmp)]

use std::path::Path;

use actrack::scene::{Scene, SceneCamera};
use nalgebra::{Matrix3, Rotation3, Vector3};
use serde_json::Value;

fn nums(v: &Value) -> Vec<f64> {
    match v {
        Value::Array(a) => a.iter().flat_map(nums).collect(),
        Value::Number(n) => vec![n.as_f64().unwrap()],
        _ => panic!("not a number: {v}"),
    }
}

fn cases() -> Vec<Value> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/opencv_project_points.json");
    let v: Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    v["cases"].as_array().unwrap().clone()
}

fn camera(c: &Value) -> SceneCamera {
    let k = nums(&c["camera_matrix"]);
    let d = nums(&c["dist_coeffs"]);
    let r = nums(&c["rotation"]);
    let t = nums(&c["tvec"]);
    SceneCamera::new(
        "cv",
        (
            c["width"].as_u64().unwrap() as u32,
            c["height"].as_u64().unwrap() as u32,
        ),
        [k[0], k[4], k[2], k[5]],
        [d[0], d[1], d[2], d[3], d[4]],
        (Matrix3::from_row_slice(&r), Vector3::new(t[0], t[1], t[2])),
    )
}

#[test]
fn projection_matches_opencv_project_points() {
    let mut worst: f64 = 0.0;
    for (i, c) in cases().iter().enumerate() {
        let cam = camera(c);
        // OpenCV's Rodrigues and nalgebra's rotation vector agree.
        let rv = nums(&c["rvec"]);
        let rn = Rotation3::new(Vector3::new(rv[0], rv[1], rv[2]));
        assert!((rn.matrix() - cam.r_cw()).abs().max() < 1e-12, "case {i}");
        let pts = nums(&c["points"]);
        let px = nums(&c["pixels"]);
        for j in 0..pts.len() / 3 {
            let x = Vector3::new(pts[3 * j], pts[3 * j + 1], pts[3 * j + 2]);
            let (u, v) = cam.project(&x).unwrap();
            let e = (u - px[2 * j]).hypot(v - px[2 * j + 1]);
            assert!(e < 1e-6, "case {i} point {j}: {e} px");
            worst = worst.max(e);
        }
    }
    eprintln!("largest difference from cv2.projectPoints: {worst:.2e} px");
}

#[test]
fn undistortion_matches_opencv_undistort_points() {
    let mut worst: f64 = 0.0;
    for (i, c) in cases().iter().enumerate() {
        let cam = camera(c).model;
        let px = nums(&c["pixels"]);
        let und = nums(&c["undistorted"]);
        for j in 0..px.len() / 2 {
            let (x, y) = cam
                .undistort(
                    (px[2 * j] - cam.cx) / cam.fx,
                    (px[2 * j + 1] - cam.cy) / cam.fy,
                )
                .unwrap();
            let e = (x - und[2 * j]).hypot(y - und[2 * j + 1]);
            assert!(e < 1e-9, "case {i} point {j}: {e}");
            worst = worst.max(e);
        }
    }
    eprintln!("largest difference from cv2.undistortPoints: {worst:.2e} (normalised)");
}

#[test]
fn scene_file_distortion_round_trips() {
    for c in cases() {
        // OpenCV's intrinsics and lens on the default scene's pose: the fixture poses do not all
        // look down on a table, which a scene file rejects.
        let mut cam = camera(&c);
        let base = actrack::scene::default_scene(cam.model.width, cam.model.height);
        cam.set_pose((base.cameras[0].r_cw(), base.cameras[0].t_cw()));
        let scene = Scene {
            cameras: vec![cam.clone()],
            ..base
        };
        let back = Scene::parse(&scene.to_toml_string(), Path::new("scene.toml")).unwrap();
        assert_eq!(back.cameras[0].model.distortion, cam.model.distortion);
        for p in [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.2, -0.1, 0.1),
            Vector3::new(-0.15, 0.2, 0.3),
        ] {
            let (u0, v0) = cam.project(&p).unwrap();
            let (u1, v1) = back.cameras[0].project(&p).unwrap();
            assert!((u0 - u1).abs() < 1e-6 && (v0 - v1).abs() < 1e-6);
        }
    }
}
