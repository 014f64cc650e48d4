//! End-to-end tests of `synth`, `track` and `eval` through the binary: the MCAP validated by the
//! official `mcap` Python package, y4m on stdin against an image directory, an mp4 through
//! ffmpeg, bad input (exit code 2, the frame named) and interruption.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;

const BIN: &str = env!("CARGO_BIN_EXE_actrack-cli");

struct Fixture {
    _dir: tempfile::TempDir,
    root: PathBuf,
}

/// A small model (generator demonstrations), the built-in scene at 160×120 and a 2-action video.
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
        let out = Command::new(BIN)
            .args([
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
            ])
            .current_dir(&root)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        Fixture { _dir: dir, root }
    })
}

fn track(root: &Path, input: &str, extra: &[&str], stdin: Option<&Path>) -> std::process::Output {
    let mut c = Command::new(BIN);
    c.args([
        "track",
        "--model",
        "model.actrack.json",
        "--scene",
        "scene.toml",
        "--input",
        input,
        "--particles",
        "60",
        "--seed",
        "2",
    ])
    .args(extra)
    .current_dir(root);
    if let Some(p) = stdin {
        c.stdin(Stdio::from(std::fs::File::open(p).unwrap()));
    }
    c.output().unwrap()
}

fn python_has_mcap() -> bool {
    Command::new("python3")
        .args(["-c", "import mcap, jsonschema"])
        .status()
        .is_ok_and(|s| s.success())
}

