#!/usr/bin/env python3
"""How consistently `webfusion planes` finds the same planes across frames.

Usage: scripts/planes_consistency.py FRAMES_JSON TRAJECTORY_TXT [--min-frames N]

Each frame's planes (camera frame, n.p + d = 0) are moved to the world with the camera-to-world
pose of that frame (a TUM trajectory, e.g. `reconstruct`'s trajectory.txt or the ground truth,
matched by timestamp within 20 ms), then grouped greedily (largest first) into world planes:
normals within 5 degrees and offsets within 5 cm. For each world plane seen in at least N frames
it prints the frames, the mean pixels, and the drift: the median and the largest angle of a
frame's normal from the group's mean normal, and the spread (std) and range of its offsets. Plain Python (no numpy).
"""
import json
import math
import sys


def quat_to_rot(qx, qy, qz, qw):
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ]


def read_trajectory(path):
    poses = []
    for line in open(path):
        f = line.split()
        if not f or f[0].startswith("#"):
            continue
        t, x, y, z, qx, qy, qz, qw = map(float, f[:8])
        poses.append((t, [x, y, z], quat_to_rot(qx, qy, qz, qw)))
    poses.sort()
    return poses


def main():
    args = sys.argv[1:]
    min_frames = 10
    if "--min-frames" in args:
        i = args.index("--min-frames")
        min_frames = int(args[i + 1])
        del args[i : i + 2]
    if len(args) != 2:
        sys.exit(__doc__)
    frames = json.load(open(args[0]))["frames"]
    poses = read_trajectory(args[1])
    groups = []  # each: list of (frame index, normal_w, offset_w, pixels)
    matched = 0
    for fr in frames:
        t = fr["timestamp"]
        best = min(poses, key=lambda p: abs(p[0] - t), default=None)
        if best is None or abs(best[0] - t) > 0.02:
            continue
        matched += 1
        _, c, r = best
        for pl in sorted(fr["planes"], key=lambda p: -p["pixels"]):
            n = pl["normal"]
            nw = [sum(r[i][j] * n[j] for j in range(3)) for i in range(3)]
            dw = pl["offset_m"] - sum(nw[i] * c[i] for i in range(3))
            for g in groups:
                mn = g["normal"]
                cos = sum(mn[i] * nw[i] for i in range(3))
                if cos > math.cos(math.radians(5)) and abs(g["offset"] - dw) < 0.05:
                    g["members"].append((fr["index"], nw, dw, pl["pixels"]))
                    k = len(g["members"])
                    g["normal"] = [mn[i] + (nw[i] - mn[i]) / k for i in range(3)]
                    norm = math.sqrt(sum(v * v for v in g["normal"]))
                    g["normal"] = [v / norm for v in g["normal"]]
                    g["offset"] += (dw - g["offset"]) / k
                    break
            else:
                groups.append({"normal": nw, "offset": dw, "members": [(fr["index"], nw, dw, pl["pixels"])]})
    counts = [len(f["planes"]) for f in frames]
    counts.sort()
    print(f"{len(frames)} frames ({matched} with a pose): planes per frame median {counts[len(counts) // 2]}, min {counts[0]}, max {counts[-1]}")
    print(f"{'world plane normal':>28} {'offset m':>9} {'frames':>6} {'pixels':>7} {'median angle °':>14} {'max angle °':>11} {'offset std mm':>13} {'offset range mm':>15}")
    for g in sorted(groups, key=lambda g: -len(g["members"])):
        m = g["members"]
        if len(m) < min_frames:
            continue
        mn = g["normal"]
        angles = [math.degrees(math.acos(max(-1.0, min(1.0, sum(mn[i] * nw[i] for i in range(3)))))) for _, nw, _, _ in m]
        offs = [d for _, _, d, _ in m]
        mean = sum(offs) / len(offs)
        std = math.sqrt(sum((d - mean) ** 2 for d in offs) / len(offs))
        pix = sum(p for *_, p in m) / len(m)
        normal = "(" + ", ".join(f"{v:+.3f}" for v in mn) + ")"
        print(f"{normal:>28} {mean:9.3f} {len(m):6d} {pix:7.0f} {sorted(angles)[len(angles) // 2]:14.2f} {max(angles):11.2f} {std * 1e3:13.1f} {(max(offs) - min(offs)) * 1e3:15.1f}")


if __name__ == "__main__":
    main()
