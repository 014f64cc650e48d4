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
    // The rest height, the reference of `track --height-scale`: the fingertip below the
    // shoulder, in metres (as the model computes it).
    let model = actrack::model::ActionModel::load(&dir.path().join("m.actrack.json")).unwrap();
    let want = format!("rest height  fingertip {:.3} m below", -model.rest_height());
    assert!(out.contains(&want), "{want:?} in {out}");

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

    // SPEC §2.6 as written (θ from the whole pose) recognises and locates it as well; the
    // estimate is a different one (other coordinates enter the EM).
    let o = cli(
        dir.path(),
        &[
            "classify",
            "--model",
            "m.actrack.json",
            "--trial",
            "data/reach_12.csv",
            "--theta-from",
            "pose",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let w: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(w["trials"][0]["recognised"], "reach");
    let tp = w["trials"][0]["theta"].as_array().unwrap();
    assert!((tp[0].as_f64().unwrap() + 0.1).abs() < 0.03, "{tp:?}");
    assert!((tp[1].as_f64().unwrap() - 0.7).abs() < 0.03, "{tp:?}");
    assert_ne!(tp, th, "--theta-from pose gave the fingertip's estimate");
    let o = cli(
        dir.path(),
        &[
            "classify",
            "--model",
            "m.actrack.json",
            "--trial",
            "data/reach_12.csv",
            "--theta-from",
            "elbow",
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
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

/// A Vicon Nexus "Trajectories" CSV with the UE-ADL right-arm markers (and the left shoulder
/// cluster for the heading): every marker at a fixed offset from a body that slides along x,
/// the fingertip reaching forward. `landmarks`: add the static-only anatomical landmarks.
fn vicon_csv(frames: usize, landmarks: bool, reach: [f64; 2]) -> String {
    let mut markers: Vec<(String, [f64; 3])> = Vec::new();
    let cluster = |name: &str, c: [f64; 3], out: &mut Vec<(String, [f64; 3])>| {
        for (k, d) in [
            [30.0, 0.0, 0.0],
            [0.0, 30.0, 0.0],
            [0.0, 0.0, 30.0],
            [20.0, 20.0, 5.0],
        ]
        .iter()
        .enumerate()
        {
            out.push((
                format!("{name}{}", k + 1),
                [c[0] + d[0], c[1] + d[1], c[2] + d[2]],
            ));
        }
    };
    cluster("RSHO", [200.0, 0.0, 330.0], &mut markers);
    cluster("RUAR", [220.0, 0.0, 180.0], &mut markers);
    cluster("RLAR", [230.0, 150.0, 60.0], &mut markers);
    markers.push(("RFTP".into(), [240.0, 400.0, 20.0]));
    cluster("LSHO", [-200.0, 0.0, 330.0], &mut markers);
    if landmarks {
        for (n, p) in [
            ("RGTH", [200.0, 0.0, 320.0]),
            ("RLEP", [240.0, 0.0, 40.0]),
            ("RMEP", [200.0, 0.0, 40.0]),
            ("RSPR", [240.0, 250.0, 40.0]),
            ("RSPU", [220.0, 250.0, 40.0]),
        ] {
            markers.push((n.into(), p));
        }
    }
    let mut s = String::from("\u{feff}Trajectories\n100\n,,");
    for (n, _) in &markers {
        let _ = write!(s, "S:{n},,,");
    }
    s.push_str("\nFrame,Sub Frame");
    for _ in &markers {
        s.push_str(",X,Y,Z");
    }
    s.push_str("\n,");
    for _ in &markers {
        s.push_str(",mm,mm,mm");
    }
    s.push('\n');
    for t in 0..frames {
        let x = t as f64;
        let _ = write!(s, "{},0", t + 1);
        for (n, p) in &markers {
            let [rx, ry] = if n == "RFTP" {
                [reach[0] * x, reach[1] * x]
            } else {
                [0.0, 0.0]
            };
            let _ = write!(s, ",{:.3},{:.3},{:.3}", p[0] + x + rx, p[1] + ry, p[2]);
        }
        s.push('\n');
    }
    s
}

#[test]
fn bad_vicon_input_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("S_static.csv"), vicon_csv(20, true, [0.0, 0.0])).unwrap();
    let good = vicon_csv(60, false, [0.0, 4.0]);
    // Three well-formed trials with different θ (a PHMM needs at least three).
    for (k, r) in [[0.0, 4.0], [-2.0, 3.0], [1.5, 3.5]].iter().enumerate() {
        std::fs::write(d.join(format!("good{k}.csv")), vicon_csv(60, false, *r)).unwrap();
    }
    let manifest = |file: &str, with_static: bool| {
        format!(
            "[options]\nstates = 3\niterations = 3\n[preprocessing]\ntrim = false\n\n[[trials]]\nfiles = [\"{file}\", \"good?.csv\"]\naction = \"reach\"\narm = \"R\"\n{}",
            if with_static {
                "static = \"S_static.csv\"\n"
            } else {
                ""
            }
        )
    };
    let run = |name: &str, text: &str, with_static: bool| -> String {
        std::fs::write(d.join(format!("{name}.csv")), text).unwrap();
        std::fs::write(
            d.join(format!("{name}.toml")),
            manifest(&format!("{name}.csv"), with_static),
        )
        .unwrap();
        let o = cli(
            d,
            &[
                "train",
                "--manifest",
                &format!("{name}.toml"),
                "-o",
                "out.actrack.json",
            ],
        );
        assert!(
            !d.join("out.actrack.json").exists(),
            "{name}: model written"
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{name}: {e}");
        e
    };
    // The well-formed trial trains (so the failures below are the mutations').
    std::fs::write(d.join("good.toml"), manifest("good0.csv", true)).unwrap();
    let o = cli(
        d,
        &[
            "train",
            "--manifest",
            "good.toml",
            "-o",
            "good.actrack.json",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let lines: Vec<&str> = good.lines().collect();
    let edit = |f: &dyn Fn(&mut Vec<String>)| {
        let mut v: Vec<String> = lines.iter().map(|s| (*s).to_string()).collect();
        f(&mut v);
        v.join("\n") + "\n"
    };
    // Ragged row (line 21 loses fields).
    let e = run(
        "ragged",
        &edit(&|v| {
            let keep: Vec<&str> = v[20].split(',').take(10).collect();
            v[20] = keep.join(",");
        }),
        true,
    );
    assert!(e.contains("ragged.csv:21") && e.contains("fields"), "{e}");
    // Text in a numeric field (line 31).
    let e = run(
        "text",
        &edit(&|v| v[30] = v[30].replacen(",0,", ",0,abc", 1)),
        true,
    );
    assert!(e.contains("text.csv:31") && e.contains("abc"), "{e}");
    // Missing header line (the `Frame,Sub Frame,X,Y,Z` line).
    let e = run("noheader", &edit(&|v| drop(v.remove(3))), true);
    assert!(
        e.contains("noheader.csv:4") && e.contains("Frame,Sub Frame"),
        "{e}"
    );
    // Unknown marker name: RFTP renamed, so the marker set's fingertip is not in the file.
    let e = run(
        "unknown",
        &edit(&|v| v[2] = v[2].replace("S:RFTP", "S:RFTX")),
        true,
    );
    assert!(e.contains("unknown.csv:3") && e.contains("RFTP"), "{e}");
    // A cluster with fewer than three markers in 20 interior frames (longer than max_gap).
    let e = run(
        "cluster",
        &edit(&|v| {
            for row in v.iter_mut().take(45).skip(25) {
                let mut f: Vec<String> = row.split(',').map(str::to_string).collect();
                // RUAR2..RUAR4 are markers 6..8 (0-based 5..7): fields 2 + 3k.
                for k in 5..8 {
                    for c in 0..3 {
                        f[2 + 3 * k + c].clear();
                    }
                }
                *row = f.join(",");
            }
        }),
        true,
    );
    assert!(
        e.contains("cluster.csv:26") && e.contains("frame 21") && e.contains("RUAR"),
        "{e}"
    );
    // A marker trial listed without a static trial: the manifest entry is named.
    let e = run("nostatic", &good, false);
    assert!(e.contains("nostatic.toml:8") && e.contains("static"), "{e}");
}
