//! Shared helpers of the integration tests: random models and brute-force references.
#![allow(dead_code, clippy::unwrap_used)]

use actrack_phmm::{EndMode, Phmm};
use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;

pub fn rng(seed: u64) -> Pcg64Mcg {
    Pcg64Mcg::seed_from_u64(seed)
}

pub fn normal(rng: &mut Pcg64Mcg) -> f64 {
    StandardNormal.sample(rng)
}

/// A random SPD matrix.
pub fn spd(rng: &mut Pcg64Mcg, d: usize, scale: f64) -> DMatrix<f64> {
    let m = DMatrix::from_fn(d, d, |_, _| normal(rng));
    (&m * m.transpose() / d as f64 + DMatrix::identity(d, d) * 0.3) * scale
}

/// A random banded model: N states, jump J, d-D, θ of dimension p.
pub fn random_model(
    rng: &mut Pcg64Mcg,
    n: usize,
    j: usize,
    d: usize,
    p: usize,
    end: EndMode,
    uniform_start: bool,
) -> Phmm {
    let mut start: Vec<f64> = if uniform_start {
        (0..n).map(|_| rng.random_range(0.1..1.0)).collect()
    } else {
        let mut s = vec![0.0; n];
        s[0] = 1.0;
        s
    };
    let s: f64 = start.iter().sum();
    for v in &mut start {
        *v /= s;
    }
    let mut a = DMatrix::zeros(n, n);
    let mut exit = vec![0.0; n];
    for i in 0..n {
        let hi = (i + j).min(n - 1);
        let mut row: Vec<f64> = (i..=hi).map(|_| rng.random_range(0.1..1.0)).collect();
        let e = match end {
            EndMode::MustEnd if i + 1 == n => rng.random_range(0.1..0.6),
            EndMode::Free => rng.random_range(0.05..0.3),
            _ => 0.0,
        };
        let tot: f64 = row.iter().sum();
        for v in &mut row {
            *v *= (1.0 - e) / tot;
        }
        for (k, v) in row.into_iter().enumerate() {
            a[(i, i + k)] = v;
        }
        exit[i] = e;
    }
    let means: Vec<DVector<f64>> = (0..n)
        .map(|_| DVector::from_fn(d, |_, _| normal(rng)))
        .collect();
    let weights: Vec<DMatrix<f64>> = (0..n)
        .map(|_| DMatrix::from_fn(d, p, |_, _| normal(rng)))
        .collect();
    let covs: Vec<DMatrix<f64>> = (0..n).map(|_| spd(rng, d, 0.8)).collect();
    Phmm::from_params(&start, &a, &exit, &means, &weights, &covs, j, end).unwrap()
}

/// Gaussian log-density by explicit inverse and determinant (independent of the crate's kernel).
pub fn log_gauss(x: &[f64], mu: &DVector<f64>, cov: &DMatrix<f64>) -> f64 {
    let d = x.len();
    let r = DVector::from_row_slice(x) - mu;
    let inv = cov.clone().try_inverse().unwrap();
    let q = (r.transpose() * inv * &r)[(0, 0)];
    -0.5 * q - 0.5 * cov.determinant().ln() - 0.5 * d as f64 * (2.0 * std::f64::consts::PI).ln()
}

/// Every state path with its log-probability (including the exit term), by enumeration.
pub fn all_paths(model: &Phmm, x: &DMatrix<f64>, theta: &[f64]) -> Vec<(Vec<usize>, f64)> {
    let (t_len, n) = (x.nrows(), model.n_states());
    let le: Vec<Vec<f64>> = (0..t_len)
        .map(|t| {
            let row: Vec<f64> = x.row(t).iter().copied().collect();
            (0..n)
                .map(|i| log_gauss(&row, &model.mean(i, theta), model.covariance(i)))
                .collect()
        })
        .collect();
    let mut out = Vec::new();
    let total = n.pow(t_len as u32);
    for code in 0..total {
        let mut path = vec![0usize; t_len];
        let mut c = code;
        for t in 0..t_len {
            path[t] = c % n;
            c /= n;
        }
        let mut lp = model.start_prob(path[0]).ln() + le[0][path[0]];
        for t in 1..t_len {
            lp += model.transition(path[t - 1], path[t]).ln() + le[t][path[t]];
        }
        lp += match model.end_mode() {
            EndMode::None => 0.0,
            _ => model.exit_prob(path[t_len - 1]).ln(),
        };
        out.push((path, lp));
    }
    out
}

pub fn logsumexp(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + v.iter().map(|x| (x - m).exp()).sum::<f64>().ln()
}

/// A random observation sequence (T × d).
pub fn random_seq(rng: &mut Pcg64Mcg, t: usize, d: usize) -> DMatrix<f64> {
    DMatrix::from_fn(t, d, |_, _| normal(rng))
}

/// The SPEC §7 test-6 ground truth: N = 12, d = 9, p = 2, smooth means, noise std 0.3.
pub fn smooth_truth(end: EndMode) -> Phmm {
    let (n, d, p) = (12, 9, 2);
    let mut a = DMatrix::zeros(n, n);
    let mut exit = vec![0.0; n];
    let jumps = [0.6, 0.3, 0.08, 0.02];
    for i in 0..n {
        let hi = (i + 3).min(n - 1);
        let e = if i + 1 == n && end == EndMode::MustEnd {
            0.3
        } else {
            0.0
        };
        let tot: f64 = jumps[..=hi - i].iter().sum();
        for k in 0..=hi - i {
            a[(i, i + k)] = jumps[k] / tot * (1.0 - e);
        }
        exit[i] = e;
    }
    let means: Vec<DVector<f64>> = (0..n)
        .map(|i| DVector::from_fn(d, |k, _| 2.0 * (0.45 * i as f64 + k as f64).sin()))
        .collect();
    let weights: Vec<DMatrix<f64>> = (0..n)
        .map(|i| {
            let s = (i + 1) as f64 / n as f64;
            DMatrix::from_fn(d, p, |k, c| {
                3.0 * s * (1.3 * k as f64 + 2.1 * c as f64).cos()
            })
        })
        .collect();
    let covs = vec![DMatrix::identity(d, d) * 0.09; n];
    let mut start = vec![0.0; n];
    start[0] = 1.0;
    Phmm::from_params(&start, &a, &exit, &means, &weights, &covs, 3, end).unwrap()
}

/// Training set for test 6: 20 sequences, θ near the four corners (±1, ±1).
pub fn corner_training_set(truth: &Phmm, seed: u64) -> (Vec<DMatrix<f64>>, Vec<DVector<f64>>) {
    let mut r = rng(seed);
    let corners = [[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]];
    let mut seqs = Vec::new();
    let mut thetas = Vec::new();
    for m in 0..20 {
        let c = corners[m % 4];
        let th = [
            c[0] + r.random_range(-0.1..0.1),
            c[1] + r.random_range(-0.1..0.1),
        ];
        let (x, _) = loop {
            let s = truth.sample(&th, None, &mut r);
            if s.0.nrows() >= 8 {
                break s;
            }
        };
        seqs.push(x);
        thetas.push(DVector::from_row_slice(&th));
    }
    (seqs, thetas)
}
