#!/usr/bin/env bash
# Benchmarks `webfusion reconstruct` against a peer, Open3D's tensor dense SLAM
# (scripts/peers/open3d_slam.py), on the same TUM RGB-D frames in the same run, scores both
# trajectories with evo (`evo_ape tum GT EST -a`: SE(3) Umeyama alignment, ATE RMSE) and
# prints one table: ATE RMSE (cm), per-frame median ms, and the speed ratio.
#
#   scripts/bench_reconstruct.sh [--frames A..B] [--data DIR] [--out DIR] [--threads N]
#                                [--webfusion-out DIR] [-- EXTRA_WEBFUSION_ARGS...]
#
#   --frames A..B      half-open frame range of the association list (default: all frames)
#   --data DIR         TUM directory (default: $WEBFUSION_TUM_DIR or ../shared/data/tum_fr1_rpy_0-99)
#   --out DIR          where both runs write (default: target/bench-reconstruct)
#   --threads N        Open3D/OpenMP threads (default: all cores)
#   --webfusion-out D  score an existing `webfusion reconstruct` output folder instead of
#                      running the binary (D/trajectory.txt, D/stats.json)
#   -- ARGS...         passed on to `webfusion reconstruct` (default: none, the CLI's defaults)
#
# Env: WEBFUSION_BIN (default target/release/webfusion; built with
# `cargo build --release -p webfusion-bridge` when missing). The peer venv (.venv-peers/,
# open3d-cpu + evo) is set up by scripts/peers/setup_venv.sh, which this script runs.
# Both run their own defaults; Open3D takes the TUM calibration of the camera the data path
# names (fr1/fr2/fr3), as webfusion does.
# Timing: webfusion's per-frame number is stats.json stages_ms.frame.median; Open3D's is the
# median of upload + tracking + integration + raycast per frame (PNG decode excluded).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

usage() { sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; }
frames=""; data="${WEBFUSION_TUM_DIR:-$ROOT/../shared/data/tum_fr1_rpy_0-99}"
out="$ROOT/target/bench-reconstruct"; threads=0; wf_out=""; wf_extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --frames) frames="${2:?$1 needs a value}"; shift 2 ;;
    --data) data="${2:?$1 needs a value}"; shift 2 ;;
    --out) out="${2:?$1 needs a value}"; shift 2 ;;
    --threads) threads="${2:?$1 needs a value}"; shift 2 ;;
    --webfusion-out) wf_out="${2:?$1 needs a value}"; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    --) shift; wf_extra=("$@"); break ;;
    *) echo "unknown argument: $1" >&2; usage >&2; exit 2 ;;
  esac
done
# Paths given on the command line are relative to the caller's directory; resolve them
# before moving to the repo root.
[ -d "$data" ] || { echo "no TUM directory at $data (use --data DIR)" >&2; exit 2; }
[ -f "$data/groundtruth.txt" ] || { echo "$data/groundtruth.txt missing" >&2; exit 2; }
data="$(cd "$data" && pwd)"
mkdir -p "$out"; out="$(cd "$out" && pwd)"
if [ -n "$wf_out" ]; then
  [ -d "$wf_out" ] || { echo "--webfusion-out $wf_out: no such directory" >&2; exit 2; }
  wf_out="$(cd "$wf_out" && pwd)"
fi
case "${WEBFUSION_BIN:-}" in ""|/*) ;; */*) WEBFUSION_BIN="$PWD/$WEBFUSION_BIN" ;; esac
cd "$ROOT"
log() { printf '\033[1;34m[bench]\033[0m %s\n' "$*" >&2; }

scripts/peers/setup_venv.sh >&2
PY="$ROOT/.venv-peers/bin/python"
EVO_APE="$ROOT/.venv-peers/bin/evo_ape"

# --- webfusion -------------------------------------------------------------------------
if [ -z "$wf_out" ]; then
  bin="${WEBFUSION_BIN:-target/release/webfusion}"
  if ! command -v "$bin" >/dev/null 2>&1; then
    log "$bin missing: cargo build --release -p webfusion-bridge"
    cargo build --release -p webfusion-bridge
    bin="${WEBFUSION_BIN:-target/release/webfusion}"
  fi
  missing=()
  for p in mesa-vulkan-drivers libvulkan1; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    log "apt-get install ${missing[*]} (Vulkan on the CPU, for machines without a GPU)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
  export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/webfusion-xdg-$(id -u)}"
  mkdir -p -m 0700 "$XDG_RUNTIME_DIR"
  wf_out="$out/webfusion"
  rm -rf "$wf_out"
  wf_args=(reconstruct "$data" --out "$wf_out")
  [ -n "$frames" ] && wf_args+=(--frames "$frames")
  wf_args+=(${wf_extra[@]+"${wf_extra[@]}"})
  log "$bin ${wf_args[*]}"
  "$bin" "${wf_args[@]}"
else
  log "using the existing webfusion output $wf_out (not running the binary)"
