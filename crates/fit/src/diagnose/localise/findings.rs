//! A localisation read as findings: each significant excess, in words, ranked.

use serde::Serialize;

use crate::diagnose::localise::types::{channel_key, ChannelLocalisation, Localisation, PhaseKind};
use crate::estimation::records::Channel;

/// What a significant finding is about.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FindingKind {
    /// The channel as a whole is above its floor.
    Gap,
    /// A phase is above the floor.
    Phase {
        /// Which phase.
        phase: PhaseKind,
        /// Its start \[s\].
        t_start_s: f64,
        /// Its end \[s\].
        t_end_s: f64,
    },
    /// A time window is above the floor.
    Window {
        /// Its start \[s\].
        t_start_s: f64,
        /// Its end \[s\].
        t_end_s: f64,
    },
    /// The band |Ω| ≈ 0 is above the floor.
    NearZeroSpeed {
        /// Whether no moving band is.
        only: bool,
    },
    /// A band of |Ω| (not near zero) is above the floor.
    SpeedBand {
        /// Lowest |Ω| \[rad/s\].
        lo: f64,
        /// Highest |Ω| \[rad/s\].
        hi: f64,
    },
    /// A band of |I| is above the floor.
    CurrentBand {
        /// Lowest |I| \[A\].
        lo: f64,
        /// Highest |I| \[A\].
        hi: f64,
    },
    /// The excess trends with |Ω|.
    SpeedTrend {
        /// Grows (true) or falls with |Ω|.
        grows: bool,
    },
    /// The excess trends with |I|.
    CurrentTrend {
        /// Grows (true) or falls with |I|.
        grows: bool,
    },
    /// A spectral peak above the floor.
    SpectralPeak {
        /// Its frequency \[Hz\].
        frequency_hz: f64,
    },
    /// Ripple at N per revolution.
    AngleRipple {
        /// N.
        periods_per_rev: u32,
    },
    /// The residual is not white.
    NotWhite,
    /// The residual correlates with the input.
    InputCorrelation,
}

/// One significant finding.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// The record's name.
    pub record: String,
    /// The channel.
    #[serde(serialize_with = "channel_key")]
    pub channel: Channel,
    /// What.
    pub what: FindingKind,
    /// The test's number: the mean square over the floor (gap, phase, window, band), t
    /// (trend), the PSD over the floor (peak), the Wald statistic (ripple), Q (whiteness) or
    /// the largest correlation in standard errors (input).
    pub statistic: f64,
    /// Its p-value (adjusted where the test says so).
    pub p_value: f64,
    /// In words, e.g. "gap grows with |Ω| (t = 7.2)".
    pub text: String,
}

/// A p-value in words: `p = 3.1e-4`, or `p < 1e-12`.
pub(crate) fn p_words(p: f64) -> String {
    if p < 1e-12 {
        "p < 1e-12".to_string()
    } else {
        format!("p = {p:.1e}")
    }
}

impl Localisation {
    /// Every significant finding, by increasing p-value, in words for the ranking and the
    /// report (e.g. "gap grows with |Ω| (t = 7.2)", "ripple at 6 per revolution (p < 1e-12)").
    pub fn significant_findings(&self) -> Vec<Finding> {
        let mut out = Vec::new();
        for rec in &self.records {
            for ch in &rec.channels {
                channel_findings(&rec.name, ch, &mut out);
            }
        }
        out.sort_by(|a, b| a.p_value.total_cmp(&b.p_value));
        out
    }

    /// Whether anything is significant.
    pub fn any_significant(&self) -> bool {
        !self.significant_findings().is_empty()
    }

    /// The localisation of `channel` of the record named `record`, if present.
    pub fn channel(&self, record: &str, channel: Channel) -> Option<&ChannelLocalisation> {
        self.records
            .iter()
            .find(|r| r.name == record)?
            .channels
            .iter()
            .find(|c| c.channel == channel)
    }
}

