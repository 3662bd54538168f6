//! Reads the record named on the command line with the CLI's own reader and with the `csv`
//! crate, three rounds each, and prints the times (see `benches/csv_crate.sh`).
#![allow(dead_code)]
mod record_csv;
use std::time::Instant;

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: csv-crate-bench RECORD.csv");
        std::process::exit(2);
    };
    for round in 0..3 {
        let t = Instant::now();
        let mut reader = csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .has_headers(true)
            .from_path(&path)
            .expect("readable record");
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); 5];
        let mut row = csv::ByteRecord::new();
        while reader.read_byte_record(&mut row).expect("a CSV row") {
            for (column, field) in columns.iter_mut().zip(row.iter()) {
                column.push(fast_float2::parse(field).expect("a number"));
            }
        }
        let csv_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let table = record_csv::read_table(std::path::Path::new(&path)).expect("a record");
        let own_ms = t.elapsed().as_secs_f64() * 1e3;
        drop(table);
        println!(
            "round {round}: {} rows: csv crate {csv_ms:.1} ms, own reader {own_ms:.1} ms",
            columns[0].len()
        );
    }
}
