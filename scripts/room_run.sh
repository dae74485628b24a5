#!/usr/bin/env bash
# A room-sized run of the default sparse map, natively and in the browser: renders the synthetic
# furnished room (`webfusion synth-room`: 10 x 10 x 3 m by default, exact ground truth) along a
# loop through it, fuses it with `reconstruct` at 1 cm voxels (memory, swapping, ATE, mesh in
# out/room/native), then in headless Chromium on WebGPU (SwiftShader) through `serve`. A
# measurement, not a test: the browser run takes a long time on a CPU adapter (use --frames and
# --width/--height for a shorter one).
#   scripts/room_run.sh [--size 10,3,10] [--frames 800] [--width 640 --height 480] [--voxel-mm 10] [--no-browser]
set -euo pipefail
cd "$(dirname "$0")/.."
size=10,3,10 frames=800 width=640 height=480 voxel_mm=10 browser=1
while [ $# -gt 0 ]; do
  case "$1" in
    --size) size=$2; shift 2 ;;
    --frames) frames=$2; shift 2 ;;
    --width) width=$2; shift 2 ;;
    --height) height=$2; shift 2 ;;
    --voxel-mm) voxel_mm=$2; shift 2 ;;
    --no-browser) browser=0; shift ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
setup_env=$(scripts/setup.sh test)
eval "$setup_env"
cargo build --release -q -p webfusion-bridge
mkdir -p out/room
target/release/webfusion synth-room --out out/room/room.wfr --size "$size" --frames "$frames" --width "$width" --height "$height"
voxel_m=$(python3 -c "print($voxel_mm / 1000)")
/usr/bin/time -f "native: %e s wall, %M KiB peak resident memory" target/release/webfusion reconstruct out/room/room.wfr --out out/room/native --voxel-size "$voxel_m"
if [ "$browser" = 1 ]; then
  trunk build index.html --release
  node tests/browser/room.mjs --webfusion target/release/webfusion --dist dist --sample out/room/room.wfr --voxel-mm "$voxel_mm"
fi
