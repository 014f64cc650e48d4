//! The experiment (`actrack-experiments`, `scripts/reproduce-paper`) and `actrack-cli track` are
//! one tracker: a small model trained on a few UE-ADL training trials, one held-out trial
//! (ADL008, forward reach) rendered into video, tracked by the experiment, then the same frames,
//! scene and configuration tracked by the binary give the same CSV, byte for byte. Also checks
//! the experiment's metrics are finite and sane (not that they reach the paper's numbers).
//! Skipped, with a message, when the data directory is absent.
#![allow(clippy::unwrap_used)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use actrack::manifest::{Manifest, TrainOptions};
use actrack::mocap::ArmSide;
use actrack::train::{fit_actions, import_manifest};
use actrack_experiments::reproduce::{ConditionSpec, export_trial, run_condition, test_trials};

const BIN: &str = env!("CARGO_BIN_EXE_actrack-cli");

fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn manifest(files: &[(&str, &str)]) -> Manifest {
    let mut text = String::from(
        "root = \"..\"\n[preprocessing]\nframe_rate = 30\nmax_gap = 10\ntrim = { speed = 0.05 }\n\
         heading = \"auto\"\ntheta = \"max-extension\"\n",
    );
    for (f, a) in files {
        writeln!(
            text,
            "[[trials]]\nfiles = \"../shared/data/ue-adl/{f}\"\naction = \"{a}\"\narm = \"R\"\n\
             static = \"{{dir}}/*_static.csv.xz\""
        )
        .unwrap();
    }
    let path = project_root().join("manifests").join("smoke.toml");
    Manifest::parse(&path, &text).unwrap()
}

#[test]
fn experiment_and_track_write_the_same_csv() {
    if !project_root().join("../shared/data/ue-adl/ADL008").is_dir() {
        eprintln!("skipped: ../shared/data/ue-adl is not there");
        return;
    }
    let train = manifest(&[
        ("ADL00[123]/ADL00?FR1.csv.xz", "reach"),
        ("ADL00[123]/ADL00?AR1.csv.xz", "reach"),
        ("ADL00[123]/ADL00?DR1.csv.xz", "drink"),
    ]);
    let trials = import_manifest(&train, None, &|_| {}).unwrap();
    assert_eq!(trials.len(), 9);
    let options = TrainOptions {
        states: 8,
        iterations: 5,
        ..TrainOptions::default()
    };
    let model = fit_actions(&trials, &options, &train.preprocessing, None, &|_| {}).unwrap();
    let test = manifest(&[("ADL008/ADL008FR1.csv.xz", "reach")]);
    let mut held_out = test_trials(&test, ArmSide::Right).unwrap();
    assert_eq!(held_out.len(), 1);
    // Short: the approach only (the first 40 frames).
    held_out[0].poses.truncate(40);
    let n = held_out[0].poses.len();

    // The default configuration (centred median, gate, penalty, floor) with fewer particles.
    let spec: ConditionSpec = toml::from_str(
        "name = \"smoke\"\npreset = \"default\"\nseeds = [3]\n[track.filter]\nparticles = 150\n",
    )
    .unwrap();
    let cond = spec.expand().unwrap().remove(0);
    let (res, runs) = run_condition(&model, &held_out, &cond).unwrap();
    assert_eq!(runs[0].track.rows.len(), n);
    let e = &res.report;
    for s in [e.shoulder, e.elbow, e.fingertip, e.overall] {
        assert!(s.rmse.is_finite() && s.mae <= s.rmse + 1e-12, "{s:?}");
        assert!(s.rmse < 0.3, "{s:?}");
    }
    assert!(res.in_view > 0.999);

    let dir = tempfile::tempdir().unwrap();
    let run = export_trial(&model, &held_out, "ADL008FR1", &cond, dir.path()).unwrap();
    assert_eq!(
        run.track, runs[0].track,
        "export tracks as run_condition does"
    );
    let out = Command::new(BIN)
        .args([
            "track",
            "--model",
            "model.actrack.json",
            "--scene",
            "scene.toml",
            "--config",
            "config.toml",
            "--input",
            "frames",
            "--csv",
            "again.csv",
            "--threads",
            "2",
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let a = std::fs::read(dir.path().join("track.csv")).unwrap();
    let b = std::fs::read(dir.path().join("again.csv")).unwrap();
    assert!(a.len() > 1000);
    assert!(a == b, "the experiment's CSV and track's differ");
}
