#!/usr/bin/env bash
# Times the fit of Eq. (33) on 50,000 samples in Rust (crate `fit`) and in SciPy's
# least_squares ('trf' and 'lm'), on the same data from the same start, in one run, and prints
# the speed ratio. Installs numpy and scipy into target/bench-venv on first use.
#
#   bash benches/fit33_vs_scipy.sh [ALPHA0 SIGMA0 WA0]     (default start: 3 0.4 0.3)
set -euo pipefail
cd "$(dirname "$0")/.."
start=("${1:-3}" "${2:-0.4}" "${3:-0.3}")
venv=target/bench-venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet -r benches/requirements.txt
fi
cargo build --quiet --release -p motorid -p fit --example fit33_timing
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# The paper's 40 V test, 50 s at 1 kHz (50,001 samples), normalised by the current at 50 s.
target/release/motorid simulate --motor paper --voltage 40 --duration 50 --rate 1000 -o "$work/hv.csv" 2>/dev/null
"$venv/bin/python" - "$work/hv.csv" "$work/i33.txt" <<'PY'
import sys
rows = [l.split(",") for l in open(sys.argv[1]) if not l.startswith("#") and not l.startswith("t,")]
current = [float(r[2]) for r in rows]
with open(sys.argv[2], "w") as f:
    f.write("0.001\n")
    f.writelines(f"{c / current[-1]!r}\n" for c in current)
PY
echo "data: $(($(wc -l < "$work/i33.txt") - 1)) samples; start alpha=${start[0]} sigma=${start[1]} wa=${start[2]}"
rust=$(target/release/examples/fit33_timing "$work/i33.txt" "${start[@]}" 200)
scipy=$("$venv/bin/python" benches/fit33_scipy.py "$work/i33.txt" "${start[@]}" 20)
echo "$rust"
echo "$scipy"
rust_s=$(awk '{print $2}' <<< "$rust")
best=$(awk '{print $2}' <<< "$scipy" | sort -g | head -n 1)
awk -v r="$rust_s" -v s="$best" 'BEGIN { printf "Rust %.3f ms, fastest SciPy %.3f ms: Rust is %.1f times faster\n", r * 1e3, s * 1e3, s / r }'
