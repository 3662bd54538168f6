//! *Which* effect: the candidates ranked by how much they improve held-out data, each judged by
//! a paired test against the noise, with an ambiguous verdict when the best two cannot be told
//! apart.
//!
//! The caller refits the model with each candidate effect. Two numbers judge it:
//!
//! - on the training data, the likelihood-ratio statistic: the fall of the weighted cost (in
//!   units of the noise variance), divided by the correlation factor `1 + 2 Σ ρₖ²` of the
//!   candidate's residuals (correlated residuals inflate the fall a chance fit achieves),
//!   against χ² with as many degrees of freedom as the effect adds, at `α / m` for `m`
//!   candidates (Bonferroni, so that the chance of naming any effect when none is present stays
//!   below α); a candidate whose fixed shape was picked from the residual among several (a
//!   cogging torque's period count, the best of those the angle search tried) has its p-value
//!   multiplied by their number ([`CandidateScore::searched`]), Bonferroni again;
//! - on the held-out data, cut into blocks, the weighted sum of squared residuals per block
//!   before and after: the improvement `Σ d_b` (`d_b = before_b − after_b`) must exceed the
//!   parameter penalty — a fall on training data alone is not evidence (SPEC section 7); its
//!   one-sided paired t-test over the blocks is reported.
//!
//! Candidates are ranked by their held-out improvement `Σ d_b` less a penalty of 2 per extra
//! parameter (Akaike's, in the same noise-variance units). A significant candidate is
//! *ambiguous* with the top significant one when the paired test of their held-out block
//! errors does not prefer the top one at α. Of the top one and those ambiguous with it, the
//! verdict is the one the training data support most: the largest likelihood-ratio statistic
//! less 2 per extra parameter and `2 ln s` for a shape picked among `s` (a cogging torque's
//! period count), the higher held-out score among equals; the others are named as ambiguous
//! with it. The held-out data cannot tell them apart, and a flexible candidate (a cogging
//! torque at the period count that fits best) takes part of the gap any effect leaves there.

use serde::Serialize;

use crate::estimation::stats::{chi_square_sf, f_sf};

/// One candidate's refit, as the ranking needs it.
#[derive(Debug, Clone, Copy)]
pub struct CandidateScore<'a> {
    /// The effect's name (SPEC section 5).
    pub name: &'a str,
    /// Parameters the effect adds to the model.
    pub extra_params: usize,
    /// Whether the records can determine the effect's parameters at all (e.g. inductance
    /// saturation needs a current that approaches saturation); an untestable candidate is
    /// ranked last and never named.
    pub testable: bool,
    /// The training likelihood-ratio statistic, corrected for the residuals' correlation (module
    /// docs); `None` when it could not be computed.
    pub train_statistic: Option<f64>,
    /// How many alternatives the candidate's fixed shape parameters were picked from by
    /// looking at the residual (1 when none was): its p-value is multiplied by this.
    pub searched: usize,
    /// Held-out weighted squared error per block without the effect \[noise variances\].
    pub heldout_sse_before: &'a [f64],
    /// The same blocks with the effect fitted \[noise variances\].
    pub heldout_sse_after: &'a [f64],
}

/// Settings of [`rank_candidates`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct VerdictSettings {
    /// Family-wise false-alarm probability of naming an effect when none is present.
    pub alpha: f64,
    /// Penalty per extra parameter on the held-out improvement \[noise variances\].
    pub penalty_per_param: f64,
}

impl Default for VerdictSettings {
    /// α = 1 %, Akaike's penalty of 2.
    fn default() -> Self {
        VerdictSettings {
            alpha: 0.01,
            penalty_per_param: 2.0,
        }
    }
}

