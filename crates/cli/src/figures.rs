//! `--plot DIR` figures of an identification: measured against model for each fitted channel
//! of each record, the residual beneath, from the traces the fit returns
//! ([`fit::FullFit::fitted`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Result;
use fit::{Channel, FittedChannel, FullFit};

use crate::plot::{self, Panel, Series, MEASURED, MODEL, OTHER};

/// The name of each record's figures, in the order of `paths`: its file stem (`record` for a
/// path without one), followed by `-2`, `-3`, ... where an earlier record already has that name
/// (`a/r.csv` and `b/r.csv` give `r` and `r-2`), so that no record's figures replace another's.
fn record_names<'a>(paths: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for path in paths {
        let stem = Path::new(path)
            .file_stem()
            .map_or_else(|| "record".into(), |s| s.to_string_lossy().into_owned());
        let mut name = stem.clone();
        let mut k = 1;
        while names.contains(&name) {
            k += 1;
            name = format!("{stem}-{k}");
        }
        names.push(name);
    }
    names
}

/// What the figures need of a record beyond the fit: its file, the time of each sample the
/// fit indexes \[s\], and the measured voltage on the same samples \[V\] if it is to be drawn.
pub struct FigureRecord<'a> {
    /// File it came from (names the figure).
    pub path: &'a str,
    /// Time of every sample of the record as fitted \[s\].
    pub t: Vec<f64>,
    /// Measured voltage of every sample \[V\], if drawn.
    pub voltage: Option<&'a [f64]>,
}

/// The axis labels of a fitted channel and of its residual.
fn labels(channel: Channel) -> (&'static str, &'static str) {
    match channel {
        Channel::Current => ("current [A]", "current residual [A]"),
        Channel::EncoderSpeed => ("speed from the encoder [rad/s]", "speed residual [rad/s]"),
        _ => ("speed [rad/s]", "speed residual [rad/s]"),
    }
}

/// Figures of a fit: for each record (in the order of `records`, the fit's), the voltage if
/// given, and for each fitted channel the measurement and the fitted model with the residual
/// (measured − model) under it, over the samples fitted (clipped samples left out), into
/// `dir/<record>_fit.svg` and `.png` (`<record>` from [`record_names`]). Channels of a record
/// fitted on different samples get a figure each.
pub fn fit_figures(
    dir: &Path,
    records: &[FigureRecord<'_>],
    fit: &FullFit,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    crate::output::create_dir(dir)?;
    let mut written = Vec::new();
    let names = record_names(records.iter().map(|r| r.path));
    for ((r, rec), name) in records.iter().enumerate().zip(&names) {
        // Channels fitted on the same samples share a figure.
        let mut groups: Vec<Vec<&FittedChannel>> = Vec::new();
        for c in fit.fitted.iter().filter(|c| c.record == r) {
            match groups.iter_mut().find(|g| g[0].samples == c.samples) {
                Some(g) => g.push(c),
                None => groups.push(vec![c]),
            }
        }
        for (g, group) in groups.iter().enumerate() {
            let samples = &group[0].samples;
            let at = |y: &[f64]| -> Vec<f64> {
                samples
                    .iter()
                    .map(|&i| y.get(i).copied().unwrap_or(f64::NAN))
                    .collect()
            };
            let t = at(&rec.t);
            let voltage = rec.voltage.filter(|_| g == 0).map(at);
            let residuals: Vec<Vec<f64>> = group
                .iter()
                .map(|c| plot::residual(&c.measured, &c.model))
                .collect();
            let mut panels = Vec::new();
            if let Some(v) = &voltage {
                panels.push(Panel {
                    y_label: "voltage [V]",
                    series: vec![Series {
                        label: "measured",
                        values: v,
                        color: MEASURED,
                    }],
                });
            }
            for (c, residual) in group.iter().zip(&residuals) {
                let (label, residual_label) = labels(c.channel);
                panels.push(Panel {
                    y_label: label,
                    series: vec![
                        Series {
                            label: "measured",
                            values: &c.measured,
                            color: MEASURED,
                        },
                        Series {
                            label: "model",
                            values: &c.model,
                            color: MODEL,
                        },
                    ],
                });
                panels.push(Panel {
                    y_label: residual_label,
                    series: vec![Series {
                        label: "measured − model",
                        values: residual,
                        color: OTHER,
                    }],
                });
            }
            let suffix = if g == 0 {
                String::new()
            } else {
                let names: Vec<&str> = group.iter().map(|c| c.channel.name()).collect();
                format!("_{}", names.join("_"))
            };
            let title = format!("{}: measured and identified model", rec.path);
            let stem = dir.join(format!("{name}{suffix}_fit"));
            let paths = plot::time_series(&stem, &title, &t, &panels)?;
            if !quiet {
                for p in &paths {
                    crate::console::errln!("wrote {}", p.display());
                }
            }
            written.extend(paths);
        }
    }
    Ok(written)
}

/// One residual of a diagnosis: a channel of a record before and after the chosen effect.
pub struct ResidualFigure<'a> {
    /// Index of its record in the order the records were given: the figures of one record
    /// share a name ([`record_names`]).
    pub record: usize,
    /// File it came from (names the figure).
    pub path: &'a str,
    /// The channel's name (names the figure: `current`, `speed`, `force`).
    pub channel: &'a str,
    /// The residual's axis label with unit.
    pub y_label: &'a str,
    /// Time of each sample \[s\].
    pub t: Vec<f64>,
    /// Measured − nominal model.
    pub before: Vec<f64>,
    /// Measured − the model with the effects named, if any is.
    pub after: Option<Vec<f64>>,
}

