"""C3D written by an independent library (the `c3d` package on PyPI) imports like the Vicon CSV
it was made from: the same real UE-ADL static and movement trials, float and integer point
formats, gaps kept as gaps (negative residual)."""

from __future__ import annotations

import lzma
import pathlib
import warnings

import c3d
import numpy as np
import pytest

import actrack

DATA = pathlib.Path(__file__).resolve().parents[3].parent / "shared" / "data" / "ue-adl" / "ADL001"


def read_vicon(path: pathlib.Path) -> tuple[float, list[str], np.ndarray]:
    """Rate, full marker labels (`Subject:Name`) and (frames, markers, 3) millimetres, NaN in gaps."""
    raw = path.read_bytes()
    if path.suffix == ".xz":
        raw = lzma.decompress(raw)
    lines = raw.decode("utf-8-sig").splitlines()
    assert lines[0].split(",")[0].strip() == "Trajectories"
    rate = float(lines[1].split(",")[0])
    names = lines[2].split(",")
    assert lines[4].split(",")[2].strip() == "mm"
    width = len(names)
    rows = [ln.split(",") for ln in lines[5:] if ln.strip()]
    data = np.array([[float(v) if v else np.nan for v in (r + [""] * width)[:width]] for r in rows])
    cols = [c for c, n in enumerate(names) if n]
    labels = [names[c] for c in cols]
    xyz = np.stack([data[:, c : c + 3] for c in cols], axis=1)
    return rate, labels, xyz


def write_c3d(path: pathlib.Path, rate: float, labels: list[str], xyz: np.ndarray, scale: float) -> None:
    """`scale` < 0: float points; > 0: 16-bit integers of `scale` mm."""
    writer = c3d.Writer(point_rate=rate, point_scale=scale, point_units="mm  ")
    frames = []
    for t in range(xyz.shape[0]):
        points = np.zeros((xyz.shape[1], 5), dtype=np.float32)
        ok = np.all(np.isfinite(xyz[t]), axis=1)
        points[ok, :3] = xyz[t][ok]
        points[~ok, 3] = -1.0  # residual < 0: no reconstruction
        frames.append((points, np.empty((0, 0), dtype=np.float32)))
    with warnings.catch_warnings():
        # The writer warns that there is no analog data; there is none by design.
        warnings.filterwarnings("ignore", message="No analog data", category=UserWarning)
        writer.add_frames(frames)
        writer.set_point_labels(labels)
        with path.open("wb") as h:
            writer.write(h)


@pytest.mark.skipif(not DATA.is_dir(), reason="UE-ADL data not available")
@pytest.mark.parametrize(("scale", "tol"), [(-1.0, 1e-6), (0.05, 2e-4)])
@pytest.mark.parametrize(("trial", "arm"), [("ADL001FR1", "R"), ("ADL001AL1", "L")])
def test_c3d_from_the_c3d_package_imports_like_the_csv(tmp_path, trial, arm, scale, tol):
    static_csv = DATA / "ADL001_static.csv.xz"
    movement_csv = DATA / f"{trial}.csv.xz"
    rate, labels, xyz = read_vicon(static_csv)
    static_c3d = tmp_path / "static.c3d"
    write_c3d(static_c3d, rate, labels, xyz, scale)
    rate, labels, xyz = read_vicon(movement_csv)
    gaps = int(np.isnan(xyz).any(axis=2).sum())
    movement_c3d = tmp_path / f"{trial}.c3d"
    write_c3d(movement_c3d, rate, labels, xyz, scale)

    want = actrack.load_mocap(movement_csv, static_trial=static_csv, arm=arm)
    got = actrack.load_mocap(movement_c3d, static_trial=static_c3d, arm=arm)
    assert got["time"].shape == want["time"].shape and want["time"].shape[0] > 30
    np.testing.assert_allclose(got["time"], want["time"], atol=1e-9)
    for joint in ["shoulder", "elbow", "wrist", "fingertip"]:
        np.testing.assert_allclose(got[joint], want[joint], rtol=0, atol=tol, err_msg=f"{trial} {joint} (gaps: {gaps})")
    np.testing.assert_allclose(got["theta"], want["theta"], rtol=0, atol=tol)


def test_c3d_without_a_wanted_marker_is_an_error_naming_it(tmp_path):
    if not DATA.is_dir():
        pytest.skip("UE-ADL data not available")
    static_csv = DATA / "ADL001_static.csv.xz"
    rate, labels, xyz = read_vicon(DATA / "ADL001FR1.csv.xz")
    keep = [i for i, n in enumerate(labels) if not n.endswith("RFTP")]
    path = tmp_path / "no_fingertip.c3d"
    write_c3d(path, rate, [labels[i] for i in keep], xyz[:, keep], -1.0)
    with pytest.raises(actrack.ActrackError, match="RFTP"):
        actrack.load_mocap(path, static_trial=static_csv, arm="R")
