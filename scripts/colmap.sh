#!/usr/bin/env bash
# Runs COLMAP's sparse reconstruction on the CPU over DIR/images:
#   DIR/colmap/database.db, DIR/colmap/sparse/0 (the largest model), DIR/colmap/dense (its
#   undistorted workspace, input for `frond densify`), and a summary line.
# `frond sfm PHOTOS --out OUT` is the faster route (photo checks, Frond's pair retrieval and
# matching, COLMAP's verification and mapper; sfm.json); this script is plain COLMAP with its
# own matchers, for users who drive COLMAP themselves and as the baseline it is measured against.
# Usage: scripts/colmap.sh DIR [--matcher exhaustive|sequential] [--camera PINHOLE|SIMPLE_RADIAL|OPENCV]
# Matching is exhaustive up to 60 images, sequential beyond (override with --matcher).
set -euo pipefail
dir="${1:?usage: scripts/colmap.sh DIR [--matcher M] [--camera MODEL]}"
shift
matcher=""
camera_model="SIMPLE_RADIAL"
while [ $# -gt 0 ]; do
  case "$1" in
    --matcher) matcher="$2"; shift 2 ;;
    --camera) camera_model="$2"; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
command -v colmap >/dev/null || { echo "colmap is not installed (run scripts/setup.sh)" >&2; exit 1; }
[ -d "$dir/images" ] || { echo "$dir/images does not exist" >&2; exit 1; }
num_images=$(find "$dir/images" -maxdepth 1 -type f \( -iname '*.png' -o -iname '*.jpg' -o -iname '*.jpeg' \) | wc -l)
[ "$num_images" -gt 1 ] || { echo "$dir/images holds $num_images images" >&2; exit 1; }
if [ -z "$matcher" ]; then
  if [ "$num_images" -le 60 ]; then matcher=exhaustive; else matcher=sequential; fi
fi
out="$dir/colmap"
rm -rf "$out"
mkdir -p "$out/sparse"
log="$out/colmap.log"
start=$(date +%s)
step() { echo "== $1"; local t0; t0=$(date +%s); shift; "$@" >>"$log" 2>&1 || { echo "COLMAP failed; see $log" >&2; tail -20 "$log" >&2; exit 1; }; echo "   $(( $(date +%s) - t0 )) s"; }
step "feature extraction ($num_images images, $camera_model, shared camera)" \
  colmap feature_extractor --database_path "$out/database.db" --image_path "$dir/images" \
    --ImageReader.camera_model "$camera_model" --ImageReader.single_camera 1 \
    --SiftExtraction.use_gpu 0 --SiftExtraction.num_threads "$(nproc)"
step "$matcher matching" \
  colmap "${matcher}_matcher" --database_path "$out/database.db" --SiftMatching.use_gpu 0 \
    --SiftMatching.num_threads "$(nproc)"
step "mapping" \
  colmap mapper --database_path "$out/database.db" --image_path "$dir/images" \
    --output_path "$out/sparse" --Mapper.num_threads "$(nproc)"
# The mapper writes sparse/0, sparse/1, ... ; report each model's registered images.
best=""; best_images=0
for model in "$out"/sparse/*/; do
  [ -f "$model/images.bin" ] || continue
  registered=$(colmap model_analyzer --path "$model" 2>&1 | sed -n 's/.*Registered images: \([0-9]*\).*/\1/p')
  points=$(colmap model_analyzer --path "$model" 2>&1 | sed -n 's/.*Points: \([0-9]*\).*/\1/p')
  echo "   model $model: $registered registered images, $points points"
  if [ "${registered:-0}" -gt "$best_images" ]; then best="$model"; best_images="$registered"; fi
done
[ -n "$best" ] || { echo "COLMAP registered no model" >&2; exit 1; }
step "undistortion" \
  colmap image_undistorter --image_path "$dir/images" --input_path "$best" \
    --output_path "$out/dense" --output_type COLMAP
echo "registered $best_images / $num_images images in $(( $(date +%s) - start )) s (best model: $best)"