#[test]
fn track_writes_valid_mcap_and_csv_then_eval() {
    let f = fixture();
    let out = track(
        &f.root,
        "video/frames",
        &[
            "-o",
            "t.mcap",
            "--csv",
            "t.csv",
            "--images",
            "--overlay",
            "ov",
        ],
        None,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let n = std::fs::read_dir(f.root.join("video/frames"))
        .unwrap()
        .count();
    assert_eq!(std::fs::read_dir(f.root.join("ov")).unwrap().count(), n);
    // No temporary files left behind.
    assert!(std::fs::read_dir(&f.root).unwrap().flatten().all(|e| {
        let n = e.file_name().to_string_lossy().into_owned();
        !(n.starts_with(".t.mcap.tmp-") || n.starts_with(".t.csv.tmp-"))
    }));
    if python_has_mcap() {
        let script =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/python/validate_mcap.py");
        let v = Command::new("python3")
            .arg(script)
            .arg(f.root.join("t.mcap"))
            .args(["--expect-frames", &n.to_string()])
            .output()
            .unwrap();
        assert!(
            v.status.success(),
            "{}\n{}",
            String::from_utf8_lossy(&v.stdout),
            String::from_utf8_lossy(&v.stderr)
        );
        // The effective configuration is in the MCAP metadata, read by the official reader.
        let meta = Command::new("python3")
            .args([
                "-c",
                "import sys; from mcap.reader import make_reader\n\
                 r = make_reader(open(sys.argv[1], 'rb'))\n\
                 m = {x.name: x.metadata for x in r.iter_metadata()}\n\
                 print(m['actrack.config']['toml'])",
            ])
            .arg(f.root.join("t.mcap"))
            .output()
            .unwrap();
        assert!(
            meta.status.success(),
            "{}",
            String::from_utf8_lossy(&meta.stderr)
        );
        let text = String::from_utf8_lossy(&meta.stdout);
        let cfg = actrack::TrackConfig::parse(&text, Path::new("metadata")).unwrap();
        assert_eq!(cfg.filter.particles, 60);
        assert_eq!(cfg.filter.seed, 2);
    } else {
        eprintln!("note: python3 with `mcap` and `jsonschema` not found; MCAP validation skipped");
    }
    // The CSV's header comment carries the configuration too.
    let csv = std::fs::read_to_string(f.root.join("t.csv")).unwrap();
    let cfg = actrack::TrackConfig::from_comment(&csv).unwrap().unwrap();
    let mut expected = actrack::TrackConfig::default();
    expected.set("filter.particles=60").unwrap();
    expected.set("filter.seed=2").unwrap();
    assert_eq!(cfg, expected);
    let e = Command::new(BIN)
        .args([
            "eval",
            "--track",
            "t.csv",
            "--truth",
            "video/truth.csv",
            "--json",
            "--plots",
            "plots",
        ])
        .current_dir(&f.root)
        .output()
        .unwrap();
    assert!(e.status.success(), "{}", String::from_utf8_lossy(&e.stderr));
    let j: serde_json::Value = serde_json::from_slice(&e.stdout).unwrap();
    assert_eq!(j["instances"].as_array().unwrap().len(), 2);
    assert!(j["overall"]["rmse"].as_f64().unwrap().is_finite());
    for p in ["posterior.png", "theta.png", "fingertip.png"] {
        assert!(f.root.join("plots").join(p).exists());
    }
}

/// The centred median writes every frame once and in order (CSV, overlays, a valid MCAP), with
/// the causal track's frames, actions and posteriors and other poses.
#[test]
fn centred_median_writes_every_frame_in_order() {
    let f = fixture();
    let ok = |out: std::process::Output| {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    ok(track(
        &f.root,
        "video/frames",
        &[
            "--csv",
            "causal.csv",
            "--set",
            "output.median=causal",
            "--set",
            "output.median_window=5",
        ],
        None,
    ));
    let args = [
        "-o",
        "centred.mcap",
        "--csv",
        "centred.csv",
        "--images",
        "--overlay",
        "ov-centred",
        "--set",
        "output.median=centred",
    ];
    ok(track(&f.root, "video/frames", &args, None));
    let n = std::fs::read_dir(f.root.join("video/frames"))
        .unwrap()
        .count();
    assert_eq!(
        std::fs::read_dir(f.root.join("ov-centred"))
            .unwrap()
            .count(),
        n
    );
    let load = |name: &str| actrack::track_csv::Trajectory::load(&f.root.join(name)).unwrap();
    let (causal, centred) = (load("causal.csv"), load("centred.csv"));
    let frames: Vec<usize> = centred.rows.iter().map(|r| r.frame).collect();
    assert_eq!(frames, (0..n).collect::<Vec<_>>());
    assert_eq!(causal.rows.len(), n);
    let mut differs = 0;
    for (a, b) in causal.rows.iter().zip(&centred.rows) {
        assert_eq!(
            (&a.action, a.theta),
            (&b.action, b.theta),
            "frame {}",
            a.frame
        );
        assert!(b.pose.iter().all(|v| v.is_finite()));
        differs += usize::from(a.pose.iter().zip(&b.pose).any(|(x, y)| (x - y).abs() > 0.0));
    }
    assert!(differs > 0, "the centred median changed no pose");
    if python_has_mcap() {
        let script =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/python/validate_mcap.py");
        let v = Command::new("python3")
            .arg(script)
            .arg(f.root.join("centred.mcap"))
            .args(["--expect-frames", &n.to_string()])
            .output()
            .unwrap();
        assert!(
            v.status.success(),
            "{}\n{}",
            String::from_utf8_lossy(&v.stdout),
            String::from_utf8_lossy(&v.stderr)
        );
    }
}

#[test]
fn y4m_on_stdin_equals_image_directory() {
    let f = fixture();
    // Grey frames make y4m (Cmono) lossless: write a grey copy of the video both ways.
    let grey = f.root.join("grey");
    std::fs::create_dir_all(&grey).unwrap();
    let mut frames = Vec::new();
    for p in actrack::frames::list_images(&f.root.join("video/frames")).unwrap() {
        let g = image::DynamicImage::ImageLuma8(image::open(&p).unwrap().to_luma8()).to_rgb8();
        g.save(grey.join(p.file_name().unwrap())).unwrap();
        frames.push(g);
    }
    actrack::frames::write_y4m(
        std::fs::File::create(f.root.join("grey.y4m")).unwrap(),
        &frames,
        30.0,
    )
    .unwrap();
    let a = track(&f.root, "grey", &["--csv", "a.csv"], None);
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    let b = track(
        &f.root,
        "-",
        &["--csv", "b.csv", "--threads", "1"],
        Some(&f.root.join("grey.y4m")),
    );
    assert!(b.status.success(), "{}", String::from_utf8_lossy(&b.stderr));
    let ca = std::fs::read_to_string(f.root.join("a.csv")).unwrap();
    let cb = std::fs::read_to_string(f.root.join("b.csv")).unwrap();
    assert_eq!(ca, cb);
}

#[test]
fn mp4_through_ffmpeg() {
    let f = fixture();
    if Command::new("ffmpeg").arg("-version").output().is_err() {
        eprintln!("note: ffmpeg is not installed; the mp4 test is skipped");
        return;
    }
    let mp4 = f.root.join("video.mp4");
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "30", "-i"])
        .arg(f.root.join("video/frames/frame_%05d.png"))
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "12"])
        .arg(&mp4)
        .status()
        .unwrap();
    if !st.success() {
        eprintln!("note: this ffmpeg cannot encode H.264; the mp4 test is skipped");
        return;
    }
    let out = track(&f.root, "video.mp4", &["--csv", "mp4.csv"], None);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let n = std::fs::read_dir(f.root.join("video/frames"))
        .unwrap()
        .count();
    let rows = std::fs::read_to_string(f.root.join("mp4.csv"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .count()
        - 1;
    assert_eq!(rows, n);
}

/// A video cut in half decodes "successfully" through ffmpeg up to the cut (exit 0, errors on
/// its error output): `track` keeps the frames before the break, says where it stopped and exits
/// with code 2; with `--skip-bad-frames` it keeps them and succeeds.
#[test]
fn mp4_cut_in_half_is_reported() {
    let f = fixture();
    if Command::new("ffmpeg").arg("-version").output().is_err() {
        eprintln!("note: ffmpeg is not installed; the test is skipped");
        return;
    }
    let mp4 = f.root.join("whole.mp4");
    let st = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "30", "-i"])
        .arg(f.root.join("video/frames/frame_%05d.png"))
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "12"])
        .args(["-movflags", "+faststart"])
        .arg(&mp4)
        .status()
        .unwrap();
    if !st.success() {
        eprintln!("note: this ffmpeg cannot encode H.264; the test is skipped");
        return;
    }
    let bytes = std::fs::read(&mp4).unwrap();
    std::fs::write(f.root.join("half.mp4"), &bytes[..bytes.len() / 2]).unwrap();
    let n = std::fs::read_dir(f.root.join("video/frames"))
        .unwrap()
        .count();
    let rows = |name: &str| {
        std::fs::read_to_string(f.root.join(name))
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .count()
            - 1
    };
    let out = track(&f.root, "half.mp4", &["--csv", "half.csv"], None);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("half.mp4") && err.contains("cut short"),
        "{err}"
    );
    let kept = rows("half.csv");
    assert!(kept > 0 && kept < n, "{kept} of {n} frames");
    let out = track(
        &f.root,
        "half.mp4",
        &["--csv", "half2.csv", "--skip-bad-frames"],
        None,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(rows("half2.csv"), kept);
}

