#!/usr/bin/env bash
# Times the two parallel commands, `identify --batch` on a fleet of motors and `montecarlo`,
# for a baseline commit and for the working tree, side by side in one run: both are built (the
# baseline from `git archive` into a temporary directory), the fleet is made once, and each
# round runs every binary in turn. Prints medians of wall and CPU time, and checks that the
# two builds print the same figures.
#
#   bash benches/parallel.sh [BASE] [RUNS] [MOTORS] [MC_RUNS]
#
# BASE: the commit to compare with (default main); RUNS: rounds of each command (default 5);
# MOTORS: fleet size (default 200); MC_RUNS: record pairs of the Monte Carlo study (default
# 200). BENCH_DIR keeps the baseline's build between runs (default target/bench-parallel).
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-main}
runs=${2:-5}
motors=${3:-200}
mc_runs=${4:-200}

# The baseline's source and build, kept by commit.
. benches/baseline.sh
baseline_source target/bench-parallel "$base"
echo "building the baseline $base and the working tree…" >&2
(cd "$src" && CARGO_TARGET_DIR="$dir/target-$commit" cargo build --quiet --release -p motorid)
cargo build --quiet --release -p motorid
old="$dir/target-$commit/release/motorid"
new="$PWD/target/release/motorid"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$new" fleet --out "$work/fleet" --motors "$motors" >/dev/null 2>&1
# Seconds and thread counts differ from run to run; every other figure must not.
figures() { grep -v -e '"seconds"' -e '"threads"' | sed 's/; [0-9.]* s on [0-9]* threads//'; }
batch=(identify --batch "$work/fleet" --quiet)
if ! diff -q <("$old" "${batch[@]}" --json 2>/dev/null | figures) \
    <("$new" "${batch[@]}" --json 2>/dev/null | figures) >/dev/null; then
    echo "note: the two builds print different figures for the batch" >&2
fi
mc=(montecarlo --runs "$mc_runs")
if ! diff -q <("$old" "${mc[@]}" 2>/dev/null | figures) \
    <("$new" "${mc[@]}" 2>/dev/null | figures) >/dev/null; then
    echo "note: the two builds print different figures for the Monte Carlo study" >&2
fi
echo "identify --batch, $motors motors ($(nproc) cores):"
python3 benches/time_runs.py "$runs" base "$old ${batch[*]}" now "$new ${batch[*]}"
echo "montecarlo --runs $mc_runs:"
python3 benches/time_runs.py "$runs" base "$old ${mc[*]} 2>/dev/null" now "$new ${mc[*]} 2>/dev/null"