/// One candidate after the ranking.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ranked {
    /// The effect's name.
    pub name: String,
    /// Held-out improvement `Σ d_b` less the parameter penalty \[noise variances\].
    pub score: f64,
    /// Fraction of the held-out error the effect removes, `Σ d_b / Σ before_b`.
    pub heldout_gain: f64,
    /// p-value of the training likelihood-ratio test (1 when untestable or not computable).
    pub p_value: f64,
    /// One-sided p-value of the paired test of the held-out blocks.
    pub heldout_p_value: f64,
    /// Whether the improvement is significant at `α / m`.
    pub significant: bool,
    /// Whether the records can determine the effect.
    pub testable: bool,
}

/// The ranking and the verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    /// Every candidate, best first.
    pub ranked: Vec<Ranked>,
    /// The top significant candidate; `None` when nothing is significant (the verdict `none`).
    pub verdict: Option<String>,
    /// Significant candidates the data cannot tell from the verdict.
    pub ambiguous_with: Vec<String>,
    /// The per-candidate significance level used, `α / m`.
    pub level: f64,
}

/// One-sided paired t-test that `a_b − b_b` is positive on average: the p-value, 1 when fewer
/// than two blocks or no spread.
fn paired_p(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let n = d.len();
    if n < 2 {
        return 1.0;
    }
    let mean = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    if !(var > 0.0 && var.is_finite()) {
        return if mean > 0.0 { 0.0 } else { 1.0 };
    }
    let t = mean / (var / n as f64).sqrt();
    // P(T > t) = ½ P(F(1, ν) > t²) for t > 0.
    let half = 0.5 * f_sf(t * t, 1.0, (n - 1) as f64);
    if t > 0.0 {
        half
    } else {
        1.0 - half
    }
}

/// The training data's support for `c`: its likelihood-ratio statistic less `penalty` per
/// extra parameter and `2 ln s` for a shape picked among `s` ([`CandidateScore::searched`]),
/// Akaike's criterion as the screening orders candidates; −∞ without a statistic.
pub(crate) fn training_support(c: &CandidateScore<'_>, penalty: f64) -> f64 {
    c.train_statistic
        .filter(|x| x.is_finite())
        .map_or(f64::NEG_INFINITY, |x| {
            x - penalty * c.extra_params as f64 - 2.0 * (c.searched.max(1) as f64).ln()
        })
}

