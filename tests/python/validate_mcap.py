#!/usr/bin/env python3
"""Validate an actrack track MCAP with the official `mcap` Python package.

Checks: the file opens (summary and chunk indexes present), every message decodes as JSON,
every message on a Foxglove topic validates against a JSON schema written here from the
Foxglove message definitions (independently of the schemas embedded in the file), every
message names a non-empty frame id, and the /tf tree connects every frame id to `world`.

Usage: validate_mcap.py TRACK.mcap [--expect-frames N]   (exit 0 = valid; prints a summary)
"""
import json
import sys

import jsonschema
from mcap.reader import make_reader

NUM = {"type": "number"}
STR = {"type": "string"}
BOOL = {"type": "boolean"}


def obj(**props):
    return {"type": "object", "properties": props, "required": list(props), "additionalProperties": False}


def arr(items):
    return {"type": "array", "items": items}


TIME = obj(sec={"type": "integer", "minimum": 0}, nsec={"type": "integer", "minimum": 0, "maximum": 999999999})
VEC3 = obj(x=NUM, y=NUM, z=NUM)
QUAT = obj(x=NUM, y=NUM, z=NUM, w=NUM)
COLOR = obj(r=NUM, g=NUM, b=NUM, a=NUM)
POSE = obj(position=VEC3, orientation=QUAT)
POINT2 = obj(x=NUM, y=NUM)

# foxglove.FrameTransforms
FRAME_TRANSFORMS = obj(transforms=arr(obj(
    timestamp=TIME, parent_frame_id=STR, child_frame_id=STR, translation=VEC3, rotation=QUAT)))

# foxglove.SceneUpdate: every primitive array of a SceneEntity is required.
SCENE_ENTITY = obj(
    timestamp=TIME, frame_id=STR, id=STR, lifetime=TIME, frame_locked=BOOL,
    metadata=arr(obj(key=STR, value=STR)),
    arrows=arr(obj(pose=POSE, shaft_length=NUM, shaft_diameter=NUM, head_length=NUM, head_diameter=NUM, color=COLOR)),
    cubes=arr(obj(pose=POSE, size=VEC3, color=COLOR)),
    spheres=arr(obj(pose=POSE, size=VEC3, color=COLOR)),
    cylinders=arr(obj(pose=POSE, size=VEC3, bottom_scale=NUM, top_scale=NUM, color=COLOR)),
    lines=arr(obj(type={"enum": [0, 1, 2]}, pose=POSE, thickness=NUM, scale_invariant=BOOL, points=arr(VEC3),
                  color=COLOR, colors=arr(COLOR), indices=arr({"type": "integer", "minimum": 0}))),
    triangles=arr(obj(pose=POSE, points=arr(VEC3), color=COLOR, colors=arr(COLOR),
                      indices=arr({"type": "integer", "minimum": 0}))),
    texts=arr(obj(pose=POSE, billboard=BOOL, font_size=NUM, scale_invariant=BOOL, color=COLOR, text=STR)),
    models=arr(obj(pose=POSE, scale=VEC3, color=COLOR, override_color=BOOL, url=STR, media_type=STR, data=STR)),
)
SCENE_UPDATE = obj(deletions=arr(obj(timestamp=TIME, type={"enum": [0, 1]}, id=STR)), entities=arr(SCENE_ENTITY))

COMPRESSED_IMAGE = obj(timestamp=TIME, frame_id=STR, data=STR, format=STR)
CAMERA_CALIBRATION = obj(
    timestamp=TIME, frame_id=STR, width={"type": "integer", "minimum": 0}, height={"type": "integer", "minimum": 0},
    distortion_model=STR, D=arr(NUM),
    K={**arr(NUM), "minItems": 9, "maxItems": 9}, R={**arr(NUM), "minItems": 9, "maxItems": 9},
    P={**arr(NUM), "minItems": 12, "maxItems": 12})
IMAGE_ANNOTATIONS = obj(
    circles=arr(obj(timestamp=TIME, position=POINT2, diameter=NUM, thickness=NUM, fill_color=COLOR, outline_color=COLOR)),
    points=arr(obj(timestamp=TIME, type={"enum": [0, 1, 2, 3, 4]}, points=arr(POINT2), outline_color=COLOR,
                   outline_colors=arr(COLOR), fill_color=COLOR, thickness=NUM)),
    texts=arr(obj(timestamp=TIME, position=POINT2, text=STR, font_size=NUM, text_color=COLOR, background_color=COLOR)),
)

