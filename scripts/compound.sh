#!/usr/bin/env bash
# The README's compound-leaf numbers: synthetic `compound` plants (pinnate leaves) through
# `frond reconstruct` and `frond eval`, one line per seed: leaflet recall and precision,
# compound leaves found, leaflets on the right rachis.
# Usage: scripts/compound.sh [--photos] [SEED ...] (default seeds 11 12 13 14; --photos runs
# the photos through COLMAP and densify instead of the semi-dense points, a few minutes each)
# Outputs under target/compound/.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
photos=0
if [ "${1:-}" = "--photos" ]; then
  photos=1
  shift
fi
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(11 12 13 14)
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
cargo build --release --quiet --bin frond
frond="$PWD/target/release/frond"
out=target/compound
mkdir -p "$out"
# Runs a step quietly into LOG; on failure shows the log's end.
quiet() {
  local log="$1"
  shift
  "$@" >>"$log" 2>&1 || {
    tail -20 "$log"
    exit 1
  }
}
for seed in "${seeds[@]}"; do
  if [ "$photos" = 1 ]; then
    data="$out/photos_$seed"
    [ -d "$data" ] || quiet "$data.log" "$frond" synth --preset compound --seed "$seed" --no-points --out "$data"
    rm -rf "$data.out"
    quiet "$data.log" "$frond" reconstruct "$data/images" --out "$data.out"
    scores=$("$frond" eval --gt "$data" --pred "$data.out" --pred-model "$data.out/dense/sparse")
  else
    data="$out/points_$seed"
    [ -d "$data" ] || quiet "$data.log" "$frond" synth --preset compound --seed "$seed" --out "$data"
    rm -rf "$data.out"
    quiet "$data.log" "$frond" reconstruct "$data" --out "$data.out"
    scores=$("$frond" eval --gt "$data" --pred "$data.out")
  fi
  echo "seed $seed"
  grep -E "^(leaves|compound leaves):" <<<"$scores"
done