/// A camera stand-in: ffmpeg plays a y4m file paced in time (`-readrate 4`, four times its rate)
/// into `track --input - --live`, which keeps up or drops frames and says how many.
#[test]
fn live_stream_from_ffmpeg_in_real_time() {
    let f = fixture();
    if Command::new("ffmpeg").arg("-version").output().is_err() {
        eprintln!("note: ffmpeg is not installed; the live test is skipped");
        return;
    }
    let frames: Vec<_> = actrack::frames::list_images(&f.root.join("video/frames"))
        .unwrap()
        .iter()
        .map(|p| image::open(p).unwrap().to_rgb8())
        .collect();
    let src = f.root.join("live-src.y4m");
    actrack::frames::write_y4m(std::fs::File::create(&src).unwrap(), &frames, 30.0).unwrap();
    let mut player = Command::new("ffmpeg")
        .args(["-v", "error", "-readrate", "4", "-i"])
        .arg(&src)
        .args([
            "-f",
            "yuv4mpegpipe",
            "-pix_fmt",
            "yuv444p",
            "-strict",
            "-1",
            "-",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let out = Command::new(BIN)
        .args([
            "track",
            "--model",
            "model.actrack.json",
            "--scene",
            "scene.toml",
            "--input",
            "-",
            "--live",
            "--particles",
            "60",
            "--csv",
            "live.csv",
        ])
        .stdin(Stdio::from(player.stdout.take().unwrap()))
        .current_dir(&f.root)
        .output()
        .unwrap();
    assert!(player.wait().unwrap().success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    // "live: N frames arrived, K tracked, D dropped (…)"
    let line = err.lines().find(|l| l.contains("frames arrived")).unwrap();
    let nums: Vec<usize> = line
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|t| t.parse().ok())
        .collect();
    let [arrived, tracked, dropped] = nums[..3] else {
        panic!("{line}")
    };
    assert_eq!(arrived, frames.len(), "{line}");
    assert_eq!(tracked + dropped, arrived, "{line}");
    let csv = std::fs::read_to_string(f.root.join("live.csv")).unwrap();
    let rows: Vec<usize> = csv
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(rows.len(), tracked);
    assert!(rows.windows(2).all(|w| w[0] < w[1]), "{rows:?}");
    assert_eq!(rows.last(), Some(&(frames.len() - 1)));
}

/// `output.mcap_particles` caps the θ cloud drawn on `/actrack/particles` (a sample of the
/// filter's particles), and the file stays valid for the official reader.
#[test]
fn mcap_particle_cloud_is_capped() {
    let f = fixture();
    if !python_has_mcap() {
        eprintln!("note: python3 with mcap and jsonschema is missing; skipped");
        return;
    }
    let out = track(
        &f.root,
        "video/frames",
        &["-o", "cap.mcap", "--set", "output.mcap_particles=25"],
        None,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/python/validate_mcap.py");
    let v = Command::new("python3")
        .arg(script)
        .arg(f.root.join("cap.mcap"))
        .args(["--particles", "25"])
        .output()
        .unwrap();
    assert!(
        v.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&v.stdout),
        String::from_utf8_lossy(&v.stderr)
    );
}

fn expect_input_error(out: &std::process::Output, needle: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    for n in needle {
        assert!(err.contains(n), "`{n}` not in: {err}");
    }
}

#[test]
fn bad_input_names_the_frame_with_exit_code_2() {
    let f = fixture();
    let bad = f.root.join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    let files = actrack::frames::list_images(&f.root.join("video/frames")).unwrap();
    for p in files.iter().take(4) {
        std::fs::copy(p, bad.join(p.file_name().unwrap())).unwrap();
    }
    // Changing size.
    image::RgbImage::new(80, 60)
        .save(bad.join("frame_00004.png"))
        .unwrap();
    expect_input_error(
        &track(&f.root, "bad", &["--csv", "x.csv"], None),
        &["frame 4", "frame_00004.png", "differs"],
    );
    // Corrupt image, then skipped on request.
    std::fs::write(bad.join("frame_00004.png"), b"garbage").unwrap();
    expect_input_error(
        &track(&f.root, "bad", &["--csv", "x.csv"], None),
        &["frame 4", "corrupt"],
    );
    let ok = track(
        &f.root,
        "bad",
        &["--csv", "x.csv", "--skip-bad-frames"],
        None,
    );
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    assert!(String::from_utf8_lossy(&ok.stderr).contains("skipped frame 4"));
    // A negative fingertip floor is a value, not a flag, and so are `table` (the scene's table
    // surface) and `off`.
    for floor in ["-0.3", "table", "off"] {
        let floored = track(
            &f.root,
            "bad",
            &[
                "--csv",
                "floor.csv",
                "--skip-bad-frames",
                "--set",
                &format!("actor.fingertip_floor={floor}"),
            ],
            None,
        );
        assert!(
            floored.status.success(),
            "{floor}: {}",
            String::from_utf8_lossy(&floored.stderr)
        );
    }
    assert!(
        !f.root.join("x.csv").exists()
            || std::fs::read_to_string(f.root.join("x.csv"))
                .unwrap()
                .lines()
                .filter(|l| !l.starts_with('#'))
                .count()
                == 5
    );
    // A bad configuration value or key is a usage error naming the key.
    let bad_sets: [(&str, &[&str]); 8] = [
        ("filter.particles=0", &["filter.particles", "0"]),
        ("filter.particles=-4", &["filter.particles"]),
        ("observation.gamma=0", &["observation.gamma"]),
        ("actor.floor_sigma=-0.01", &["actor.floor_sigma"]),
        ("filter.action_floor=1.5", &["filter.action_floor", "1.5"]),
        (
            "observation.short_contour_penalty.quantile=2",
            &["quantile"],
        ),
        ("output.median_window=4", &["output.median_window", "odd"]),
        ("filter.particels=10", &["particels", "unknown"]),
    ];
    for (set, needles) in bad_sets {
        expect_input_error(
            &track(
                &f.root,
                "video/frames",
                &["--csv", "x.csv", "--set", set],
                None,
            ),
            needles,
        );
    }
    std::fs::write(
        f.root.join("bad.toml"),
        "[filter]\nparticles = 100\nsigma = 0.1\n",
    )
    .unwrap();
    expect_input_error(
        &track(
            &f.root,
            "video/frames",
            &["--csv", "x.csv", "--config", "bad.toml"],
            None,
        ),
        &["bad.toml:3", "sigma"],
    );
    expect_input_error(
        &track(
            &f.root,
            "video/frames",
            &["--csv", "x.csv", "--preset", "fastest"],
            None,
        ),
        &["fastest", "default", "paper"],
    );
    // Empty directory.
    std::fs::create_dir_all(f.root.join("empty")).unwrap();
    expect_input_error(
        &track(&f.root, "empty", &["--csv", "x.csv"], None),
        &["empty", "no frames"],
    );
    // Truncated y4m.
    let y = std::fs::read(f.root.join("video/video.y4m")).unwrap();
    std::fs::write(f.root.join("cut.y4m"), &y[..y.len() - 100]).unwrap();
    let n = files.len();
    expect_input_error(
        &track(&f.root, "cut.y4m", &["-o", "cut.mcap"], None),
        &[&format!("frame {}", n - 1), "truncated"],
    );
    // The frames before the cut are kept: the MCAP is finished with them.
    assert!(
        std::fs::metadata(f.root.join("cut.mcap")).is_ok_and(|m| m.len() > 0),
        "the frames tracked before the cut are kept"
    );
    // Frames of another size than the scene's camera.
    let big = f.root.join("big");
    std::fs::create_dir_all(&big).unwrap();
    image::RgbImage::new(200, 100)
        .save(big.join("f0.png"))
        .unwrap();
    expect_input_error(
        &track(&f.root, "big", &["--csv", "x.csv"], None),
        &["frame 0", "camera"],
    );
    // A camera that does not see the table (moved 5 m behind it).
    let mut blind = actrack::scene::default_scene(160, 120);
    blind.cameras[0].model.translation[2] -= 5.0;
    std::fs::write(f.root.join("blind.toml"), blind.to_toml_string()).unwrap();
    let out = Command::new(BIN)
        .args([
            "track",
            "--model",
            "model.actrack.json",
            "--scene",
            "blind.toml",
            "--input",
            "video/frames",
            "--csv",
            "x.csv",
        ])
        .current_dir(&f.root)
        .output()
        .unwrap();
    expect_input_error(&out, &["blind.toml", "does not see the table"]);
    // Missing ffmpeg-decodable file.
    expect_input_error(
        &track(&f.root, "nothing.mp4", &["--csv", "x.csv"], None),
        &["nothing.mp4"],
    );
}

#[cfg(unix)]
#[test]
fn sigterm_finishes_a_valid_mcap() {
    let f = fixture();
    // Loop the video many times through stdin so tracking is still running when signalled.
    let y = std::fs::read(f.root.join("video/video.y4m")).unwrap();
    let header_end = y.iter().position(|b| *b == b'\n').unwrap() + 1;
    let mut long = y.clone();
    for _ in 0..30 {
        long.extend_from_slice(&y[header_end..]);
    }
    std::fs::write(f.root.join("long.y4m"), &long).unwrap();
    let child = Command::new(BIN)
        .args([
            "track",
            "--model",
            "model.actrack.json",
            "--scene",
            "scene.toml",
            "--input",
            "long.y4m",
            "-o",
            "int.mcap",
            "--particles",
            "60",
        ])
        .current_dir(&f.root)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(2500));
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(143), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    let bytes = std::fs::read(f.root.join("int.mcap")).unwrap();
    assert!(bytes.len() > 100);
    if python_has_mcap() {
        let script =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/python/validate_mcap.py");
        let v = Command::new("python3")
            .arg(script)
            .arg(f.root.join("int.mcap"))
            .output()
            .unwrap();
        assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stdout));
    }
}

