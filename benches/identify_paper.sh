#!/usr/bin/env bash
# Times `motorid identify --method paper` on two 50,001-sample records, and `identify --batch`
# on a fleet of motors, for a baseline commit and for the working tree, side by side in one run:
# both are built (the baseline from `git archive` into a temporary directory), the records are
# made once, and each round runs every binary in turn. Prints medians of wall and CPU time.
#
#   bash benches/identify_paper.sh [BASE] [RUNS] [MOTORS]
#
# BASE: the commit to compare with (default 8457ec0, main before the reader, the step-pair
# pipeline and the (C.8) check were reworked); RUNS: rounds of the step pair (default 30; the
# batch gets a fifth of them, at least 3); MOTORS: fleet size (default 1000, 0 to skip).
# BENCH_DIR keeps the baseline's build between runs (default target/bench-identify).
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-8457ec0}
runs=${2:-30}
motors=${3:-1000}

# The baseline's source and build, kept by commit.
. benches/baseline.sh
baseline_source target/bench-identify "$base"
echo "building the baseline $base and the working tree…" >&2
(cd "$src" && CARGO_TARGET_DIR="$dir/target-$commit" cargo build --quiet --release -p motorid)
cargo build --quiet --release -p motorid
old="$dir/target-$commit/release/motorid"
new="$PWD/target/release/motorid"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
logger=(--adc-bits 10 --noise-lsb 1 --encoder-cpr 2000 --speed-from encoder)
"$new" simulate --voltage 40 --duration 50 "${logger[@]}" -o "$work/hv.csv" 2>/dev/null
"$new" simulate --voltage 2.5 --duration 50 "${logger[@]}" -o "$work/lv.csv" 2>/dev/null
pair="identify --high $work/hv.csv --low $work/lv.csv --method paper"
if ! diff <("$old" $pair) <("$new" $pair) >/dev/null; then
    echo "note: the two builds print different figures for the step pair" >&2
fi
echo "identify --method paper, two 50,001-sample records ($(nproc) cores):"
python3 benches/time_runs.py "$runs" base "$old $pair" now "$new $pair"

if [ "$motors" -gt 0 ]; then
    "$new" fleet --out "$work/fleet" --motors "$motors" >/dev/null 2>&1
    batch=(identify --batch "$work/fleet" --quiet)
    echo "identify --batch, $motors motors:"
    python3 benches/time_runs.py "$(( runs / 5 > 3 ? runs / 5 : 3 ))" \
        base "$old ${batch[*]}" now "$new ${batch[*]}"
fi
