//! Quality of the mocap importers and action models on the real UE-ADL Vicon data
//! (../shared/data/ue-adl): train on ADL001–ADL007, test on ADL008–ADL010.
//!
//! Every file is imported once (the import dominates the run time: the xz decoder is pure Rust),
//! then the two-action (reach vs drink) and three-action splits are trained and evaluated.
//! Skipped, with a message, when the data directory is absent.

use std::path::{Path, PathBuf};

use actrack::manifest::{Manifest, TrainOptions};
use actrack::mocap::trial::Importer;
use actrack::train::{
    Classifier, FractionOf, LabelledTrial, ThetaFrom, TrialResult, confusion, evaluate,
    fit_actions, format_confusion, import_trials, quantile,
};

fn project_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn subject(t: &LabelledTrial) -> u32 {
    let name = t
        .trial
        .source
        .file_name()
        .expect("trial path has a file name")
        .to_string_lossy()
        .into_owned();
    name[3..6]
        .parse()
        .expect("UE-ADL file names start with ADLnnn")
}

fn summarise(
    name: &str,
    results: &[TrialResult],
    actions: &[&str],
    reach: &[&str],
) -> (f64, f64, f64) {
    let correct = results
        .iter()
        .filter(|r| r.result.action == r.action)
        .count();
    let rate = correct as f64 / results.len() as f64;
    let errs: Vec<f64> = results
        .iter()
        .filter(|r| reach.contains(&r.action.as_str()))
        .map(|r| r.theta_error)
        .collect();
    let (med, p90) = (quantile(&errs, 0.5), quantile(&errs, 0.9));
    println!(
        "{name}: recognition {correct}/{} = {:.1} %; reach θ error median {:.2} cm, p90 {:.2} cm, max {:.2} cm (n = {})",
        results.len(),
        100.0 * rate,
        100.0 * med,
        100.0 * p90,
        100.0 * quantile(&errs, 1.0),
        errs.len()
    );
    println!(
        "  θ error quantiles 10/25/50/75/90/100 %: {}",
        [0.1, 0.25, 0.5, 0.75, 0.9, 1.0]
            .iter()
            .map(|&q| format!("{:.2}", 100.0 * quantile(&errs, q)))
            .collect::<Vec<_>>()
            .join(" / ")
    );
    if reach.len() > 1 {
        for a in reach {
            let e: Vec<f64> = results
                .iter()
                .filter(|r| r.action == *a)
                .map(|r| r.theta_error)
                .collect();
            println!(
                "  {a}: median {:.2} cm, p90 {:.2} cm, max {:.2} cm (n = {})",
                100.0 * quantile(&e, 0.5),
                100.0 * quantile(&e, 0.9),
                100.0 * quantile(&e, 1.0),
                e.len()
            );
        }
    }
    print!(
        "{}",
        format_confusion(&confusion(results, actions), actions)
    );
    (rate, med, p90)
}