fi
for f in trajectory.txt stats.json; do
  [ -f "$wf_out/$f" ] || { echo "$wf_out/$f missing" >&2; exit 1; }
done

# --- Open3D ----------------------------------------------------------------------------
o3d_out="$out/open3d"
mkdir -p "$o3d_out"
o3d_args=("$data" --frames "${frames:-..}" --out-trajectory "$o3d_out/trajectory.txt"
          --out-json "$o3d_out/stats.json" --quiet)
[ "$threads" -gt 0 ] && o3d_args+=(--threads "$threads")
log "open3d_slam.py ${o3d_args[*]}"
"$PY" scripts/peers/open3d_slam.py "${o3d_args[@]}" >&2

# --- evo -------------------------------------------------------------------------------
ate() {  # ate NAME TRAJ -> ATE RMSE in metres on stdout, evo's report in $out/ape_NAME.txt
  if ! "$EVO_APE" tum "$data/groundtruth.txt" "$2" -a >"$out/ape_$1.txt" 2>&1; then
    echo "evo_ape failed on $2:" >&2; cat "$out/ape_$1.txt" >&2; return 1
  fi
  awk '$1 == "rmse" { print $2 }' "$out/ape_$1.txt"
}
wf_ate=$(ate webfusion "$wf_out/trajectory.txt")
o3d_ate=$(ate open3d "$o3d_out/trajectory.txt")

# --- table -----------------------------------------------------------------------------
"$PY" - "$wf_out/stats.json" "$o3d_out/stats.json" "$wf_ate" "$o3d_ate" "$data" "${frames:-all}" \
  <<'PYEOF' | tee "$out/summary.txt"
import json, sys
wf, o3d = (json.load(open(p)) for p in sys.argv[1:3])
wf_ate, o3d_ate = float(sys.argv[3]) * 100, float(sys.argv[4]) * 100
data, frames = sys.argv[5], sys.argv[6]

def stage(stats, key, name):
    s = (stats.get(key) or {}).get(name) or {}
    return s.get("median"), s.get("p95")

wf_ms, wf_p95 = stage(wf, "stages_ms", "frame")
o3d_ms, o3d_p95 = stage(o3d, "stages_ms", "frame")
fmt = lambda v, p=1: "-" if v is None else f"{v:.{p}f}"
rows = [
    ("", "ATE RMSE (cm)", "frame median ms", "frame p95 ms", "frames", "lost"),
    (f"webfusion ({wf.get('adapter', '?')})", fmt(wf_ate, 2), fmt(wf_ms), fmt(wf_p95),
     str(wf.get("frames", "?")), str(len(wf.get("lost_frames", [])))),
    (f"open3d {o3d['open3d_version']} dense SLAM (CPU, {o3d['threads']} thread{'s' if o3d['threads'] != 1 else ''})", fmt(o3d_ate, 2),
     fmt(o3d_ms), fmt(o3d_p95), str(o3d["frames"]), str(len(o3d["lost_frames"]))),
]
w = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
print(f"data {data}, frames {frames}; ATE = evo_ape tum -a (SE(3) alignment)")
for i, r in enumerate(rows):
    print("  ".join(c.ljust(w[0]) if j == 0 else c.rjust(w[j]) for j, c in enumerate(r)))
    if i == 0:
        print("  ".join("-" * x for x in w))
for key, label in (("webfusion", wf), ("open3d", o3d)):
    st = label.get("stages_ms", {})
    order = ["load", "upload", "preprocess", "track", "tracking", "integrate", "integration", "raycast"]
    keys = sorted(st, key=lambda k: (order.index(k) if k in order else len(order), k))
    parts = [f"{k} {st[k]['median']:.1f}" for k in keys
             if isinstance(st[k], dict) and st[k].get("median") is not None
             and k not in ("frame", "frame_with_load", "frame_cpu")]
    print(f"  {key} stage medians (ms): " + (", ".join(parts) or "-"))
cpu = (o3d.get("stages_ms", {}).get("frame_cpu") or {}).get("median")
if cpu and o3d_ms:
    busy = cpu / o3d_ms
    warn = ("  <- well below the thread count: something else was using the CPU, times are inflated"
            if busy < 0.75 * o3d["threads"] else "")
    print(f"  open3d CPU time {cpu:.1f} ms/frame: {busy:.2f} of {o3d['threads']} threads busy{warn}")
if wf.get("frames") != o3d["frames"]:
    print(f"WARNING: webfusion ran {wf.get('frames')} frames, open3d {o3d['frames']}: not the same frames")
if wf_ms and o3d_ms:
    r = o3d_ms / wf_ms
    verdict = f"webfusion is {r:.2f}x faster" if r >= 1 else f"webfusion is {1 / r:.2f}x slower"
    print(f"open3d_ms / webfusion_ms = {r:.2f}: {verdict} per frame")
else:
    print("no per-frame time for one of the two: no ratio")
PYEOF
log "outputs in $out (summary.txt, ape_*.txt, webfusion/, open3d/)"
