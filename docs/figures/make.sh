#!/usr/bin/env bash
# Regenerates the README's figures: bash docs/figures/make.sh (from the repository root;
# the EMPS figure needs ../shared/real-data/emps beside the repository).
set -euo pipefail
root=$(pwd)
figures="$root/docs/figures"
cargo build --release -q
motorid="$root/target/release/motorid"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
logger=(--adc-bits 10 --noise-lsb 1 --encoder-cpr 2000 --speed-from encoder)
# The paper's two step tests through its logger, identified by the full model.
"$motorid" simulate --voltage 40 --step-at 0.005 "${logger[@]}" -o paper_40V.csv
"$motorid" simulate --voltage 2.5 --step-at 0.005 "${logger[@]}" -o paper_2.5V.csv
"$motorid" identify --high paper_40V.csv --low paper_2.5V.csv --plot "$figures" -q > /dev/null
# A staircase with a reversal, identified by simulation (output error).
"$motorid" simulate --levels 0.5:40,40.5:-20,80.5:0,100.5:2.5 --duration 140 "${logger[@]}" -o staircase.csv
"$motorid" identify --record staircase.csv --plot "$figures" -q > /dev/null
# A small servo with a brush drop the diagnosis is not told of: the current residual of its
# 12 V step before and after the effect the diagnosis names.
servo="$root/fixtures/motors/small_servo.json"
"$motorid" simulate --motor "$servo" --voltage 12 --duration 0.6 --rate 5000 "${logger[@]}" \
    --effect brush_drop:vb=0.3 --seed 1 --quiet -o brush12.csv
"$motorid" simulate --motor "$servo" --voltage 3 --duration 0.6 --rate 5000 "${logger[@]}" \
    --effect brush_drop:vb=0.3 --seed 2 --quiet -o brush3.csv
"$motorid" diagnose --high brush12.csv --low brush3.csv --plot diagnosis --quiet > /dev/null
cp diagnosis/brush12_current_residual.svg diagnosis/brush12_current_residual.png "$figures"
# EMPS: where the unmodelled force pulses hurt.
cd "$root"
"$motorid" emps --plot "$figures" > /dev/null
ls -l "$figures"
