#!/usr/bin/env bash
# The halo on ground truth: synthetic plants photographed before a cabin's plain dark cloth
# (`frond synth --backdrop studio`, exact cameras and sparse-like points standing in for SfM),
# densified three ways — neither filter, the free-space check alone (--backdrop-views 0), and
# the default (free-space check + backdrop carving) — then reconstructed and scored:
# `frond eval --dense` (halo share, centreline coverage) and `frond eval` (leaves, skeleton).
# Usage: scripts/studio_backdrop.sh [WORK_DIR] [PRESET:SEED ...]
#   (default target/studio, broadleaf:1 broadleaf:2 broadleaf:3 medium:5 medium:6; about 4 min
#   per plant on 2 cores)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="${1:-$root/target/studio}"
shift || true
plants=("$@")
[ ${#plants[@]} -gt 0 ] || plants=(broadleaf:1 broadleaf:2 broadleaf:3 medium:5 medium:6)
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
cargo build --release --quiet --manifest-path "$root/Cargo.toml"
frond="$root/target/release/frond"
mkdir -p "$work"
for plant in "${plants[@]}"; do
  preset="${plant%%:*}"; seed="${plant##*:}"; p="$work/${preset}_$seed"
  [ -d "$p" ] || "$frond" synth --preset "$preset" --seed "$seed" --backdrop studio --out "$p"
  for run in neither:"--free-space-maps 0 --backdrop-views 0" free_space:"--backdrop-views 0" default:""; do
    tag="${run%%:*}"; args="${run#*:}"
    # shellcheck disable=SC2086
    [ -f "$p.$tag/report.json" ] || {
      "$frond" densify "$p" $args --out "$p.$tag.dense"
      "$frond" reconstruct "$p.$tag.dense" --out "$p.$tag"
    }
    "$frond" eval --gt "$p" --dense "$p.$tag.dense" --json > "$p.$tag.dense.json"
    "$frond" eval --gt "$p" --pred "$p.$tag" --pred-model "$p.$tag.dense/sparse" --json > "$p.$tag.json"
  done
  python3 - "$p" <<'PY'
import json, sys
p = sys.argv[1]
print(f"== {p}")
print("run          halo   centreline  leaf P  leaf R  skeleton P  petiole R")
for tag in ["neither", "free_space", "default"]:
    dense = json.load(open(f"{p}.{tag}.dense.json"))["thin_organs"]
    m = json.load(open(f"{p}.{tag}.json"))
    length = m["skeleton"]["length"]
    print(f"{tag:11s} {dense['halo_fraction'] * 100:5.1f} %  {dense['centerline_coverage']:.3f}     "
          f"{m['leaves']['precision']:.3f}   {m['leaves']['recall']:.3f}   {length['precision']:.3f}       "
          f"{length['petiole_recall']:.3f}")
PY
done
