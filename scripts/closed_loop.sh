#!/usr/bin/env bash
# Seed 000's closed loop, the round trip of issue 13: render the synthetic furnished room
# (`synth-room`, exact ground truth) along a loop, fuse it at its ground-truth poses into a saved
# map (`reconstruct --poses --save-map`), simulate the depth sensor in that map at the same
# poses (`simulate`, exact and with the seeded Kinect noise model), and track the simulated
# logs (`reconstruct`): the ATE against `simulate`'s ground truth says how well a planner's or
# tracker's closed loop works. A measurement, not a test (minutes on lavapipe).
#   scripts/closed_loop.sh [--size 4,2.5,4] [--frames 150] [--width 640 --height 480] [--voxel-mm 5] [--seed 1]
# Outputs in out/closed_loop/ (room.wfr, map.wfm, sim_exact/, sim_noise/, track_exact/, track_noise/).
set -euo pipefail
cd "$(dirname "$0")/.."
size=4,2.5,4 frames=150 width=640 height=480 voxel_mm=5 seed=1
while [ $# -gt 0 ]; do
  case "$1" in
    --size) size=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --width) width=$2; shift 2 ;;
    --height) height=$2; shift 2 ;;
    --voxel-mm) voxel_mm=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
setup_env=$(scripts/setup.sh test)
eval "$setup_env"
cargo build --release -q -p webfusion-bridge
w=target/release/webfusion
out=out/closed_loop
rm -rf "$out" && mkdir -p "$out"
voxel_m=$(python3 -c "print($voxel_mm / 1000)")
$w synth-room --out "$out/room.wfr" --size "$size" --frames "$frames" --width "$width" --height "$height"
# The recording carries its ground truth; reconstruct writes it out as groundtruth.txt.
$w reconstruct "$out/room.wfr" --out "$out/truth" --frames 0..1 --no-mesh > /dev/null 2>&1
$w reconstruct "$out/room.wfr" --out "$out/fused" --poses "$out/truth/groundtruth.txt" --voxel-size "$voxel_m" --save-map "$out/map.wfm" --no-mesh > "$out/fused.log" 2>&1
$w simulate --map "$out/map.wfm" --poses "$out/truth/groundtruth.txt" --out "$out/sim_exact" --color > "$out/sim_exact.log"
$w simulate --map "$out/map.wfm" --poses "$out/truth/groundtruth.txt" --out "$out/sim_noise" --color --noise kinect --seed "$seed" > "$out/sim_noise.log"
for kind in exact noise; do
  $w reconstruct "$out/sim_$kind" --out "$out/track_$kind" --voxel-size "$voxel_m" --no-mesh > "$out/track_$kind.log" 2>&1
done
python3 - "$out" <<'EOF'
import json, sys
out = sys.argv[1]
print(f"closed loop ({out}): ATE of tracking the simulated logs against the poses they were simulated at")
for kind, what in (("exact", "exact depth"), ("noise", "Kinect noise model")):
    s = json.load(open(f"{out}/track_{kind}/stats.json"))
    ate = s["ate"]
    print(f"  {what:20s} RMSE {ate['rmse_m'] * 1000:6.2f} mm, max {ate['max_m'] * 1000:6.2f} mm over {ate['pairs']} poses, {len(s['lost_frames'])} lost")
EOF
