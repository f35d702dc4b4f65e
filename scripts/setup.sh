#!/usr/bin/env bash
# Installs every system package Frond needs on a fresh Debian (bookworm) machine.
# Idempotent: packages already present are skipped; safe to run repeatedly.
# Needs root (or sudo) for apt-get. Nothing else has to be installed by hand.
set -euo pipefail

PACKAGES=(
  # Rust crates with C parts (opencv binding generation needs libclang)
  build-essential pkg-config clang libclang-dev
  # OpenCV 4.6 (imgproc, imgcodecs, ximgproc, calib3d, ...)
  libopencv-dev
  # wgpu headless rendering on software Vulkan (llvmpipe), GL fallback
  mesa-vulkan-drivers libvulkan1 libgl1-mesa-dri libegl1
  # eframe GUI under a virtual display, and screenshots
  xvfb xauth libxkbcommon-x11-0 libxkbcommon-dev libx11-dev libxcursor1 libxrandr2 libxi6
  libwayland-dev imagemagick
  # COLMAP (CPU build) for interop tests and the photo pipeline; SQLite to read its feature
  # database (rusqlite links the system library)
  colmap libsqlite3-dev
)

as_root() {
  if [ "$(id -u)" -eq 0 ]; then
    "$@"
  elif command -v sudo >/dev/null 2>&1; then
    sudo "$@"
  else
    echo "setup.sh: need root (or sudo) to run: $*" >&2
    exit 1
  fi
}

missing=()
for pkg in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done

# Export checks need Node (the Khronos glTF validator) and pip (a Python glTF reader); a Node
# from elsewhere (e.g. NodeSource, which bundles npm) is used as it is.
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  missing+=(nodejs npm)
fi
if ! command -v python3 >/dev/null 2>&1 || ! python3 -m pip --version >/dev/null 2>&1; then
  missing+=(python3 python3-pip)
fi

if [ "${#missing[@]}" -eq 0 ]; then
  echo "setup.sh: all system packages present"
else
  echo "setup.sh: installing ${missing[*]}"
  log="$(mktemp -t frond-setup.XXXXXX.log)"
  export DEBIAN_FRONTEND=noninteractive
  if ! { as_root apt-get update -q && as_root apt-get install -y -q --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
    echo "setup.sh: apt-get failed; last lines of $log:" >&2
    tail -n 40 "$log" >&2
    exit 1
  fi
  echo "setup.sh: system packages done (log: $log)"
fi

# Project-local tools in .tools/ (git-ignored), pinned: the Khronos glTF validator and
# pygltflib, used by the export tests through scripts/validate_gltf.js and scripts/read_gltf.py.
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
GLTF_VALIDATOR_VERSION="2.0.0-dev.3.10"
PYGLTFLIB_VERSION="1.16.5"
validator_json="$root/.tools/npm/node_modules/gltf-validator/package.json"
if ! grep -q "\"version\": \"$GLTF_VALIDATOR_VERSION\"" "$validator_json" 2>/dev/null; then
  echo "setup.sh: installing gltf-validator $GLTF_VALIDATOR_VERSION into .tools/npm"
  npm install --silent --prefix "$root/.tools/npm" --no-audit --no-fund --no-save \
    "gltf-validator@$GLTF_VALIDATOR_VERSION"
fi
if ! [ -d "$root/.tools/py/pygltflib-$PYGLTFLIB_VERSION.dist-info" ]; then
  echo "setup.sh: installing pygltflib $PYGLTFLIB_VERSION into .tools/py"
  rm -rf "$root/.tools/py"
  python3 -m pip install --quiet --disable-pip-version-check --no-warn-script-location --root-user-action=ignore \
    --target "$root/.tools/py" "pygltflib==$PYGLTFLIB_VERSION"
fi
# Snakemake, the workflow engine of workflow/Snakefile (many plants, local or on a cluster),
# with the Slurm and Kubernetes executors and the fs storage plugin its profiles use. Run it
# through scripts/snakemake.sh.
SNAKEMAKE_VERSION="9.27.1"
SNAKEMAKE_PACKAGES=(
  "snakemake==$SNAKEMAKE_VERSION"
  "snakemake-executor-plugin-slurm==2.8.0"
  "snakemake-executor-plugin-kubernetes==0.5.1"
  "snakemake-storage-plugin-fs==1.1.3"
)
snakemake_stamp="$root/.tools/snakemake/.frond-pins"
if [ "$(cat "$snakemake_stamp" 2>/dev/null)" != "${SNAKEMAKE_PACKAGES[*]}" ]; then
  echo "setup.sh: installing ${SNAKEMAKE_PACKAGES[*]} into .tools/snakemake"
  rm -rf "$root/.tools/snakemake"
  python3 -m pip install --quiet --disable-pip-version-check --no-warn-script-location --root-user-action=ignore \
    --target "$root/.tools/snakemake" "${SNAKEMAKE_PACKAGES[@]}"
  echo "${SNAKEMAKE_PACKAGES[*]}" >"$snakemake_stamp"
fi
echo "setup.sh: done"
