"""The parametric HMM through the Python API: θ recovery, generation, files, pickling."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import actrack


def true_model(n: int = 8, d: int = 4, p: int = 2) -> actrack.Phmm:
    """A smooth ground-truth PHMM: means move along a curve whose shape depends on θ."""
    rng = np.random.default_rng(7)
    trans = np.zeros((n, n))
    for i in range(n - 1):
        trans[i, i], trans[i, i + 1] = 0.75, 0.25
    trans[n - 1, n - 1] = 0.75
    exitprob = np.zeros(n)
    exitprob[-1] = 0.25
    s = np.linspace(0.0, 1.0, n)
    bias = np.stack([np.sin(np.pi * s * (k + 1)) for k in range(d)], axis=1)
    weights = np.stack([np.outer(np.sin(np.pi * si) * np.ones(d), np.ones(p)) for si in s])
    weights *= rng.uniform(0.5, 1.5, size=(1, d, p))
    covars = np.stack([0.05**2 * np.eye(d) for _ in range(n)])
    start = np.eye(n)[0]
    return actrack.Phmm.from_params(start, trans, bias, weights, covars, exitprob=exitprob)


def test_from_params_accessors():
    m = true_model()
    assert (m.n_states, m.dim, m.theta_dim, m.max_jump) == (8, 4, 2, 1)
    assert m.end_mode == "must_end"
    assert m.mean_bias.shape == (8, 4)
    assert m.mean_weights.shape == (8, 4, 2)
    theta = np.array([0.3, -0.2])
    np.testing.assert_allclose(m.means(theta), m.mean_bias + m.mean_weights @ theta, rtol=1e-12)
    np.testing.assert_allclose(m.transmat.sum(axis=1) + m.exitprob, 1.0, rtol=1e-12)
    assert "Phmm(n_states=8" in repr(m)


def test_theta_recovery_on_synthetic_data():
    truth = true_model()
    rng = np.random.default_rng(1)
    corners = np.array([[-1, -1], [-1, 1], [1, -1], [1, 1]], dtype=float)
    thetas = np.concatenate([corners, corners, rng.uniform(-1, 1, size=(12, 2))])
    seqs = [truth.sample(t, seed=100 + k)[0] for k, t in enumerate(thetas)]
    model = actrack.Phmm.fit(seqs, thetas, n_states=8, max_jump=2, cov_floor=0.01)
    report = model.fit_report
    assert report is not None
    assert report.iterations >= 1
    assert np.all(np.diff(report.log_likelihoods) > -1e-6 * np.abs(report.log_likelihoods[1:]))
    errors = []
    for k, theta in enumerate(rng.uniform(-1, 1, size=(6, 2))):
        x, _ = truth.sample(theta, seed=1000 + k)
        est = model.estimate_theta(x, multi_start=True)
        assert est.theta.shape == (2,)
        assert np.isfinite(est.log_likelihood)
        errors.append(np.abs(est.theta - theta).max())
    assert max(errors) < 0.15, errors


def test_sample_and_expected_trajectory():
    m = true_model()
    x, states = m.sample([0.5, 0.5], seed=3)
    assert x.shape == (len(states), 4)
    assert states[0] == 0 and states[-1] == 7
    assert np.all(np.diff(states) >= 0)
    x2, _ = m.sample(np.array([0.5, 0.5]), seed=3)
    np.testing.assert_array_equal(x, x2)
    fixed, st = m.sample([0.5, 0.5], length=25, seed=4)
    assert fixed.shape == (25, 4) and st.shape == (25,)
    traj = m.expected_trajectory([0.0, 0.0], length=30)
    assert traj.shape == (30, 4)
    np.testing.assert_allclose(traj[0], m.means([0.0, 0.0])[0], rtol=1e-12)


def test_inference_with_theta():
    m = true_model()
    theta = np.array([-0.4, 0.2])
    x, states = m.sample(theta, seed=9)
    gamma = m.posteriors(x, theta)
    np.testing.assert_allclose(gamma.sum(axis=1), 1.0, rtol=1e-12)
    path, lp = m.viterbi(x, theta)
    assert lp <= m.log_likelihood(x, theta) + 1e-9
    assert path[-1] == m.n_states - 1
    assert np.mean(path == states) > 0.8


def test_save_load_and_pickle(tmp_path):
    m = true_model()
    path = tmp_path / "reach.phmm.json"
    m.save(path)
    back = actrack.Phmm.load(path)
    for name in ["startprob", "transmat", "exitprob", "mean_bias", "mean_weights", "covars"]:
        np.testing.assert_allclose(getattr(back, name), getattr(m, name), rtol=1e-15, atol=1e-15)
    again = pickle.loads(pickle.dumps(m))
    assert isinstance(again, actrack.Phmm)
    np.testing.assert_array_equal(again.covars, m.covars)
    assert actrack.Phmm.from_json(m.to_json()).n_states == 8


def test_hmm_file_is_a_phmm_with_no_theta(tmp_path):
    m = actrack.Hmm.from_params([1.0, 0.0], [[0.5, 0.5], [0.0, 1.0]], [[0.0], [1.0]], [[1.0], [1.0]])
    path = tmp_path / "plain.json"
    m.save(path)
    assert actrack.Phmm.load(path).theta_dim == 0
    assert actrack.Hmm.load(path).n_states == 2
    phmm_path = tmp_path / "param.json"
    true_model().save(phmm_path)
    with pytest.raises(actrack.ActrackError, match="load it with actrack.Phmm"):
        actrack.Hmm.load(phmm_path)
