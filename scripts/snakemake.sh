#!/usr/bin/env bash
# Runs the project's pinned Snakemake (installed into .tools/snakemake by scripts/setup.sh).
# Usage: scripts/snakemake.sh -s workflow/Snakefile --cores 4 --config manifest=plants.csv out=results
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if ! [ -f "$root/.tools/snakemake/snakemake/__init__.py" ]; then
  echo "scripts/snakemake.sh: Snakemake is not installed; run scripts/setup.sh" >&2
  exit 1
fi
export PYTHONPATH="$root/.tools/snakemake${PYTHONPATH:+:$PYTHONPATH}"
exec python3 -m snakemake "$@"
