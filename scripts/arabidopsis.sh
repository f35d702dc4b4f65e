#!/usr/bin/env bash
# Real photos through the whole chain on ../shared/data/romi_arabidopsis (60 photos):
# COLMAP (CPU, OPENCV camera) -> frond densify -> frond reconstruct -> internodes and
# divergence angles of the automatic skeleton beside the dataset's manual measures.json.
# Usage: scripts/arabidopsis.sh [WORK_DIR]   (default target/arabidopsis; about 10 min on 2
# cores; an existing WORK_DIR/colmap/sparse/0 is reused)
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
data="${FROND_ARABIDOPSIS:-$root/../shared/data/romi_arabidopsis}"
work="${1:-$root/target/arabidopsis}"
[ -d "$data/images" ] || { echo "no images in $data" >&2; exit 1; }
mkdir -p "$work"
rm -rf "$work/images" && cp -r "$data/images" "$work/images"
[ -f "$work/colmap/sparse/0/points3D.bin" ] || bash "$root/scripts/colmap.sh" "$work" --camera OPENCV
cargo build --release --quiet --manifest-path "$root/Cargo.toml"
"$root/target/release/frond" densify --model "$work/colmap/sparse/0" --images "$work/images" --out "$work/dense"
"$root/target/release/frond" reconstruct "$work/dense" --out "$work/out"
mkdir -p "$work/txt"
colmap model_converter --input_path "$work/colmap/sparse/0" --output_path "$work/txt" --output_type TXT >/dev/null
python3 "$root/scripts/phyllotaxis.py" "$work/txt" "$work/out/skeleton.json" "$data/measures.json"
