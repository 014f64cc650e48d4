"""Real motion capture (UE-ADL, read in place from ../shared/data/ue-adl; skipped without it)."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

import actrack

DATA = pathlib.Path(__file__).resolve().parents[3].parent / "shared" / "data" / "ue-adl" / "ADL001"


@pytest.mark.skipif(not DATA.is_dir(), reason="UE-ADL data not available")
def test_load_mocap_vicon_trial():
    static = next(DATA.glob("*_static.csv.xz"))
    demo = actrack.load_mocap(DATA / "ADL001AR1.csv.xz", static_trial=static, arm="R")
    t = demo["time"].shape[0]
    assert t > 10
    for joint in ["shoulder", "elbow", "wrist", "fingertip"]:
        assert demo[joint].shape == (t, 3)
        assert np.all(np.isfinite(demo[joint]))
    np.testing.assert_allclose(demo["time"][1], 1 / 30)  # resampled to the video rate
    # Actor frame: the shoulder stays near the origin; upper arm ≈ 25–40 cm.
    assert np.abs(demo["shoulder"]).max() < 0.2
    upper = np.linalg.norm(demo["elbow"] - demo["shoulder"], axis=1)
    assert 0.2 < np.median(upper) < 0.45
    assert demo["theta"].shape == (2,)
