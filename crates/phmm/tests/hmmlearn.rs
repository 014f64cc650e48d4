//! Cross-check against hmmlearn 0.3.3 (`GaussianHMM`, full covariance). The fixtures are written
//! by `scripts/make-hmmlearn-fixtures`; the models are left-right with zeros outside the band, so
//! they are our `EndMode::None` topology (no exit modelling, last row a_NN = 1).

#![allow(clippy::unwrap_used, clippy::float_cmp)] // helpers outside #[test] fns; exact zeros are the point

use actrack_phmm::{EndMode, Phmm, PhmmParams};
use nalgebra::{DMatrix, DVector};
use serde_json::Value;

fn load(name: &str) -> Value {
    let path = format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"));
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn vec1(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn mat(v: &Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = v.as_array().unwrap().iter().map(vec1).collect();
    let (r, c) = (rows.len(), rows[0].len());
    DMatrix::from_fn(r, c, |i, j| rows[i][j])
}

fn model_from(p: &Value, max_jump: usize) -> Phmm {
    let start = vec1(&p["startprob"]);
    let n = start.len();
    let means: Vec<DVector<f64>> = p["means"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| DVector::from_vec(vec1(m)))
        .collect();
    let d = means[0].len();
    let covs: Vec<DMatrix<f64>> = p["covars"].as_array().unwrap().iter().map(mat).collect();
    Phmm::from_params(
        &start,
        &mat(&p["transmat"]),
        &vec![0.0; n],
        &means,
        &vec![DMatrix::zeros(d, 0); n],
        &covs,
        max_jump,
        EndMode::None,
    )
    .unwrap()
}

fn close(a: f64, b: f64, rel: f64, abs: f64) -> bool {
    (a - b).abs() <= rel * b.abs() + abs
}

#[test]
fn inference_matches_hmmlearn() {
    let f = load("hmmlearn_inference.json");
    let model = model_from(&f["params"], f["max_jump"].as_u64().unwrap() as usize);
    for (k, s) in f["sequences"].as_array().unwrap().iter().enumerate() {
        let x = mat(&s["x"]);
        let ll = model.log_likelihood(&x, &[]).unwrap();
        let want = s["log_likelihood"].as_f64().unwrap();
        assert!(
            close(ll, want, 1e-8, 0.0),
            "seq {k}: log-likelihood {ll} vs hmmlearn {want}"
        );
        let post = model.posteriors(&x, &[]).unwrap();
        let want_post = mat(&s["posteriors"]);
        for t in 0..x.nrows() {
            for i in 0..model.n_states() {
                let (a, b) = (post[(t, i)], want_post[(t, i)]);
                assert!(
                    close(a, b, 1e-8, 1e-14),
                    "seq {k}: γ[{t}][{i}] = {a} vs hmmlearn {b}"
                );
            }
        }
        let (path, lp) = model.viterbi(&x, &[]).unwrap();
        let want_path: Vec<usize> = s["viterbi_path"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as usize)
            .collect();
        assert_eq!(path, want_path, "seq {k}: Viterbi path");
        let want_lp = s["viterbi_log_prob"].as_f64().unwrap();
        assert!(
            close(lp, want_lp, 1e-8, 0.0),
            "seq {k}: Viterbi log-prob {lp} vs {want_lp}"
        );
    }
}

#[test]
fn ten_baum_welch_iterations_match_hmmlearn() {
    let f = load("hmmlearn_baum_welch.json");
    let j = f["max_jump"].as_u64().unwrap() as usize;
    let init = model_from(&f["initial"], j);
    let seqs: Vec<DMatrix<f64>> = f["sequences"].as_array().unwrap().iter().map(mat).collect();
    let iters = f["iterations"].as_u64().unwrap() as usize;
    // hmmlearn learns π ('s' in params); no floor, no low-occupancy rule, no early stop.
    let params = PhmmParams::new(init.n_states())
        .max_jump(j)
        .end_mode(EndMode::None)
        .cov_floor(0.0)
        .min_occupancy(0.0)
        .tolerance(0.0)
        .max_iterations(iters)
        .learn_start(true)
        .check()
        .unwrap();
    let (fit, report) = params.fit_from(&init, &seqs, &[]).unwrap();
    assert_eq!(report.iterations, iters);
    let want = model_from(&f["fitted"], j);
    let n = fit.n_states();
    let d = fit.dim();
    let (rel, abs) = (1e-6, 1e-10);
    for i in 0..n {
        assert!(
            close(fit.start_prob(i), want.start_prob(i), rel, abs),
            "π[{i}]"
        );
        for jj in 0..n {
            let (a, b) = (fit.transition(i, jj), want.transition(i, jj));
            assert!(close(a, b, rel, abs), "a[{i}][{jj}] = {a} vs hmmlearn {b}");
        }
        let (ma, mb) = (fit.mean(i, &[]), want.mean(i, &[]));
        let (ca, cb) = (fit.covariance(i), want.covariance(i));
        for r in 0..d {
            assert!(
                close(ma[r], mb[r], rel, abs),
                "μ[{i}][{r}] = {} vs {}",
                ma[r],
                mb[r]
            );
            for c in 0..d {
                assert!(
                    close(ca[(r, c)], cb[(r, c)], rel, abs),
                    "Σ[{i}][{r},{c}] = {} vs {}",
                    ca[(r, c)],
                    cb[(r, c)]
                );
            }
        }
    }
    // The log-likelihood of the first iteration is the initial model's; the last entry of our
    // report is the fitted model's, which hmmlearn's score gives.
    let hist = vec1(&f["log_likelihood_history"]);
    assert!(close(report.log_likelihoods[0], hist[0], 1e-8, 0.0));
    let final_ll = f["final_log_likelihood"].as_f64().unwrap();
    assert!(close(
        *report.log_likelihoods.last().unwrap(),
        final_ll,
        1e-8,
        0.0
    ));
}
