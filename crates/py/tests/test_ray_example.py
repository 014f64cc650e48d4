"""examples/ray_track_folder.py on two short synthetic videos, on a local Ray cluster (skipped
when Ray is not installed)."""

from __future__ import annotations

import importlib.util
import pathlib

import pytest

import actrack

from conftest import synthetic_frames, write_y4m
from test_actrack_io import THETAS, write_trial

EXAMPLE = pathlib.Path(__file__).resolve().parents[3] / "examples" / "ray_track_folder.py"


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.filterwarnings("ignore::PendingDeprecationWarning")
@pytest.mark.filterwarnings("ignore::FutureWarning")
@pytest.mark.filterwarnings("ignore::ResourceWarning")
def test_ray_tracks_a_folder(tmp_path):
    ray = pytest.importorskip("ray")
    spec = importlib.util.spec_from_file_location("ray_track_folder", EXAMPLE)
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)

    demos = tmp_path / "demos"
    demos.mkdir()
    for action in ["reach", "point"]:
        for k, theta in enumerate(THETAS):
            write_trial(demos / f"{action}_{k}.csv", theta, action, seed=k)
    (demos / "train.toml").write_text(
        "[options]\nstates = 6\nmax_jump = 2\niterations = 5\ncov_floor = 0.005\n\n"
        '[[trials]]\nfiles = "reach_*.csv"\naction = "reach"\n\n'
        '[[trials]]\nfiles = "point_*.csv"\naction = "point"\n'
    )
    model_path = tmp_path / "model.actrack.json"
    actrack.ActionModel.train(demos / "train.toml").save(model_path)
    scene_path = tmp_path / "scene.toml"
    scene_path.write_text(actrack.Scene.default(160, 120).to_toml())
    videos = tmp_path / "videos"
    videos.mkdir()
    for k in range(2):
        write_y4m(videos / f"clip{k}.y4m", synthetic_frames(4, seed=k))

    try:
        results = example.run(
            model_path, scene_path, videos, tmp_path / "tracks", n_particles=32, num_cpus=2
        )
    finally:
        ray.shutdown()
    assert sorted(pathlib.Path(r["video"]).name for r in results) == ["clip0.y4m", "clip1.y4m"]
    assert all(r["frames"] == 4 for r in results)
    reader_mod = pytest.importorskip("mcap.reader")
    for r in results:
        with open(r["mcap"], "rb") as f:
            reader = reader_mod.make_reader(f)
            n = sum(1 for _ in reader.iter_messages(topics=["/actrack/estimate"]))
        assert n == 4
