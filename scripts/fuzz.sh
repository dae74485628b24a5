#!/usr/bin/env bash
# Mutation fuzzing of every decoder of outside input (a tool, not a test): the .wfr reader
# (strict and recovering), the protocol decoder with the frame images it carries, and the RVL,
# RVL+DEFLATE and 16-bit PNG depth decoders, each on mutated copies of valid inputs. Stable
# Rust (cargo-fuzz needs nightly): a seeded generator in core/examples/fuzz.rs, so a run repeats.
#   scripts/fuzz.sh [CASES_PER_TARGET (default 1000000)] [SEED]
# Prints cases, ok/err counts, panics and seconds per target; exits non-zero on any panic.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p webfusion-core --example fuzz
exec target/release/examples/fuzz "${1:-1000000}" ${2:+"$2"}
