"""The `actrack` crate through Python: mocap import, action models (train / classify / files),
scenes and the evaluation metrics, on small synthetic files written by the tests."""

from __future__ import annotations

import math

import numpy as np
import pytest

import actrack

HEADER = "frame,time,action,theta_u,theta_v,px,py,pz,qx,qy,qz,rx,ry,rz"
REST = np.array([0.05, 0.15, -0.50])  # fingertip at rest (actor frame, metres)


def arm_poses(theta, action: str, n: int = 120, rate: float = 100.0) -> np.ndarray:
    """(n, 9) poses of a right arm: `reach` goes to θ on the table and stays, `point` goes to θ
    and comes back. Shoulder at the origin; elbow bent below the shoulder–fingertip line."""
    t = np.arange(n) / rate
    s = np.clip((t - 0.15) / (n / rate - 0.3), 0.0, 1.0)
    if action == "point":
        s = np.sin(np.pi * s)
    s = 3 * s**2 - 2 * s**3
    target = np.array([theta[0], theta[1], -0.25])
    r = REST + s[:, None] * (target - REST)
    p = np.zeros_like(r)
    q = 0.5 * r + np.array([0.05, -0.05, -0.12])
    return np.concatenate([p, q, r], axis=1)


def write_trial(path, theta, action: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    poses = arm_poses(theta, action) + rng.normal(scale=0.002, size=(120, 9))
    lines = [HEADER]
    for k, pose in enumerate(poses):
        vals = ",".join(f"{v:.6f}" for v in pose)
        lines.append(f"{k},{k / 100.0:.4f},{action},{theta[0]:.4f},{theta[1]:.4f},{vals}")
    path.write_text("\n".join(lines) + "\n")


THETAS = [(-0.15, 0.35), (-0.15, 0.55), (0.15, 0.35), (0.15, 0.55), (0.0, 0.45), (0.05, 0.40)]


@pytest.fixture(scope="module")
def manifest(tmp_path_factory):
    d = tmp_path_factory.mktemp("demos")
    for action in ["reach", "point"]:
        for k, theta in enumerate(THETAS):
            write_trial(d / f"{action}_{k}.csv", theta, action, seed=len(action) * 100 + k)
    m = d / "train.toml"
    m.write_text(
        "[options]\nstates = 6\nmax_jump = 2\niterations = 15\ncov_floor = 0.005\n\n"
        '[[trials]]\nfiles = "reach_*.csv"\naction = "reach"\n\n'
        '[[trials]]\nfiles = "point_*.csv"\naction = "point"\n'
    )
    return m


@pytest.fixture(scope="module")
def model(manifest):
    return actrack.ActionModel.train(manifest)


def test_load_mocap_joints_csv(tmp_path):
    path = tmp_path / "trial.csv"
    write_trial(path, (0.1, 0.5), "reach", seed=1)
    demo = actrack.load_mocap(path, frame_rate=None, trim=False)
    assert set(demo) == {"shoulder", "elbow", "wrist", "fingertip", "time", "theta"}
    assert demo["fingertip"].shape == (120, 3)
    assert demo["time"][1] == pytest.approx(0.01)
    np.testing.assert_allclose(demo["theta"], [0.1, 0.5])
    assert np.all(np.isnan(demo["wrist"]))  # the CSV has no wrist columns
    resampled = actrack.load_mocap(path, frame_rate=30.0, trim=False)
    assert resampled["fingertip"].shape[0] == pytest.approx(120 * 0.3, abs=2)


def test_load_mocap_errors(tmp_path):
    with pytest.raises(actrack.ActrackOSError):
        actrack.load_mocap(tmp_path / "missing.csv")
    with pytest.raises(actrack.ActrackError, match="arm must be R or L"):
        actrack.load_mocap(tmp_path / "missing.csv", arm="X")


def test_train_classify_and_files(model, manifest, tmp_path):
    assert model.actions == ["reach", "point"]
    reach = model.phmm("reach")
    assert (reach.n_states, reach.dim, reach.theta_dim) == (6, 9, 2)
    upper, forearm = model.arm_lengths
    assert upper > 0 and forearm > 0
    assert model.provenance["states"] == 6
    with pytest.raises(actrack.ActrackError, match="no action `drink`"):
        model.phmm("drink")

    path = tmp_path / "demo.actrack.json"
    model.save(path)
    assert '"format": "actrack-model"' in path.read_text()
    again = actrack.ActionModel.load(path)
    assert again.actions == model.actions

    for action in ["reach", "point"]:
        trial = tmp_path / f"new_{action}.csv"
        write_trial(trial, (0.08, 0.42), action, seed=999)
        demo = actrack.load_mocap(trial)
        x = np.concatenate([demo["shoulder"], demo["elbow"], demo["fingertip"]], axis=1)
        result = again.classify(x)
        assert result["action"] == action
        assert set(result["scores"]) == {"reach", "point"}
        assert np.abs(result["theta"] - [0.08, 0.42]).max() < 0.05
        assert again.classify(x, multi_start=True)["action"] == action
        early = again.classify(x[: len(x) // 2], partial=True)
        assert set(early["scores"]) == {"reach", "point"}


def test_scene_round_trip(tmp_path):
    scene = actrack.Scene.default(320, 240)
    assert scene.image_sizes == [(320, 240)]
    path = tmp_path / "scene.toml"
    path.write_text(scene.to_toml())
    loaded = actrack.Scene.load(path)
    assert loaded.cameras == scene.cameras
    centre, half = loaded.theta_region
    assert centre.shape == (2,) and np.all(half > 0)
    world = loaded.theta_to_world(centre)
    uv = loaded.project(world[None, :])
    assert uv.shape == (1, 2) and np.all(np.isfinite(uv))
    poses = np.random.default_rng(0).normal(size=(4, 9))
    np.testing.assert_allclose(loaded.pose_to_actor(loaded.pose_to_world(poses)), poses, atol=1e-12)
    with pytest.raises(actrack.ActrackError, match="camera 3 does not exist"):
        loaded.project(world[None, :], camera=3)


def test_scene_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[cameras]]\nwidth = -1\n")
    with pytest.raises(actrack.ActrackError):
        actrack.Scene.load(bad)
    with pytest.raises(actrack.ActrackOSError):
        actrack.Scene.load(tmp_path / "none.toml")


def write_trajectory(path, poses, track: bool) -> None:
    header = HEADER + (",p_reach,p_point,theta_u_std,theta_v_std,entropy,ess" if track else "")
    lines = [header]
    for k, pose in enumerate(poses):
        vals = ",".join(f"{v:.6f}" for v in pose)
        extra = ",0.9,0.1,0.01,0.01,0.2,300" if track else ""
        lines.append(f"{k},{k / 30.0:.6f},reach,0.1,0.5,{vals}{extra}")
    path.write_text("\n".join(lines) + "\n")


def test_evaluate(tmp_path):
    truth = arm_poses((0.1, 0.5), "reach", n=40, rate=30.0)
    est = truth.copy()
    est[:, 2::3] += 0.01  # every joint 1 cm too high
    write_trajectory(tmp_path / "truth.csv", truth, track=False)
    write_trajectory(tmp_path / "track.csv", est, track=True)
    report = actrack.evaluate(tmp_path / "track.csv", tmp_path / "truth.csv")
    assert report["frames"] == 40
    assert report["shoulder"]["rmse"] == pytest.approx(0.01 / math.sqrt(3), rel=1e-4)
    assert report["overall"]["mae"] == pytest.approx(0.01 / 3, rel=1e-4)
    assert report["recognition_rate"] == 1.0
    assert len(report["instances"]) == 1
