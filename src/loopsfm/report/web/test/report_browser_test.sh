#!/usr/bin/env bash
# ctest report_browser_test: a synthetic scene reconstructed by the CLI, its HTML report
# written by html_report_fixture, then opened in headless Chromium by
# report_browser_test.mjs (which leaves WORK_DIR/screenshot.png to look at).
#
#   report_browser_test.sh LOOPSFM HTML_REPORT_FIXTURE NODE WORK_DIR
#
# Exits 77 (skipped) only when there is no Chromium; scripts/setup installs Debian's.
set -euo pipefail
[ $# -eq 4 ] || { echo "usage: $0 LOOPSFM HTML_REPORT_FIXTURE NODE WORK_DIR" >&2; exit 2; }
loopsfm=$1 fixture=$2 node=$3 work=$4
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
  >"$work/reconstruct.log" 2>&1 || { cat "$work/reconstruct.log"; exit 1; }
"$fixture" "$work/run" "$work/scene/groundtruth.txt" "$work/reconstruct.log" "$work/report.html"
"$node" "$here/report_browser_test.mjs" "$work/report.html" "$work/screenshot.png"