SCHEMAS = {
    "foxglove.FrameTransforms": FRAME_TRANSFORMS,
    "foxglove.SceneUpdate": SCENE_UPDATE,
    "foxglove.CompressedImage": COMPRESSED_IMAGE,
    "foxglove.CameraCalibration": CAMERA_CALIBRATION,
    "foxglove.ImageAnnotations": IMAGE_ANNOTATIONS,
}
REQUIRED_TOPICS = {"/tf", "/actrack/arm", "/actrack/particles", "/actrack/estimate"}


def frame_ids(schema_name, msg):
    """The frame ids a message names (its own, or its entities')."""
    if schema_name == "foxglove.FrameTransforms":
        return [t["child_frame_id"] for t in msg["transforms"]] + [t["parent_frame_id"] for t in msg["transforms"]]
    if schema_name == "foxglove.SceneUpdate":
        return [e["frame_id"] for e in msg["entities"]] or [None]
    if schema_name == "foxglove.ImageAnnotations":
        return ["(image annotations follow /camera/image)"]
    return [msg.get("frame_id")]


def main(argv):
    path = argv[1]
    expect = int(argv[argv.index("--expect-frames") + 1]) if "--expect-frames" in argv else None
    # --particles N: every /actrack/particles message draws at most N spheres, the fullest N.
    drawn = int(argv[argv.index("--particles") + 1]) if "--particles" in argv else None
    spheres = []
    errors = []
    counts = {}
    parents = {}
    used_frames = set()
    log_times = {}
    # Compile each schema once (jsonschema.validate() recompiles on every call).
    fox = {name: jsonschema.Draft7Validator(s) for name, s in SCHEMAS.items()}
    embedded = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None or not summary.chunk_indexes:
            errors.append("no summary / chunk indexes (file not indexed)")
        for schema, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            try:
                msg = json.loads(message.data)
            except ValueError as e:
                errors.append(f"{channel.topic}: message {message.sequence} is not JSON: {e}")
                continue
            if schema.id not in embedded:
                embedded[schema.id] = jsonschema.Draft7Validator(json.loads(schema.data))
            validator = fox.get(schema.name)
            if validator is not None:
                for e in list(validator.iter_errors(msg))[:1]:
                    errors.append(f"{channel.topic} ({schema.name}): {e.message} at {list(e.absolute_path)}")
            # The embedded schema (for actrack.Estimate the only one) must accept the message too.
            for e in list(embedded[schema.id].iter_errors(msg))[:1]:
                errors.append(f"{channel.topic}: embedded schema {schema.name} rejects the message: {e.message}")
            for fid in frame_ids(schema.name, msg):
                if not fid:
                    errors.append(f"{channel.topic}: message {message.sequence} has an empty frame_id")
                elif schema.name != "foxglove.FrameTransforms" and not fid.startswith("("):
                    used_frames.add(fid)
            if channel.topic == "/actrack/particles":
                spheres.append(sum(len(e.get("spheres", [])) for e in msg["entities"]))
            if schema.name == "foxglove.FrameTransforms":
                for t in msg["transforms"]:
                    parents[t["child_frame_id"]] = t["parent_frame_id"]
            log_times.setdefault(channel.topic, []).append(message.log_time)
    missing = REQUIRED_TOPICS - set(counts)
    if missing:
        errors.append(f"missing topics: {sorted(missing)}")
    for fid in sorted(used_frames | set(parents)):
        seen, cur = set(), fid
        while cur != "world":
            if cur in seen or cur not in parents:
                errors.append(f"frame `{fid}` does not reach `world` through /tf")
                break
            seen.add(cur)
            cur = parents[cur]
    for topic, times in log_times.items():
        if times != sorted(times):
            errors.append(f"{topic}: log times are not in order")
    if expect is not None and counts.get("/actrack/estimate") != expect:
        errors.append(f"expected {expect} frames, /actrack/estimate has {counts.get('/actrack/estimate')}")
    if drawn is not None and (not spheres or max(spheres) != drawn):
        errors.append(f"/actrack/particles: expected at most and at best {drawn} spheres, got {sorted(set(spheres))[-5:]}")
    print(json.dumps({"topics": counts, "frames": sorted(used_frames | set(parents)), "errors": errors[:20]}))
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
