#!/usr/bin/env bash
# Runs frond-ui under a virtual X display on a scene, takes a screenshot and checks that it is
# not blank (pixel standard deviation above a floor).
# Usage: scripts/screenshot_ui.sh [OUT.png] [SCENE] [--release]
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
out="${1:-target/frond-ui.png}"
scene="${2:-fixtures/toy_scene}"
profile="${3:-}"
cargo build --quiet -p frond-ui ${profile}
bin="target/debug/frond-ui"
[ "$profile" = "--release" ] && bin="target/release/frond-ui"
mkdir -p "$(dirname "$out")"
xvfb-run -a -s "-screen 0 1280x800x24" bash -c '
  "$0" "$1" & pid=$!
  sleep "${FROND_SCREENSHOT_WAIT:-10}"
  /usr/bin/import -window root "$2"
  kill $pid 2>/dev/null || true
  wait $pid 2>/dev/null || true
' "$bin" "$scene" "$out"
std=$(/usr/bin/convert "$out" -colorspace Gray -format "%[fx:standard_deviation]" info:)
echo "screenshot $out: grey-level standard deviation $std"
awk -v s="$std" 'BEGIN { exit !(s > 0.02) }' || { echo "screenshot looks blank" >&2; exit 1; }
