#!/usr/bin/env bash
# Seed 000's virtual Kinect, 640x480, exact and with Kinect noise: native `simulate --bench`,
# `serve --map` answering the Python client, and the browser's virtual sensor (headless
# Chromium, WebGPU on SwiftShader) on the same map and poses, side by side. A benchmark, not a
# test: numbers depend on the machine's load.
#   scripts/bench_sim.sh [--map M.wfm --poses TUM.txt] [--views 32]
# Without --map the bundled sample is fused first and its trajectory gives the poses.
set -euo pipefail
cd "$(dirname "$0")/.."
# Set-up installs what is missing and prints the environment (XDG_RUNTIME_DIR for wgpu/Mesa);
# a failing set-up stops here (an eval of a failed substitution would carry on).
setup_env=$(scripts/setup.sh test)
eval "$setup_env"
trunk build index.html --release
cargo build --release -q -p webfusion-bridge
node tests/browser/bench_sim.mjs --webfusion target/release/webfusion --dist dist "$@"
