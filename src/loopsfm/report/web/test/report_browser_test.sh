#!/usr/bin/env bash
# ctest report_browser_test: a synthetic scene reconstructed by the CLI, which writes
# OUT/report.html (scored against the scene's ground truth), then opened in headless
# Chromium by report_browser_test.mjs (which leaves WORK_DIR/screenshot.png to look at).
#
#   report_browser_test.sh LOOPSFM NODE WORK_DIR
#
# Exits 77 (skipped) only when there is no Chromium; scripts/setup installs Debian's.
set -euo pipefail
[ $# -eq 3 ] || { echo "usage: $0 LOOPSFM NODE WORK_DIR" >&2; exit 2; }
loopsfm=$1 node=$2 work=$3
here=$(cd "$(dirname "$0")" && pwd)
chromium=${LOOPSFM_CHROMIUM:-/usr/bin/chromium}
if [ ! -x "$chromium" ]; then
  echo "SKIP: no Chromium at $chromium; run scripts/setup (installs Debian's chromium)"
  exit 77
fi

rm -rf "$work"
mkdir -p "$work"
"$loopsfm" synth cylinder -o "$work/scene" --frames 40 >"$work/synth.log" 2>&1 ||
  { cat "$work/synth.log"; exit 1; }
"$loopsfm" reconstruct "$work/scene/images" -o "$work/run" --intrinsics "$work/scene/intrinsics.txt" \
  --groundtruth "$work/scene/groundtruth.txt" --alternate-poses >"$work/reconstruct.log" 2>&1 ||
  { cat "$work/reconstruct.log"; exit 1; }
"$node" "$here/report_browser_test.mjs" "$work/run/report.html" "$work/screenshot.png"
