#!/usr/bin/env bash
# Reads one record with the CLI's own reader (`crates/cli/src/record_csv.rs`, `read_table`:
# the whole table with every text check) and with the `csv` crate (`ByteRecord`s, each field
# parsed by fast_float2, no checks), three rounds each in one process, and prints the times.
# The reader is compiled from the working tree into a scratch crate beside the csv crate.
#
#   bash benches/csv_crate.sh [RECORD.csv]
#
# Without a record it makes the README's 50 s logger record and a 2,000,000-row one.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/src"
cat > "$work/Cargo.toml" <<TOML
[package]
name = "csv-crate-bench"
version = "0.1.0"
edition = "2021"
[dependencies]
csv = "1"
fast-float2 = "0.2"
anyhow = "1"
memchr = "2"
serde_json = "1"
motor-model = { path = "$root/crates/motor-model" }
fit = { path = "$root/crates/fit" }
TOML
cp benches/csv_crate/main.rs "$work/src/main.rs"
# The reader alone: its tests, the writer and the CLI's error type and range parser left out.
python3 - "$root/crates/cli/src/record_csv.rs" "$work/src/record_csv.rs" <<'PY'
import sys
s = open(sys.argv[1]).read()
s = s[: s.index("#[cfg(test)]\nmod tests")]
s = s.replace("use crate::BadInput;", "#[derive(Debug)]\npub struct BadInput(pub String);\nimpl std::fmt::Display for BadInput {\n    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {\n        f.write_str(&self.0)\n    }\n}\nimpl std::error::Error for BadInput {}")
s = s.replace("crate::output::write_with(path, |mut out| write_to(&mut out, record, metadata))", "{\n        let _ = (path, record, metadata);\n        unimplemented!()\n    }")
s = s.replace("crate::settings::pair(key, text)", "Err::<(f64, f64), ()>(())")
open(sys.argv[2], "w").write(s)
PY
cargo build --quiet --release -p motorid
(cd "$work" && CARGO_TARGET_DIR="$root/target/bench-csv" cargo build --quiet --release)
bench="$root/target/bench-csv/release/csv-crate-bench"
if [ $# -gt 0 ]; then
    "$bench" "$1"
else
    logger=(--adc-bits 10 --noise-lsb 1 --encoder-cpr 2000 --speed-from encoder)
    target/release/motorid simulate --voltage 40 --duration 50 "${logger[@]}" -o "$work/hv.csv" -q
    target/release/motorid simulate --voltage 40 --duration 2000 -o "$work/long.csv" -q
    echo "50,001 rows:"; "$bench" "$work/hv.csv"
    echo "2,000,001 rows:"; "$bench" "$work/long.csv"
fi
