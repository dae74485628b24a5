#!/usr/bin/env python3
"""Peer measuring stick: OpenCV ORB feature odometry, frame to frame, on a TUM RGB-D directory.

Usage (from the repo root, after scripts/peers/setup_venv.sh):
  .venv-peers/bin/python scripts/peers/opencv_orb_odometry.py DATA_DIR \
      --out-trajectory est.txt --out-json cv.json [--frames A..B] [--every N] [--drop A..B]

The pipeline issue 14 names: cv2.ORB_create(nfeatures=1000) on the grey image, a brute-force
Hamming matcher (cv2.BFMatcher, knnMatch k=2) with Lowe's ratio test (0.8, as seed 002 and
webfusion odometry use), and cv2.solvePnPRansac (OpenCV's defaults: 100 iterations, 8 px
reprojection error, confidence 0.99) on the reference frame's keypoints lifted to 3D with its
depth (depth_scale 5000; no depth, no point) and the current frame's 2D keypoints. The same
policy as webfusion odometry: a frame is accepted when PnP succeeds with at least 20 inliers;
it then becomes the reference; a rejected frame keeps the last pose. Intrinsics and frame
selection as scripts/peers/open3d_slam.py (the TUM camera the path names, or --intrinsics).

Outputs: --out-trajectory (TUM, camera-to-world at the depth timestamps, first = identity);
--out-json: per-stage wall-clock ms (detect = ORB detect+compute, match, estimate = PnP, frame =
all three; image decoding excluded, reported as load), median counts, rejected frames.
"""
import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from open3d_slam import associate, camera_from_path, parse_range, rot_to_quat, summary  # noqa: E402

RATIO = 0.8
MIN_INLIERS = 20
FEATURES = 1000
DEPTH_SCALE = 5000.0


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("data")
    p.add_argument("--frames", default="..")
    p.add_argument("--every", type=int, default=1)
    p.add_argument("--drop", default=None, help="leave out frames A..B (half-open)")
    p.add_argument("--out-trajectory", required=True)
    p.add_argument("--out-json", required=True)
    p.add_argument("--intrinsics", default=None)
    p.add_argument("--threads", type=int, default=0, help="cv2.setNumThreads (0: OpenCV's default)")
    args = p.parse_args()
    import cv2
    import numpy as np
    if args.threads:
        cv2.setNumThreads(args.threads)
    if args.intrinsics:
        fx, fy, cx, cy = (float(v) for v in args.intrinsics.split(","))
    else:
        camera = camera_from_path(args.data)
        if camera is None:
            sys.exit(f"{args.data}: the path names no TUM camera; give --intrinsics fx,fy,cx,cy")
        fx, fy, cx, cy = camera
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)
    frames, _ = associate(args.data)
    start, end = parse_range(args.frames, len(frames))
    drop = parse_range(args.drop, 1 << 30) if args.drop else None
    orb = cv2.ORB_create(nfeatures=FEATURES)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    times = {"load": [], "detect": [], "match": [], "estimate": [], "frame": []}
    counts = {"keypoints": [], "matches": [], "inliers": []}
    reference = None  # (keypoints, descriptors, depth, world_from_camera)
    rejected = 0
    lines = []
    for i in range(start, end, args.every):
        if drop and drop[0] <= i < drop[1]:
            continue
        ts, rgb_path, depth_path = frames[i]
        t0 = time.perf_counter()
        grey = cv2.imread(rgb_path, cv2.IMREAD_GRAYSCALE)
        depth = cv2.imread(depth_path, cv2.IMREAD_UNCHANGED).astype(np.float64) / DEPTH_SCALE
        t1 = time.perf_counter()
        kps, des = orb.detectAndCompute(grey, None)
        t2 = time.perf_counter()
        counts["keypoints"].append(len(kps))
        pose = np.eye(4)
        accepted = reference is None
        t3 = t4 = t2
        if reference is not None:
            rkps, rdes, rdepth, world_from_ref = reference
            pose = world_from_ref
            good = []
            if des is not None and rdes is not None and len(rdes) >= 2:
                for pair in matcher.knnMatch(des, rdes, k=2):
                    if len(pair) == 2 and pair[0].distance < RATIO * pair[1].distance:
                        good.append(pair[0])
            object_points, image_points = [], []
            for m in good:
                u, v = rkps[m.trainIdx].pt
                z = rdepth[int(round(v)), int(round(u))] if 0 <= round(v) < rdepth.shape[0] and 0 <= round(u) < rdepth.shape[1] else 0.0
                if z > 0:
                    object_points.append(((u - cx) / fx * z, (v - cy) / fy * z, z))
                    image_points.append(kps[m.queryIdx].pt)
            counts["matches"].append(len(good))
            t3 = time.perf_counter()
            inliers = 0
            if len(object_points) >= 6:
                ok, rvec, tvec, inl = cv2.solvePnPRansac(np.array(object_points), np.array(image_points), K, None)
                inliers = 0 if inl is None else len(inl)
                if ok and inliers >= MIN_INLIERS:
                    R, _ = cv2.Rodrigues(rvec)
                    cur_from_ref = np.eye(4)
                    cur_from_ref[:3, :3] = R
                    cur_from_ref[:3, 3] = tvec.ravel()
                    pose = world_from_ref @ np.linalg.inv(cur_from_ref)
                    accepted = True
            counts["inliers"].append(inliers)
            t4 = time.perf_counter()
            if not accepted:
                rejected += 1
        if accepted:
            reference = (kps, des, depth, pose)
        times["load"].append((t1 - t0) * 1e3)
        times["detect"].append((t2 - t1) * 1e3)
        times["match"].append((t3 - t2) * 1e3)
        times["estimate"].append((t4 - t3) * 1e3)
        times["frame"].append((t4 - t1) * 1e3)
        q = rot_to_quat(pose[:3, :3])
        t = pose[:3, 3]
        lines.append(f"{ts} {t[0]:.6f} {t[1]:.6f} {t[2]:.6f} {q[0]:.6f} {q[1]:.6f} {q[2]:.6f} {q[3]:.6f}")
    with open(args.out_trajectory, "w") as f:
        f.write("\n".join(lines) + "\n")
    out = {"frames": len(lines), "rejected": rejected, "opencv": cv2.__version__,
           "threads": cv2.getNumThreads(), "stages_ms": {k: summary(v) for k, v in times.items()},
           "median_counts": {k: float(np.median(v)) if v else 0 for k, v in counts.items()},
           "params": {"nfeatures": FEATURES, "ratio": RATIO, "min_inliers": MIN_INLIERS}}
    with open(args.out_json, "w") as f:
        json.dump(out, f, indent=1)
    print(json.dumps({k: out[k] for k in ("frames", "rejected", "median_counts")}))


if __name__ == "__main__":
    main()
