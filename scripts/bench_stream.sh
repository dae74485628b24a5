#!/usr/bin/env bash
# Streaming benchmarks (not tests): depth codecs on real frames (RVL and RVL+DEFLATE against
# PNG and zstd, same frames, same run) and sustained frames/s to 1, 4 and 16 WebSocket clients
# on loopback with the bridge's CPU and memory.
#   scripts/bench_stream.sh [--source TUM_DIR_OR_WFR]
set -euo pipefail
cd "$(dirname "$0")/.."
source_path=data/sample/fr1_rpy.wfr
[ -d ../shared/data/tum_fr1_rpy_0-99 ] && source_path=../shared/data/tum_fr1_rpy_0-99
[ "${1:-}" = --source ] && source_path="$2"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/webfusion-xdg-$(id -u)}"
mkdir -p -m 0700 "$XDG_RUNTIME_DIR"
cargo build --release -q -p webfusion-bridge
echo "== depth codecs =="
target/release/webfusion bench-codecs --source "$source_path" --frames 100
echo
echo "== WebSocket clients =="
target/release/webfusion bench-clients --source "$source_path" --clients 1,4,16 --seconds 5
