#!/usr/bin/env bash
# Browser vs native: the KinectFusion pipeline on the bundled sample in headless Chromium
# (WebGPU on SwiftShader) and natively (Vulkan), per-stage medians side by side, wasm size and
# time to the first frame. A benchmark, not a test: numbers depend on the machine's load.
#   scripts/bench_web.sh [--map dense|sparse] [--volume 256] [--voxel-mm 20] [--repeat N] [--planes 0|1]
#   (N alternating runs, median ratio; --planes 1: the page's per-frame plane segmentation on)
set -euo pipefail
cd "$(dirname "$0")/.."
# Set-up installs what is missing and prints the environment (XDG_RUNTIME_DIR for wgpu/Mesa);
# a failing set-up stops here (an eval of a failed substitution would carry on).
setup_env=$(scripts/setup.sh test)
eval "$setup_env"
trunk build index.html --release
cargo build --release -q -p webfusion-bridge
node tests/browser/bench.mjs --webfusion target/release/webfusion --dist dist "$@"
