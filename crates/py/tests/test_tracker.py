"""The tracker through Python: frame-by-frame estimates, whole sequences, and `track_video`
writing an MCAP track that the official `mcap` package reads."""

from __future__ import annotations

import numpy as np
import pytest

import actrack

from conftest import synthetic_frames, write_y4m
from test_actrack_io import THETAS, write_trial


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    d = tmp_path_factory.mktemp("tracker_demos")
    for action in ["reach", "point"]:
        for k, theta in enumerate(THETAS):
            write_trial(d / f"{action}_{k}.csv", theta, action, seed=k)
    m = d / "train.toml"
    m.write_text(
        "[options]\nstates = 6\nmax_jump = 2\niterations = 5\ncov_floor = 0.005\n\n"
        '[[trials]]\nfiles = "reach_*.csv"\naction = "reach"\n\n'
        '[[trials]]\nfiles = "point_*.csv"\naction = "point"\n'
    )
    return actrack.ActionModel.train(m)


@pytest.fixture(scope="module")
def scene():
    return actrack.Scene.default(160, 120)


def test_step_gives_an_estimate(model, scene):
    tracker = actrack.Tracker(model, scene, n_particles=100, seed=3)
    assert tracker.actions == ["reach", "point"]
    frames = synthetic_frames(3)
    rgb = np.repeat(frames[0][:, :, None], 3, axis=2)
    est = tracker.step(rgb)
    assert est.frame == 0
    assert set(est.action_posterior) == {"reach", "point"}
    assert sum(est.action_posterior.values()) == pytest.approx(1.0)
    assert est.action in {"reach", "point"}
    assert est.theta_mean.shape == (2,) and est.theta_std.shape == (2,)
    assert est.best_pose.shape == (9,) and est.smoothed_pose.shape == (9,)
    assert 0.0 <= est.entropy <= 1.0
    assert 0.0 < est.ess <= 100.0 + 1e-9
    assert tracker.step(frames[1]).frame == 1  # grey frames work too


def test_track_is_deterministic(model, scene):
    frames = synthetic_frames(4)
    a = actrack.Tracker(model, scene, n_particles=64, seed=5).track(frames)
    b = actrack.Tracker(model, scene, n_particles=64, seed=5).track(list(frames))
    assert a["action_posterior"].shape == (4, 2)
    assert a["best_pose"].shape == (4, 9)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    np.testing.assert_allclose(a["action_posterior"].sum(axis=1), 1.0)


def test_height_scale(model, scene):
    """`height_scale` multiplies the models' heights (`track --height-scale`): 1 is the models'
    own, bit for bit; another factor tracks; a factor that is not finite and positive is a
    ValueError naming it."""
    frames = synthetic_frames(4)
    base = actrack.Tracker(model, scene, n_particles=64, seed=5).track(frames)
    same = actrack.Tracker(model, scene, n_particles=64, seed=5, height_scale=1.0).track(frames)
    for key in base:
        np.testing.assert_array_equal(base[key], same[key])
    other = actrack.Tracker(model, scene, n_particles=64, seed=5, height_scale=0.8).track(frames)
    assert np.isfinite(other["best_pose"]).all()
    for bad in [0.0, -1.0, float("nan"), float("inf")]:
        with pytest.raises(ValueError, match="height scale"):
            actrack.Tracker(model, scene, height_scale=bad)


def test_fingertip_floor(model, scene):
    """`fingertip_floor` is `track --fingertip-floor` (metres, actor frame): a floor below
    every pose is the track without it, bit for bit; a height that is not finite is a
    ValueError naming it."""
    frames = synthetic_frames(4)
    base = actrack.Tracker(model, scene, n_particles=64, seed=5).track(frames)
    low = actrack.Tracker(model, scene, n_particles=64, seed=5, fingertip_floor=-10.0).track(frames)
    for key in base:
        np.testing.assert_array_equal(base[key], low[key])
    for bad in [float("nan"), float("inf")]:
        with pytest.raises(ValueError, match="fingertip floor"):
            actrack.Tracker(model, scene, fingertip_floor=bad)
    # The scene's table surface, below the shoulder, is a valid floor (`--fingertip-floor table`).
    assert scene.table_height < 0.0
    on_table = actrack.Tracker(
        model, scene, n_particles=64, seed=5, fingertip_floor=scene.table_height
    ).track(frames)
    assert np.isfinite(on_table["best_pose"]).all()


def test_action_floor(model, scene):
    """`action_floor` is `track --action-floor` (default 0.25, the same track bit for bit); a
    floor outside (0, 1) is a ValueError naming it."""
    frames = synthetic_frames(4)
    base = actrack.Tracker(model, scene, n_particles=64, seed=5).track(frames)
    same = actrack.Tracker(model, scene, n_particles=64, seed=5, action_floor=0.25).track(frames)
    for key in base:
        np.testing.assert_array_equal(base[key], same[key])
    for bad in [0.0, 1.0, float("nan")]:
        with pytest.raises(ValueError, match="particle floor"):
            actrack.Tracker(model, scene, action_floor=bad)


