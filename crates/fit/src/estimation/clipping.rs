//! Samples at an ADC rail: a clipped sample says only that the signal was at least the rail,
//! so the fits leave such samples out.

/// Shortest run of identical samples at a channel's extreme that counts as clipping when the
/// rails are not known.
pub const MIN_CLIPPED_RUN: usize = 20;

/// Which samples of `y` sit on an ADC rail.
///
/// With the conditioning range `rails = [lo, hi]` known (e.g. from the record's metadata), a
/// sample is clipped when it is within `tolerance` of either rail — except a rail at exactly 0:
/// a unipolar channel (0–5 V conditioning) reads its zero rail whenever the signal rests at 0
/// (a motor at standstill), which is what the model predicts there, so those samples stay in. Without it, the rails are
/// inferred: a channel is clipped at its largest (smallest) value when that value is not zero
/// and is held exactly for at least [`MIN_CLIPPED_RUN`] consecutive samples while the channel
/// is noisy elsewhere (fewer than half of its other samples repeat the one before) — a noisy
/// signal does not repeat one value twenty times unless something holds it there. A signal
/// resting at exactly 0 cannot be told from one clipped at a rail at 0: give the rails.
pub fn find_clipping(y: &[f64], rails: Option<[f64; 2]>, tolerance: f64) -> Vec<bool> {
    if let Some([lo, hi]) = rails {
        return y
            .iter()
            .map(|&v| (hi != 0.0 && v >= hi - tolerance) || (lo != 0.0 && v <= lo + tolerance))
            .collect();
    }
    let mut mask = vec![false; y.len()];
    if y.len() < 2 * MIN_CLIPPED_RUN {
        return mask;
    }
    let (lo, hi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let mut extreme_runs = Vec::new();
    for rail in [lo, hi] {
        if rail == 0.0 || !rail.is_finite() {
            continue;
        }
        let mut i = 0;
        while i < y.len() {
            if y[i] == rail {
                let start = i;
                while i < y.len() && y[i] == rail {
                    i += 1;
                }
                if i - start >= MIN_CLIPPED_RUN {
                    extreme_runs.push(start..i);
                }
            } else {
                i += 1;
            }
        }
    }
    if extreme_runs.is_empty() {
        return mask;
    }
    for run in &extreme_runs {
        mask[run.clone()].iter_mut().for_each(|m| *m = true);
    }
    let (repeats, others) = (1..y.len())
        .filter(|&i| !mask[i])
        .fold((0usize, 0usize), |(r, n), i| {
            (r + usize::from(y[i] == y[i - 1]), n + 1)
        });
    if others == 0 || 2 * repeats >= others {
        // A quiet (noise-free or coarsely quantised) signal: runs prove nothing.
        return vec![false; y.len()];
    }
    // Every sample at a rail that has a long run is clipped, runs or not.
    let rails: Vec<f64> = extreme_runs.iter().map(|r| y[r.start]).collect();
    y.iter().map(|v| rails.contains(v)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::NoiseRng;

    fn noisy(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = NoiseRng::new(seed);
        (0..n)
            .map(|i| ((i as f64 * 0.01).sin() * 10.0 + rng.normal()).round())
            .collect()
    }

    #[test]
    fn a_clamped_noisy_signal_is_found_and_an_unclamped_one_is_not() {
        let y = noisy(2000, 3);
        assert!(find_clipping(&y, None, 0.0).iter().all(|c| !c));
        let clamped: Vec<f64> = y.iter().map(|v| v.min(7.0)).collect();
        let mask = find_clipping(&clamped, None, 0.0);
        let expected = y.iter().filter(|&&v| v >= 7.0).count();
        assert_eq!(mask.iter().filter(|&&c| c).count(), expected);
        assert!(mask.iter().zip(&clamped).all(|(&c, &v)| c == (v == 7.0)));
    }

    #[test]
    fn quiet_signals_and_zero_rails_are_not_called_clipped() {
        // A noise-free quantised step: long constant runs everywhere.
        let step: Vec<f64> = (0..1000).map(|i| if i < 500 { 0.0 } else { 5.0 }).collect();
        assert!(find_clipping(&step, None, 0.0).iter().all(|c| !c));
        // Noisy signal resting at exactly 0 (a rail at 0 cannot be told from rest).
        let y: Vec<f64> = noisy(2000, 5).iter().map(|v| v.max(0.0)).collect();
        assert!(find_clipping(&y, None, 0.0).iter().all(|c| !c));
        // Nor with the rails given; a non-zero rail is found.
        assert!(find_clipping(&y, Some([0.0, 100.0]), 1e-9)
            .iter()
            .all(|&c| !c));
        let mask = find_clipping(&y, Some([0.0, 5.0]), 1e-9);
        assert_eq!(
            mask.iter().filter(|&&c| c).count(),
            y.iter().filter(|&&v| v >= 5.0).count()
        );
    }
}
