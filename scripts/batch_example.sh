#!/usr/bin/env bash
# The README's batch example: three synthetic plants photographed on a turntable-like rig
# (36 photos each, no points), `frond batch` from the photos to one trait table, then the
# scale from the rig (its known camera positions: the mean distance of the cameras from their
# centre, true against reconstructed) applied with `frond traits --scale` and the table
# gathered again in metres with its leaf-area plot.
# Usage: scripts/batch_example.sh [OUT_DIR] (default target/batch_example)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
out="${1:-target/batch_example}"
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
cargo build --release --quiet --bin frond
frond="$PWD/target/release/frond"
mkdir -p "$out/photos" "$out/rig"
plants=(pot_01:broadleaf:21 pot_02:broadleaf:22 pot_03:medium:21)
echo "plant,input" >"$out/plants.csv"
for spec in "${plants[@]}"; do
  IFS=: read -r plant preset seed <<<"$spec"
  if ! [ -d "$out/rig/$plant" ]; then
    "$frond" synth --preset "$preset" --seed "$seed" --no-points --out "$out/rig/$plant" >/dev/null
  fi
  rm -rf "$out/photos/$plant"
  cp -r "$out/rig/$plant/images" "$out/photos/$plant"
  echo "$plant,photos/$plant" >>"$out/plants.csv"
done
"$frond" batch "$out/plants.csv" --out "$out/results" --jobs 1
# The rig's scale: true camera positions (the synthetic rig's model) against reconstructed.
tables=()
for spec in "${plants[@]}"; do
  IFS=: read -r plant preset seed <<<"$spec"
  rm -rf "$out/txt/$plant" && mkdir -p "$out/txt/$plant/rig" "$out/txt/$plant/model"
  "$frond" convert "$out/rig/$plant/sparse/0" "$out/txt/$plant/rig" --format txt >/dev/null
  "$frond" convert "$out/results/$plant/dense/sparse" "$out/txt/$plant/model" --format txt >/dev/null
  scale=$(python3 - "$out/txt/$plant/rig/images.txt" "$out/txt/$plant/model/images.txt" <<'PY'
import math, sys

def centres(path):
    out, lines = {}, [l for l in open(path) if not l.startswith("#")]
    for header in lines[0::2]:
        f = header.split()
        if len(f) < 10:
            continue
        qw, qx, qy, qz, tx, ty, tz = map(float, f[1:8])
        r = [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
             [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
             [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]]
        t = (tx, ty, tz)
        out[f[9]] = [-sum(r[i][j] * t[i] for i in range(3)) for j in range(3)]
    return out

def spread(points):
    c = [sum(p[k] for p in points) / len(points) for k in range(3)]
    return sum(math.dist(p, c) for p in points) / len(points)

rig, model = centres(sys.argv[1]), centres(sys.argv[2])
common = sorted(set(rig) & set(model))
print(spread([rig[n] for n in common]) / spread([model[n] for n in common]))
PY
)
  echo "$plant: $scale m per model unit (from the rig's camera positions)"
  "$frond" traits "$out/results/$plant" --plant "$plant" --scale "$scale" --out "$out/results/$plant" 2>/dev/null
  tables+=("$out/results/$plant/traits.json")
done
"$frond" gather "${tables[@]}" --out "$out/results/traits.csv" --plot "$out/results/leaf_area.png"
python3 - "$out/results/traits.csv" <<'PY'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
print("| plant | leaves | total leaf area | median leaf area | median inclination | height |")
print("|---|---|---|---|---|---|")
for plant in sorted({r["plant"] for r in rows}):
    mine = [r for r in rows if r["plant"] == plant]
    value = lambda organ, name: [float(r["value"]) for r in mine if r["organ_type"] == organ and r["trait"] == name]
    areas = value("leaf", "area")
    print(f"| {plant} | {len(areas)} | {1e4 * sum(areas):.0f} cm² | {1e4 * statistics.median(areas):.1f} cm² | "
          f"{statistics.median(value('leaf', 'inclination')):.0f}° | {100 * value('plant', 'height')[0]:.1f} cm |")
PY