pub(crate) fn channel_findings(record: &str, ch: &ChannelLocalisation, out: &mut Vec<Finding>) {
    let mut push = |what: FindingKind, statistic: f64, p_value: f64, text: String| {
        out.push(Finding {
            record: record.to_string(),
            channel: ch.channel,
            what,
            statistic,
            p_value,
            text: format!("{record}, {}: {text}", ch.channel.name()),
        });
    };
    if ch.overall.significant {
        push(
            FindingKind::Gap,
            ch.overall.ratio,
            ch.overall.p_value,
            format!(
                "NRMSE {:.4} over a floor of {:.4} (gap {:.4}; mean square {:.3}× the floor, {})",
                ch.nrmse,
                ch.floor.nrmse_floor,
                ch.gap,
                ch.overall.ratio,
                p_words(ch.overall.p_value)
            ),
        );
    }
    for ph in ch.phases.iter().filter(|p| p.test.significant) {
        push(
            FindingKind::Phase {
                phase: ph.phase.kind,
                t_start_s: ph.phase.t_start_s,
                t_end_s: ph.phase.t_end_s,
            },
            ph.test.ratio,
            ph.test.p_value,
            format!(
                "gap in the {} phase, {:.4}–{:.4} s ({:.3}× the floor, {})",
                ph.phase.kind.words(),
                ph.phase.t_start_s,
                ph.phase.t_end_s,
                ph.test.ratio,
                p_words(ph.test.p_value)
            ),
        );
    }
    for w in ch.windows.iter().filter(|w| w.test.significant) {
        push(
            FindingKind::Window {
                t_start_s: w.t_start_s,
                t_end_s: w.t_end_s,
            },
            w.test.ratio,
            w.test.p_value,
            format!(
                "gap in the window {:.4}–{:.4} s ({:.3}× the floor, {})",
                w.t_start_s,
                w.t_end_s,
                w.test.ratio,
                p_words(w.test.p_value)
            ),
        );
    }
    for bands in [&ch.speed_bands, &ch.current_bands].into_iter().flatten() {
        let (sym, unit) = if bands.variable == "speed" {
            ("|Ω|", "rad/s")
        } else {
            ("|I|", "A")
        };
        let any_moving = bands.bands.iter().any(|b| b.test.significant);
        if let Some(z) = bands.near_zero.filter(|z| z.test.significant) {
            push(
                FindingKind::NearZeroSpeed { only: !any_moving },
                z.test.ratio,
                z.test.p_value,
                format!(
                    "gap {}near Ω = 0 (|Ω| ≤ {:.3} rad/s: {:.3}× the floor, {})",
                    if any_moving { "also " } else { "only " },
                    z.hi,
                    z.test.ratio,
                    p_words(z.test.p_value)
                ),
            );
        }
        for b in bands.bands.iter().filter(|b| b.test.significant) {
            let what = if bands.variable == "speed" {
                FindingKind::SpeedBand { lo: b.lo, hi: b.hi }
            } else {
                FindingKind::CurrentBand { lo: b.lo, hi: b.hi }
            };
            push(
                what,
                b.test.ratio,
                b.test.p_value,
                format!(
                    "gap at {sym} {:.3}–{:.3} {unit} ({:.3}× the floor, {})",
                    b.lo,
                    b.hi,
                    b.test.ratio,
                    p_words(b.test.p_value)
                ),
            );
        }
        if let Some(t) = bands.trend.filter(|t| t.significant) {
            let grows = t.t > 0.0;
            let what = if bands.variable == "speed" {
                FindingKind::SpeedTrend { grows }
            } else {
                FindingKind::CurrentTrend { grows }
            };
            push(
                what,
                t.t,
                t.p_value,
                format!(
                    "gap {} with {sym} (t = {:.1})",
                    if grows { "grows" } else { "falls" },
                    t.t
                ),
            );
        }
    }
    for pk in ch.spectrum.peaks.iter().filter(|p| p.significant) {
        push(
            FindingKind::SpectralPeak {
                frequency_hz: pk.frequency_hz,
            },
            pk.ratio,
            pk.p_value,
            format!(
                "spectral peak at {:.3} Hz ({:.1}× the floor, {})",
                pk.frequency_hz,
                pk.ratio,
                p_words(pk.p_value)
            ),
        );
    }
    if let Some(a) = ch.angle_ripple.filter(|a| a.significant) {
        push(
            FindingKind::AngleRipple {
                periods_per_rev: a.periods_per_rev,
            },
            a.wald,
            a.p_value,
            format!(
                "ripple at {} per revolution (amplitude {:.3e}, {})",
                a.periods_per_rev,
                a.amplitude,
                p_words(a.p_value)
            ),
        );
    }
    if ch.whiteness.significant {
        push(
            FindingKind::NotWhite,
            ch.whiteness.ljung_box_q,
            ch.whiteness.p_value,
            format!(
                "residual not white (Ljung–Box Q = {:.1} on {} lags, {})",
                ch.whiteness.ljung_box_q,
                ch.whiteness.dof,
                p_words(ch.whiteness.p_value)
            ),
        );
    }
    if let Some(x) = ch.cross_correlation.as_ref().filter(|x| x.significant) {
        push(
            FindingKind::InputCorrelation,
            x.max_ratio,
            x.p_value,
            format!(
                "residual correlates with the voltage ({:.1} standard errors, {})",
                x.max_ratio,
                p_words(x.p_value)
            ),
        );
    }
}
