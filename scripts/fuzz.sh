#!/usr/bin/env bash
# Fuzzes the COLMAP binary and text readers (and PLY / fused.ply.vis) with cargo-fuzz.
# Usage: scripts/fuzz.sh [seconds per target, default 300]
# Stable Rust is used with RUSTC_BOOTSTRAP=1 (cargo-fuzz passes nightly-only -Z flags).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
seconds="${1:-300}"
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz
export RUSTC_BOOTSTRAP=1
# Seed corpora from valid files written by Frond's generator.
cargo run --quiet --example make_fuzz_seeds -- fuzz/corpus
for target in colmap_binary colmap_text; do
  echo "== fuzzing $target for ${seconds}s"
  cargo fuzz run "$target" "fuzz/corpus/$target" -- -max_total_time="$seconds" -rss_limit_mb=4096 2>&1 \
    | grep -E "^(#[0-9]+.*DONE|Done|==[0-9]+==|SUMMARY|INFO: seed)|stat::number_of_executed_units|panicked" || true
done
