"""Live cross-check against hmmlearn's GaussianHMM (full covariance).

hmmlearn has no exit state and treats a sequence as truncated anywhere, which is our
``end_mode="none"``. With the same parameters both libraries must give the same log-likelihood,
posteriors and Viterbi path; from the same initial parameters, Baum–Welch must reach the same
parameters (our covariance floor off, hmmlearn's priors neutral and ``init_params=""``).
"""

from __future__ import annotations

import numpy as np
import pytest

import actrack

from conftest import banded_transmat, spd

hmm = pytest.importorskip("hmmlearn.hmm")

RTOL = 1e-8


def make_pair(
    rng: np.random.Generator, n: int = 5, d: int = 3, max_jump: int = 2, sticky: bool = False
):
    start = rng.uniform(0.1, 1.0, n)
    if sticky:
        # Sequences then start early and dwell ~10 frames per state: every state is well used.
        start[0] += 20.0
    start /= start.sum()
    trans = banded_transmat(rng, n, max_jump)
    if sticky:
        for i in range(n - 1):
            stay = rng.uniform(0.88, 0.92)
            trans[i] *= (1.0 - stay) / (1.0 - trans[i, i])
            trans[i, i] = stay
    means = np.cumsum(rng.normal(size=(n, d)), axis=0)
    if sticky:
        means = 2.0 * np.arange(n)[:, None] + rng.normal(scale=0.3, size=(n, d))
    covars = np.stack([spd(rng, d, 0.5) for _ in range(n)])
    ours = actrack.Hmm.from_params(start, trans, means, covars, end_mode="none")
    ref = hmm.GaussianHMM(n_components=n, covariance_type="full", init_params="")
    ref.n_features = d
    ref.startprob_ = start
    ref.transmat_ = trans
    ref.means_ = means
    ref.covars_ = covars
    return ours, ref


def test_parameters_round_trip(rng):
    ours, ref = make_pair(rng)
    np.testing.assert_allclose(ours.startprob, ref.startprob_, rtol=1e-12)
    np.testing.assert_allclose(ours.transmat, ref.transmat_, rtol=1e-12)
    np.testing.assert_allclose(ours.means, ref.means_, rtol=1e-12)
    np.testing.assert_allclose(ours.covars, ref.covars_, rtol=1e-12)
    assert ours.end_mode == "none"
    np.testing.assert_array_equal(ours.exitprob, np.zeros(ours.n_states))


@pytest.mark.parametrize("length", [1, 7, 80, 400])
def test_inference_matches_hmmlearn(rng, length):
    ours, ref = make_pair(rng)
    x, _ = ref.sample(length, random_state=7)
    ll = ours.log_likelihood(x)
    ll_ref = ref.score(x)
    assert ll == pytest.approx(ll_ref, rel=RTOL)
    np.testing.assert_allclose(ours.posteriors(x), ref.predict_proba(x), rtol=RTOL, atol=1e-12)
    path, lp = ours.viterbi(x)
    lp_ref, path_ref = ref.decode(x, algorithm="viterbi")
    np.testing.assert_array_equal(path, path_ref)
    assert lp == pytest.approx(lp_ref, rel=RTOL)
    assert path.dtype == np.int64


def test_float32_input_gives_float64_results(rng):
    ours, ref = make_pair(rng)
    x, _ = ref.sample(50, random_state=3)
    x32 = x.astype(np.float32)
    assert ours.log_likelihood(x32) == pytest.approx(ref.score(x32.astype(np.float64)), rel=RTOL)
    assert ours.posteriors(x32).dtype == np.float64


@pytest.mark.parametrize("learn_startprob", [False, True])
def test_baum_welch_matches_hmmlearn(rng, learn_startprob):
    ours, ref = make_pair(rng, sticky=True)
    lengths = [50, 40, 60, 45, 55, 50]
    x = np.concatenate([ref.sample(n, random_state=10 + k)[0] for k, n in enumerate(lengths)])
    del ref
    seqs = np.split(x, np.cumsum(lengths)[:-1])
    n_iter = 5
    fitted = actrack.Hmm.fit(
        seqs,
        init=ours,
        n_iter=n_iter,
        tol=0.0,
        cov_floor=0.0,
        min_occupancy=0.0,
        transition_floor=0.0,
        learn_startprob=learn_startprob,
    )
    # A fresh estimator: hmmlearn builds its convergence monitor (n_iter, tol) in __init__.
    ref = hmm.GaussianHMM(
        n_components=ours.n_states,
        covariance_type="full",
        n_iter=n_iter,
        tol=-np.inf,
        params="stmc" if learn_startprob else "tmc",
        init_params="",
        covars_prior=0.0,
        covars_weight=1.0,
        means_prior=0.0,
        means_weight=0.0,
        startprob_prior=1.0,
        transmat_prior=1.0,
    )
    ref.startprob_ = ours.startprob
    ref.transmat_ = ours.transmat
    ref.means_ = ours.means
    ref.covars_ = ours.covars
    ref.fit(x, lengths)
    report = fitted.fit_report
    assert report is not None and report.iterations == n_iter
    # hmmlearn's history holds the log-likelihood of each E-step, i.e. before each M-step.
    np.testing.assert_allclose(report.log_likelihoods[:n_iter], ref.monitor_.history, rtol=RTOL)
    assert np.all(np.diff(report.log_likelihoods) > 0)
    np.testing.assert_allclose(fitted.startprob, ref.startprob_, rtol=RTOL, atol=1e-12)
    np.testing.assert_allclose(fitted.transmat, ref.transmat_, rtol=RTOL, atol=1e-12)
    np.testing.assert_allclose(fitted.means, ref.means_, rtol=RTOL)
    np.testing.assert_allclose(fitted.covars, ref.covars_, rtol=RTOL, atol=1e-12)
