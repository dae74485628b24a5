#!/usr/bin/env bash
# The main job: build the web app, reconstruct the bundled sample natively (trajectory, mesh,
# ATE, per-stage timings), then start the bridge (`webfusion serve`): one port serves the web
# app and streams the sample's frames over WebSocket. Prints the URL. Installs what is missing.
#   scripts/run.sh [--port 8080] [--no-serve] [--source PATH]
set -euo pipefail
cd "$(dirname "$0")/.."
port=8080; serve=1; source=data/sample/fr1_rpy.wfr
while [ $# -gt 0 ]; do
  case "$1" in
    --port) port="$2"; shift 2 ;;
    --no-serve) serve=0; shift ;;
    --source) source="$2"; shift 2 ;;
    *) echo "usage: scripts/run.sh [--port N] [--no-serve] [--source TUM_DIR_OR_WFR]" >&2; exit 2 ;;
  esac
done
# Set-up installs what is missing and prints the environment (XDG_RUNTIME_DIR for wgpu/Mesa);
# a failing set-up stops here (an eval of a failed substitution would carry on).
setup_env=$(scripts/setup.sh run)
eval "$setup_env"

echo "== building the web app (trunk) =="
trunk build index.html --release

echo "== native KinectFusion on the bundled sample (trajectory, mesh, ATE against the sample's ground truth, per-stage times) =="
# The default sparse map grows wherever fr1/rpy turns; 2 cm voxels, as the page below uses.
cargo run --release -q -p webfusion-bridge -- reconstruct data/sample/fr1_rpy.wfr --out out/sample --voxel-size 0.02

if [ "$serve" = 1 ]; then
  echo
  echo "== bridge: web app and frames of ${source} on one port (Ctrl-C stops) =="
  # The page connects to this bridge by itself; the query sets 2 cm voxels (the default map:
  # sparse blocks) and starts playing.
  echo "webfusion web app: http://127.0.0.1:${port}/?voxel_mm=20&autoplay=1  (WebGPU browser needed)"
  exec cargo run --release -q -p webfusion-bridge -- serve --source "$source" --bind "127.0.0.1:${port}" --web-dir dist
fi
