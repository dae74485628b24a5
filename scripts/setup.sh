#!/usr/bin/env bash
# Installs what webfusion needs on a fresh Debian 12 machine, idempotently: each tool is
# checked first and installed only when missing or at the wrong version.
#   scripts/setup.sh test   # what the test command needs (adds Chromium, Node, playwright-core, OpenNI2)
#   scripts/setup.sh run    # what the main command needs
# Versions are pinned to what ../shared/TOOLCHAIN.md verified.
set -euo pipefail
what="${1:-test}"
WASM_BINDGEN_VERSION=0.2.130   # must equal wasm-bindgen in Cargo.lock
TRUNK_VERSION=0.21.14          # newest that builds on Rust 1.95
SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"

log() { printf '\033[1;34m[setup]\033[0m %s\n' "$*" >&2; }

apt_packages=(mesa-vulkan-drivers libvulkan1)
# OpenNI2 (.oni recordings, feature `openni2`): the tests build and run it.
[ "$what" = test ] && apt_packages+=(chromium chromium-driver libopenni2-dev libopenni2-0)
# Node for the end-to-end test: only when none is installed (a NodeSource nodejs bundles npm
# and conflicts with Debian's npm package). playwright-core wants Node 20+.
if [ "$what" = test ] && ! { command -v node && command -v npm; } >/dev/null; then
  apt_packages+=(nodejs npm)
fi
missing=()
for p in "${apt_packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  log "apt-get install ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

if ! rustup target list --installed | grep -q '^wasm32-unknown-unknown$'; then
  log "rustup target add wasm32-unknown-unknown"
  rustup target add wasm32-unknown-unknown
fi

if [ "$(wasm-bindgen --version 2>/dev/null | awk '{print $2}')" != "$WASM_BINDGEN_VERSION" ]; then
  log "cargo install wasm-bindgen-cli $WASM_BINDGEN_VERSION (about 2 minutes)"
  cargo install wasm-bindgen-cli --version "$WASM_BINDGEN_VERSION" --force
fi

if ! command -v cargo-nextest >/dev/null; then
  log "cargo install cargo-nextest"
  cargo install cargo-nextest --locked
fi

# Both commands build the web app with trunk (the test command for the end-to-end test).
if [ "$(trunk --version 2>/dev/null | awk '{print $2}')" != "$TRUNK_VERSION" ]; then
  log "cargo install trunk $TRUNK_VERSION (about 9 minutes, once)"
  cargo install trunk --locked --version "$TRUNK_VERSION" --force
fi

# playwright-core drives Debian's Chromium; it downloads no browser.
if [ "$what" = test ] && [ ! -d tests/browser/node_modules/playwright-core ]; then
  log "npm ci (tests/browser: playwright-core)"
  (cd tests/browser && npm ci --no-audit --no-fund --loglevel=error >&2)
fi

# wgpu/Mesa warn on stderr when XDG_RUNTIME_DIR is unset or invalid; give them a private one.
if [ -z "${XDG_RUNTIME_DIR:-}" ] || [ ! -d "${XDG_RUNTIME_DIR}" ]; then
  mkdir -p -m 0700 "/tmp/webfusion-xdg-$(id -u)"
  echo "export XDG_RUNTIME_DIR=/tmp/webfusion-xdg-$(id -u)"
fi
