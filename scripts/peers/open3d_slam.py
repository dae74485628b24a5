#!/usr/bin/env python3
"""Peer measuring stick: Open3D tensor dense SLAM on a TUM RGB-D directory.

Usage (from the repo root, after scripts/peers/setup_venv.sh):
  .venv-peers/bin/python scripts/peers/open3d_slam.py DATA_DIR \
      --out-trajectory est.txt --out-json o3d.json [--frames A..B] [--threads N]

Runs open3d.t.pipelines.slam.Model exactly as Open3D's
examples/python/t_reconstruction_system/dense_slam.py does (frame-to-model tracking,
point-to-plane, then integrate, then raycast the model for the next frame), with the
parameters of that example's default config, except depth_scale = 5000 (TUM):
  voxel_size 0.0058 m, block_resolution 16, block_count 40000, depth_scale 5000,
  depth_min 0.1, depth_max 3.0, trunc_voxel_multiplier 8, odometry_distance_thr 0.07,
  device CPU:0.
Intrinsics: the published TUM calibration of the camera the path names, found the way
webfusion finds it (the nearest path component naming freiburg1/fr1, 2 or 3, the resolved path
first), or --intrinsics fx,fy,cx,cy; 640x480, no undistortion.

--frames A..B is half-open, like `webfusion --frames`: frames A, A+1, .., B-1 of the
association list ("..B", "A.." and ".." allowed; default: all). Frames come from
DATA_DIR/rgbd_assoc.txt ("ts_rgb rgb/x.png ts_depth depth/y.png"); without it, rgb.txt
and depth.txt are associated by nearest timestamp (|dt| <= 20 ms, one-to-one, in order).

Outputs:
  --out-trajectory  TUM format "t tx ty tz qx qy qz qw" (t = depth timestamp),
                    camera-to-world, first pose = identity.
  --out-json        per-frame and per-stage timing (median/p95 ms), frames, lost frames,
                    thread count, Open3D version, parameters.
Timing: stage times are wall-clock around each Open3D call (Open3D's CPU kernels are
synchronous). "frame" = upload + tracking + integration + raycast (PNG decode excluded, it
is reported separately as "load"); "frame_with_load" adds it.
"""
import argparse
import json
import os
import sys
import time

WIDTH, HEIGHT = 640, 480
# Published TUM RGB-D calibrations (fx, fy, cx, cy), as core/src/camera.rs has them.
TUM_CAMERAS = {"1": (517.3, 516.5, 318.6, 255.3), "2": (520.9, 521.0, 325.1, 249.7),
               "3": (535.4, 539.2, 320.1, 247.6)}
PARAMS = dict(voxel_size=0.0058, block_resolution=16, block_count=40000, depth_scale=5000.0,
              depth_min=0.1, depth_max=3.0, trunc_voxel_multiplier=8.0,
              odometry_distance_thr=0.07, method="PointToPlane", device="CPU:0")


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("data", help="TUM RGB-D directory (rgb/, depth/, rgbd_assoc.txt or rgb.txt+depth.txt)")
    p.add_argument("--frames", default="..", help="half-open range A..B of associated frames (default: all)")
    p.add_argument("--out-trajectory", required=True, help="estimated trajectory, TUM format")
    p.add_argument("--out-json", required=True, help="timing/statistics JSON")
    p.add_argument("--threads", type=int, default=0, help="OpenMP/Open3D threads (default: all cores)")
    p.add_argument("--out-mesh", default=None, help="optional: write the extracted triangle mesh (PLY)")
    p.add_argument("--quiet", action="store_true", help="no per-frame log")
    p.add_argument("--intrinsics", default=None,
                   help="fx,fy,cx,cy in pixels (default: the TUM camera the path names)")
    return p.parse_args()


def read_list(path):
    out = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            out.append(line.split())
    return out


def associate(data):
    """[(depth_ts_str, rgb_path, depth_path)] in time order."""
    assoc = os.path.join(data, "rgbd_assoc.txt")
    if os.path.exists(assoc):
        rows = read_list(assoc)
        return [(r[2], os.path.join(data, r[1]), os.path.join(data, r[3])) for r in rows], "rgbd_assoc.txt"
    rgb = [(float(r[0]), r[1]) for r in read_list(os.path.join(data, "rgb.txt"))]
    depth = [(float(r[0]), r[0], r[1]) for r in read_list(os.path.join(data, "depth.txt"))]
    # Greedy nearest-timestamp matching, one-to-one, as TUM's associate.py (max |dt| 20 ms).
    cands = sorted((abs(dt - rt), i, j) for i, (dt, _, _) in enumerate(depth)
                   for j, (rt, _) in enumerate(rgb) if abs(dt - rt) <= 0.02)
    used_d, used_r, pairs = set(), set(), []
    for _, i, j in cands:
        if i in used_d or j in used_r:
            continue
        used_d.add(i)
        used_r.add(j)
        pairs.append((depth[i][0], depth[i][1], os.path.join(data, rgb[j][1]), os.path.join(data, depth[i][2])))
    pairs.sort()
    return [(ts, r, d) for _, ts, r, d in pairs], "rgb.txt+depth.txt (nearest timestamp, <= 20 ms)"


