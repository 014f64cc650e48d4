//! Inputs that used to give a silently wrong result, lose work or abort, fed to the built
//! binary exactly as a user would: each must now be a clear error (exit code 2, the file, key or
//! frame named) or a warning with valid outputs.
#![allow(clippy::unwrap_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

const BIN: &str = env!("CARGO_BIN_EXE_actrack-cli");

fn cli(dir: &Path, args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit code 2 and every needle in the message.
fn expect_input_error(o: &Output, needles: &[&str]) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "`{n}` not in: {err}");
    }
}

struct Fixture {
    _dir: tempfile::TempDir,
    root: PathBuf,
}

/// A generator model, the built-in scene at 160×120, a two-action video (frames, y4m, truth)
/// and a joint-trajectory model trained on synthetic actor-frame trials.
fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().to_path_buf();
        let scene = actrack::scene::default_scene(160, 120);
        std::fs::write(root.join("scene.toml"), scene.to_toml_string()).unwrap();
        let (model, _) =
            actrack::demo::train_generator_model(&scene, &["point", "push"], 2, 12, 3).unwrap();
        model.save(&root.join("model.actrack.json")).unwrap();
        let o = cli(
            &root,
            &[
                "synth",
                "--scene",
                "scene.toml",
                "-o",
                "video",
                "--action",
                "point@-0.1,0.42",
                "--action",
                "push",
                "--seed",
                "5",
                "--y4m",
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        write_trials(&root);
        let o = cli(
            &root,
            &[
                "train",
                "--manifest",
                "train.toml",
                "-o",
                "joints.actrack.json",
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        Fixture { _dir: dir, root }
    })
}

/// A synthetic demonstration in the actor frame (metres): the fingertip leaves a rest point and
/// goes to θ on the table (reach), or to θ, up to the mouth and back (drink).
fn trial_csv(action: &str, theta: [f64; 2], len: usize, seed: f64, scale: f64) -> String {
    let mut s = String::from("frame,time,action,theta_u,theta_v,px,py,pz,qx,qy,qz,rx,ry,rz\n");
    let rest = [0.0, 0.3, -0.35];
    for t in 0..len {
        let u = t as f64 / (len - 1) as f64;
        let smooth = |a: f64| a * a * (3.0 - 2.0 * a);
        let r = if action == "reach" {
            let k = smooth(u);
            [
                rest[0] + k * (theta[0] - rest[0]),
                rest[1] + k * (theta[1] - rest[1]),
                -0.35 + 0.08 * (std::f64::consts::PI * u).sin(),
            ]
        } else {
            let (k, lift) = if u < 0.5 {
                (smooth(2.0 * u), 0.0)
            } else {
                (
                    1.0 - smooth(2.0 * u - 1.0),
                    (std::f64::consts::PI * (2.0 * u - 1.0)).sin(),
                )
            };
            [
                rest[0] + k * (theta[0] - rest[0]),
                rest[1] + k * (theta[1] - rest[1]) - 0.2 * lift,
                -0.35 + 0.35 * lift,
            ]
        };
        let wob = 0.002 * ((t as f64) * 1.7 + seed).sin();
        let p = [wob, 0.0, 0.0];
        let q = [0.5 * r[0] + 0.1, 0.5 * r[1] - 0.05, -0.28 + wob];
        let _ = write!(
            s,
            "{t},{:.4},{action},{},{}",
            t as f64 / 30.0,
            theta[0],
            theta[1]
        );
        for v in [p, q, r] {
            let _ = write!(
                s,
                ",{:.5},{:.5},{:.5}",
                scale * v[0],
                scale * (v[1] + wob),
                scale * v[2]
            );
        }
        s.push('\n');
    }
    s
}

fn write_trials(dir: &Path) {
    std::fs::create_dir_all(dir.join("data")).unwrap();
    let mut k = 0;
    for action in ["reach", "drink"] {
        for (i, x) in [-0.2, -0.1, 0.0, 0.1].iter().enumerate() {
            for (j, y) in [0.5, 0.6, 0.7].iter().enumerate() {
                let name = format!("data/{action}_{i}{j}.csv");
                let len = 40 + 3 * i + 2 * j;
                std::fs::write(
                    dir.join(name),
                    trial_csv(action, [*x, *y], len, f64::from(k), 1.0),
                )
                .unwrap();
                k += 1;
            }
        }
    }
    let manifest = "[options]\nstates = 6\niterations = 20\ncov_floor = 0.003\n\n\
        [preprocessing]\ntrim = false\nframe_rate = \"capture\"\n\n\
        [[trials]]\nfiles = \"data/reach_*.csv\"\naction = \"reach\"\n\n\
        [[trials]]\nfiles = \"data/drink_*.csv\"\naction = \"drink\"\n";
    std::fs::write(dir.join("train.toml"), manifest).unwrap();
}

fn track(root: &Path, args: &[&str]) -> Output {
    let mut all = vec![
        "track",
        "--model",
        "model.actrack.json",
        "--particles",
        "40",
        "--seed",
        "2",
    ];
    all.extend_from_slice(args);
    cli(root, &all)
}

// ---- 1. Silently wrong results --------------------------------------------------------------

#[test]
fn two_cameras_and_one_video_is_refused_naming_the_scene() {
    let f = fixture();
    let scene = std::fs::read_to_string(f.root.join("scene.toml")).unwrap();
    let cut = scene.find("[table]").unwrap();
    let second = scene[..cut].replace("camera0", "camera1");
    std::fs::write(f.root.join("two_cameras.toml"), format!("{second}{scene}")).unwrap();
    let o = track(
        &f.root,
        &[
            "--scene",
            "two_cameras.toml",
            "--input",
            "video/video.y4m",
            "--csv",
            "two.csv",
        ],
    );
    expect_input_error(&o, &["two_cameras.toml", "2 [[camera]]s", "one video"]);
    assert!(!f.root.join("two.csv").exists());
}

#[test]
fn classify_refuses_a_world_frame_truth_csv() {
    let f = fixture();
    // The ground truth `synth` writes: DESIGN's columns, poses in the world frame.
    let o = cli(
        &f.root,
        &[
            "classify",
            "--model",
            "joints.actrack.json",
            "--trial",
            "video/truth.csv",
        ],
    );
    expect_input_error(&o, &["video/truth.csv", "actor frame", "world-frame"]);
}

#[test]
fn classify_refuses_millimetres() {
    let f = fixture();
    std::fs::write(
        f.root.join("reach_mm.csv"),
        trial_csv("reach", [0.0, 0.6], 45, 0.5, 1000.0),
    )
    .unwrap();
    let o = cli(
        &f.root,
        &[
            "classify",
            "--model",
            "joints.actrack.json",
            "--trial",
            "reach_mm.csv",
        ],
    );
    expect_input_error(&o, &["reach_mm.csv", "millimetres"]);
}

/// θ of a movement seen only in part stays within the model's θ support (its training θ box
/// plus [`actrack::train::THETA_SUPPORT_MARGIN`]) and comes with an uncertainty, however far
/// the movement heads.
#[test]
fn partial_theta_stays_within_the_support_with_its_uncertainty() {
    let f = fixture();
    let model = actrack::ActionModel::load(&f.root.join("joints.actrack.json")).unwrap();
    for (name, theta) in [("far", [0.9, 1.4]), ("near", [-0.15, 0.55])] {
        let file = format!("reach_{name}.csv");
        std::fs::write(f.root.join(&file), trial_csv("reach", theta, 45, 0.3, 1.0)).unwrap();
        for fraction in ["0.5", "0.75"] {
            let o = cli(
                &f.root,
                &[
                    "classify",
                    "--model",
                    "joints.actrack.json",
                    "--trial",
                    &file,
                    "--fraction",
                    fraction,
                    "--json",
                ],
            );
            assert!(o.status.success(), "{}", stderr(&o));
            let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            let t = &v["trials"][0];
            for s in t["scores"].as_array().unwrap() {
                let a = model
                    .actions
                    .iter()
                    .find(|a| a.name == s["action"].as_str().unwrap())
                    .unwrap();
                let (lo, hi) = actrack::train::theta_support(a);
                for k in 0..2 {
                    let th = s["theta"][k].as_f64().unwrap();
                    assert!(
                        th >= lo[k] - 1e-9 && th <= hi[k] + 1e-9,
                        "{name} at {fraction}: {} θ[{k}] = {th} outside [{}, {}]",
                        a.name,
                        lo[k],
                        hi[k]
                    );
                    let sd = s["theta_std"][k].as_f64().unwrap();
                    assert!(sd.is_finite() && sd > 0.0, "{name}: σ {sd}");
                }
            }
            if name == "far" {
                assert_eq!(t["theta_at_bound"], true, "{t}");
            } else {
                let th = t["theta"].as_array().unwrap();
                let err =
                    (th[0].as_f64().unwrap() - theta[0]).hypot(th[1].as_f64().unwrap() - theta[1]);
                assert!(err < 0.1, "near at {fraction}: θ {th:?} off by {err}");
            }
        }
    }
}

// ---- 2. Plausibility --------------------------------------------------------------------------

/// The fixture's scene with one key changed, written to `name`.
fn scene_with(root: &Path, name: &str, edit: impl FnOnce(&mut toml::Table)) {
    let text = std::fs::read_to_string(root.join("scene.toml")).unwrap();
    let mut t: toml::Table = toml::from_str(&text).unwrap();
    edit(&mut t);
    std::fs::write(root.join(name), toml::to_string(&t).unwrap()).unwrap();
}

/// World → camera rotation (rows) and translation of a camera at `eye` looking at `target`
/// (z up), for scenes written by the tests.
fn look_at(eye: [f64; 3], target: [f64; 3]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let norm = |a: [f64; 3]| {
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        [a[0] / n, a[1] / n, a[2] / n]
    };
    let z = norm(sub(target, eye));
    let x = norm(cross(z, [0.0, 0.0, 1.0]));
    let y = cross(z, x);
    let r = vec![x.to_vec(), y.to_vec(), z.to_vec()];
    let t = (0..3)
        .map(|i| -(r[i][0] * eye[0] + r[i][1] * eye[1] + r[i][2] * eye[2]))
        .collect();
    (r, t)
}

fn set_camera(t: &mut toml::Table, eye: [f64; 3]) {
    let (r, tr) = look_at(eye, [0.0, 0.5, 0.75]);
    let cam = t["camera"].as_array_mut().unwrap()[0]
        .as_table_mut()
        .unwrap();
    cam.insert("rotation".into(), toml::Value::try_from(r).unwrap());
    cam.insert("translation".into(), toml::Value::try_from(tr).unwrap());
}

#[test]
fn implausible_scenes_are_refused_naming_the_key() {
    type Edit = Box<dyn FnOnce(&mut toml::Table)>;
    let f = fixture();
    let cases: Vec<(&str, Edit, &[&str])> = vec![
        (
            "far_camera.toml",
            Box::new(|t| set_camera(t, [0.0, 1300.5, 300.75])),
            &["camera[0]", "from the table centre"],
        ),
        (
            "grazing_camera.toml",
            Box::new(|t| set_camera(t, [0.0, 2.5, 0.80])),
            &["camera[0]", "above the table plane"],
        ),
        (
            "under_camera.toml",
            Box::new(|t| set_camera(t, [0.0, 2.5, 0.70])),
            &["camera[0]"],
        ),
        (
            "far_actor.toml",
            Box::new(|t| {
                t["actor"].as_table_mut().unwrap().insert(
                    "origin".into(),
                    toml::Value::try_from([0.05, -9.9, 1.1]).unwrap(),
                );
            }),
            &["actor.origin", "from the nearest point of the table"],
        ),
        (
            "giant_arm.toml",
            Box::new(|t| {
                t["arm"]
                    .as_table_mut()
                    .unwrap()
                    .insert("upper_arm_length".into(), toml::Value::Float(1e6));
            }),
            &["arm.upper_arm_length", "human arm"],
        ),
    ];
    for (name, edit, needles) in cases {
        scene_with(&f.root, name, edit);
        let o = track(
            &f.root,
            &[
                "--scene",
                name,
                "--input",
                "video/video.y4m",
                "--csv",
                "x.csv",
            ],
        );
        let mut n = vec![name];
        n.extend_from_slice(needles);
        expect_input_error(&o, &n);
    }
}

/// The fixture's generator model with its JSON edited, written to `name`.
fn model_with(root: &Path, name: &str, edit: impl FnOnce(&mut serde_json::Value)) {
    let text = std::fs::read_to_string(root.join("model.actrack.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    edit(&mut v);
    std::fs::write(root.join(name), serde_json::to_string(&v).unwrap()).unwrap();
}

#[test]
fn implausible_models_are_refused() {
    let f = fixture();
    model_with(&f.root, "dup.actrack.json", |v| {
        v["actions"][1]["name"] = v["actions"][0]["name"].clone();
    });
    let o = cli(&f.root, &["inspect", "dup.actrack.json"]);
    expect_input_error(&o, &["dup.actrack.json", "appears twice"]);
    model_with(&f.root, "swapped.actrack.json", |v| {
        let a = &mut v["actions"][0];
        let (lo, hi) = (a["theta_min"].clone(), a["theta_max"].clone());
        a["theta_min"] = hi;
        a["theta_max"] = lo;
    });
    let o = cli(&f.root, &["inspect", "swapped.actrack.json"]);
    expect_input_error(&o, &["swapped.actrack.json", "theta_min"]);
}

#[test]
fn synth_refuses_theta_off_the_table_and_huge_frames() {
    let f = fixture();
    let o = cli(&f.root, &["synth", "-o", "off", "--action", "point@50,0.4"]);
    expect_input_error(
        &o,
        &["--action point@50,0.4", "outside the scene's table region"],
    );
    assert!(!f.root.join("off").exists());
    let o = cli(
        &f.root,
        &[
            "synth",
            "-o",
            "huge",
            "--action",
            "point",
            "--size",
            "100000x100000",
        ],
    );
    expect_input_error(&o, &["--size 100000x100000", "megapixels"]);
}

// ---- 3. I/O and no lost work ------------------------------------------------------------------

/// Data rows of a track CSV (comment lines and the header skipped).
fn csv_rows(p: &Path) -> usize {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .count()
        - 1
}

fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| {
            let n = e.unwrap().file_name().to_string_lossy().into_owned();
            n.contains(".tmp-").then_some(n)
        })
        .collect()
}

/// The fixture's y4m cut after its header and `frames` whole frames plus `extra` bytes.
fn cut_y4m(root: &Path, name: &str, frames: usize, extra: usize) {
    let data = std::fs::read(root.join("video/video.y4m")).unwrap();
    let header = data.iter().position(|&b| b == b'\n').unwrap() + 1;
    // The second FRAME marker: the length of one frame record.
    let frame = data[header + 6..]
        .windows(6)
        .position(|w| w == b"FRAME\n")
        .unwrap()
        + 6;
    assert_eq!((data.len() - header) % frame, 0);
    std::fs::write(root.join(name), &data[..header + frames * frame + extra]).unwrap();
}

#[test]
fn y4m_cut_mid_frame_keeps_the_frames_before() {
    let f = fixture();
    let dir = tempfile::tempdir_in(&f.root).unwrap();
    let d = dir.path();
    for p in ["scene.toml", "model.actrack.json"] {
        std::fs::copy(f.root.join(p), d.join(p)).unwrap();
    }
    std::fs::create_dir_all(d.join("video")).unwrap();
    std::fs::copy(f.root.join("video/video.y4m"), d.join("video/video.y4m")).unwrap();
    cut_y4m(d, "cut.y4m", 12, 1000);
    let o = track(
        d,
        &[
            "--scene",
            "scene.toml",
            "--input",
            "cut.y4m",
            "-o",
            "cut.mcap",
            "--csv",
            "cut.csv",
        ],
    );
    expect_input_error(&o, &["cut.y4m", "frame 12", "stopped after 12 frames"]);
    assert_eq!(csv_rows(&d.join("cut.csv")), 12);
    assert!(std::fs::metadata(d.join("cut.mcap")).unwrap().len() > 0);
    let o = track(
        d,
        &[
            "--scene",
            "scene.toml",
            "--input",
            "cut.y4m",
            "--csv",
            "skip.csv",
            "--skip-bad-frames",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("broke off after 12 frames"),
        "{}",
        stderr(&o)
    );
    assert_eq!(csv_rows(&d.join("skip.csv")), 12);
    assert!(leftovers(d).is_empty(), "{:?}", leftovers(d));

    // A header and no frame is an error like an empty directory, and leaves no temporary file.
    cut_y4m(d, "header.y4m", 0, 0);
    let o = track(
        d,
        &[
            "--scene",
            "scene.toml",
            "--input",
            "header.y4m",
            "-o",
            "h.mcap",
        ],
    );
    expect_input_error(&o, &["header.y4m", "no frames"]);
    assert!(!d.join("h.mcap").exists());
    assert!(leftovers(d).is_empty(), "{:?}", leftovers(d));
}

#[test]
fn output_paths_are_checked_before_tracking() {
    let f = fixture();
    let base = ["--scene", "scene.toml", "--input", "video/frames"];
    let run = |extra: &[&str]| {
        let mut a = base.to_vec();
        a.extend_from_slice(extra);
        let t = std::time::Instant::now();
        let o = track(&f.root, &a);
        (o, t.elapsed())
    };
    let (o, took) = run(&["--csv", "missing/dir/t.csv"]);
    expect_input_error(&o, &["missing/dir/t.csv", "does not exist"]);
    assert!(!stderr(&o).contains(".tmp-"), "{}", stderr(&o));
    // Refused before the video is tracked (the whole video takes far longer).
    assert!(took.as_secs_f64() < 20.0, "{took:?}");
    let (o, _) = run(&["-o", "same.out", "--csv", "same.out"]);
    expect_input_error(&o, &["same.out", "same file"]);
    assert!(!f.root.join("same.out").exists());
    let (o, _) = run(&["--overlay", "video/frames/overlays"]);
    expect_input_error(&o, &["video/frames/overlays", "inside the input directory"]);
    assert!(!f.root.join("video/frames/overlays").exists());
    assert!(leftovers(&f.root).is_empty());
}

// ---- 4. Resource limits and bad numbers -------------------------------------------------------

#[test]
fn eval_refuses_a_track_with_nan_naming_line_and_column() {
    let f = fixture();
    let dir = tempfile::tempdir_in(&f.root).unwrap();
    let d = dir.path();
    let o = track(
        &f.root,
        &[
            "--scene",
            "scene.toml",
            "--input",
            "video/video.y4m",
            "--csv",
            d.join("t.csv").to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(d.join("t.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let header = lines.iter().position(|l| !l.starts_with('#')).unwrap();
    let rx = lines[header].split(',').position(|c| c == "rx").unwrap();
    let bad_line = header + 4;
    let mut out = String::new();
    for (i, l) in lines.iter().enumerate() {
        if i == bad_line {
            let mut f: Vec<&str> = l.split(',').collect();
            f[rx] = "NaN";
            out.push_str(&f.join(","));
        } else {
            out.push_str(l);
        }
        out.push('\n');
    }
    std::fs::write(d.join("nan.csv"), out).unwrap();
    let o = cli(
        d,
        &[
            "eval",
            "--track",
            "nan.csv",
            "--truth",
            f.root.join("video/truth.csv").to_str().unwrap(),
        ],
    );
    expect_input_error(&o, &[&format!("nan.csv:{}", bad_line + 1), "column `rx`"]);
    assert!(!String::from_utf8_lossy(&o.stdout).contains("NaN"));
}

#[test]
fn track_refuses_a_billion_particles_before_allocating() {
    let f = fixture();
    let t = std::time::Instant::now();
    let o = cli(
        &f.root,
        &[
            "track",
            "--model",
            "model.actrack.json",
            "--scene",
            "scene.toml",
            "--input",
            "video/video.y4m",
            "--particles",
            "1000000000",
            "--csv",
            "billion.csv",
        ],
    );
    let max = actrack::config::MAX_PARTICLES.to_string();
    expect_input_error(&o, &["filter.particles", "got 1000000000", &max]);
    // Refused up front: a billion particles (hundreds of GB) were never allocated, nothing
    // was tracked or written.
    assert!(t.elapsed().as_secs_f64() < 20.0, "{:?}", t.elapsed());
    assert!(!f.root.join("billion.csv").exists());
    assert!(leftovers(&f.root).is_empty(), "{:?}", leftovers(&f.root));
}

#[test]
fn demo_refuses_zero_particles_before_training() {
    let dir = tempfile::tempdir().unwrap();
    let t = std::time::Instant::now();
    let o = cli(dir.path(), &["demo", "--dir", "out", "--particles", "0"]);
    expect_input_error(&o, &["filter.particles", "got 0"]);
    // Refused before the demo trains its models and renders its video (which take far
    // longer): it has not even made its folder.
    assert!(t.elapsed().as_secs_f64() < 20.0, "{:?}", t.elapsed());
    assert!(!dir.path().join("out").exists());
    assert!(
        o.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
}

/// `train` on the manifest of [`write_trials`] in `d` into `short.actrack.json`.
fn train_short(d: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "train",
        "--manifest",
        "train.toml",
        "-o",
        "short.actrack.json",
    ];
    args.extend_from_slice(extra);
    cli(d, &args)
}

/// A trial shorter than the path through the model's states (6 states, max_jump 3: at least
/// ⌈5 / 3⌉ + 1 = 3 frames) is the user's input: refused naming the file, its action, its frame
/// count and the minimum, in words (no internal type names); a trial of exactly the minimum
/// trains.
#[test]
fn train_refuses_a_trial_too_short_for_the_model_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_trials(d);
    std::fs::write(
        d.join("data/reach_12.csv"),
        trial_csv("reach", [-0.1, 0.7], 2, 0.5, 1.0),
    )
    .unwrap();
    let o = train_short(d, &[]);
    expect_input_error(
        &o,
        &[
            "reach_12.csv",
            "`reach` trial",
            "has 2 frames",
            "at least 3 frames",
            "6 states",
            "max_jump 3",
        ],
    );
    let err = stderr(&o);
    for internal in ["EndMode", "MustEnd", "::", "sequence"] {
        assert!(!err.contains(internal), "`{internal}` in: {err}");
    }
    assert!(!d.join("short.actrack.json").exists());
    // The minimum follows the options: --max-jump 1 needs one frame per state.
    let o = train_short(d, &["--max-jump", "1"]);
    expect_input_error(&o, &["reach_12.csv", "at least 6 frames", "max_jump 1"]);
    // Exactly the minimum is enough.
    std::fs::write(
        d.join("data/reach_12.csv"),
        trial_csv("reach", [-0.1, 0.7], 3, 0.5, 1.0),
    )
    .unwrap();
    let o = train_short(d, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("short.actrack.json").exists());
    assert!(leftovers(d).is_empty(), "{:?}", leftovers(d));
}
