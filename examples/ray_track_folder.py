"""Track every video of a folder in parallel on a Ray cluster: one task per video, one MCAP (and
one trajectory CSV) per video.

This is the path for users who outgrow one machine. Each task runs the same pipeline as
``actrack-cli track`` (``actrack.track_video``) with the GIL released, so a worker process spends
its time in Rust. The model and the scene travel through Ray's object store as text, so workers on
other nodes need no copy of them; the videos and the output folder must be reachable from every
node (a shared file system) — on one machine that is automatic.

    pip install actrack "ray>=2.9"
    python examples/ray_track_folder.py model.actrack.json scene.toml videos/ tracks/
    python examples/ray_track_folder.py ... --address auto        # an existing cluster

A video is a ``.y4m`` file, any file ffmpeg reads (``.mp4``, ``.mkv``, …), or a sub-folder of
PNG/JPEG frames.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from typing import Any

import ray

import actrack

VIDEO_SUFFIXES = {".y4m", ".mp4", ".m4v", ".mkv", ".mov", ".avi", ".webm"}


def find_videos(folder: pathlib.Path) -> list[pathlib.Path]:
    """The videos of a folder, sorted: video files and sub-folders of frames."""
    videos = []
    for p in sorted(folder.iterdir()):
        if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES:
            videos.append(p)
        elif p.is_dir() and any(
            f.suffix.lower() in {".png", ".jpg", ".jpeg"} for f in p.iterdir()
        ):
            videos.append(p)
    return videos


@ray.remote
def track_one(
    model_json: str,
    scene_toml: str,
    video: str,
    out_dir: str,
    n_particles: int,
    seed: int,
) -> dict[str, Any]:
    """One Ray task: track one video, write `<stem>.mcap` and `<stem>.csv` into `out_dir`."""
    model = actrack.ActionModel.from_json(model_json)
    scene = actrack.Scene.parse(scene_toml)
    stem = pathlib.Path(video).stem
    mcap = pathlib.Path(out_dir) / f"{stem}.mcap"
    csv = pathlib.Path(out_dir) / f"{stem}.csv"
    summary = actrack.track_video(
        model, scene, video, mcap=mcap, csv=csv, n_particles=n_particles, seed=seed
    )
    return {"video": video, "mcap": str(mcap), "csv": str(csv), **summary}


def run(
    model_path: str | pathlib.Path,
    scene_path: str | pathlib.Path,
    videos_dir: str | pathlib.Path,
    out_dir: str | pathlib.Path,
    *,
    n_particles: int = 400,
    seed: int = 0,
    cpus_per_task: int = 1,
    address: str | None = None,
    num_cpus: int | None = None,
) -> list[dict[str, Any]]:
    """Track every video of `videos_dir` on Ray; returns one summary dict per video."""
    videos = find_videos(pathlib.Path(videos_dir))
    if not videos:
        raise FileNotFoundError(f"no videos in {videos_dir}")
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # Validate the inputs here, once, with clear errors, before any task starts.
    model_json = actrack.ActionModel.load(model_path).to_json()
    scene_toml = actrack.Scene.load(scene_path).to_toml()
    if not ray.is_initialized():
        ray.init(address=address, num_cpus=num_cpus, include_dashboard=False, log_to_driver=False)
    model_ref, scene_ref = ray.put(model_json), ray.put(scene_toml)
    # Each task's particle filter runs on `cpus_per_task` threads (rayon), so that tasks sharing
    # a node do not oversubscribe its cores.
    task = track_one.options(
        num_cpus=cpus_per_task,
        runtime_env={"env_vars": {"RAYON_NUM_THREADS": str(cpus_per_task)}},
    )
    refs = [
        task.remote(model_ref, scene_ref, str(v), str(out.resolve()), n_particles, seed)
        for v in videos
    ]
    return ray.get(refs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("model", help="model file (*.actrack.json) from actrack-cli train")
    ap.add_argument("scene", help="scene file (TOML)")
    ap.add_argument("videos", help="folder of videos")
    ap.add_argument("out", help="output folder: one .mcap and one .csv per video")
    ap.add_argument("--particles", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cpus-per-task", type=int, default=1)
    ap.add_argument("--address", default=None, help="Ray cluster address (default: local)")
    args = ap.parse_args(argv)
    results = run(
        args.model,
        args.scene,
        args.videos,
        args.out,
        n_particles=args.particles,
        seed=args.seed,
        cpus_per_task=args.cpus_per_task,
        address=args.address,
    )
    for r in results:
        print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