#[test]
fn ue_adl_recognition_and_theta() {
    let root = project_root();
    let data = root.join("../shared/data/ue-adl");
    if !data.is_dir() {
        eprintln!(
            "SKIPPED: {} is absent (the UE-ADL data is needed for this test)",
            data.display()
        );
        return;
    }
    let t0 = std::time::Instant::now();
    // One manifest with three labels; the two-action split relabels F and A as `reach`.
    let m3 = Manifest::load(&root.join("manifests/ue-adl3-train.toml")).unwrap();
    let m3_test = Manifest::load(&root.join("manifests/ue-adl3-test.toml")).unwrap();
    let importer = Importer::new(m3.preprocessing.clone()).unwrap();
    let train3 = import_trials(&importer, &m3.trials, &|_| {}).unwrap();
    let test3 = import_trials(&importer, &m3_test.trials, &|_| {}).unwrap();
    println!(
        "imported {} + {} trials in {:.1?}",
        train3.len(),
        test3.len(),
        t0.elapsed()
    );
    assert!(train3.iter().all(|t| subject(t) <= 7));
    assert!(test3.iter().all(|t| subject(t) >= 8));
    assert_eq!(train3.len(), 7 * 30);
    assert!(test3.len() >= 3 * 30); // ADL008 has a sixth DL repetition

    let two = |v: &[LabelledTrial]| -> Vec<LabelledTrial> {
        v.iter()
            .map(|t| LabelledTrial {
                action: if t.action.starts_with("reach") {
                    "reach".into()
                } else {
                    t.action.clone()
                },
                trial: t.trial.clone(),
            })
            .collect()
    };
    let (train2, test2) = (two(&train3), two(&test3));
    let opts = TrainOptions {
        states: 20,
        ..m3.options.clone()
    };

    let t1 = std::time::Instant::now();
    let model2 = fit_actions(&train2, &opts, &m3.preprocessing, None, &|_| {}).unwrap();
    let model3 = fit_actions(&train3, &opts, &m3.preprocessing, None, &|_| {}).unwrap();
    println!("fitted 2 + 3 action models in {:.1?}", t1.elapsed());
    println!(
        "arm lengths L1 = {:.3} m, L2 = {:.3} m",
        model2.arm_lengths.upper_arm, model2.arm_lengths.forearm_hand
    );

    // The model file round-trips.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.actrack.json");
    model2.save(&path).unwrap();
    let back = actrack::model::ActionModel::load(&path).unwrap();
    assert_eq!(back.action_names(), model2.action_names());

    let c2 = Classifier::new(&model2).unwrap();
    let c3 = Classifier::new(&model3).unwrap();
    assert_eq!(c3.theta_from, ThetaFrom::Fingertip);
    assert_eq!(c3.theta_from_partial, ThetaFrom::Pose);
    // SPEC §2.6 as written (θ from the whole pose), for comparison.
    let mut c2_pose = Classifier::new(&model2).unwrap();
    c2_pose.theta_from = ThetaFrom::Pose;
    let mut c3_pose = Classifier::new(&model3).unwrap();
    c3_pose.theta_from = ThetaFrom::Pose;
    let right = |v: &[LabelledTrial]| -> Vec<LabelledTrial> {
        v.iter()
            .filter(|t| t.trial.arm == actrack::mocap::ArmSide::Right)
            .cloned()
            .collect()
    };
    let mut figures = Vec::new();
    for (label, c, test, actions, reach) in [
        (
            "2 actions, both arms",
            &c2,
            test2.clone(),
            vec!["reach", "drink"],
            vec!["reach"],
        ),
        (
            "2 actions, right arm",
            &c2,
            right(&test2),
            vec!["reach", "drink"],
            vec!["reach"],
        ),
        (
            "3 actions, both arms",
            &c3,
            test3.clone(),
            vec!["reach-forward", "reach-across", "drink"],
            vec!["reach-forward", "reach-across"],
        ),
        (
            "3 actions, right arm",
            &c3,
            right(&test3),
            vec!["reach-forward", "reach-across", "drink"],
            vec!["reach-forward", "reach-across"],
        ),
        (
            "2 actions, both arms, θ from the pose",
            &c2_pose,
            test2.clone(),
            vec!["reach", "drink"],
            vec!["reach"],
        ),
        (
            "3 actions, both arms, θ from the pose",
            &c3_pose,
            test3.clone(),
            vec!["reach-forward", "reach-across", "drink"],
            vec!["reach-forward", "reach-across"],
        ),
    ] {
        for (fraction, of) in [
            (1.0, FractionOf::Movement),
            (0.75, FractionOf::Movement),
            (0.5, FractionOf::Movement),
            (0.75, FractionOf::Recording),
            (0.5, FractionOf::Recording),
        ] {
            if fraction < 1.0 && (label.ends_with("right arm") || label.ends_with("pose")) {
                // Partial sequences: both arms, default classifier only (their θ comes from the
                // pose either way); keeps the test short.
                continue;
            }
            let res = evaluate(c, &test, fraction, of).unwrap();
            let f = summarise(
                &format!("{label}, first {:.0} % of the {of:?}", fraction * 100.0),
                &res,
                &actions,
                &reach,
            );
            figures.push((label, fraction, of, f));
        }
    }
    println!("total {:.1?}", t0.elapsed());
    for (label, fraction, of, (rate, med, p90)) in figures {
        if fraction < 1.0 {
            // A cut inside the movement (2026-12-01: 100 %, 2.83 / 5.73 cm at 75 %; before the
            // partial models' covariance inflation 3.06 / 9.63 cm): a regression guard only.
            if label.starts_with('2') && of == FractionOf::Movement && fraction >= 0.75 {
                assert!(rate >= 0.99, "{label}, 75 %: recognition {rate}");
                assert!(med <= 0.035, "{label}, 75 %: median θ error {med}");
                assert!(p90 <= 0.07, "{label}, 75 %: p90 θ error {p90}");
            }
            continue;
        }
        // Recognition of whole trials in every split; θ accuracy (issue 5: median ≤ 1 cm, p90
        // ≤ 2 cm) on both splits, both arms, with the default classifier (θ from the
        // fingertip). θ from the whole pose (SPEC §2.6 as written) is reported, not asserted
        // (2026-12-02: three actions 1.08 / 2.74 cm).
        assert!(rate >= 0.99, "{label}: recognition {rate}");
        if label.ends_with("both arms") {
            assert!(med <= 0.01, "{label}: median θ error {med}");
            assert!(p90 <= 0.02, "{label}: p90 θ error {p90}");
        }
    }
}