/// Ranks `candidates` and names the verdict (module docs).
pub fn rank_candidates(candidates: &[CandidateScore<'_>], settings: &VerdictSettings) -> Verdict {
    let m = candidates.iter().filter(|c| c.testable).count().max(1);
    let level = settings.alpha / m as f64;
    let mut ranked: Vec<(Ranked, usize)> = candidates
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let aligned = c.heldout_sse_before.len() == c.heldout_sse_after.len();
            let before: f64 = c.heldout_sse_before.iter().sum();
            let after: f64 = c.heldout_sse_after.iter().sum();
            let gain = before - after;
            let heldout_p_value = if c.testable && aligned {
                paired_p(c.heldout_sse_before, c.heldout_sse_after)
            } else {
                1.0
            };
            let p_value = match c.train_statistic {
                Some(x) if c.testable && x.is_finite() => {
                    (chi_square_sf(x, c.extra_params.max(1) as f64) * c.searched.max(1) as f64)
                        .min(1.0)
                }
                _ => 1.0,
            };
            let score = gain - settings.penalty_per_param * c.extra_params as f64;
            (
                Ranked {
                    name: c.name.to_string(),
                    score: if c.testable && aligned {
                        score
                    } else {
                        f64::NEG_INFINITY
                    },
                    heldout_gain: if before > 0.0 { gain / before } else { 0.0 },
                    p_value,
                    heldout_p_value,
                    significant: c.testable && aligned && score > 0.0 && p_value < level,
                    testable: c.testable,
                },
                k,
            )
        })
        .collect();
    ranked.sort_by(|a, b| b.0.score.total_cmp(&a.0.score));
    let significant: Vec<&(Ranked, usize)> = ranked.iter().filter(|r| r.0.significant).collect();
    // The top candidate and those it does not beat on the held-out blocks: the data cannot
    // tell them apart.
    let alike: Vec<&(Ranked, usize)> = match significant.first() {
        Some(first) => {
            let top = first.1;
            std::iter::once(*first)
                .chain(significant[1..].iter().copied().filter(|(_, k)| {
                    paired_p(
                        candidates[*k].heldout_sse_after,
                        candidates[top].heldout_sse_after,
                    ) >= settings.alpha
                }))
                .collect()
        }
        None => Vec::new(),
    };
    // Of those, the verdict is the one the training data support most, by its penalised
    // likelihood ratio; the best held-out score among equals.
    let mut strongest: Option<(&(Ranked, usize), f64)> = None;
    for r in &alike {
        let support = training_support(&candidates[r.1], settings.penalty_per_param);
        if strongest.is_none_or(|(_, best)| support > best) {
            strongest = Some((r, support));
        }
    }
    let verdict = strongest.map(|(r, _)| r.0.name.clone());
    let ambiguous_with = alike
        .iter()
        .map(|r| r.0.name.clone())
        .filter(|name| Some(name) != verdict.as_ref())
        .collect();
    Verdict {
        ranked: ranked.into_iter().map(|(r, _)| r).collect(),
        verdict,
        ambiguous_with,
        level,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::NoiseRng;

    /// Blocks of 200 unit-variance residuals: their sum of squares, with `shift` added to every
    /// residual (a gap the model leaves).
    fn blocks(rng: &mut NoiseRng, shift: f64, count: usize) -> Vec<f64> {
        (0..count)
            .map(|_| (0..200).map(|_| (rng.normal() + shift).powi(2)).sum())
            .collect()
    }

    fn candidate<'a>(
        name: &'a str,
        train_statistic: f64,
        before: &'a [f64],
        after: &'a [f64],
    ) -> CandidateScore<'a> {
        CandidateScore {
            name,
            extra_params: 1,
            testable: true,
            train_statistic: Some(train_statistic),
            searched: 1,
            heldout_sse_before: before,
            heldout_sse_after: after,
        }
    }

    #[test]
    fn a_clear_winner_is_named_and_a_look_alike_is_ambiguous_with_it() {
        let mut rng = NoiseRng::new(1);
        let before = blocks(&mut rng, 0.5, 20);
        // The right effect removes the gap; a weaker one removes part of it; a useless one
        // falls on the training data by chance only.
        let right = blocks(&mut rng, 0.0, 20);
        let partial = blocks(&mut rng, 0.42, 20);
        let useless = blocks(&mut rng, 0.5, 20);
        let cands = [
            candidate("partial", 300.0, &before, &partial),
            candidate("right", 1000.0, &before, &right),
            candidate("useless", 1.5, &before, &useless),
        ];
        let v = rank_candidates(&cands, &VerdictSettings::default());
        assert_eq!(v.verdict.as_deref(), Some("right"));
        assert_eq!(v.ranked[0].name, "right");
        assert!(
            !v.ranked
                .iter()
                .find(|r| r.name == "useless")
                .unwrap()
                .significant
        );
        // "partial" is significant but clearly worse than "right" on held-out data.
        assert!(v.ambiguous_with.is_empty(), "{v:?}");
        // Two candidates explaining the data alike are ambiguous.
        let twin = blocks(&mut rng, 0.0, 20);
        let cands = [cands[1], candidate("twin", 990.0, &before, &twin)];
        let v = rank_candidates(&cands, &VerdictSettings::default());
        assert!(v.verdict.is_some());
        assert_eq!(v.ambiguous_with.len(), 1, "{v:?}");
    }

    #[test]
    fn of_two_candidates_the_held_out_data_cannot_tell_apart_the_training_data_pick_one() {
        let mut rng = NoiseRng::new(5);
        let before = blocks(&mut rng, 0.5, 20);
        // A flexible candidate (two parameters and a shape searched among 40) scores better on
        // held-out data than a one-parameter one (by 10 noise variances, 8 after the
        // penalties), by less than the paired test can tell from the blocks' spread (±3 a
        // block); on the training data it explains less.
        let flexible = blocks(&mut rng, 0.0, 20);
        let simple: Vec<f64> = flexible
            .iter()
            .enumerate()
            .map(|(b, x)| x + 0.5 + if b % 2 == 0 { 3.0 } else { -3.0 })
            .collect();
        let flexible_candidate = CandidateScore {
            extra_params: 2,
            searched: 40,
            ..candidate("flexible", 300.0, &before, &flexible)
        };
        let cands = [
            flexible_candidate,
            candidate("simple", 1000.0, &before, &simple),
        ];
        let v = rank_candidates(&cands, &VerdictSettings::default());
        assert_eq!(v.ranked[0].name, "flexible", "{v:?}");
        assert_eq!(v.verdict.as_deref(), Some("simple"), "{v:?}");
        assert_eq!(v.ambiguous_with, ["flexible"], "{v:?}");
        // With the training data behind the flexible one (its 300 less 4 and 2 ln 40 against
        // the simple one's 100 less 2), it is named.
        let cands = [
            flexible_candidate,
            candidate("simple", 100.0, &before, &simple),
        ];
        let v = rank_candidates(&cands, &VerdictSettings::default());
        assert_eq!(v.verdict.as_deref(), Some("flexible"), "{v:?}");
        assert_eq!(v.ambiguous_with, ["simple"], "{v:?}");
        // Clearly better on held-out data, the flexible one is named alone.
        let worse = blocks(&mut rng, 0.3, 20);
        let cands = [
            flexible_candidate,
            candidate("simple", 1000.0, &before, &worse),
        ];
        let v = rank_candidates(&cands, &VerdictSettings::default());
        assert_eq!(v.verdict.as_deref(), Some("flexible"), "{v:?}");
        assert!(v.ambiguous_with.is_empty(), "{v:?}");
    }

    #[test]
    fn a_fall_on_training_data_alone_names_nothing() {
        let mut rng = NoiseRng::new(3);
        let before = blocks(&mut rng, 0.0, 20);
        let worse = blocks(&mut rng, 0.05, 20);
        let v = rank_candidates(
            &[candidate("overfit", 500.0, &before, &worse)],
            &VerdictSettings::default(),
        );
        assert_eq!(v.verdict, None, "{v:?}");
    }

    #[test]
    fn nothing_is_named_on_noise_and_untestable_candidates_never_are() {
        // Seven candidates that change nothing: the training fall of a one-parameter nested
        // fit is χ²(1), the held-out blocks change by noise alone. Over 200 trials the verdict
        // is `none` in at least 97 % (α = 1 % family-wise; the bound leaves room for chance).
        let mut named = 0;
        let mut rng = NoiseRng::new(7);
        for _ in 0..200 {
            let before = blocks(&mut rng, 0.0, 16);
            let afters: Vec<Vec<f64>> = (0..7).map(|_| blocks(&mut rng, 0.0, 16)).collect();
            let stats: Vec<f64> = (0..7).map(|_| rng.normal().powi(2)).collect();
            let cands: Vec<CandidateScore<'_>> = afters
                .iter()
                .zip(&stats)
                .map(|(a, x)| candidate("x", *x, &before, a))
                .collect();
            if rank_candidates(&cands, &VerdictSettings::default())
                .verdict
                .is_some()
            {
                named += 1;
            }
        }
        assert!(
            named <= 6,
            "{named} of 200 noise-only trials named an effect"
        );
        let mut rng = NoiseRng::new(8);
        let before = blocks(&mut rng, 0.5, 20);
        let after = blocks(&mut rng, 0.0, 20);
        let v = rank_candidates(
            &[CandidateScore {
                testable: false,
                ..candidate("inductance_saturation", 1000.0, &before, &after)
            }],
            &VerdictSettings::default(),
        );
        assert_eq!(v.verdict, None);
        assert!(!v.ranked[0].testable);
    }
}