/// Figures of a diagnosis: for each record and channel, the residual of the nominal model and,
/// when an effect is named (`named`), the residual with it, into
/// `dir/<record>_<channel>_residual.svg` and `.png` (`<record>` from [`record_names`], the
/// records in the order given).
pub fn residual_figures(
    dir: &Path,
    figures: &[ResidualFigure<'_>],
    named: &str,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    crate::output::create_dir(dir)?;
    let mut written = Vec::new();
    let after_label = format!("with {named}");
    let paths: BTreeMap<usize, &str> = figures.iter().map(|f| (f.record, f.path)).collect();
    let names: BTreeMap<usize, String> = paths
        .keys()
        .copied()
        .zip(record_names(paths.values().copied()))
        .collect();
    for f in figures {
        let mut series = vec![Series {
            label: "nominal model",
            values: &f.before,
            color: OTHER,
        }];
        if let Some(after) = &f.after {
            series.push(Series {
                label: &after_label,
                values: after,
                color: MODEL,
            });
        }
        let title = match f.after {
            Some(_) => format!(
                "{}: {} residual before and after {named}",
                f.path, f.channel
            ),
            None => format!("{}: {} residual (no effect named)", f.path, f.channel),
        };
        let stem = dir.join(format!(
            "{}_{}_residual",
            names[&f.record],
            f.channel.replace(' ', "_")
        ));
        let paths = plot::time_series(
            &stem,
            &title,
            &f.t,
            &[Panel {
                y_label: f.y_label,
                series,
            }],
        )?;
        if !quiet {
            for p in &paths {
                crate::console::errln!("wrote {}", p.display());
            }
        }
        written.extend(paths);
    }
    Ok(written)
}

/// The residual figures of the channels `before` and `after` hold (the same records and
/// channels; `after` may be absent), on the records' times.
pub fn channel_residuals<'a>(
    records: &[FigureRecord<'a>],
    before: &[FittedChannel],
    after: Option<&[FittedChannel]>,
) -> Vec<ResidualFigure<'a>> {
    before
        .iter()
        .filter_map(|b| {
            let rec = records.get(b.record)?;
            let t = b
                .samples
                .iter()
                .map(|&i| rec.t.get(i).copied().unwrap_or(f64::NAN))
                .collect();
            let after = after.and_then(|all| {
                all.iter()
                    .find(|a| {
                        a.record == b.record && a.channel == b.channel && a.samples == b.samples
                    })
                    .map(|a| plot::residual(&a.measured, &a.model))
            });
            Some(ResidualFigure {
                record: b.record,
                path: rec.path,
                channel: b.channel.name(),
                y_label: labels(b.channel).1,
                t,
                before: plot::residual(&b.measured, &b.model),
                after,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_of_the_same_file_name_are_numbered_in_order() {
        let names = record_names(["a/r.csv", "b/r.csv", "r-2.csv", "c/r.csv", "/"]);
        assert_eq!(names, ["r", "r-2", "r-2-2", "r-3", "record"]);
    }
}
