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
  # COLMAP (CPU build) for interop tests and the photo pipeline
  colmap
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

if [ "${#missing[@]}" -eq 0 ]; then
  echo "setup.sh: all system packages present"
  exit 0
fi

echo "setup.sh: installing ${missing[*]}"
log="$(mktemp -t frond-setup.XXXXXX.log)"
export DEBIAN_FRONTEND=noninteractive
if ! { as_root apt-get update -q && as_root apt-get install -y -q --no-install-recommends "${missing[@]}"; } >"$log" 2>&1; then
  echo "setup.sh: apt-get failed; last lines of $log:" >&2
  tail -n 40 "$log" >&2
  exit 1
fi
echo "setup.sh: done (log: $log)"
