//! The numbers the paper prints (Sec. 4.1), as text exactly as printed, to compare against.

/// Table 1: derived constants of the simulated motor (key, printed value, unit).
/// The table prints ωa = 0.3381: a transposition typo, Table 3 and Eq. (22) give 0.3881.
pub const TABLE_1: [(&str, &str, &str); 11] = [
    ("KE", "1.3333", "A/V"),
    ("Ks", "4", "A/(N·m)"),
    ("wn", "0.3536", "rad/s"),
    ("zeta", "1.4849", "-"),
    ("sigma", "0.5250", "1/s"),
    ("wa", "0.3381", "rad/s"),
    ("tau_m", "20", "s"),
    ("tau_e", "1", "s"),
    ("alpha", "4.9896", "-"),
    ("gamma", "0.9110", "-"),
    ("i0", "0.2", "A"),
];

/// Table 2: simulated values at t = 50 s (test, quantity, printed value, unit).
pub const TABLE_2: [(&str, &str, &str, &str); 4] = [
    ("Em = 40 V", "Im", "53.57", "A"),
    ("Em = 40 V", "Wm", "159.6", "rad/s"),
    ("Eb = 2.5 V", "Ib", "3.46", "A"),
    ("Eb = 2.5 V", "Wb", "9.748", "rad/s"),
];

/// The paper's high- and low-voltage step tests (Sec. 4.1): Em, Eb [V], length [s].
pub const HIGH_VOLTAGE_V: f64 = 40.0;
/// See [`HIGH_VOLTAGE_V`].
pub const LOW_VOLTAGE_V: f64 = 2.5;
/// See [`HIGH_VOLTAGE_V`].
pub const TEST_LENGTH_S: f64 = 50.0;
/// The logger's sample rate (Sec. 3) [Hz].
pub const LOGGER_RATE_HZ: f64 = 1000.0;

/// Decimals printed in `text` (0 for an integer).
pub fn decimals(text: &str) -> usize {
    text.find('.').map_or(0, |dot| text.len() - dot - 1)
}

/// `value` rounded to the decimals of `printed`, and whether it equals `printed`.
pub fn compare(value: f64, printed: &str) -> (String, bool) {
    let ours = format!("{value:.*}", decimals(printed));
    let same = ours == printed;
    (ours, same)
}
