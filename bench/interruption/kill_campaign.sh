#!/usr/bin/env bash
# kill -9 campaign: runs `loopsfm reconstruct` once uninterrupted, then TRIALS times killed
# with SIGKILL at a random moment and run again to the end, and reports for each trial the
# stage the kill hit, what was committed before it, the work the rerun did again
# (frames extracted / pairs matched beyond what was missing), and whether the final
# model and trajectory are byte-identical to the uninterrupted run's.
#
#   bench/interruption/kill_campaign.sh BIN OUT [TRIALS] [FRAMES] [CHECKPOINT_SECONDS]
#
# One thread and the default seed, so an uninterrupted run is reproducible bit for bit.
set -euo pipefail
bin=$(realpath "$1"); out=$2; trials=${3:-10}; frames=${4:-120}; every=${5:-2}
mkdir -p "$out"; out=$(realpath "$out"); cd "$out"
flags=(--threads 1 reconstruct scene/video.mp4 --export colmap,ply,tum --checkpoint-every "$every")

[ -f scene/video.mp4 ] || "$bin" -q synth street -o scene --video --frames "$frames" --width 320 --height 240
if [ ! -f reference/sparse/0/images.bin ]; then
  rm -rf reference
  start=$(date +%s.%N)
  "$bin" "${flags[@]}" -o reference > reference.log 2>&1
  echo "$start $(date +%s.%N)" | awk '{print $2 - $1}' > reference.seconds
fi
total=$(cat reference.seconds)
stored() {  # frames with features, pairs matched
  sqlite3 "$1/database.db" "select count(*) from keypoints; select count(*) from matches;" 2>/dev/null |
    paste -sd' ' || echo "0 0"
}
read -r all_frames all_pairs < <(stored reference)

echo "trial kill_s stage frames_before pairs_before ckpt_registered rerun_frames rerun_pairs" \
     "recomputed_frames recomputed_pairs resumed_mapping identical" > campaign.txt
for t in $(seq 1 "$trials"); do
  dir=trial_$t; rm -rf "$dir"
  kill_at=$(awk -v s="$RANDOM" -v T="$total" 'BEGIN { srand(s); printf "%.1f", rand() * T }')
  "$bin" "${flags[@]}" -o "$dir" > "$dir.kill.log" 2>&1 &
  pid=$!
  sleep "$kill_at"
  kill -9 "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  stage=$(grep -oE "^(extract|match|map|export)|\[info\] (extract|match|tracks|mapper|model)" "$dir.kill.log" |
          tail -1 | sed 's/\[info\] //')
  [ -n "$stage" ] || stage=start
  [ -f "$dir/sparse/0/images.bin" ] && stage=finished
  read -r frames_before pairs_before < <(stored "$dir")
  ckpt=0
  if [ -f "$dir/mapper_checkpoint.bin" ]; then
    ckpt=$(python3 -c "
import json, struct, sys
b = open('$dir/mapper_checkpoint.bin', 'rb').read()
n = struct.unpack('<Q', b[30:38])[0]
print(json.loads(b[38:38 + n])['report']['counts'][1])")
  fi
  "$bin" "${flags[@]}" -o "$dir" > "$dir.rerun.log" 2>&1
  rerun_frames=$(grep -oE "extract: [0-9]+ frames \(([0-9]+) new\)" "$dir.rerun.log" | grep -oE "\([0-9]+" | tr -d '(')
  rerun_pairs=$(grep -oE "\(([0-9]+) matched now" "$dir.rerun.log" | grep -oE "[0-9]+")
  resumed=$(grep -c "going on from a checkpoint" "$dir.rerun.log" || true)
  identical=yes
  for f in sparse/0/cameras.bin sparse/0/images.bin sparse/0/points3D.bin trajectory.txt points.ply; do
    cmp -s "reference/$f" "$dir/$f" || identical="no($f)"
  done
  echo "$t $kill_at $stage $frames_before $pairs_before $ckpt $rerun_frames $rerun_pairs" \
       "$((rerun_frames - (all_frames - frames_before))) $((rerun_pairs - (all_pairs - pairs_before)))" \
       "$resumed $identical" >> campaign.txt
  tail -1 campaign.txt
done
column -t campaign.txt
