#!/usr/bin/env bash
# Benchmarks `webfusion planes` against a peer, Open3D's RANSAC `segment_plane` repeated for
# as many planes per frame as webfusion found (scripts/peers/open3d_planes.py), on the same TUM
# frames in the same run, and prints per-stage median ms per frame and the speed ratios.
#
#   scripts/bench_planes.sh [--data DIR] [--frames A..B] [--out DIR]
#
#   --data DIR    TUM directory (default: $WEBFUSION_TUM_DIR or ../shared/data/tum_fr1_rpy_0-99)
#   --frames A..B frames of the source (default: all)
#   --out DIR     where both runs write (default: target/bench-planes)
#
# webfusion's stages: preprocess (depth to vertex and normal maps) and segment (the whole
# segmentation), from frames.json, for the GPU kernels (the default) and the CPU reference
# (--cpu-reference), then the GPU segmentation's time per kernel (--kernel-times); Open3D's:
# cloud (depth to points) and segment (RANSAC).
# Then the world model of the same run (frames tracked by KinectFusion on the GPU): its
# per-frame cost, planes and compactness against marching cubes, from planes.json.
# Env: WEBFUSION_BIN (default target/release/webfusion, built when missing).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
data="${WEBFUSION_TUM_DIR:-$ROOT/../shared/data/tum_fr1_rpy_0-99}"; frames=""; out="$ROOT/target/bench-planes"
while [ $# -gt 0 ]; do
  case "$1" in
    --data) data="${2:?$1 needs a value}"; shift 2 ;;
    --frames) frames="${2:?$1 needs a value}"; shift 2 ;;
    --out) out="${2:?$1 needs a value}"; shift 2 ;;
    -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "unknown argument: $1" >&2; exit 2 ;;
  esac
done
[ -f "$data/depth.txt" ] || { echo "no TUM directory at $data (use --data DIR)" >&2; exit 2; }
data="$(cd "$data" && pwd)"
mkdir -p "$out"; out="$(cd "$out" && pwd)"
cd "$ROOT"
WF="${WEBFUSION_BIN:-$ROOT/target/release/webfusion}"
[ -x "$WF" ] || cargo build --release -p webfusion-bridge >&2
scripts/peers/setup_venv.sh >&2
PY="$ROOT/.venv-peers/bin/python"
rm -rf "$out/webfusion"
rm -rf "$out/webfusion-cpu" "$out/webfusion-kernels"
"$WF" planes "$data" --out "$out/webfusion" ${frames:+--frames "$frames"} >&2
"$WF" planes "$data" --out "$out/webfusion-cpu" --no-world --cpu-reference ${frames:+--frames "$frames"} >&2
"$WF" planes "$data" --out "$out/webfusion-kernels" --no-world --kernel-times ${frames:+--frames "$frames"} >&2
"$PY" scripts/peers/open3d_planes.py "$data" "$out/webfusion/frames.json" "$out/open3d.json"
"$PY" - "$out/webfusion/frames.json" "$out/webfusion-cpu/frames.json" "$out/webfusion-kernels/frames.json" "$out/open3d.json" <<'PYEOF'
import json, statistics, sys
load = lambda p: json.load(open(p))
gpu_run, cpu_run, kernel_run, o3 = load(sys.argv[1]), load(sys.argv[2]), load(sys.argv[3]), load(sys.argv[4])["frames"]
wf, wc = gpu_run["frames"], cpu_run["frames"]
med = lambda xs: statistics.median(xs) if xs else float("nan")
wp, ws = med([f["stages_ms"]["preprocess"] for f in wf]), med([f["stages_ms"]["segment"] for f in wf])
cp, cs = med([f["stages_ms"]["preprocess"] for f in wc]), med([f["stages_ms"]["segment"] for f in wc])
oc, os_ = med([f["cloud_ms"] for f in o3]), med([f["segment_ms"] for f in o3])
planes = med([len(f["planes"]) for f in wf])
print(f"{len(wf)} frames, {planes:g} planes per frame (median; CPU reference {med([len(f['planes']) for f in wc]):g}); GPU: {gpu_run.get('adapter')}; per-frame median ms")
print(f"{'':28}{'depth to points':>16}{'segmentation':>14}{'total':>10}")
print(f"{'webfusion (GPU kernels)':28}{wp:16.1f}{ws:14.1f}{wp + ws:10.1f}")
print(f"{'webfusion (CPU reference)':28}{cp:16.1f}{cs:14.1f}{cp + cs:10.1f}")
print(f"{'Open3D segment_plane':28}{oc:16.1f}{os_:14.1f}{oc + os_:10.1f}")
print(f"ratio webfusion GPU / Open3D: segmentation {ws / os_:.2f}, total {(wp + ws) / (oc + os_):.2f} (below 1: webfusion faster)")
print(f"ratio webfusion GPU / CPU reference: segmentation {ws / cs:.2f}")
kernels = {}
for f in kernel_run["frames"]:
    for k, ms in (f.get("kernels_ms") or {}).items():
        kernels.setdefault(k, []).append(ms)
print("GPU segmentation per kernel (one submission each, median ms per frame):")
for k, ms in sorted(kernels.items(), key=lambda kv: -med(kv[1])):
    print(f"  {k:24}{med(ms):8.1f}")
PYEOF
# The world model of the same run (planes.json): per-frame cost, planes, compactness.
"$PY" - "$out/webfusion/frames.json" "$out/webfusion/planes.json" <<'PYEOF'
import json, statistics, sys
wf = json.load(open(sys.argv[1]))["frames"]
w = json.load(open(sys.argv[2]))
world = [f["stages_ms"]["world"] for f in wf if f["stages_ms"].get("world") is not None]
complete = [f["stages_ms"]["complete_labels"] for f in wf if f["stages_ms"].get("complete_labels") is not None]
med = lambda v: statistics.median(v) if v else float("nan")
c = w["compactness"]
print(f"world model ({w['poses']} poses, {w['frames_with_pose']} frames): label completion on the GPU {med(complete):.1f} ms, then association and texels on the CPU {med(world):.1f} ms per frame")
print(f"  {len(w['planes'])} world planes, {sum(p['area_m2'] for p in w['planes']):.2f} m2 meshed")
print(f"  compactness: {c['planar_triangles']} planar quadtree triangles replace {c['marching_cubes_triangles_replaced']} marching-cubes triangles "
      f"({c['marching_cubes_triangles_replaced'] / max(c['planar_triangles'], 1):.1f}x fewer; voxel {w['remainder']['voxel_m'] * 100:.2f} cm); textures {c['texture_bytes'] / 1e6:.1f} MB")
PYEOF
