#!/usr/bin/env bash
# The README's leaf-recall numbers per preset: synthetic plants through `frond reconstruct` and
# `frond eval`, per seed: leaf recall and precision, and for compound plants the compound
# leaves found and the leaflets on the right rachis.
# Usage: scripts/leaves.sh [--preset P] [--photos] [SEED ...] (preset default compound, seeds
# default 11 12 13 14; --photos runs the photos through COLMAP and densify instead of the
# semi-dense points, a few minutes each). Outputs under target/leaves/PRESET/.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
photos=0
preset=compound
seeds=()
while [ $# -gt 0 ]; do
  case "$1" in
    --photos) photos=1; shift ;;
    --preset) preset="$2"; shift 2 ;;
    *) seeds+=("$1"); shift ;;
  esac
done
[ ${#seeds[@]} -gt 0 ] || seeds=(11 12 13 14)
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
cargo build --release --quiet --bin frond
frond="$PWD/target/release/frond"
out=target/leaves/$preset
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
    [ -d "$data" ] || quiet "$data.log" "$frond" synth --preset "$preset" --seed "$seed" --no-points --out "$data"
    rm -rf "$data.out"
    quiet "$data.log" "$frond" reconstruct "$data/images" --out "$data.out"
    scores=$("$frond" eval --gt "$data" --pred "$data.out" --pred-model "$data.out/dense/sparse")
  else
    data="$out/points_$seed"
    [ -d "$data" ] || quiet "$data.log" "$frond" synth --preset "$preset" --seed "$seed" --out "$data"
    rm -rf "$data.out"
    quiet "$data.log" "$frond" reconstruct "$data" --out "$data.out"
    scores=$("$frond" eval --gt "$data" --pred "$data.out")
  fi
  echo "seed $seed"
  grep -E "^(leaves|leaf geometry|compound leaves):" <<<"$scores"
done
