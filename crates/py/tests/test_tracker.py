"""The tracker through Python: frame-by-frame estimates, whole sequences, and `track_video`
writing an MCAP track that the official `mcap` package reads."""

from __future__ import annotations

import re

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


def read_track_csv(path):
    """The comment lines, the header and the rows (dicts of strings) of a track CSV."""
    lines = path.read_text().splitlines()
    comment = [line for line in lines if line.startswith("#")]
    body = [line for line in lines if line and not line.startswith("#")]
    header = body[0].split(",")
    return comment, header, [dict(zip(header, line.split(","))) for line in body[1:]]


def test_config_keys_change_the_track(model, scene):
    """The former keywords are configuration keys: explicit defaults are the track bit for bit,
    `actor.fingertip_floor = "table"` is the scene's table height, a floor below every pose is no
    floor, and another height scale still tracks."""
    frames = synthetic_frames(4)

    def run(*assignments):
        return actrack.Tracker(model, scene, n_particles=64, seed=5, set=list(assignments)).track(
            frames
        )

    def same(a, b):
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)

    base = run()
    same(
        base,
        run("prior.height_scale=1.0", "filter.action_floor=0.9", "actor.fingertip_floor=table"),
    )
    assert scene.table_height < 0.0
    same(base, run(f"actor.fingertip_floor={scene.table_height!r}"))
    same(run("actor.fingertip_floor=off"), run("actor.fingertip_floor=-10.0"))
    other = run("prior.height_scale=0.8")
    assert np.isfinite(other["best_pose"]).all()
    joint = run("filter.action_floor=0")  # 0: SPEC's joint resampling
    assert np.isfinite(joint["best_pose"]).all()


def test_config_sources(model, scene, tmp_path):
    """`preset`, `config` (a dict over the preset, or a file), `set`, `n_particles` and `seed`,
    applied in that order; `config` / `config_dict` give the effective configuration back."""
    default = actrack.Tracker(model, scene)
    d = default.config_dict
    assert d["filter"]["particles"] == 3200 and d["output"]["median"] == "centred"
    assert "[filter]" in default.config and "particles = 3200" in default.config
    paper = actrack.Tracker(model, scene, preset="paper").config_dict
    assert paper["filter"]["particles"] == 400 and paper["observation"]["contour"] == "raster"

    t = actrack.Tracker(
        model,
        scene,
        preset="paper",
        config={
            "filter": {"particles": 64, "speed_range": [0.5, 2.0]},
            "output.median_window": 3,
            "observation": {"gamma": 1, "foreground_gate": {"enabled": True}},
            "actor": {"fingertip_floor": -0.3},
        },
    )
    c = t.config_dict
    assert c["filter"]["particles"] == 64 and c["filter"]["speed_range"] == [0.5, 2.0]
    assert c["output"] == {"median": "causal", "median_window": 3, "mcap_particles": 400}
    assert c["observation"]["gamma"] == 1.0 and c["observation"]["contour"] == "raster"
    assert c["observation"]["foreground_gate"]["enabled"] is True
    assert c["actor"]["fingertip_floor"] == -0.3
    assert actrack.Tracker(model, scene, config=c).config == t.config  # the dict round-trips

    path = tmp_path / "track.toml"
    path.write_text(t.config)
    assert actrack.Tracker(model, scene, config=path).config == t.config
    assert actrack.Tracker(model, scene, config=str(path)).config == t.config

    def particles(**kw):
        return actrack.Tracker(model, scene, **kw).config_dict["filter"]["particles"]

    assert particles(config={"filter": {"particles": 10}}, set=["filter.particles=20"]) == 20
    assert particles(set=["filter.particles=20"], n_particles=30) == 30
    s = actrack.Tracker(model, scene, n_particles=16, set="filter.seed=4").config_dict
    assert s["filter"]["seed"] == 4
    assert actrack.Tracker(model, scene, n_particles=16, seed=9).config_dict["filter"]["seed"] == 9


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"set": ["filter.particles=0"]}, "filter.particles"),
        ({"set": ["filter.particels=3"]}, "filter.particels"),
        ({"set": ["observation.gamma=-1"]}, "observation.gamma"),
        ({"set": ["observation.gamma=0"]}, "observation.gamma"),
        ({"set": ["prior.height_scale=nan"]}, "prior.height_scale"),
        ({"set": ["actor.fingertip_floor=inf"]}, "actor.fingertip_floor"),
        ({"set": ["actor.fingertip_floor=floor"]}, "actor.fingertip_floor"),
        ({"set": ["filter.action_floor=1"]}, "filter.action_floor"),
        ({"set": ["output.median_window=4"]}, "output.median_window"),  # centred: odd
        ({"set": ["output.median=mean"]}, "output.median"),
        ({"set": ["filter.particles"]}, "KEY=VALUE"),
        ({"set": [3]}, "key=value"),
        ({"config": {"filter": {"particles": 0}}}, "filter.particles"),
        ({"config": {"observation": {"gama": 0.2}}}, "observation.gama"),
        ({"config": {"filter.particles": None}}, "filter.particles"),
        ({"config": 42}, "config must be"),
        ({"n_particles": 0}, "filter.particles"),
        ({"n_particles": -3}, "filter.particles"),
        ({"seed": -1}, "filter.seed"),
        ({"preset": "nope"}, "unknown preset `nope`"),
    ],
)
def test_bad_config_is_a_value_error_naming_the_key(model, scene, tmp_path, kwargs, needle):
    """`Tracker` and `track_video` check the configuration first (before reading the video)."""
    with pytest.raises(ValueError, match=re.escape(needle)) as e:
        actrack.Tracker(model, scene, **kwargs)
    assert isinstance(e.value, actrack.ActrackError)
    with pytest.raises(actrack.ActrackError, match=re.escape(needle)):
        actrack.track_video(model, scene, tmp_path / "missing.y4m", csv=tmp_path / "x.csv", **kwargs)


