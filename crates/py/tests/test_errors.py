"""Error paths: invalid input raises ActrackError (a ValueError) with the Rust message; files that
cannot be read raise ActrackOSError (an OSError)."""

from __future__ import annotations

import errno

import numpy as np
import pytest

import actrack


@pytest.fixture
def model() -> actrack.Hmm:
    return actrack.Hmm.from_params(
        [1.0, 0.0, 0.0],
        [[0.6, 0.4, 0.0], [0.0, 0.6, 0.4], [0.0, 0.0, 1.0]],
        [[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]],
        np.stack([np.eye(2)] * 3),
    )


def test_exception_hierarchy():
    assert issubclass(actrack.ActrackError, ValueError)
    assert issubclass(actrack.ActrackOSError, OSError)


def test_nan_input_is_a_value_error_naming_the_frame(model):
    x = np.zeros((5, 2))
    x[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"non-finite value NaN in sequence 0 at row 3, column 1"):
        model.log_likelihood(x)
    with pytest.raises(actrack.ActrackError):
        model.posteriors(x)


def test_wrong_number_of_columns(model):
    with pytest.raises(actrack.ActrackError, match="3 columns but the model's observations are 2-D"):
        model.viterbi(np.zeros((4, 3)))


def test_wrong_rank(model):
    with pytest.raises(actrack.ActrackError, match=r"x must be a 2-D array.*got shape \(4,\)"):
        model.log_likelihood(np.zeros(4))


def test_empty_sequence(model):
    with pytest.raises(actrack.ActrackError, match="empty"):
        model.log_likelihood(np.zeros((0, 2)))


def test_not_numeric(model):
    with pytest.raises(ValueError):
        model.log_likelihood([["a", "b"]])


def test_invalid_parameters():
    with pytest.raises(actrack.ActrackError, match="outside the band"):
        actrack.Hmm.from_params(
            [1.0, 0.0], [[0.5, 0.5], [0.5, 0.5]], [[0.0], [1.0]], [[1.0], [1.0]]
        )
    with pytest.raises(actrack.ActrackError, match="not positive definite"):
        actrack.Hmm.from_params([1.0], [[1.0]], [[0.0, 0.0]], [[[1.0, 2.0], [2.0, 1.0]]])
    with pytest.raises(actrack.ActrackError, match="end_mode must be"):
        actrack.Hmm.from_params([1.0], [[1.0]], [[0.0]], [[1.0]], end_mode="sometimes")
    with pytest.raises(actrack.ActrackError, match=r"transmat must be \(2, 2\)"):
        actrack.Hmm.from_params([0.5, 0.5], [[1.0]], [[0.0], [1.0]], [[1.0], [1.0]])


def test_fit_errors():
    with pytest.raises(actrack.ActrackError, match="n_states is required"):
        actrack.Hmm.fit([np.zeros((10, 2))])
    with pytest.raises(actrack.ActrackError, match="invalid parameter `cov_floor`"):
        actrack.Hmm.fit([np.zeros((10, 2))], n_states=2, cov_floor=-1.0)
    with pytest.raises(actrack.ActrackError, match="2 sequences but 1 thetas"):
        actrack.Phmm.fit([np.zeros((10, 2))] * 2, [[0.0, 0.0]], n_states=2)


def test_theta_errors():
    m = actrack.Phmm.from_params(
        [1.0], [[1.0]], [[0.0, 0.0]], [[[1.0], [0.0]]], [np.eye(2)], end_mode="none"
    )
    with pytest.raises(actrack.ActrackError, match="theta must have 1 values, got 2"):
        m.sample([0.0, 1.0])
    with pytest.raises(actrack.ActrackError, match="non-finite"):
        m.expected_trajectory([np.inf])
    with pytest.raises(actrack.ActrackError, match="θ is 1-D"):
        m.log_likelihood(np.zeros((3, 2)), [0.0, 0.0])


def test_missing_file_is_an_os_error(tmp_path):
    missing = tmp_path / "nope.json"
    with pytest.raises(actrack.ActrackOSError) as info:
        actrack.Phmm.load(missing)
    assert isinstance(info.value, OSError)
    assert info.value.errno == errno.ENOENT
    assert info.value.filename == str(missing)
    assert "cannot read" in str(info.value)


def test_malformed_file_is_a_value_error(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(actrack.ActrackError, match="not valid JSON"):
        actrack.Phmm.load(bad)
    other = tmp_path / "other.json"
    other.write_text('{"format": "actrack-phmm", "version": 99, "model": {}}')
    with pytest.raises(actrack.ActrackError, match="unsupported actrack-phmm version 99"):
        actrack.Phmm.load(other)


def test_nan_in_training_data_names_the_sequence():
    seqs = [np.random.default_rng(k).normal(size=(20, 2)) for k in range(3)]
    seqs[1][4, 0] = np.nan
    with pytest.raises(actrack.ActrackError, match=r"non-finite value NaN in sequence 1 at row 4"):
        actrack.Hmm.fit(seqs, n_states=2)
    with pytest.raises(actrack.ActrackError, match=r"non-finite"):
        actrack.Phmm.fit(seqs, [[0.0, 0.0], [1.0, 0.0], [np.nan, 1.0]], n_states=2)
