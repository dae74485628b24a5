#!/usr/bin/env bash
# The main job: build the web app, run the native GPU pipeline over the bundled sample
# (per-stage timings), then serve the web app, which replays the same sample through the
# same WGSL kernels on WebGPU, and print its URL. Installs what is missing first.
#   scripts/run.sh [--port 8080] [--no-serve]
set -euo pipefail
cd "$(dirname "$0")/.."
port=8080; serve=1
while [ $# -gt 0 ]; do
  case "$1" in
    --port) port="$2"; shift 2 ;;
    --no-serve) serve=0; shift ;;
    *) echo "usage: scripts/run.sh [--port N] [--no-serve]" >&2; exit 2 ;;
  esac
done
eval "$(scripts/setup.sh run)"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/webfusion-xdg-$(id -u)}"
mkdir -p -m 0700 "$XDG_RUNTIME_DIR"

echo "== building the web app (trunk) =="
trunk build index.html --release

echo "== native KinectFusion on the bundled sample (trajectory, mesh, ATE against the sample's ground truth, per-stage times) =="
# fr1/rpy turns 90 degrees in place: put the camera at the centre of a 5.1 m volume.
cargo run --release -q -p webfusion-bridge -- reconstruct data/sample/fr1_rpy.wfr --out out/sample --centred --voxel-size 0.02

if [ "$serve" = 1 ]; then
  echo
  echo "webfusion web app: http://127.0.0.1:${port}/  (WebGPU browser needed; Ctrl-C stops)"
  exec python3 -m http.server "$port" --bind 127.0.0.1 --directory dist
fi
