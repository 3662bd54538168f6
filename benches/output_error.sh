#!/usr/bin/env bash
# Times the output-error fit for a baseline commit and for the working tree, side by side in
# one run: both builds of the coverage example (one 140,001-sample staircase of the reference
# simulator, 1 ms sampling of time constants near 1 s: start and fit) and of
# `motorid identify --record` on a staircase of the small servo (τe = 1 ms sampled at 2 kHz,
# 8,001 samples: 40 RK4 steps a sample before exact propagation). Each round runs every
# command in turn (`benches/time_runs.py`:
# medians of wall and of CPU time, user + system); the figures each build prints are shown
# once, so that the answers can be compared.
#
#   bash benches/output_error.sh [BASE] [RUNS]
#
# BASE: the commit to compare with (default 21462d2, before exact propagation); RUNS: rounds
# (default 5). BENCH_DIR keeps the baseline's build between runs (default target/bench-identify).
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-21462d2}
runs=${2:-5}

# The baseline's source and build, kept by commit.
. benches/baseline.sh
baseline_source target/bench-identify "$base"
echo "building the baseline $base and the working tree…" >&2
for tree in "$src" "$PWD"; do
    target=$([ "$tree" = "$PWD" ] && echo "$PWD/target" || echo "$dir/target-$commit")
    (cd "$tree" && CARGO_TARGET_DIR="$target" cargo build --quiet --release -p motorid \
        && CARGO_TARGET_DIR="$target" cargo build --quiet --release -p fit \
            --example output_error_coverage)
done
old="$dir/target-$commit/release"
new="$PWD/target/release"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$new/motorid" simulate --motor fixtures/motors/small_servo.json --levels 0.05:24,1.05:-12,2.05:0,3.05:3 \
    --duration 4 --rate 2000 --adc-bits 10 --noise-lsb 1 --encoder-cpr 2000 --speed-from encoder \
    --range-voltage -30,30 --seed 3 -o "$work/servo.csv" 2>/dev/null

staircase="output_error_coverage 1 --voltage-noise-lsb 0.5 --subsample-step"
servo="identify --record $work/servo.csv"
for label in base now; do
    bin=$([ "$label" = base ] && echo "$old" || echo "$new")
    echo "== $label: one staircase (errors in half-widths), and the servo staircase" >&2
    COVERAGE_VERBOSE=1 "$bin/examples/"$staircase 2>&1 | grep -E 'half-width|runs' >&2 || true
    "$bin/motorid" $servo 2>&1 | grep -E '^ *(R|L|k|f|J|Ts) |^fit:' >&2 || true
done
echo "output-error fit of one 140,001-sample staircase ($(nproc) cores):"
python3 benches/time_runs.py "$runs" base "$old/examples/$staircase" now "$new/examples/$staircase"
echo "identify --record, small servo staircase, 8,001 samples at 2 kHz:"
python3 benches/time_runs.py "$runs" base "$old/motorid $servo --quiet" now "$new/motorid $servo --quiet"