def parse_range(spec, count):
    if ".." not in spec:
        raise SystemExit(f"--frames {spec!r}: expected A..B")
    a, b = spec.split("..", 1)
    start = int(a) if a else 0
    end = int(b) if b else count
    if not (0 <= start < end <= count):
        raise SystemExit(f"--frames {spec}: the source has frames 0..{count}")
    return start, end


def rot_to_quat(R):
    """3x3 rotation -> (qx, qy, qz, qw), qw >= 0."""
    import numpy as np
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax([R[0, 0], R[1, 1], R[2, 2]]))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def summary(values):
    import numpy as np
    if not values:
        return None
    v = np.asarray(values, dtype=float)
    return {"median": round(float(np.median(v)), 3), "p95": round(float(np.percentile(v, 95)), 3),
            "mean": round(float(v.mean()), 3), "min": round(float(v.min()), 3),
            "max": round(float(v.max()), 3), "n": int(v.size)}


def camera_from_path(path):
    """The TUM camera (fx, fy, cx, cy) the nearest path component names, or None."""
    import re
    for candidate in (os.path.realpath(path), os.path.abspath(path)):
        for part in reversed([p for p in candidate.split(os.sep) if p]):
            named = {n for n in TUM_CAMERAS if re.search(rf"(freiburg|fr){n}(?![0-9])", part.lower())}
            if len(named) == 1:
                return TUM_CAMERAS[named.pop()]
            if named:
                break  # ambiguous (fr1_vs_fr2): try the path as given, then give up
    return None


