#!/usr/bin/env python3
"""Stands in for the person who clicks the corners in scripts/walkthrough: projects the hidden
scene's table corners (the whole rendered table) and the acting shoulder through its camera
(pinhole + OpenCV's Brown distortion, written here independently of actrack) and adds Gaussian
noise of SIGMA px to each coordinate. Also writes the camera's intrinsics as an OpenCV
cv::FileStorage YAML, as `cv2.calibrateCamera` users have them.

Usage: click.py HIDDEN_SCENE.toml OUT_DIR [SIGMA] [SEED]
Writes OUT_DIR/corners.csv, OUT_DIR/shoulder.txt ("u,v"), OUT_DIR/camera.yml and prints the
table size "W,D" (the rendered table: the scene's region plus 0.15 m and 0.12 m each side).
"""
import math
import random
import sys
import tomllib

scene_path, out = sys.argv[1], sys.argv[2]
sigma = float(sys.argv[3]) if len(sys.argv) > 3 else 2.0
rng = random.Random(int(sys.argv[4]) if len(sys.argv) > 4 else 0)
scene = tomllib.load(open(scene_path, "rb"))
cam = scene["camera"][0]


def sub(a, b):
    return [a[i] - b[i] for i in range(3)]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def unit(a):
    n = math.sqrt(sum(x * x for x in a))
    return [x / n for x in a]


la = cam["look_at"]
z = unit(sub(la["target"], la["eye"]))
x = unit(cross(z, la.get("up", [0.0, 0.0, 1.0])))
y = cross(z, x)
rows = [x, y, z]
t = [-sum(r[i] * la["eye"][i] for i in range(3)) for r in rows]
k1, k2, p1, p2, k3 = (cam.get(k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3"))


def project(p):
    c = [sum(r[i] * p[i] for i in range(3)) + t[j] for j, r in enumerate(rows)]
    xn, yn = c[0] / c[2], c[1] / c[2]
    r2 = xn * xn + yn * yn
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return cam["fx"] * xd + cam["cx"], cam["fy"] * yd + cam["cy"]


def noisy(uv):
    return uv[0] + rng.gauss(0.0, sigma), uv[1] + rng.gauss(0.0, sigma)


tab = scene["table"]
assert tab.get("yaw_deg", 0.0) == 0.0
hx, hy = tab["half_extents"][0] + 0.15, tab["half_extents"][1] + 0.12
cx, cy, h = tab["centre"][0], tab["centre"][1], tab["height"]
corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]  # near-left, near-right, far-right, far-left
with open(f"{out}/corners.csv", "w") as f:
    f.write("u,v\n")
    for a, b in corners:
        f.write("%.2f,%.2f\n" % noisy(project([cx + a, cy + b, h])))
with open(f"{out}/shoulder.txt", "w") as f:
    f.write("%.2f,%.2f\n" % noisy(project(scene["actor"]["origin"])))
with open(f"{out}/camera.yml", "w") as f:
    f.write("%YAML:1.0\n---\n")
    f.write(f"image_width: {cam['width']}\nimage_height: {cam['height']}\n")
    f.write("camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n")
    f.write(f"   data: [ {cam['fx']}, 0., {cam['cx']}, 0., {cam['fy']}, {cam['cy']}, 0., 0., 1. ]\n")
    f.write("distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n")
    f.write(f"   data: [ {k1}, {k2}, {p1}, {p2}, {k3} ]\n")
print("%.2f,%.2f" % (2 * hx, 2 * hy))
