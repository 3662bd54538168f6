//! The withheld-effect benchmark: generates the cases of `motor_model::withheld` for a seed,
//! diagnoses each without telling it the effect, and prints the confusion matrix, the top-1
//! accuracy, false alarms on `none`, the both-named rate of two-effect cases and the median
//! held-out NRMSE after/before of correctly named effects.
//!
//! ```text
//! cargo run --release -p fit --example withheld_benchmark -- [SEED] [N] [CASE]
//! ```
//!
//! With CASE, only that case is diagnosed and every candidate of every stage printed.
//!
//! (default seed 1, 160 cases: 20 `none`, 20 with two effects, 120 with one; heavy — minutes
//! per ten cases on two cores). One line per case as it finishes, the summary at the end.

use fit::diagnose::benchmark::{diagnose_case, run_case, CaseOutcome, Summary};
use fit::diagnose::DiagnoseSettings;
use motor_model::withheld::benchmark_case;

#[path = "../tests/common/diagnose_records.rs"]
mod records;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let n: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(160);
    let settings = DiagnoseSettings::default();
    if let Some(index) = args.next().map(|s| s.parse::<usize>()).transpose()? {
        let case = benchmark_case(seed, index, n)?;
        println!("case {index}: truth {:?}", case.truth());
        if std::env::var_os("WITHHELD_VERBOSE").is_some() {
            println!("{}", serde_json::to_string(&case)?);
        }
        let d = diagnose_case(&case, &settings)?;
        records::print_stages(&d);
        return Ok(());
    }
    let mut outcomes: Vec<CaseOutcome> = Vec::with_capacity(n);
    for i in 0..n {
        let case = benchmark_case(seed, i, n)?;
        let o = run_case(&case, &settings);
        println!(
            "{:>4}  truth {:<45} named {:<45} ratio {:>6}  {:.1} s{}",
            i,
            o.truth.join("+"),
            match &o.named {
                Ok(v) if v.is_empty() => "none".to_string(),
                Ok(v) => v.join("+"),
                Err(_) => "failed".to_string(),
            },
            o.heldout_ratio.map_or("-".into(), |r| format!("{r:.3}")),
            o.seconds,
            o.named
                .as_ref()
                .err()
                .map_or(String::new(), |e| format!("  ({e})"))
        );
        outcomes.push(o);
    }
    let s = Summary::of(&outcomes);
    println!("\nconfusion (rows: truth, one effect or none; columns: top-ranked verdict)");
    let short = |l: &str| l.chars().take(8).collect::<String>();
    print!("{:<22}", "");
    for l in &s.labels {
        print!(" {:>8}", short(l));
    }
    println!();
    for (r, row) in s.confusion.iter().enumerate() {
        print!("{:<22}", s.labels[r]);
        for c in row {
            print!(" {c:>8}");
        }
        println!();
    }
    println!(
        "\nseed {seed}, {} cases: top-1 accuracy {:.1} %, false alarms on none {}/{}, both named {}/{}, median held-out NRMSE after/before {:.3}, failed {}, median {:.1} s a case",
        s.cases,
        100.0 * s.top1_accuracy,
        s.false_alarms.0,
        s.false_alarms.1,
        s.both_named.0,
        s.both_named.1,
        s.median_heldout_ratio,
        s.failed,
        s.median_seconds
    );
    Ok(())
}
