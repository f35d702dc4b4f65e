#!/usr/bin/env bash
# The main job on a built-in default dataset (no download): render a synthetic broadleaf plant
# with ground truth, reconstruct it as a user's COLMAP project, and score the result.
# Usage: scripts/demo.sh [OUT_DIR] (default target/demo)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
out="${1:-target/demo}"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
cargo build --release --quiet --bin frond
frond=target/release/frond
"$frond" synth --preset broadleaf --seed 1 --out "$out/plant"
"$frond" info "$out/plant"
"$frond" reconstruct "$out/plant" --out "$out/reconstruction"
"$frond" eval --gt "$out/plant" --pred "$out/reconstruction"
echo "outputs: $out/reconstruction (plant.glb, plant.obj, segmentation.ply, segments.json, skeleton.json, report.json, traits.csv, traits.json)"
