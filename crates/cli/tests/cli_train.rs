//! `actrack-cli train`, `classify` and `inspect`, run as the built binary in a temporary
//! directory: synthetic joint-trajectory CSV trials (always), exit codes and messages of bad
//! input, and nothing half-written.

use std::fmt::Write as _;
use std::path::Path;
use std::process::{Command, Output};

fn cli(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_actrack-cli"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run actrack-cli")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A synthetic demonstration in the actor frame: the fingertip leaves a rest point, goes to θ
/// on the table (reach) or to θ and then up to the mouth and back (drink).
fn trial_csv(action: &str, theta: [f64; 2], len: usize, seed: f64) -> String {
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
            let _ = write!(s, ",{:.5},{:.5},{:.5}", v[0], v[1] + wob, v[2]);
        }
        s.push('\n');
    }
    s
}

fn write_demo(dir: &Path) {
    std::fs::create_dir_all(dir.join("data")).expect("create data dir");
    let mut k = 0;
    for action in ["reach", "drink"] {
        for (i, x) in [-0.2, -0.1, 0.0, 0.1].iter().enumerate() {
            for (j, y) in [0.5, 0.6, 0.7].iter().enumerate() {
                let len = 40 + 3 * i + 2 * j;
                let name = format!("data/{action}_{i}{j}.csv");
                std::fs::write(
                    dir.join(name),
                    trial_csv(action, [*x, *y], len, f64::from(k)),
                )
                .expect("write trial");
                k += 1;
            }
        }
    }
    let manifest = "[options]\nstates = 6\niterations = 20\ncov_floor = 0.003\n\n[preprocessing]\ntrim = false\nframe_rate = \"capture\"\n\n[[trials]]\nfiles = \"data/reach_*.csv\"\naction = \"reach\"\n\n[[trials]]\nfiles = \"data/drink_*.csv\"\naction = \"drink\"\n";
    std::fs::write(dir.join("train.toml"), manifest).expect("write manifest");
}

#[test]
fn train_inspect_classify_synthetic() {
    let dir = tempfile::tempdir().unwrap();
    write_demo(dir.path());
    let o = cli(
        dir.path(),
        &["train", "--manifest", "train.toml", "-o", "m.actrack.json"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(dir.path().join("m.actrack.json")).unwrap();
    assert!(text.contains("\"format\": \"actrack-model\"") && text.contains("\"version\": 1"));

    let o = cli(dir.path(), &["inspect", "m.actrack.json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("reach") && out.contains("drink") && out.contains("6 states"),
        "{out}"
    );

    let o = cli(
        dir.path(),
        &[
            "classify",
            "--model",
            "m.actrack.json",
            "--manifest",
            "train.toml",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("recognition: 24/24"), "{out}");

    let o = cli(
        dir.path(),
        &[
            "classify",
            "--model",
            "m.actrack.json",
            "--trial",
            "data/reach_12.csv",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["trials"][0]["recognised"], "reach");
    let th = v["trials"][0]["theta"].as_array().unwrap();
    assert!((th[0].as_f64().unwrap() + 0.1).abs() < 0.03, "{th:?}");
    assert!((th[1].as_f64().unwrap() - 0.7).abs() < 0.03, "{th:?}");
}

#[test]
fn bad_input_exits_2_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write_demo(d);
    // Empty manifest.
    std::fs::write(d.join("empty.toml"), "").unwrap();
    let o = cli(
        d,
        &["train", "--manifest", "empty.toml", "-o", "e.actrack.json"],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("empty.toml") && stderr(&o).contains("no trials"),
        "{}",
        stderr(&o)
    );
    assert!(!d.join("e.actrack.json").exists());
    // Manifest naming missing files: file and line.
    std::fs::write(
        d.join("missing.toml"),
        "\n[[trials]]\nfiles = \"data/nope_*.csv\"\naction = \"reach\"\n",
    )
    .unwrap();
    let o = cli(
        d,
        &[
            "train",
            "--manifest",
            "missing.toml",
            "-o",
            "e.actrack.json",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("missing.toml:3"), "{}", stderr(&o));
    // Missing static trial for a marker file.
    std::fs::write(d.join("m.csv"), "Trajectories\n100\n").unwrap();
    std::fs::write(
        d.join("nostatic.toml"),
        "[[trials]]\nfiles = \"m.csv\"\naction = \"reach\"\nstatic = \"{dir}/*_static.csv\"\n",
    )
    .unwrap();
    let o = cli(
        d,
        &[
            "train",
            "--manifest",
            "nostatic.toml",
            "-o",
            "e.actrack.json",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("static trial"), "{}", stderr(&o));
    // A malformed joints CSV: file and line.
    let mut bad = trial_csv("reach", [0.0, 0.6], 40, 0.0);
    bad = bad.replacen("\n3,", "\n3,x", 1);
    std::fs::write(d.join("data/reach_00.csv"), bad).unwrap();
    let o = cli(
        d,
        &["train", "--manifest", "train.toml", "-o", "e.actrack.json"],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("reach_00.csv:5"), "{}", stderr(&o));
    assert!(!d.join("e.actrack.json").exists());
    // A model of another version.
    std::fs::write(
        d.join("v2.actrack.json"),
        "{\"format\":\"actrack-model\",\"version\":2}",
    )
    .unwrap();
    let o = cli(d, &["inspect", "v2.actrack.json"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("v2.actrack.json") && stderr(&o).contains("version 2"),
        "{}",
        stderr(&o)
    );
    let o = cli(
        d,
        &[
            "classify",
            "--model",
            "v2.actrack.json",
            "--trial",
            "data/reach_01.csv",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    // Usage errors.
    let o = cli(d, &["train"]);
    assert_eq!(o.status.code(), Some(2));
    let o = cli(
        d,
        &[
            "train",
            "--manifest",
            "train.toml",
            "-o",
            "x.actrack.json",
            "--states",
            "0",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    // Nothing half-written anywhere.
    let stray: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().contains(".tmp"))
        .collect();
    assert!(stray.is_empty());
}