def test_track_equals_frame_by_frame_steps(model, scene):
    """`track` overlaps each step with the next frame's edge image; the estimates are those of
    `step` called frame by frame, and frame numbering carries on after it."""
    frames = synthetic_frames(5)
    whole = actrack.Tracker(model, scene, n_particles=64, seed=9)
    a = whole.track(frames)
    one = actrack.Tracker(model, scene, n_particles=64, seed=9)
    steps = [one.step(f) for f in frames]
    np.testing.assert_array_equal(a["best_pose"], np.stack([e.best_pose for e in steps]))
    np.testing.assert_array_equal(a["smoothed_pose"], np.stack([e.smoothed_pose for e in steps]))
    np.testing.assert_array_equal(a["theta_mean"], np.stack([e.theta_mean for e in steps]))
    np.testing.assert_array_equal(
        a["action_posterior"][:, 0], [e.action_posterior["reach"] for e in steps]
    )
    assert whole.step(frames[0]).frame == 5


def test_track_names_a_bad_frame_mid_sequence(model, scene):
    frames = list(synthetic_frames(3))
    frames.insert(2, np.zeros((50, 60), dtype=np.uint8))
    with pytest.raises(actrack.ActrackError, match="frame 2"):
        actrack.Tracker(model, scene, n_particles=16).track(frames)


def test_bad_frames(model, scene):
    tracker = actrack.Tracker(model, scene, n_particles=16)
    with pytest.raises(actrack.ActrackError, match="160×120"):
        tracker.step(np.zeros((50, 60, 3), dtype=np.uint8))
    with pytest.raises(actrack.ActrackError, match="uint8"):
        tracker.step(np.zeros((120, 160, 3)))
    with pytest.raises(actrack.ActrackError, match="particles"):
        actrack.Tracker(model, scene, n_particles=0)


def test_track_video_writes_mcap_and_csv(model, scene, tmp_path):
    video = tmp_path / "clip.y4m"
    write_y4m(video, synthetic_frames(5))
    summary = actrack.track_video(
        model, scene, video, mcap=tmp_path / "clip.mcap", csv=tmp_path / "clip.csv", n_particles=64
    )
    assert summary["frames"] == 5
    lines = (tmp_path / "clip.csv").read_text().splitlines()
    assert lines[0].startswith("frame,time,action,theta_u,theta_v")
    assert len(lines) == 6

    reader_mod = pytest.importorskip("mcap.reader")
    with open(tmp_path / "clip.mcap", "rb") as f:
        reader = reader_mod.make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic for c in summary.channels.values()}
        assert {"/tf", "/actrack/arm", "/actrack/particles", "/actrack/estimate"} <= topics
        estimates = [
            m for _, ch, m in reader.iter_messages(topics=["/actrack/estimate"])
        ]
        assert len(estimates) == 5
        assert all(m.log_time == pytest.approx(k * 1e9 / 30, abs=1e3) for k, m in enumerate(estimates))


def test_edge_image():
    frames = synthetic_frames(1)
    g = actrack.edge_image(frames[0])
    assert g.shape == (120, 160) and g.dtype == np.float32
    assert g.max() == pytest.approx(1.0) and g.min() >= 0.0
    flat = actrack.edge_image(np.full((120, 160, 3), 77, dtype=np.uint8))
    assert np.all(flat == 0.0)  # no gradient anywhere: G ≡ 0
    sharp = actrack.edge_image(frames[0], sigma=0.0, binary=True)
    assert set(np.unique(sharp)) <= {0.0, 1.0}


def test_contour_likelihood_limits(model, scene):
    """SPEC §7.9: G ≡ 1 on the contour gives log P = 0, G ≡ 0 gives −1/(2·0.15²)."""
    tracker = actrack.Tracker(model, scene, n_particles=32, seed=1)
    pose = tracker.step(synthetic_frames(1)[0]).best_pose
    poses = np.stack([pose, pose])
    ones = np.ones((120, 160))
    np.testing.assert_allclose(actrack.contour_likelihood(scene, ones, poses, model=model), 0.0, atol=1e-9)
    zeros = [np.zeros((120, 160), dtype=np.float32)]
    np.testing.assert_allclose(
        actrack.contour_likelihood(scene, zeros, poses, arm_lengths=model.arm_lengths),
        -1.0 / (2 * 0.15**2),
        rtol=1e-9,
    )
    with pytest.raises(actrack.ActrackError, match="arm lengths are unknown"):
        actrack.contour_likelihood(scene, ones, poses)
