//! The speed a record gives: from the encoder angle where there is one, else the tachometer.

use motor_model::{difference_over, mean_period};

/// Shortest time base \[s\] of a speed taken from the encoder: at 100 kHz a 2000-count encoder
/// moves half a count per sample at 160 rad/s, and the central difference of one sample reads
/// 0 or 157 rad/s.
pub const ENCODER_SPEED_BASE_S: f64 = 1e-3;

/// Speed \[rad/s\] from the encoder angle `theta` \[rad\] sampled at `t` \[s\], by differences
/// over ±m samples, m the fewest that span [`ENCODER_SPEED_BASE_S`] (m = 1, the central
/// difference, at 1 kHz and below); one-sided near the ends. As long as the shorter of `t` and
/// `theta`.
pub fn encoder_speed(t: &[f64], theta: &[f64]) -> Vec<f64> {
    let n = t.len().min(theta.len());
    let dt = mean_period(&t[..n]);
    let m = if dt > 0.0 {
        ((0.5 * ENCODER_SPEED_BASE_S / dt).ceil() as usize).max(1)
    } else {
        1
    };
    difference_over(t, theta, m)
}

/// The speed \[rad/s\] of a record sampled at `t` \[s\]: from the encoder angle `position`
/// \[rad\] where there is one ([`encoder_speed`]) — a speed column beside it may be a
/// one-sample difference of the same encoder — else the tachometer column `speed`; `None`
/// when the record has neither.
pub fn record_speed(
    t: &[f64],
    speed: Option<&[f64]>,
    position: Option<&[f64]>,
) -> Option<Vec<f64>> {
    match (speed, position) {
        (_, Some(p)) => Some(encoder_speed(t, p)),
        (Some(s), None) => Some(s.to_vec()),
        (None, None) => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motor_model::central_difference;

    #[test]
    fn encoder_speed_of_a_ramp_is_its_slope_at_any_rate() {
        for rate in [100.0, 1e3, 1e5] {
            let t: Vec<f64> = (0..2000).map(|i| i as f64 / rate).collect();
            let theta: Vec<f64> = t.iter().map(|t| 3.0 * t + 1.0).collect();
            let w = encoder_speed(&t, &theta);
            assert_eq!(w.len(), t.len());
            for x in w {
                assert!((x - 3.0).abs() < 1e-6, "{rate} Hz: {x}");
            }
        }
    }

    #[test]
    fn wide_base_smooths_a_half_count_per_sample() {
        // 2000 counts/rev at 100 kHz and 160 rad/s: about half a count per sample.
        let q = std::f64::consts::TAU / 2000.0;
        let t: Vec<f64> = (0..20_000).map(|i| i as f64 * 1e-5).collect();
        let theta: Vec<f64> = t.iter().map(|t| (160.0 * t / q).floor() * q).collect();
        let wide = encoder_speed(&t, &theta);
        let narrow = central_difference(&t, &theta);
        let spread = |w: &[f64]| {
            w[1000..19_000]
                .iter()
                .fold(0.0_f64, |m, x| m.max((x - 160.0).abs()))
        };
        assert!(spread(&wide) < 10.0, "{}", spread(&wide));
        assert!(spread(&narrow) > 50.0, "{}", spread(&narrow));
    }

    #[test]
    fn encoder_first_then_tachometer() {
        let t = [0.0, 1.0, 2.0];
        let tacho = [5.0, 5.0, 5.0];
        let angle = [0.0, 2.0, 4.0];
        assert_eq!(
            record_speed(&t, Some(&tacho), Some(&angle)),
            Some(vec![2.0, 2.0, 2.0])
        );
        assert_eq!(record_speed(&t, Some(&tacho), None), Some(tacho.to_vec()));
        assert_eq!(record_speed(&t, None, None), None);
    }

    #[test]
    fn short_or_mismatched_channels_do_not_panic() {
        assert!(encoder_speed(&[], &[]).is_empty());
        assert_eq!(encoder_speed(&[0.0], &[1.0]), vec![0.0]);
        let t: Vec<f64> = (0..10).map(|i| i as f64 * 1e-5).collect();
        assert_eq!(encoder_speed(&t, &[0.0, 1.0, 2.0]).len(), 3);
    }
}
