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


def write_y4m(path, frames: np.ndarray, fps: int = 30, full_range: bool = False) -> None:
    """Write (T, H, W) uint8 grey frames as a monochrome y4m video. Limited range (the y4m
    default) maps the grey levels on reading; `full_range` reads back the frames exactly."""
    t, h, w = frames.shape
    extra = " XCOLORRANGE=FULL" if full_range else ""
    with open(path, "wb") as f:
        f.write(f"YUV4MPEG2 W{w} H{h} F{fps}:1 Ip A1:1 Cmono{extra}\n".encode())
        for frame in frames:
            f.write(b"FRAME\n")
            f.write(np.ascontiguousarray(frame, dtype=np.uint8).tobytes())


def synthetic_frames(n: int, width: int = 160, height: int = 120, seed: int = 0) -> np.ndarray:
    """(n, H, W) grey frames: a textured background with a bright bar sweeping across."""
    rng = np.random.default_rng(seed)
    base = rng.integers(60, 120, size=(height, width)).astype(np.uint8)
    frames = np.repeat(base[None], n, axis=0)
    for k in range(n):
        x = int(20 + k * (width - 40) / max(n - 1, 1))
        frames[k, height // 3 : 2 * height // 3, x : x + 6] = 230
    return frames
