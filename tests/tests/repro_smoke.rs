//! Smoke test of the reproduction pipeline (`actrack::reproduce`, `scripts/reproduce-paper`): a
//! small model trained on a few UE-ADL training trials, one held-out trial (ADL008, forward
//! reach) rendered into synthetic video in memory, tracked with few particles, evaluated.
//! Checks that the metrics are finite and sane, not that they reach the paper's numbers.
//! Skipped, with a message, when the data directory is absent.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use actrack::manifest::{Manifest, TrainOptions};
use actrack::mocap::ArmSide;
use actrack::reproduce::{ActorHeight, Condition, Segment, run_condition, scene_for, test_trials};
use actrack::train::{fit_actions, import_manifest};

fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
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
        .expect("writing to a String cannot fail");
    }
    let path = project_root().join("manifests").join("smoke.toml");
    Manifest::parse(&path, &text).expect("smoke manifest parses")
}

#[test]
fn reproduce_one_held_out_trial() {
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
    assert_eq!(held_out[0].subject, "ADL008");
    // Short: the approach only (the first 45 frames, 1.5 s).
    held_out[0].poses.truncate(45);
    let n = held_out[0].poses.len();
    assert!(n >= 20, "{n} frames");

    // The camera of the data README keeps the arm in view.
    let cond = Condition {
        particles: 60,
        ..Condition::monocular("smoke")
    };
    let scene = scene_for(&model, &cond, held_out[0].lengths).unwrap();
    let seg = Segment::from(&held_out[0]);
    for p in &seg.poses {
        let w = scene.pose_to_world(p);
        for j in 0..3 {
            let x = nalgebra::Vector3::new(w[3 * j], w[3 * j + 1], w[3 * j + 2]);
            let (u, v) = scene.cameras[0].project(&x).unwrap();
            assert!(scene.cameras[0].in_image(u, v), "joint {j} at ({u}, {v})");
        }
    }

    let (res, runs) = run_condition(&model, &held_out, &cond).unwrap();
    assert_eq!(runs.len(), 1);
    assert_eq!(runs[0].track.rows.len(), n);
    let e = &res.report;
    assert_eq!(e.frames, n);
    for s in [e.shoulder, e.elbow, e.fingertip, e.overall] {
        assert!(s.rmse.is_finite() && s.mae.is_finite(), "{s:?}");
        assert!(s.mae <= s.rmse + 1e-12, "{s:?}");
        // A tracked arm is within decimetres, not metres.
        assert!(s.rmse < 0.3, "{s:?}");
    }
    assert!(e.table_error.is_finite() && e.table_error < 0.3);
    assert!((0.0..=1.0).contains(&e.recognition_rate));
    assert_eq!(e.instances.len(), 1);
    assert_eq!(res.confusion.iter().flatten().sum::<usize>(), 1);
    assert!(res.ms_per_frame.is_finite() && res.ms_per_frame > 0.0);
    assert!(res.in_view > 0.999);
    // Posteriors are distributions.
    for r in &runs[0].track.rows {
        let s: f64 = r.posterior.iter().sum();
        assert!((s - 1.0).abs() < 1e-6, "posterior sums to {s}");
    }

    // The actor height: ADL008's hand rests below the shoulder, the models' too, so the rest
    // pose gives a factor near 1 and a track that differs from the uncalibrated one; a given
    // factor of exactly 1 gives the uncalibrated track bit for bit.
    let rest = actrack::reproduce::rest_heights(&held_out);
    let models = model.rest_height();
    let factor = ActorHeight::RestPose
        .factor("ADL008", &rest, models)
        .unwrap();
    assert!((0.7..1.3).contains(&factor), "{factor}");
    let given = Condition {
        actor_height: ActorHeight::Given(vec![("ADL008".into(), 1.0)]),
        ..cond.clone()
    };
    let (_, same) = run_condition(&model, &held_out, &given).unwrap();
    let poses = |r: &[actrack::reproduce::VideoRun]| -> Vec<[f64; 9]> {
        r[0].track.rows.iter().map(|x| x.pose).collect()
    };
    assert_eq!(poses(&same), poses(&runs));
    // The fingertip floor at ADL008's rest height moves the track, which stays finite.
    let floored = Condition {
        fingertip_floor: Some(actrack::pipeline::FINGERTIP_FLOOR_SIGMA),
        ..cond.clone()
    };
    let (res, floor_runs) = run_condition(&model, &held_out, &floored).unwrap();
    assert_ne!(poses(&floor_runs), poses(&runs));
    assert!(res.report.overall.rmse.is_finite() && res.report.overall.rmse < 0.3);
    let calibrated = Condition {
        actor_height: ActorHeight::RestPose,
        ..cond
    };
    let (res, moved) = run_condition(&model, &held_out, &calibrated).unwrap();
    assert_ne!(poses(&moved), poses(&runs));
    assert!(res.report.overall.rmse.is_finite() && res.report.overall.rmse < 0.3);
}
