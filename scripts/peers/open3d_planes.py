#!/usr/bin/env python3
"""Peer for `webfusion planes`: Open3D's RANSAC plane segmentation, repeated for as many planes
per frame as webfusion found in that frame (removing each plane's inliers before the next), on
the same TUM frames, timed per frame.

Usage: open3d_planes.py TUM_DIR FRAMES_JSON OUT_JSON [--threads N]

Per frame: the depth PNG is read (not timed), a point cloud is made from it with the camera's
intrinsics (TUM calibration of the camera the path names, 5000 units/m, depth up to 5 m; timed
as "cloud"), then `segment_plane(distance_threshold=0.015, ransac_n=3, num_iterations=1000)`
runs once per plane (timed as "segment"; seed 003's final distance of 1.5 cm). Writes the
per-frame times and the planes found (camera frame, normal facing the camera).
"""
import json
import sys
import time

import numpy as np
import open3d as o3d

CAMERAS = {
    "freiburg1": (517.3, 516.5, 318.6, 255.3),
    "freiburg2": (520.9, 521.0, 325.1, 249.7),
    "freiburg3": (535.4, 539.2, 320.1, 247.6),
    "fr1": (517.3, 516.5, 318.6, 255.3),
    "fr2": (520.9, 521.0, 325.1, 249.7),
    "fr3": (535.4, 539.2, 320.1, 247.6),
}


def intrinsics_for(path):
    for key, k in CAMERAS.items():
        if key in path:
            return k
    return (525.0, 525.0, 319.5, 239.5)


def read_list(path):
    entries = []
    for line in open(path):
        f = line.split()
        if len(f) >= 2 and not f[0].startswith("#"):
            entries.append((float(f[0]), f[1]))
    return entries


def main():
    args = sys.argv[1:]
    threads = 0
    if "--threads" in args:
        i = args.index("--threads")
        threads = int(args[i + 1])
        del args[i : i + 2]
    if len(args) != 3:
        sys.exit(__doc__)
    tum, frames_json, out_json = args
    if threads > 0:
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    frames = json.load(open(frames_json))["frames"]
    depth = read_list(f"{tum}/depth.txt")
    fx, fy, cx, cy = intrinsics_for(tum)
    o3d.utility.random.seed(1)
    results = []
    for fr in frames:
        t, name = min(depth, key=lambda e: abs(e[0] - fr["timestamp"]))
        img = o3d.io.read_image(f"{tum}/{name}")
        w, h = np.asarray(img).shape[1], np.asarray(img).shape[0]
        k = o3d.camera.PinholeCameraIntrinsic(w, h, fx, fy, cx, cy)
        t0 = time.perf_counter()
        cloud = o3d.geometry.PointCloud.create_from_depth_image(img, k, depth_scale=5000.0, depth_trunc=5.0)
        t1 = time.perf_counter()
        planes = []
        rest = cloud
        for _ in range(len(fr["planes"])):
            if len(rest.points) < 3:
                break
            model, inliers = rest.segment_plane(distance_threshold=0.015, ransac_n=3, num_iterations=1000)
            a, b, c, d = model
            if d < 0:
                a, b, c, d = -a, -b, -c, -d
            planes.append({"normal": [a, b, c], "offset_m": d, "pixels": len(inliers)})
            rest = rest.select_by_index(inliers, invert=True)
        t2 = time.perf_counter()
        results.append({"index": fr["index"], "cloud_ms": (t1 - t0) * 1e3, "segment_ms": (t2 - t1) * 1e3, "planes": planes})
    json.dump({"frames": results}, open(out_json, "w"), indent=1)


if __name__ == "__main__":
    main()
