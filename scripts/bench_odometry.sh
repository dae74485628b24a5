#!/usr/bin/env bash
# Benchmarks `webfusion odometry` (seed 002's feature odometry on the GPU) against the peer the
# issue names, OpenCV ORB (1000 features) + BFMatcher + ratio test + solvePnPRansac
# (scripts/peers/opencv_orb_odometry.py), on the same TUM frames in the same run: per-stage
# median ms per frame with keypoint counts, the ratio of the totals, seed 002's 151.7 ms, and
# the trajectories' ATE and RPE (webfusion eval, as evo computes them) against the ground truth.
# webfusion runs twice: its default (each frame against a keyframe and the previous frame,
# fused by their covariances) and `--frame-to-frame` (seed 002's method, as the peer does).
#
#   scripts/bench_odometry.sh [--data DIR] [--frames A..B] [--every N] [--drop A..B] [--out DIR]
#                             [-- EXTRA webfusion odometry OPTIONS]
#
#   --data DIR    TUM directory (default: $WEBFUSION_TUM_DIR or ../shared/data/tum_fr1_rpy_0-99)
#   --frames A..B frames of the source (default: all)
#   --every N     keep every N-th frame (both runs)
#   --drop A..B   leave frames A..B out (both runs)
#   --out DIR     where both runs write (default: target/bench-odometry)
#
# webfusion's stages are GPU timestamps (update = upload + preprocessing, detection,
# description, matching, estimation); OpenCV's are wall-clock (detect = ORB
# detect+compute, match, estimate = PnP). Env: WEBFUSION_BIN (default target/release/webfusion,
# built when missing).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
data="${WEBFUSION_TUM_DIR:-$ROOT/../shared/data/tum_fr1_rpy_0-99}"; frames=""; every=1; drop=""; out="$ROOT/target/bench-odometry"
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --data) data="${2:?$1 needs a value}"; shift 2 ;;
    --frames) frames="${2:?$1 needs a value}"; shift 2 ;;
    --every) every="${2:?$1 needs a value}"; shift 2 ;;
    --drop) drop="${2:?$1 needs a value}"; shift 2 ;;
    --out) out="${2:?$1 needs a value}"; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "unknown argument: $1" >&2; exit 2 ;;
  esac
done
[ -f "$data/depth.txt" ] || { echo "no TUM directory at $data (use --data DIR)" >&2; exit 2; }
[ -f "$data/groundtruth.txt" ] || { echo "$data has no groundtruth.txt" >&2; exit 2; }
data="$(cd "$data" && pwd)"
mkdir -p "$out"; out="$(cd "$out" && pwd)"
cd "$ROOT"
WF="${WEBFUSION_BIN:-$ROOT/target/release/webfusion}"
[ -x "$WF" ] || cargo build --release -p webfusion-bridge >&2
scripts/peers/setup_venv.sh >&2
PY="$ROOT/.venv-peers/bin/python"
sel=(${frames:+--frames "$frames"} --every "$every" ${drop:+--drop "$drop"})
rm -rf "$out/webfusion" "$out/webfusion-f2f"
"$WF" odometry "$data" --out "$out/webfusion" "${sel[@]}" "${extra[@]}" >&2
"$WF" odometry "$data" --out "$out/webfusion-f2f" --frame-to-frame "${sel[@]}" "${extra[@]}" >&2
"$PY" scripts/peers/opencv_orb_odometry.py "$data" --out-trajectory "$out/opencv.txt" --out-json "$out/opencv.json" "${sel[@]}" >&2
for who in webfusion webfusion-f2f opencv; do
  est="$out/opencv.txt"; [ "$who" != opencv ] && est="$out/$who/trajectory.txt"
  "$WF" eval --gt "$data/groundtruth.txt" --est "$est" --json "$out/$who-eval.json" >/dev/null
done
"$PY" - "$out" <<'PYEOF'
import json, sys
out = sys.argv[1]
runs = {"webfusion": "webfusion (keyframes)", "webfusion-f2f": "webfusion (frame to frame)"}
wfs = {w: json.load(open(f"{out}/{w}/stats.json")) for w in runs}
cv = json.load(open(f"{out}/opencv.json"))
ev = {w: json.load(open(f"{out}/{w}-eval.json")) for w in (*runs, "opencv")}
def ate_cm(e):
    return 100 * e["ate"]["stats"]["rmse_m"]
def rpe(e):
    return 1000 * e["rpe"]["translation"]["rmse_m"], e["rpe"]["rotation"]["rmse_deg"]
wf = wfs["webfusion"]
print(f"{wf['frames']} frames (every {wf['every']}); per-frame median ms (the keyframe runs match and estimate against the previous frame too, in the same submission)")
print(f"{'':28}{'update':>8}{'detect':>8}{'describe':>9}{'match':>8}{'estimate':>9}{'total':>8}  keypoints/matches/inliers  rejected")
for w, label in runs.items():
    f = wfs[w]; s = f["stages_ms"]
    m = lambda k: s[k]["median"] if k in s else float("nan")
    print(f"{label:28}{m('update'):8.1f}{m('detection'):8.1f}{m('description'):9.1f}{m('matching'):8.1f}{m('estimation'):9.1f}{m('total'):8.1f}"
          f"  {f['median_keypoints']:.0f}/{f['median_matches']:.0f}/{f['median_inliers']:.0f}  {f['rejected']} ({f['reanchored']} restarts)")
c = cv["stages_ms"]; n = cv["median_counts"]
print(f"{'OpenCV ORB + PnP (CPU)':28}{'':8}{c['detect']['median']:8.1f}{'':9}{c['match']['median']:8.1f}{c['estimate']['median']:9.1f}{'':8}{c['frame']['median']:8.1f}"
      f"  {n['keypoints']:.0f}/{n['matches']:.0f}/{n['inliers']:.0f}  {cv['rejected']}")
for w, label in runs.items():
    total = wfs[w]["stages_ms"]["total"]["median"]
    print(f"speed {label}: / OpenCV total {total / c['frame']['median']:.2f}; / seed 002 (151.7 ms) {total / 151.7:.2f} (below 1: webfusion faster)")
print(f"keyframes: {wf['fused']} frames fused from both paths, {wf['disagreed']} disagreed (new keyframe), {wf['tracked_against_previous']} through the previous frame alone")
for w in (*runs, "opencv"):
    t, r = rpe(ev[w])
    print(f"{w:14} ATE {ate_cm(ev[w]):6.2f} cm   RPE {t:5.2f} mm/frame {r:5.3f} deg/frame")
for w, label in runs.items():
    print(f"ATE ratio {label} / OpenCV: {ate_cm(ev[w]) / ate_cm(ev['opencv']):.2f} (target <= 0.7)")
PYEOF