def test_bad_config_files(model, scene, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[filter]\nparticles = 10\nparticels = 3\n")
    with pytest.raises(actrack.ActrackError, match=r"bad\.toml:\d+: .*particels"):
        actrack.Tracker(model, scene, config=bad)
    zero = tmp_path / "zero.toml"
    zero.write_text("[filter]\nparticles = 0\n")
    with pytest.raises(actrack.ActrackError, match="filter.particles"):
        actrack.Tracker(model, scene, config=zero)
    with pytest.raises(actrack.ActrackOSError) as e:
        actrack.Tracker(model, scene, config=tmp_path / "missing.toml")
    assert e.value.filename == str(tmp_path / "missing.toml")
    good = tmp_path / "good.toml"
    good.write_text("[filter]\nparticles = 10\n")
    with pytest.raises(actrack.ActrackError, match="not both"):
        actrack.Tracker(model, scene, config=good, preset="paper")


@pytest.mark.parametrize("window", [1, 5])
def test_tracker_steps_match_track_video(model, scene, tmp_path, window):
    """`Tracker.step` frame by frame gives `track_video`'s estimates for the same frames,
    configuration and seed: the action posterior, θ and its spread, the entropy, the ESS and the
    causally smoothed pose (with a window of 1, the best pose). The CSV carries the
    configuration."""
    frames = synthetic_frames(6)
    video = tmp_path / "clip.y4m"
    write_y4m(video, frames, full_range=True)
    kw = {
        "n_particles": 200,
        "seed": 7,
        "set": ["output.median=causal", f"output.median_window={window}"],
    }
    csv = tmp_path / "clip.csv"
    summary = actrack.track_video(model, scene, video, csv=csv, **kw)
    assert summary["frames"] == len(frames)
    tracker = actrack.Tracker(model, scene, **kw)
    assert tracker.config == summary["config"]
    steps = [tracker.step(f) for f in frames]
    assert tracker.frames == len(frames)

    comment, header, rows = read_track_csv(csv)
    toml_lines = [line for line in tracker.config.splitlines() if line.strip()]
    assert [line[2:] for line in comment[1:]] == toml_lines
    assert [f"p_{a}" for a in tracker.actions] == [c for c in header if c.startswith("p_")]
    assert len(rows) == len(steps)

    def col(*names):
        return np.array([[float(r[n]) for n in names] for r in rows])

    tol = {"rtol": 0.0, "atol": 1e-5}
    assert [int(r["frame"]) for r in rows] == [e.frame for e in steps]
    assert [r["action"] for r in rows] == [e.action for e in steps]
    np.testing.assert_allclose(
        col(*[f"p_{a}" for a in tracker.actions]),
        [[e.action_posterior[a] for a in tracker.actions] for e in steps],
        **tol,
    )
    np.testing.assert_allclose(col("theta_u", "theta_v"), [e.theta_mean for e in steps], **tol)
    np.testing.assert_allclose(
        col("theta_u_std", "theta_v_std"), [e.theta_std for e in steps], **tol
    )
    np.testing.assert_allclose(col("entropy"), [[e.entropy] for e in steps], **tol)
    np.testing.assert_allclose(col("ess"), [[e.ess] for e in steps], **tol)
    pose = col("px", "py", "pz", "qx", "qy", "qz", "rx", "ry", "rz")
    np.testing.assert_allclose(pose, [e.smoothed_pose for e in steps], **tol)
    if window == 1:
        for e in steps:
            np.testing.assert_array_equal(e.smoothed_pose, e.best_pose)
        np.testing.assert_allclose(pose, [e.best_pose for e in steps], **tol)


def test_track_video_and_the_cli_write_the_same_csv(model, scene, tmp_path):
    """`track_video` and `actrack-cli track` (the binary the Rust tests built beside the
    wheel) write byte-identical CSV for the same model, scene, video, configuration and seed."""
    import os
    import pathlib
    import subprocess

    root = pathlib.Path(__file__).resolve().parents[3]
    target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", root / "target"))
    cli = next(
        (p for p in (target / "debug" / "actrack-cli", target / "release" / "actrack-cli") if p.exists()),
        None,
    )
    if cli is None:
        pytest.skip("actrack-cli is not built (cargo build -p actrack-cli)")
    frames = synthetic_frames(6)
    video = tmp_path / "clip.y4m"
    write_y4m(video, frames, full_range=True)
    model.save(tmp_path / "model.actrack.json")
    (tmp_path / "scene.toml").write_text(scene.to_toml())
    config = tmp_path / "config.toml"
    config.write_text('[filter]\nparticles = 150\nseed = 5\n\n[output]\nmedian = "causal"\n')
    actrack.track_video(model, scene, video, csv=tmp_path / "py.csv", config=config)
    subprocess.run(
        [str(cli), "track", "--model", "model.actrack.json", "--scene", "scene.toml",
         "--input", "clip.y4m", "--config", "config.toml", "--csv", "cli.csv"],
        cwd=tmp_path, check=True, capture_output=True,
    )
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()


def test_track_equals_frame_by_frame_steps(model, scene):
    """`track` gives the estimates of `step` called frame by frame, and frame numbering carries
    on after it."""
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
    summary_config = summary["config"]
    assert summary["frames"] == 5
    comment, header, rows = read_track_csv(tmp_path / "clip.csv")
    assert ",".join(header).startswith("frame,time,action,theta_u,theta_v")
    assert len(rows) == 5
    assert comment[0].startswith("# actrack track configuration")
    assert "particles = 64" in summary["config"]

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
        configs = [m for m in reader.iter_metadata() if m.name == "actrack.config"]
        assert [m.metadata["toml"] for m in configs] == [summary_config]


def test_edge_image():
    frames = synthetic_frames(1)
    g = actrack.edge_image(frames[0])
    assert g.shape == (120, 160) and g.dtype == np.float32
    assert g.max() == pytest.approx(1.0) and g.min() >= 0.0
    flat = actrack.edge_image(np.full((120, 160, 3), 77, dtype=np.uint8))
    assert np.all(flat == 0.0)  # no gradient anywhere: G ≡ 0
    sharp = actrack.edge_image(frames[0], sigma=0.0, binary=True)
    assert set(np.unique(sharp)) <= {0.0, 1.0}
    # Two colours of (nearly) the same grey value beside a black stripe: only the colour
    # gradient sees their boundary (column 20).
    img = np.zeros((30, 40, 3), dtype=np.uint8)
    img[:, :20] = (100, 100, 100)
    img[:, 20:32] = (0, 150, 105)
    grey = actrack.edge_image(img, sigma=0.0, tau=0.5)
    colour = actrack.edge_image(img, sigma=0.0, tau=0.5, colour=True)
    assert grey[:, 20].max() < 0.01 and grey[:, 32].min() > 0.999
    assert colour[:, 20].min() > 0.999 and colour[:, 32].min() > 0.999


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


def test_centred_median_matches_numpy():
    """`centred_median` against numpy's median over each clipped window t − h … t + h."""
    rng = np.random.default_rng(4)
    poses = rng.normal(size=(23, 9))
    poses[7, 3] = 1e3  # an outlier a median ignores
    for window in [1, 3, 7, 9, 51]:
        h = window // 2
        want = np.stack(
            [np.median(poses[max(0, t - h) : t + h + 1], axis=0) for t in range(len(poses))]
        )
        got = actrack.centred_median(poses, window)
        assert got.shape == poses.shape
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(actrack.centred_median(poses), actrack.centred_median(poses, 7))
    assert actrack.centred_median(np.zeros((0, 9))).shape == (0, 9)
    with pytest.raises(actrack.ActrackError, match="odd window"):
        actrack.centred_median(poses, 4)
    bad = poses.copy()
    bad[5, 2] = np.nan
    with pytest.raises(actrack.ActrackError, match="row 5"):
        actrack.centred_median(bad)
    with pytest.raises(actrack.ActrackError, match="columns"):
        actrack.centred_median(poses[:, :8])


def test_track_video_centred_median(model, scene, tmp_path):
    """`output.median = "centred"` writes every frame, with the actions and θ of a causal run
    whose window is the filter's own under a centred median (5 frames), and other poses."""
    video = tmp_path / "clip.y4m"
    write_y4m(video, synthetic_frames(6))
    rows = {}
    for median, window in [("causal", 5), ("centred", 7)]:
        csv = tmp_path / f"{median}.csv"
        s = actrack.track_video(
            model,
            scene,
            video,
            csv=csv,
            n_particles=64,
            set=[f"output.median={median}", f"output.median_window={window}"],
        )
        assert s["frames"] == 6
        rows[median] = read_track_csv(csv)[2]
    causal, centred = rows["causal"], rows["centred"]
    assert [r["frame"] for r in centred] == [str(k) for k in range(6)]
    pose = ["px", "py", "pz", "qx", "qy", "qz", "rx", "ry", "rz"]
    for a, b in zip(causal, centred):
        assert (a["action"], a["theta_u"], a["theta_v"]) == (b["action"], b["theta_u"], b["theta_v"])
    assert any(a[c] != b[c] for a, b in zip(causal, centred) for c in pose)
    with pytest.raises(actrack.ActrackError, match="output.median_window"):
        actrack.track_video(
            model, scene, video, csv=tmp_path / "x.csv", set=["output.median_window=6"]
        )
    with pytest.raises(actrack.ActrackError, match="output.median_window"):
        actrack.Tracker(model, scene, set=["output.median_window=0"])
