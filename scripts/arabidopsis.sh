#!/usr/bin/env bash
# Real photos through the whole chain on ../shared/data/romi_arabidopsis (60 photos of a potted
# Arabidopsis on a circular path of radius 0.3 m): `frond reconstruct PHOTOS` (SfM, densify,
# reconstruction), then `frond phyllotaxis` aligns the organ sequence along the main stem with
# the dataset's manual measures.json (scale from the camera circle).
# Usage: scripts/arabidopsis.sh [WORK_DIR]   (default target/arabidopsis; about 7 min on 2
# cores; an existing WORK_DIR/out/report.json is reused: delete it to reconstruct again)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
data="${FROND_ARABIDOPSIS:-$root/../shared/data/romi_arabidopsis}"
work="${1:-$root/target/arabidopsis}"
[ -d "$data/images" ] || { echo "no images in $data" >&2; exit 1; }
mkdir -p "$work"
cargo build --release --quiet --manifest-path "$root/Cargo.toml"
frond="$root/target/release/frond"
[ -f "$work/out/report.json" ] || "$frond" reconstruct "$data/images" --out "$work/out"
echo "== every organ on the main stem (side branches and the leaves attached to it)"
"$frond" phyllotaxis "$work/out" --measures "$data/measures.json" --scale-orbit 0.3
echo "== side branches only: fruits, pedicels and shoots, what measures.json counts (no leaves)"
"$frond" phyllotaxis "$work/out" --measures "$data/measures.json" --scale-orbit 0.3 --organs branches
