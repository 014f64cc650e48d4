//! Time Baum–Welch iterations (the Rust side of `scripts/compare-hmmlearn`).
//!
//! `cargo run --release -p actrack-phmm --example fit_timing -- DATA.json` reads
//! `{"max_jump": J, "n_iter": K, "sequences": [[[..d..] × T] × S],
//!   "init": {"startprob", "transmat", "means", "covars"}}` (hmmlearn's parameter names; the
//! transmat must be zero outside the band), runs exactly K Baum–Welch iterations from `init`
//! with no exit modelling, no floor and no early stop (like hmmlearn with init_params=""),
//! and prints one JSON line with the seconds per iteration and the final log-likelihood.
//! Without an argument it times the same fixed synthetic workload as the criterion bench
//! (40 states, 9-D, full covariance, 20 sequences × 110 frames, PHMM with 2-D θ, 20 iterations).

use std::time::Instant;

use actrack_phmm::{EndMode, Phmm, PhmmParams};
use nalgebra::{DMatrix, DVector};
use serde_json::Value;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    match std::env::args().nth(1) {
        Some(path) => from_file(&path),
        None => synthetic(),
    }
}

fn arr(v: &Value) -> Result<&Vec<Value>, String> {
    v.as_array()
        .ok_or_else(|| format!("expected an array, got {v}"))
}

fn vec1(v: &Value) -> Result<Vec<f64>, String> {
    arr(v)?
        .iter()
        .map(|x| {
            x.as_f64()
                .ok_or_else(|| format!("expected a number, got {x}"))
        })
        .collect()
}

fn mat(v: &Value) -> Result<DMatrix<f64>, String> {
    let rows = arr(v)?.iter().map(vec1).collect::<Result<Vec<_>, _>>()?;
    let (r, c) = (rows.len(), rows.first().map_or(0, Vec::len));
    Ok(DMatrix::from_fn(r, c, |i, j| rows[i][j]))
}

fn from_file(path: &str) -> Result<(), Box<dyn std::error::Error>> {
    let f: Value = serde_json::from_str(&std::fs::read_to_string(path)?)?;
    let j = f["max_jump"].as_u64().ok_or("max_jump missing")? as usize;
    let n_iter = f["n_iter"].as_u64().ok_or("n_iter missing")? as usize;
    let seqs = arr(&f["sequences"])?
        .iter()
        .map(mat)
        .collect::<Result<Vec<_>, _>>()?;
    let p = &f["init"];
    let start = vec1(&p["startprob"])?;
    let n = start.len();
    let means = arr(&p["means"])?
        .iter()
        .map(|m| vec1(m).map(DVector::from_vec))
        .collect::<Result<Vec<_>, _>>()?;
    let d = means.first().map_or(0, DVector::len);
    let covs = arr(&p["covars"])?
        .iter()
        .map(mat)
        .collect::<Result<Vec<_>, _>>()?;
    let init = Phmm::from_params(
        &start,
        &mat(&p["transmat"])?,
        &vec![0.0; n],
        &means,
        &vec![DMatrix::zeros(d, 0); n],
        &covs,
        j,
        EndMode::None,
    )?;
    let params = PhmmParams::new(n)
        .max_jump(j)
        .end_mode(EndMode::None)
        .cov_floor(0.0)
        .min_occupancy(0.0)
        .tolerance(0.0)
        .max_iterations(n_iter)
        .learn_start(true)
        .check()?;
    // Warm-up (page faults, rayon pool start-up), then the timed runs; the median is reported.
    params.fit_from(&init, &seqs[..1], &[])?;
    let repeats = 5;
    let mut wall = Vec::new();
    let mut cpu = Vec::new();
    let mut last = None;
    for _ in 0..repeats {
        let (c0, t0) = (process_cpu_seconds(), Instant::now());
        let (_, report) = params.fit_from(&init, &seqs, &[])?;
        // n_iter E+M steps plus one final E-step (the fitted model's likelihood).
        let steps = report.iterations as f64 + 1.0;
        wall.push(t0.elapsed().as_secs_f64() / steps);
        cpu.push((process_cpu_seconds() - c0) / steps);
        last = Some(report);
    }
    let report = last.ok_or("no run")?;
    println!(
        "{{\"seconds_per_iteration\": {}, \"cpu_seconds_per_iteration\": {}, \"iterations\": {}, \"final_log_likelihood\": {}, \"threads\": {}}}",
        median(&mut wall),
        median(&mut cpu),
        report.iterations,
        report.log_likelihoods.last().copied().unwrap_or(f64::NAN),
        rayon::current_num_threads()
    );
    Ok(())
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// CPU time of all threads of this process (Linux: the sum of /proc/self/task/*/schedstat);
/// NaN elsewhere.
fn process_cpu_seconds() -> f64 {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return f64::NAN;
    };
    let mut ns = 0u64;
    for e in dir.flatten() {
        if let Ok(s) = std::fs::read_to_string(e.path().join("schedstat")) {
            ns += s
                .split_whitespace()
                .next()
                .and_then(|v| v.parse::<u64>().ok())
                .unwrap_or(0);
        }
    }
    ns as f64 * 1e-9
}

fn synthetic() -> Result<(), Box<dyn std::error::Error>> {
    let (seqs, thetas) = actrack_phmm_bench_data();
    let params = PhmmParams::new(40)
        .max_iterations(20)
        .tolerance(0.0)
        .check()?;
    let (c0, t0) = (process_cpu_seconds(), Instant::now());
    let (_, report) = params.fit(&seqs, &thetas)?;
    let (secs, cpu) = (t0.elapsed().as_secs_f64(), process_cpu_seconds() - c0);
    let steps = report.iterations as f64 + 1.0;
    println!(
        "synthetic PHMM fit (init + {} iterations): {:.2} ms per iteration wall, {:.2} ms CPU ({} threads)",
        report.iterations,
        1e3 * secs / steps,
        1e3 * cpu / steps,
        rayon::current_num_threads()
    );
    Ok(())
}

/// The fixed synthetic workload: a smooth 9-D reach-like path through 40 states whose end
/// depends on a 2-D θ, 20 sequences × 110 frames.
fn actrack_phmm_bench_data() -> (Vec<DMatrix<f64>>, Vec<DVector<f64>>) {
    let (s, t_len, d) = (20usize, 110usize, 9usize);
    let mut seqs = Vec::with_capacity(s);
    let mut thetas = Vec::with_capacity(s);
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..s {
        let th = [uniform() * 2.0 - 1.0, uniform() * 2.0 - 1.0];
        let speed = 0.8 + 0.4 * uniform();
        let x = DMatrix::from_fn(t_len, d, |t, k| {
            let ph = ((t as f64 / t_len as f64) * speed).min(1.0);
            let base = (3.0 * ph + k as f64).sin() * 0.3;
            base + ph
                * (th[0] * ((k + 1) as f64 * 0.7).cos() + th[1] * ((k + 2) as f64 * 0.3).sin())
                * 0.2
                + 0.01 * (uniform() - 0.5)
        });
        seqs.push(x);
        thetas.push(DVector::from_row_slice(&th));
    }
    (seqs, thetas)
}
