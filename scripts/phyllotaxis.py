#!/usr/bin/env python3
"""Compares a Frond skeleton of a ROMI plant-imager scan with its manual measures.

Usage: phyllotaxis.py MODEL_TXT_DIR SKELETON_JSON MEASURES_JSON [PATH_RADIUS_MM]

The COLMAP model is scaled to millimetres by the camera path (a circle of PATH_RADIUS_MM,
300 by default, around the plant). Branches on the main stem, ordered by their attachment,
give internodes (mm along the stem) and divergence angles (around the stem's tangent, between
successive branches' initial directions), printed beside measures.json's. Standard library only.
"""
import json
import math
import statistics
import sys


def sub(a, b):
    return [x - y for x, y in zip(a, b)]


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    return math.sqrt(dot(a, a))


def camera_centres(model_dir):
    lines = [l for l in open(f"{model_dir}/images.txt") if not l.startswith("#")]
    centres = []
    for line in lines[0::2]:
        f = line.split()
        w, x, y, z = map(float, f[1:5])
        t = list(map(float, f[5:8]))
        rotation = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
        # centre = -R^T t
        centres.append([-sum(rotation[r][c] * t[r] for r in range(3)) for c in range(3)])
    return centres


def main():
    model_dir, skeleton_path, measures_path = sys.argv[1:4]
    path_radius_mm = float(sys.argv[4]) if len(sys.argv) > 4 else 300.0
    centres = camera_centres(model_dir)
    centroid = [sum(c[i] for c in centres) / len(centres) for i in range(3)]
    radius = statistics.mean(norm(sub(c, centroid)) for c in centres)
    scale = path_radius_mm / radius
    print(f"{len(centres)} cameras on a circle of {radius:.4f} model units: {scale:.1f} mm per unit")
    skeleton = json.load(open(skeleton_path))
    if isinstance(skeleton, dict):  # versioned file: {"format", "version", "branches"}
        skeleton = skeleton["branches"]
    measures = json.load(open(measures_path))
    roots = [b for b in skeleton if b["parent"] is None]
    if not roots:
        print("the skeleton is empty")
        return
    root = roots[0]
    print(
        f"skeleton: {len(skeleton)} branches; main stem {root['length'] * scale:.0f} mm long, "
        f"radius {root['radius_start'] * scale:.1f} to {root['radius_end'] * scale:.1f} mm"
    )
    children = sorted(
        (b for b in skeleton if b["parent"] == root["id"]), key=lambda b: b["parent_fraction"]
    )
    positions = [b["parent_fraction"] * root["length"] * scale for b in children]
    internodes = [b - a for a, b in zip(positions, positions[1:])]
    truth = measures["internodes"]
    print(
        f"branches on the main stem: {len(children)} "
        f"(measures.json: {len(truth) + 1} organs, {len(truth)} internodes)"
    )
    print(
        f"internodes (mm): {[round(v) for v in internodes]}; measures.json median "
        f"{statistics.median(truth):.1f}, total {sum(truth):.0f}"
    )
    line = root["centerline"]

    def direction(branch):
        k = min(int(branch["parent_fraction"] * (len(line) - 1)), len(line) - 2)
        tangent = sub(line[k + 1], line[k])
        tangent = [v / norm(tangent) for v in tangent]
        points = branch["centerline"]
        d = sub(points[min(5, len(points) - 1)], points[0])
        d = sub(d, [tangent[i] * dot(d, tangent) for i in range(3)])
        return d, tangent

    angles = []
    for a, b in zip(children, children[1:]):
        (da, tangent), (db, _) = direction(a), direction(b)
        angles.append(math.degrees(math.atan2(dot(cross(da, db), tangent), dot(da, db)) % (2 * math.pi)))
    print(
        f"divergence angles (deg): {[round(v) for v in angles]}; measures.json median "
        f"{math.degrees(statistics.median(measures['angles'])):.0f}"
    )


if __name__ == "__main__":
    main()
