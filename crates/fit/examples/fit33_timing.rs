//! Times the fit of Eq. (33) on a data file, for `benches/fit33_vs_scipy.sh`.
//!
//! `cargo run --release -p fit --example fit33_timing -- DATA.txt ALPHA0 SIGMA0 WA0 [REPEATS]`
//! where DATA.txt holds `dt` on its first line and one normalised current sample per line
//! after it. Prints the median wall time of the whole fit and the fitted parameters.

use std::time::Instant;

use fit::{fit_33, LmSettings, Params33, Record33};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 5 {
        return Err("usage: fit33_timing DATA.txt ALPHA0 SIGMA0 WA0 [REPEATS]".into());
    }
    let text = std::fs::read_to_string(&args[1])?;
    let mut lines = text.lines();
    let dt: f64 = lines.next().ok_or("empty data file")?.trim().parse()?;
    let y: Vec<f64> = lines.map(|l| l.trim().parse()).collect::<Result<_, _>>()?;
    let start = Params33 {
        alpha: args[2].parse()?,
        sigma: args[3].parse()?,
        omega_a: args[4].parse()?,
    };
    let repeats: usize = args.get(5).map_or(Ok(200), |r| r.parse())?;
    let record = Record33 {
        t_first: 0.0,
        dt,
        normalized_current: &y,
    };
    let mut times = Vec::with_capacity(repeats);
    let mut last = None;
    for _ in 0..repeats {
        let t = Instant::now();
        let fit = fit_33(&record, start, LmSettings::default())?;
        times.push(t.elapsed().as_secs_f64());
        last = Some(fit);
    }
    times.sort_by(f64::total_cmp);
    let fit = last.ok_or("no repeat")?;
    println!(
        "rust_median_s {:.6e} alpha {:.9} sigma {:.9} wa {:.9} iterations {} termination {}",
        times[times.len() / 2],
        fit.params.alpha,
        fit.params.sigma,
        fit.params.omega_a,
        fit.report.iterations,
        fit.report.termination.text()
    );
    Ok(())
}
