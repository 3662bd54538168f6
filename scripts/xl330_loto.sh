#!/usr/bin/env bash
# Leave-one-trajectory-out on the shared XL330 pendulum logs: for each of the four
# trajectories, identify the servo on the other three (six logs, kp 100 and 200) and replay the
# two held-out logs in closed loop; prints each split's held-out position MAE and their mean
# beside the BAM project's published models replayed on the same logs.
#
#   scripts/xl330_loto.sh [path/to/motorid [identify options...]]
#   (default: target/release/motorid; e.g. `scripts/xl330_loto.sh target/release/motorid
#   --friction stribeck`)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-target/release/motorid}
shift || true
data=../shared/real-data/bam_xl330
[ -x "$bin" ] || cargo build --release -q
trajectories=(sin_sin lift_and_drop up_and_down sin_time_square)
total=0
for out in "${trajectories[@]}"; do
  args=()
  for tr in "${trajectories[@]}"; do
    for kp in 100 200; do
      if [ "$tr" = "$out" ]; then
        args+=(--validate "$data/xl330_${tr}_kp${kp}.csv")
      else
        args+=(--record "$data/xl330_${tr}_kp${kp}.csv")
      fi
    done
  done
  start=$(date +%s.%N)
  json=$("$bin" identify "${args[@]}" "$@" --json -q) || true
  took=$(python3 -c "print($(date +%s.%N) - $start)")
  read -r fitted held < <(printf '%s' "$json" | python3 -c \
    'import json,sys; r=json.load(sys.stdin); print(r["mae_rad"], r["validation"]["mae_rad"])')
  printf '%-16s fitted %6.1f mrad   held out %6.1f mrad   (%.1f s)\n' \
    "$out" "$(python3 -c "print($fitted*1e3)")" "$(python3 -c "print($held*1e3)")" "$took"
  total=$(python3 -c "print($total + $held)")
done
printf 'mean held-out position MAE %.1f mrad\n' "$(python3 -c "print($total * 1e3 / 4)")"
echo "BAM's published XL330 models on the same logs: M1 57.2, M2 57.0, M3 44.4, M4 44.1, M5 45.8, M6 44.3 mrad"
