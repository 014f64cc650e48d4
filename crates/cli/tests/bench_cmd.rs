//! `actrack-cli bench` with tiny settings: the JSON object has the documented fields, and bad
//! options are usage errors (exit code 2).
#![allow(clippy::unwrap_used)]

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_actrack-cli");

/// `bench` with tiny settings; an option in `extra` replaces its default (clap refuses an
/// option given twice, which would make any bad value look refused).
fn bench(extra: &[&str]) -> std::process::Output {
    let defaults = [
        ("--particles", "24"),
        ("--width", "96"),
        ("--height", "72"),
        ("--frames", "4"),
        ("--warmup", "1"),
        ("--states", "4"),
    ];
    let mut args = vec!["bench"];
    for (flag, value) in defaults {
        if !extra.contains(&flag) {
            args.extend([flag, value]);
        }
    }
    args.extend_from_slice(extra);
    Command::new(BIN).args(&args).output().unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn json_has_the_fields() {
    for (contour, views) in [("analytic", "1"), ("raster", "2")] {
        let out = bench(&[
            "--contour",
            contour,
            "--views",
            views,
            "--threads",
            "2",
            "--json",
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for k in ["median_ms", "p95_ms", "fps", "mean_ms"] {
            let x = v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"));
            assert!(x.is_finite() && x > 0.0, "{k} = {x}");
        }
        assert!(v["p95_ms"].as_f64().unwrap() >= v["median_ms"].as_f64().unwrap());
        assert_eq!(v["particles"], 24);
        assert_eq!(v["threads"], 2);
        assert_eq!(v["views"].as_u64().unwrap(), views.parse::<u64>().unwrap());
        assert_eq!(v["contour"], contour);
        assert_eq!(v["frames"], 4);
        assert_eq!(v["device"], "cpu");
        for k in [
            "edge_image",
            "resample",
            "propagate_sample",
            "likelihood",
            "estimates",
        ] {
            let x = v["stages_ms"][k]
                .as_f64()
                .unwrap_or_else(|| panic!("stage {k} in {v}"));
            assert!(x.is_finite() && x >= 0.0, "{k} = {x}");
        }
        assert!(v["stages_ms"]["likelihood"].as_f64().unwrap() > 0.0);
        if cfg!(target_os = "linux") {
            assert!(v["peak_rss_kib"].as_u64().unwrap() > 0);
        }
    }
}

#[test]
fn text_report_and_usage_errors() {
    let out = bench(&[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    for s in [
        "median",
        "p95",
        "frames/s",
        "render + contour + likelihood",
        "budget",
    ] {
        assert!(text.contains(s), "`{s}` missing in:\n{text}");
    }
    let bad = bench(&["--particles", "0"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        stderr(&bad).contains("filter.particles"),
        "{}",
        stderr(&bad)
    );
    let bad = bench(&["--contour", "splines"]);
    assert_eq!(bad.status.code(), Some(2));
    // Without the `gpu` feature, `auto` falls back to the CPU with a message.
    if !cfg!(feature = "gpu") {
        let out = bench(&["--device", "auto", "--json"]);
        assert!(out.status.success());
        assert!(String::from_utf8_lossy(&out.stderr).contains("CPU"));
    }
}

/// `--states 0` (and 1: a left-to-right model needs two states) is refused naming the flag
/// before the models are trained, not a panic or a model error.
#[test]
fn too_few_states_are_refused_naming_the_flag() {
    for states in ["0", "1"] {
        let t = std::time::Instant::now();
        let out = bench(&["--states", states]);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "--states {states}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(err.contains("--states") && err.contains("≥ 2"), "{err}");
        assert!(!err.contains("cannot be used multiple times"), "{err}");
        assert!(
            out.stdout.is_empty(),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
        assert!(t.elapsed().as_secs_f64() < 20.0, "{:?}", t.elapsed());
    }
}
