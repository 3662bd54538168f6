//! `--plot DIR` figures of an identification: measured against model for each channel of each
//! record, the residual beneath.

use std::path::{Path, PathBuf};

use anyhow::Result;
use motor_model::{central_difference, Effects, MotorParams, Simulator};

use crate::plot::{self, Panel, Series, MEASURED, MODEL, OTHER};
use crate::steps::LoadedExcited;

/// A file stem for `path` in `dir`: `dir/<file stem>_fit`.
fn stem_in(dir: &Path, path: &str) -> PathBuf {
    let name = Path::new(path)
        .file_stem()
        .map_or_else(|| "record".into(), |s| s.to_string_lossy().into_owned());
    dir.join(format!("{name}_fit"))
}

/// Figures of the output-error fit: for each record, the voltage, and for current and speed
/// the measurement and the simulation of `params`, with the residual (measured − model) under
/// each. Clipped samples are drawn but were not fitted.
pub fn fit_figures(
    dir: &Path,
    records: &[LoadedExcited],
    params: &MotorParams,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
    let mut written = Vec::new();
    for rec in records {
        let r = &rec.record;
        let n = r.t.len();
        let rate = 1.0 / motor_model::mean_period(&r.t);
        let trace = Simulator::new(*params, Effects::none(), rec.input.clone())
            .and_then(|s| s.run((n as f64 - 0.5) / rate, rate))
            .map_err(|e| anyhow::anyhow!("{}: simulating the fitted model: {e}", rec.path))?;
        let t: Vec<f64> = r.t.clone();
        let model_v: Vec<f64> = trace.voltage.clone();
        let current_res = plot::residual(&r.current, &trace.current);
        let (speed, speed_label): (Vec<f64>, &str) = match (&r.position, &r.speed) {
            (Some(p), _) => (
                central_difference(&r.t, p),
                "speed from the encoder [rad/s]",
            ),
            (None, Some(w)) => (w.clone(), "speed [rad/s]"),
            (None, None) => (Vec::new(), ""),
        };
        let model_speed = if r.position.is_some() {
            central_difference(&trace.t, &trace.position)
        } else {
            trace.speed.clone()
        };
        let speed_res = plot::residual(&speed, &model_speed);
        let mut panels = vec![
            Panel {
                y_label: "voltage [V]",
                series: vec![
                    Series {
                        label: "measured",
                        values: &r.voltage,
                        color: MEASURED,
                    },
                    Series {
                        label: "as simulated",
                        values: &model_v,
                        color: MODEL,
                    },
                ],
            },
            Panel {
                y_label: "current [A]",
                series: vec![
                    Series {
                        label: "measured",
                        values: &r.current,
                        color: MEASURED,
                    },
                    Series {
                        label: "model",
                        values: &trace.current,
                        color: MODEL,
                    },
                ],
            },
            Panel {
                y_label: "current residual [A]",
                series: vec![Series {
                    label: "measured − model",
                    values: &current_res,
                    color: OTHER,
                }],
            },
        ];
        if !speed.is_empty() {
            panels.push(Panel {
                y_label: speed_label,
                series: vec![
                    Series {
                        label: "measured",
                        values: &speed,
                        color: MEASURED,
                    },
                    Series {
                        label: "model",
                        values: &model_speed,
                        color: MODEL,
                    },
                ],
            });
            panels.push(Panel {
                y_label: "speed residual [rad/s]",
                series: vec![Series {
                    label: "measured − model",
                    values: &speed_res,
                    color: OTHER,
                }],
            });
        }
        let title = format!("{}: measured and identified model", rec.path);
        let paths = plot::time_series(&stem_in(dir, &rec.path), &title, &t, &panels)?;
        if !quiet {
            for p in &paths {
                eprintln!("wrote {}", p.display());
            }
        }
        written.extend(paths);
    }
    Ok(written)
}