#[test]
fn synth_random_style_writes_its_scene_and_style_and_repeats_from_them() {
    let dir = tempfile::tempdir().unwrap();
    let synth = |out: &str, style: &str| {
        Command::new(BIN)
            .current_dir(dir.path())
            .args(["synth", "-o", out, "--action", "point@-0.1,0.42"])
            .args(["--seed", "1", "--style", style])
            .output()
            .unwrap()
    };
    let out = synth("a", "random");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let a = dir.path().join("a");
    let style = actrack::style::Style::parse(
        &std::fs::read_to_string(a.join("style.toml")).unwrap(),
        &a.join("style.toml"),
    )
    .unwrap();
    assert_eq!(style, actrack::style::Style::random(1));
    // The scene is seen through the style's camera.
    let scene = actrack::scene::Scene::load(&a.join("scene.toml")).unwrap();
    let cam = &scene.cameras[0].model;
    assert_eq!(
        (cam.width, cam.height),
        (style.camera.width, style.camera.height)
    );
    assert!(
        cam.distortion
            .iter()
            .zip(style.camera.distortion)
            .all(|(a, b)| (a - b).abs() < 1e-12)
    );
    let first = image::open(a.join("frames/frame_00000.png")).unwrap();
    assert_eq!((first.width(), first.height()), (cam.width, cam.height));
    // The style file gives the same video again.
    let out = synth("b", "a/style.toml");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for k in [0, 20, 40] {
        let name = format!("frames/frame_{k:05}.png");
        assert!(
            std::fs::read(a.join(&name)).unwrap()
                == std::fs::read(dir.path().join("b").join(&name)).unwrap(),
            "{name}"
        );
    }
    let out = synth("c", "glossy");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--style glossy"));
}
