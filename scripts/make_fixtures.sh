#!/usr/bin/env bash
# Regenerates the bundled fixtures from Frond's own generator and real COLMAP:
#   fixtures/toy_scene/             COLMAP project (binary sparse/0 + images/) written by Frond
#   fixtures/toy_scene_colmap_txt/  the same model converted to text by `colmap model_converter`
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
rm -rf fixtures/toy_scene fixtures/toy_scene_colmap_txt
cargo run --quiet --example make_fixtures -- fixtures/toy_scene
mkdir -p fixtures/toy_scene_colmap_txt
colmap model_converter --input_path fixtures/toy_scene/sparse/0 \
  --output_path fixtures/toy_scene_colmap_txt --output_type TXT
du -sh fixtures/*