def main():
    args = parse_args()
    if args.intrinsics:
        try:
            fx, fy, cx, cy = (float(v) for v in args.intrinsics.split(","))
        except ValueError:
            sys.exit(f"--intrinsics {args.intrinsics!r}: expected fx,fy,cx,cy")
    else:
        camera = camera_from_path(args.data)
        if camera is None:
            sys.exit(f"{args.data}: the path names no TUM camera (freiburg1/fr1, 2, 3); give --intrinsics fx,fy,cx,cy")
        fx, fy, cx, cy = camera
    threads = args.threads if args.threads > 0 else len(os.sched_getaffinity(0))
    # OpenMP reads this when the runtime starts, so set it before importing open3d.
    os.environ["OMP_NUM_THREADS"] = str(threads)
    import numpy as np
    import open3d as o3d
    import open3d.core as o3c
    o3d.utility.set_max_threads(threads)
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)

    frames, assoc_source = associate(args.data)
    start, end = parse_range(args.frames, len(frames))
    frames = frames[start:end]

    device = o3c.Device(PARAMS["device"])
    intrinsic = o3c.Tensor([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], o3c.Dtype.Float64)
    T = o3c.Tensor(np.identity(4))
    model = o3d.t.pipelines.slam.Model(PARAMS["voxel_size"], PARAMS["block_resolution"],
                                       PARAMS["block_count"], T, device)
    depth0 = o3d.t.io.read_image(frames[0][2])
    if (depth0.rows, depth0.columns) != (HEIGHT, WIDTH):
        print(f"warning: depth is {depth0.columns}x{depth0.rows}, intrinsics are for {WIDTH}x{HEIGHT}",
              file=sys.stderr)
    input_frame = o3d.t.pipelines.slam.Frame(depth0.rows, depth0.columns, intrinsic, device)
    raycast_frame = o3d.t.pipelines.slam.Frame(depth0.rows, depth0.columns, intrinsic, device)
    method = getattr(o3d.t.pipelines.odometry.Method, PARAMS["method"])
    ds, dmin, dmax = PARAMS["depth_scale"], PARAMS["depth_min"], PARAMS["depth_max"]
    trunc, dthr = PARAMS["trunc_voxel_multiplier"], PARAMS["odometry_distance_thr"]

    times = {k: [] for k in ("load", "upload", "tracking", "integration", "raycast", "frame", "frame_with_load",
                             "frame_cpu")}
    poses, lost = [], []
    t_run = time.perf_counter()
    for i, (ts, rgb_path, depth_path) in enumerate(frames):
        t0 = time.perf_counter()
        depth = o3d.t.io.read_image(depth_path)
        color = o3d.t.io.read_image(rgb_path)
        t1 = time.perf_counter()
        c1 = time.process_time()
        input_frame.set_data_from_image("depth", depth.to(device))
        input_frame.set_data_from_image("color", color.to(device))
        t2 = time.perf_counter()
        if i > 0:
            try:
                result = model.track_frame_to_model(input_frame, raycast_frame, ds, dmax, dthr, method)
                T = T @ result.transformation
            except RuntimeError as e:  # e.g. "Singular 6x6 linear system": keep the last pose
                lost.append(start + i)
                print(f"frame {start + i}: tracking failed ({e}); keeping the previous pose", file=sys.stderr)
            t3 = time.perf_counter()
            times["tracking"].append((t3 - t2) * 1e3)
        else:
            t3 = t2
        poses.append(T.cpu().numpy())
        model.update_frame_pose(i, T)
        model.integrate(input_frame, ds, dmax, trunc)
        t4 = time.perf_counter()
        model.synthesize_model_frame(raycast_frame, ds, dmin, dmax, trunc, False)
        t5 = time.perf_counter()
        c5 = time.process_time()
        times["load"].append((t1 - t0) * 1e3)
        times["upload"].append((t2 - t1) * 1e3)
        times["integration"].append((t4 - t3) * 1e3)
        times["raycast"].append((t5 - t4) * 1e3)
        times["frame"].append((t5 - t1) * 1e3)
        times["frame_with_load"].append((t5 - t0) * 1e3)
        times["frame_cpu"].append((c5 - c1) * 1e3)
        if not args.quiet:
            print(f"{start + i:04d} [{i + 1}/{len(frames)}] frame {times['frame'][-1]:7.1f} ms"
                  f" (track {(t3 - t2) * 1e3:6.1f}, integrate {(t4 - t3) * 1e3:6.1f},"
                  f" raycast {(t5 - t4) * 1e3:6.1f}, load {(t1 - t0) * 1e3:5.1f})", flush=True)
    wall_s = time.perf_counter() - t_run

    os.makedirs(os.path.dirname(os.path.abspath(args.out_trajectory)), exist_ok=True)
    with open(args.out_trajectory, "w") as f:
        f.write("# open3d t.pipelines.slam dense SLAM (camera-to-world)\n# timestamp tx ty tz qx qy qz qw\n")
        for (ts, _, _), P in zip(frames, poses):
            q = rot_to_quat(P[:3, :3])
            f.write(f"{ts} {P[0, 3]:.6f} {P[1, 3]:.6f} {P[2, 3]:.6f} "
                    f"{q[0]:.6f} {q[1]:.6f} {q[2]:.6f} {q[3]:.6f}\n")

    if args.out_mesh:
        mesh = model.voxel_grid.extract_triangle_mesh()
        o3d.io.write_triangle_mesh(args.out_mesh, mesh.to_legacy())

    stats = {
        "system": "open3d.t.pipelines.slam (dense_slam.py)",
        "open3d_version": o3d.__version__,
        "python": sys.version.split()[0],
        "threads": threads,
        "open3d_max_threads": o3d.utility.get_max_threads(),
        "cpu_count": os.cpu_count(),
        "data": os.path.abspath(args.data),
        "association": assoc_source,
        "frame_range": [start, end],
        "frames": len(frames),
        "lost_frames": lost,
        "active_blocks": int(model.voxel_grid.hashmap().size()),
        "wall_s": round(wall_s, 3),
        "params": dict(PARAMS, intrinsics=dict(fx=fx, fy=fy, cx=cx, cy=cy, width=WIDTH, height=HEIGHT)),
        "stages_ms": {k: summary(v) for k, v in times.items()},
        "per_frame_ms": [round(x, 3) for x in times["frame"]],
        "note": "frame = upload + tracking + integration + raycast (PNG decode is 'load'); "
                "tracking has no sample on the first frame; frame_cpu = process CPU time (all threads) over "
                "the same span as frame: frame_cpu / frame well below the thread count means the "
                "machine was busy with something else",
    }
    with open(args.out_json, "w") as f:
        json.dump(stats, f, indent=2)
    st = stats["stages_ms"]
    print(f"open3d {o3d.__version__}, {threads} threads, {len(frames)} frames, lost {len(lost)}: "
          f"frame median {st['frame']['median']} ms (p95 {st['frame']['p95']}), "
          f"tracking {st['tracking']['median'] if st['tracking'] else '-'}, "
          f"integration {st['integration']['median']}, raycast {st['raycast']['median']}; "
          f"CPU {st['frame_cpu']['median']} ms/frame")


if __name__ == "__main__":
    main()
