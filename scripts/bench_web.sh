#!/usr/bin/env bash
# Browser vs native: the KinectFusion pipeline on the bundled sample in headless Chromium
# (WebGPU on SwiftShader) and natively (Vulkan), per-stage medians side by side, wasm size and
# time to the first frame. A benchmark, not a test: numbers depend on the machine's load.
#   scripts/bench_web.sh [--volume 256] [--voxel-mm 20]
set -euo pipefail
cd "$(dirname "$0")/.."
# A failing set-up stops here (an eval of a failed substitution would carry on).
setup_env=$(scripts/setup.sh test)
eval "$setup_env"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/webfusion-xdg-$(id -u)}"
mkdir -p -m 0700 "$XDG_RUNTIME_DIR"
trunk build index.html --release
cargo build --release -q -p webfusion-bridge
node tests/browser/bench.mjs --webfusion target/release/webfusion --dist dist "$@"
