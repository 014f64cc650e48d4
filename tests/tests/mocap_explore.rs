//! Scratch exploration of settings on UE-ADL (ignored; run by hand with --ignored --nocapture).
use actrack::manifest::{Manifest, TrainOptions};
use actrack::mocap::trial::{Importer, Preprocessing};
use actrack::train::{
    Classifier, FractionOf, LabelledTrial, evaluate, fit_actions, import_trials, quantile,
};
use std::path::Path;

fn two(v: &[LabelledTrial]) -> Vec<LabelledTrial> {
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
}

#[test]
#[ignore = "exploration"]
fn explore() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let m3 = Manifest::load(&root.join("manifests/ue-adl3-train.toml")).unwrap();
    let m3t = Manifest::load(&root.join("manifests/ue-adl3-test.toml")).unwrap();
    let rates: Vec<f64> = std::env::var("RATES")
        .unwrap_or("30".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    let floors: Vec<f64> = std::env::var("FLOORS")
        .unwrap_or("0.005".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    let trims: Vec<f64> = std::env::var("TRIMS")
        .unwrap_or("0.05".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    for &rate in &rates {
        for &trim in &trims {
            let mut pre: Preprocessing = m3.preprocessing.clone();
            pre.frame_rate = Some(rate);
            pre.trim = if trim > 0.0 {
                Some(actrack::mocap::trial::TrimOptions {
                    speed: trim,
                    margin: 0,
                })
            } else {
                None
            };
            let imp = Importer::new(pre.clone()).unwrap();
            let tr = two(&import_trials(&imp, &m3.trials, &|_| {}).unwrap());
            let te = two(&import_trials(&imp, &m3t.trials, &|_| {}).unwrap());
            for &floor in &floors {
                let opts = TrainOptions {
                    cov_floor: floor,
                    ..m3.options.clone()
                };
                let t0 = std::time::Instant::now();
                let model = fit_actions(&tr, &opts, &pre, None, &|_| {}).unwrap();
                let fit_t = t0.elapsed();
                for ms in [false] {
                    let mut c = Classifier::new(&model).unwrap();
                    c.multi_start = ms;
                    for (frac, of) in [
                        (1.0, FractionOf::Movement),
                        (0.75, FractionOf::Movement),
                        (0.5, FractionOf::Movement),
                        (0.75, FractionOf::Recording),
                        (0.5, FractionOf::Recording),
                    ] {
                        let res = evaluate(&c, &te, frac, of).unwrap();
                        let ok = res.iter().filter(|r| r.result.action == r.action).count();
                        let e: Vec<f64> = res
                            .iter()
                            .filter(|r| r.action == "reach")
                            .map(|r| r.theta_error)
                            .collect();
                        println!(
                            "rate {rate} trim {trim} floor {floor} ms {ms} frac {frac} {of:?}: {ok}/{} med {:.2} p90 {:.2} cm (fit {fit_t:.1?})",
                            res.len(),
                            100.0 * quantile(&e, 0.5),
                            100.0 * quantile(&e, 0.9)
                        );
                    }
                }
            }
        }
    }
}
