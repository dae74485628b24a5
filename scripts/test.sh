#!/usr/bin/env bash
# Runs every test: native unit and GPU tests (Mesa lavapipe) under nextest, the wasm tests in
# headless Chromium on WebGPU, then the end-to-end test (the trunk-built app against
# `webfusion serve`, in headless Chromium via playwright-core). Installs what is missing first.
# Everything it runs stands on the repository alone (real frames come from data/sample).
#
#   scripts/test.sh            every test
#   scripts/test.sh --extras   only the optional checks against the original TUM files the
#                              sample was made from (`#[ignore]`d tests): they need
#                              $WEBFUSION_SHARED_DATA, by default ../shared/data
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--extras" ]; then
  data="${WEBFUSION_SHARED_DATA:-$PWD/../shared/data}"
  [ -d "$data/tum_fr1_rpy_0-99" ] || { echo "--extras needs the shared TUM excerpt at $data/tum_fr1_rpy_0-99 (set WEBFUSION_SHARED_DATA)" >&2; exit 2; }
  eval "$(scripts/setup.sh test)"
  WEBFUSION_SHARED_DATA="$(cd "$data" && pwd)" exec cargo nextest run --workspace --features webfusion-bridge/openni2 --run-ignored only --no-fail-fast
elif [ $# -gt 0 ]; then
  echo "usage: scripts/test.sh [--extras]" >&2; exit 2
fi
# Set-up installs what is missing and prints the environment (XDG_RUNTIME_DIR for wgpu/Mesa);
# a failing set-up stops here (an eval of a failed substitution would carry on).
setup_env=$(scripts/setup.sh test)
eval "$setup_env"
log=$(mktemp -d)

echo "== native tests (cargo nextest, Vulkan: lavapipe or any adapter) =="
set +e
cargo nextest run --workspace --features webfusion-bridge/openni2 --no-fail-fast 2>&1 | tee "$log/native.txt"
native_rc=${PIPESTATUS[0]}

echo "== browser tests (wasm-bindgen-test, headless Chromium, WebGPU) =="
(cd web && CHROMEDRIVER=/usr/bin/chromedriver WASM_BINDGEN_TEST_TIMEOUT=300 \
  cargo test -p webfusion-web --target wasm32-unknown-unknown -- --nocapture) 2>&1 | tee "$log/web.txt"
web_rc=${PIPESTATUS[0]}

echo "== end-to-end (web app + bridge in headless Chromium on WebGPU) =="
# nextest built target/debug/webfusion above; trunk builds dist/ as scripts/run.sh does.
trunk build index.html --release 2>&1 | tail -2 && \
  node tests/browser/e2e.mjs --webfusion target/debug/webfusion --dist dist --out out/e2e 2>&1 | tee "$log/e2e.txt"
e2e_rc=${PIPESTATUS[0]}
set -e

# One closing line over all runners.
native_passed=$(grep -oE '[0-9]+ passed' "$log/native.txt" | tail -1 | grep -oE '[0-9]+' || echo 0)
native_failed=$(grep -oE '[0-9]+ failed' "$log/native.txt" | tail -1 | grep -oE '[0-9]+' || echo 0)
sum() { awk '{ s += $1 } END { print s + 0 }'; }
web_passed=$(grep -E '^test result' "$log/web.txt" | grep -oE '[0-9]+ passed' | sum)
web_failed=$(grep -E '^test result' "$log/web.txt" | grep -oE '[0-9]+ failed' | sum)
[ "$native_rc" -ne 0 ] && [ "$native_failed" = 0 ] && native_failed=1
[ "$web_rc" -ne 0 ] && [ "${web_failed}" = 0 ] && web_failed=1
e2e_passed=$(grep -E '^e2e: ' "$log/e2e.txt" 2>/dev/null | grep -oE '[0-9]+ passed' | grep -oE '[0-9]+' || echo 0)
e2e_failed=$(grep -E '^e2e: ' "$log/e2e.txt" 2>/dev/null | grep -oE '[0-9]+ failed' | grep -oE '[0-9]+' || echo 0)
[ "$e2e_rc" -ne 0 ] && [ "${e2e_failed}" = 0 ] && e2e_failed=1
echo
echo "native: ${native_passed} passed, ${native_failed} failed; browser: ${web_passed} passed, ${web_failed} failed; end-to-end: ${e2e_passed} passed, ${e2e_failed} failed"
echo "all: $((native_passed + web_passed + e2e_passed)) passed, $((native_failed + web_failed + e2e_failed)) failed"
[ "$native_rc" -eq 0 ] && [ "$web_rc" -eq 0 ] && [ "$e2e_rc" -eq 0 ]
