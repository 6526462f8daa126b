#!/usr/bin/env bash
# Renders the logo-CNN dataset with `topspin render` (issue 7):
#   OUT/lab-sN/        the training distribution (the lab's light and noise),
#                      split 4:1 into train/test by ball in train.py;
#   OUT/other-lab/     a held-out test set under another light and twice the
#                      sensor noise, to show the network generalises.
# Both ball colours, 10 consecutive 380 Hz frames per ball, all nine launcher
# settings. Deterministic in the seeds. Usage:
#   tools/logo_cnn/dataset.sh OUT [BALLS_PER_SHARD] [SHARDS]
set -euo pipefail
out=${1:?usage: dataset.sh OUT [BALLS_PER_SHARD] [SHARDS]}
balls=${2:-80}
shards=${3:-4}
topspin=${TOPSPIN:-target/release/topspin}
[ -x "$topspin" ] || cargo build --release --quiet
mkdir -p "$out"
pids=()
for s in $(seq 1 "$shards"); do
  "$topspin" render --out "$out/lab-s$s" --seed "$s" --balls "$balls" --colour both \
    --frames-per-ball 10 > "$out/lab-s$s.log" &
  pids+=($!)
done
"$topspin" render --out "$out/other-lab" --seed 101 --balls $((balls * 3 / 4)) --colour both \
  --frames-per-ball 10 --conditions other-lab > "$out/other-lab.log" &
pids+=($!)
for p in "${pids[@]}"; do wait "$p"; done
for d in "$out"/lab-s* "$out"/other-lab; do
  [ -d "$d" ] && echo "$d: $(($(wc -l < "$d/labels.csv") - 1)) crops"
done
