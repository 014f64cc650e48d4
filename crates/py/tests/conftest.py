"""Shared fixtures of the actrack Python tests."""

from __future__ import annotations

import numpy as np
import pytest


def banded_transmat(rng: np.random.Generator, n: int, max_jump: int) -> np.ndarray:
    """A random left-right transition matrix with rows summing to 1 over the band."""
    a = np.zeros((n, n))
    for i in range(n):
        hi = min(n, i + max_jump + 1)
        row = rng.uniform(0.2, 1.0, hi - i)
        row[0] += 1.0  # self-transitions dominate, as in a real left-right model
        a[i, i:hi] = row / row.sum()
    return a


def spd(rng: np.random.Generator, d: int, scale: float = 1.0) -> np.ndarray:
    """A random well-conditioned symmetric positive definite matrix."""
    m = rng.normal(size=(d, d))
    return scale * (m @ m.T / d + 0.5 * np.eye(d))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
