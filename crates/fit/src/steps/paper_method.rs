//! The paper's identification method (Sec. 2.2 and 2.4), equation by equation.
//!
//! The high-voltage test gives α, σ, ωa by the fit of (33) ([`crate::fit_33`]); from them and
//! the steady values `Irm`, `Ωrm`, Eqs. (34)–(44) give every parameter but Ts
//! ([`from_high_voltage`]); the low-voltage test adds Ts by (46)–(48) and refines the static
//! gains by (49)–(51) ([`with_low_voltage`]). Eq. (37) is used in its corrected form (erratum
//! E8 in `docs/errata.md`).

use crate::error::FitError;
use crate::steps::model33::Params33;

/// Everything Eqs. (34)–(44) compute from the high-voltage test (the paper's Table 4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HighVoltageResult {
    /// Eq. (34) `KE,c = Irm/Em` \[A/V\].
    pub k_e: f64,
    /// Eq. (35) `ωn,c = ωa √((σ/ωa)² − 1)` \[rad/s\].
    pub omega_n: f64,
    /// Eq. (36) `ζc = 1/√(1 − (ωa/σ)²)` [-].
    pub zeta: f64,
    /// Eq. (37), corrected: `τm,c = (σ/ωa + √(α² + 1)) / (ωa ((σ/ωa)² − 1))` \[s\].
    pub tau_m: f64,
    /// Eq. (38) `Lc = 1/(KE τm ωn²)` \[H\].
    pub l_henry: f64,
    /// Eq. (39) `Rc = (2ζ/(ωn KE) − L)/τm` \[Ω\].
    pub r_ohm: f64,
    /// Eq. (41) `kc = Irm (1 − R KE)/(KE Ωrm)` \[N·m/A\].
    pub k_nm_per_a: f64,
    /// Eq. (42) `fc = k Irm/Ωrm` \[N·m·s/rad\].
    pub f_nms_per_rad: f64,
    /// Eq. (43) `Jc = τm f` \[kg·m²\].
    pub j_kgm2: f64,
    /// Eq. (44) `Ks,c = k/(R f + k²)` \[A/(N·m)\].
    pub k_s: f64,
}

fn domain(equation: &'static str, reason: String) -> FitError {
    FitError::MethodDomain { equation, reason }
}

/// Eqs. (34)–(44) from the (33) fit and the high-voltage test's `Em` \[V\], `Irm` \[A\] and
/// `Ωrm` \[rad/s\] (the paper uses the values at the end of the record, Table 2).
pub fn from_high_voltage(
    fit: Params33,
    e_m_volt: f64,
    i_rm_a: f64,
    omega_rm_rad_s: f64,
) -> Result<HighVoltageResult, FitError> {
    let Params33 {
        alpha,
        sigma,
        omega_a,
    } = fit;
    all_positive(
        "Eqs. (34)-(44)",
        &[
            ("Em", e_m_volt),
            ("Irm", i_rm_a),
            ("Ωrm", omega_rm_rad_s),
            ("α", alpha),
            ("σ", sigma),
            ("ωa", omega_a),
        ],
        "the method needs it finite and positive",
    )?;
    let ratio = sigma / omega_a;
    if ratio <= 1.0 {
        return Err(domain(
            "Eqs. (35)-(37)",
            format!("σ = {sigma} ≤ ωa = {omega_a}: the fitted response is not overdamped"),
        ));
    }
    let k_e = i_rm_a / e_m_volt; // (34)
    let omega_n = omega_a * (ratio * ratio - 1.0).sqrt(); // (35)
    let zeta = 1.0 / (1.0 - (omega_a / sigma).powi(2)).sqrt(); // (36)
    let tau_m = (ratio + (alpha * alpha + 1.0).sqrt()) / (omega_a * (ratio * ratio - 1.0)); // (37) corrected
    let l_henry = 1.0 / (k_e * tau_m * omega_n * omega_n); // (38)
    let r_ohm = (2.0 * zeta / (omega_n * k_e) - l_henry) / tau_m; // (39)
    let k_nm_per_a = i_rm_a * (1.0 - r_ohm * k_e) / (k_e * omega_rm_rad_s); // (41)
    let f_nms_per_rad = i_rm_a / omega_rm_rad_s * k_nm_per_a; // (42)
    let j_kgm2 = tau_m * f_nms_per_rad; // (43)
    let k_s = k_nm_per_a / (r_ohm * f_nms_per_rad + k_nm_per_a * k_nm_per_a); // (44)
    let out = HighVoltageResult {
        k_e,
        omega_n,
        zeta,
        tau_m,
        l_henry,
        r_ohm,
        k_nm_per_a,
        f_nms_per_rad,
        j_kgm2,
        k_s,
    };
    all_positive(
        "Eqs. (38)-(44)",
        &[
            ("L (38)", l_henry),
            ("R (39)", r_ohm),
            ("k (41)", k_nm_per_a),
            ("f (42)", f_nms_per_rad),
        ],
        "the high-voltage test does not determine a physical motor (is the step high enough, Eq. (31)?)",
    )?;
    Ok(out)
}

/// The first of the named `values` that is not finite and positive, as the domain error of
/// `equations` with `why` after its name and value.
fn all_positive(
    equations: &'static str,
    values: &[(&str, f64)],
    why: &str,
) -> Result<(), FitError> {
    match values.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
        Some((name, v)) => Err(domain(equations, format!("{name} = {v}: {why}"))),
        None => Ok(()),
    }
}

/// Eq. (37) exactly as printed: `(σ/ωa + √(α²+1)) / (ωa √((σ/ωa)² − 1))` \[s\]. Kept to show
/// that it contradicts the paper's own Table 4 (erratum E8).
pub fn tau_m_as_printed_37(fit: Params33) -> f64 {
    let ratio = fit.sigma / fit.omega_a;
    (ratio + (fit.alpha * fit.alpha + 1.0).sqrt()) / (fit.omega_a * (ratio * ratio - 1.0).sqrt())
}

/// The apparent-resistance coefficients and Ts from the two tests, Eqs. (46)–(48).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoTestFriction {
    /// Eq. (47) `a` \[Ω\].
    pub a_ohm: f64,
    /// Eq. (47) `b` \[Ω·A\].
    pub b_ohm_a: f64,
    /// Eq. (48) `Ts,c = k b/a` \[N·m\].
    pub ts_nm: f64,
    /// Eq. (50) refined `KE` \[A/V\].
    pub k_e: f64,
    /// Eq. (51) refined `Ks` \[A/(N·m)\].
    pub k_s: f64,
}

/// Eqs. (46)–(51): Ts from the high- and low-voltage steady states (`Em`, `Irm`, `Eb`, `Irb`;
/// V and A) with `Rc` \[Ω\] and `kc` \[N·m/A\] of the high-voltage test, then the refined gains.
pub fn with_low_voltage(
    r_c_ohm: f64,
    k_c: f64,
    e_m_volt: f64,
    i_rm_a: f64,
    e_b_volt: f64,
    i_rb_a: f64,
) -> Result<TwoTestFriction, FitError> {
    if !(e_b_volt.is_finite() && i_rb_a.is_finite() && e_b_volt > 0.0 && i_rb_a > 0.0) {
        return Err(domain(
            "Eqs. (46)-(48)",
            format!("Eb = {e_b_volt} V, Irb = {i_rb_a} A: both must be finite and positive"),
        ));
    }
    if (i_rm_a - i_rb_a).abs() <= f64::EPSILON * i_rm_a || (e_m_volt - e_b_volt).abs() <= 0.0 {
        return Err(domain(
            "Eqs. (47), (50)",
            format!("the two tests must differ: Em = {e_m_volt} V, Eb = {e_b_volt} V, Irm = {i_rm_a} A, Irb = {i_rb_a} A"),
        ));
    }
    let dr_m = e_m_volt / i_rm_a - r_c_ohm; // (46)
    let dr_b = e_b_volt / i_rb_a - r_c_ohm;
    let a_ohm = (dr_b * i_rb_a - dr_m * i_rm_a) / (i_rb_a - i_rm_a); // (47)
    let b_ohm_a = i_rb_a * i_rm_a * (dr_b - dr_m) / (i_rb_a - i_rm_a);
    // (48), in the measured values:
    let ts_nm = k_c * (e_b_volt * i_rm_a - e_m_volt * i_rb_a)
        / (r_c_ohm * (i_rm_a - i_rb_a) + e_b_volt - e_m_volt);
    if !(ts_nm.is_finite() && ts_nm > 0.0) {
        return Err(domain(
            "Eq. (48)",
            format!("Ts = {ts_nm} N·m: the low-voltage test shows no Coulomb friction (is Eb low enough, Eq. (45)?)"),
        ));
    }
    let k_e = (i_rm_a - i_rb_a) / (e_m_volt - e_b_volt); // (50)
    let k_s = (e_m_volt * i_rb_a - e_b_volt * i_rm_a) / (ts_nm * (e_m_volt - e_b_volt)); // (51)
    Ok(TwoTestFriction {
        a_ohm,
        b_ohm_a,
        ts_nm,
        k_e,
        k_s,
    })
}

/// Eq. (45): the order of magnitude of a low test voltage, `½ (R/k + k/f)` \[V per N·m … \]
/// times nothing — the paper's empirical starting point `Eb ≈ ½ (Rc/kc + kc/fc)` \[V\].
pub fn suggested_low_voltage_45(r_c: f64, k_c: f64, f_c: f64) -> f64 {
    0.5 * (r_c / k_c + k_c / f_c)
}

/// The steady values the paper's method reads off the two step records (Table 2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyValues {
    /// `Irm`: steady current of the high-voltage test \[A\].
    pub i_rm_a: f64,
    /// `Ωrm`: steady speed of the high-voltage test \[rad/s\] (NaN without a speed column).
    pub omega_rm_rad_s: f64,
    /// `Irb`: steady current of the low-voltage test \[A\].
    pub i_rb_a: f64,
}

/// The paper's whole method on a high- and a low-voltage step test.
#[derive(Debug, Clone, PartialEq)]
pub struct PaperIdentification {
    /// Fit of Eq. (33) (Table 3).
    pub fit_33: crate::steps::model33::Fit33,
    /// Eqs. (34)–(44) (Table 4).
    pub high: HighVoltageResult,
    /// Eqs. (46)–(51): Ts and refined gains.
    pub low: TwoTestFriction,
    /// The motor: R, L, k, f, J of (38)–(43) with Ts of (48).
    pub params: motor_model::MotorParams,
    /// `Irm`, `Ωrm`, `Irb` used: the last samples of the records, as the paper took its Table 2
    /// at t = 50 s.
    pub steady_values: SteadyValues,
    /// The tachometer check (C.8) of ωn and ζ from the speed, or why it could not be made.
    pub speed_check: Result<SpeedCheck, FitError>,
}

/// Largest ratio between the (C.8) check's ωn or ζ and the current fit's (Eqs. (35), (36))
/// within which the speed bears the result out. The paper's motor agrees within 2 %
/// (ωn 0.3580 against 0.3552 rad/s, ζ 1.515 against 1.468, logger records); a factor of two is
/// no agreement (a small servo at 2 kHz: ωn 350.5 against 1841 rad/s).
pub const C8_MAX_RATIO: f64 = 2.0;

impl PaperIdentification {
    /// Why the high-voltage speed contradicts the result, if its (C.8) check gives ωn or ζ more
    /// than [`C8_MAX_RATIO`] away from the current fit's; `None` when they agree or the check
    /// was not made.
    pub fn speed_check_contradiction(&self) -> Option<String> {
        let c = self.speed_check.as_ref().ok()?;
        let ratio = |a: f64, b: f64| (a / b).max(b / a);
        let off = |a: f64, b: f64| ratio(a, b).is_nan() || ratio(a, b) > C8_MAX_RATIO;
        (off(c.omega_n, self.high.omega_n) || off(c.zeta, self.high.zeta)).then(|| {
            format!(
                "the (C.8) speed check contradicts the current's fit (wn {:.4} against {:.4} rad/s, zeta {:.4} against {:.4}): the speed does not bear the paper method's result out",
                c.omega_n, self.high.omega_n, c.zeta, self.high.zeta
            )
        })
    }
}

/// Samples averaged per block by [`undershoot`].
const UNDERSHOOT_BLOCK: usize = 16;
/// Standard errors of a block mean by which it must fall below the final level to count as an
/// undershoot ([`undershoot`]): the lowest of thousands of block means of a settled current
/// lies some 3.5 below.
const UNDERSHOOT_SIGMAS: f64 = 6.0;
/// Smallest undershoot, as a fraction of the final current, that counts ([`undershoot`]).
const MIN_UNDERSHOOT: f64 = 0.01;

/// The lowest mean of [`UNDERSHOOT_BLOCK`] samples of the step current `current` after its
/// peak, as a fraction of its final level (the mean of its last tenth), when it lies below
/// that level by more than [`UNDERSHOOT_SIGMAS`] standard errors (`noise` the current's noise
/// level) and [`MIN_UNDERSHOOT`] of it: an overdamped motor's current (Eq. (33)) decays to its
/// final value from above, an underdamped one's swings below it for half a period.
fn undershoot(current: &[f64], noise: f64) -> Option<f64> {
    let peak = current
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)?;
    let end = crate::estimation::checks::tail_mean(current);
    let low = current[peak..]
        .chunks_exact(UNDERSHOOT_BLOCK)
        .map(|b| b.iter().sum::<f64>() / UNDERSHOOT_BLOCK as f64)
        .fold(f64::INFINITY, f64::min);
    let bound =
        (UNDERSHOOT_SIGMAS * noise / (UNDERSHOOT_BLOCK as f64).sqrt()).max(MIN_UNDERSHOOT * end);
    (end > 0.0 && end - low > bound).then_some(low / end)
}

/// Runs the paper's method: normalise the high-voltage current by its last sample, fit (33)
/// (from the paper's start β0 = [1; 1; 1], Appendix A), apply (34)–(44) with the last speed
/// sample as Ωrm, then (46)–(51) with the low-voltage test's last current sample, and finally
/// the tachometer check (C.8) ([`speed_check_c8`]).
pub fn identify_paper(
    high: &crate::estimation::records::StepTest<'_>,
    low: &crate::estimation::records::StepTest<'_>,
    settings: crate::estimation::lm::LmSettings,
) -> Result<PaperIdentification, FitError> {
    let bad = |series: &str, reason: String| FitError::BadData {
        series: series.into(),
        reason,
    };
    crate::estimation::checks::check_step_test("high-voltage test", high)?;
    crate::estimation::checks::check_step_test("low-voltage test", low)?;
    let (Some(&i_rm), Some(&i_rb)) = (high.current.last(), low.current.last()) else {
        return Err(bad("step tests", "a record has no samples".into()));
    };
    let speed = high.speed.ok_or_else(|| {
        bad(
            "high-voltage speed",
            "the paper's method needs the steady speed Ωrm (Eq. (40)): give a speed or position channel".into(),
        )
    })?;
    let omega_rm = speed.last().copied().unwrap_or(f64::NAN);
    crate::estimation::checks::check_settled(
        "high-voltage test",
        "current",
        high.current,
        high.dt,
    )?;
    crate::estimation::checks::check_settled("high-voltage test", "speed", speed, high.dt)?;
    crate::estimation::checks::check_settled("low-voltage test", "current", low.current, low.dt)?;
    if !(i_rm.is_finite() && i_rm > 0.0) {
        return Err(bad(
            "high-voltage current",
            format!("final current {i_rm} A: expected a positive steady current"),
        ));
    }
    let y: Vec<f64> = high.current.iter().map(|c| c / i_rm).collect();
    if let Some(low) = undershoot(
        high.current,
        crate::estimation::records::noise_std(high.current),
    ) {
        return Err(domain(
            "Eq. (33) fit",
            format!(
                "after its peak the high-voltage current falls to {:.3} times its final value: the response \
                 is underdamped (ζ < 1), and Eq. (33), two real exponentials, cannot follow it — use the full \
                 method (--method full)",
                low
            ),
        ));
    }
    let record = crate::steps::model33::Record33 {
        t_first: high.t_first,
        dt: high.dt,
        normalized_current: &y,
    };
    let start = Params33 {
        alpha: 1.0,
        sigma: 1.0,
        omega_a: 1.0,
    };
    let fit = crate::steps::model33::fit_33(&record, start, settings)?;
    if !fit.report.termination.converged() {
        return Err(domain(
            "Eq. (33) fit",
            format!(
                "the fit did not converge ({}; residual ½‖r‖² = {:.3e} after {} iterations)",
                fit.report.termination.text(),
                fit.report.normal.cost,
                fit.report.iterations
            ),
        ));
    }
    let hv = from_high_voltage(fit.params, high.volts, i_rm, omega_rm)?;
    let lv = with_low_voltage(hv.r_ohm, hv.k_nm_per_a, high.volts, i_rm, low.volts, i_rb)?;
    let params = motor_model::MotorParams::new(
        hv.r_ohm,
        hv.l_henry,
        hv.k_nm_per_a,
        hv.f_nms_per_rad,
        hv.j_kgm2,
        lv.ts_nm,
    )
    .map_err(FitError::model("Eqs. (38)-(48)"))?;
    // The method reads every parameter off one fit and the records' ends: on records it does
    // not suit (a motor whose time constants are a few samples) it can return a motor the
    // records rule out (k = 1.4e-12 N·m/A, J = 8e-15 kg·m² for a 0.05 N·m/A servo) — judged
    // as the full fit's result is.
    let mut facts = crate::estimation::plausibility::RecordFacts::default();
    for t in [high, low] {
        let speed = t
            .speed
            .map(|s| (crate::estimation::records::Channel::Speed, s));
        facts.add(
            t.dt,
            t.current.len(),
            std::iter::once((crate::estimation::records::Channel::Current, t.current)).chain(speed),
        );
    }
    if let Some(refusal) = crate::estimation::plausibility::implausible_motor(&params, &facts) {
        return Err(domain(
            "Eqs. (38)-(48)",
            format!("the result is {refusal} — use the full method (--method full)"),
        ));
    }
    // The record shows the rotor turning: a motor that would start only after the record ends
    // (or never) is not its motor.
    let end_s = high.t_first + high.dt * high.current.len() as f64;
    let t0 = motor_model::breakaway_time(&params, high.volts);
    if high
        .speed
        .is_some_and(crate::estimation::plausibility::shows_motion)
        && !t0.is_some_and(|t| t < end_s)
    {
        return Err(domain(
            "Eqs. (38)-(48)",
            format!(
                "the identified motor (R = {:.4e} Ω, k = {:.4e} N·m/A, Ts = {:.4e} N·m) would break away at {} at {:.4} V, yet the rotor turns in the {end_s:.4} s record: the method does not suit these records — use the full method (--method full)",
                params.r_ohm,
                params.k_nm_per_a,
                params.ts_nm,
                t0.map_or("no time".to_string(), |t| format!("t0 = {t:.4} s")),
                high.volts
            ),
        ));
    }
    let speed_check = t0
        .ok_or_else(|| {
            domain(
                "Eq. (C.8)",
                "the identified motor does not break away at the high voltage".into(),
            )
        })
        .and_then(|t0| speed_check_c8(high, t0, fit.params, settings));
    Ok(PaperIdentification {
        fit_33: fit,
        high: hv,
        low: lv,
        params,
        steady_values: SteadyValues {
            i_rm_a: i_rm,
            omega_rm_rad_s: omega_rm,
            i_rb_a: i_rb,
        },
        speed_check,
    })
}

/// The paper's tachometer check (Sec. 2.4, Appendix C): (C.8) fitted to the normalised
/// high-voltage speed gives ωn and ζ independently of the current.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedCheck {
    /// ωn \[rad/s\] from the speed record.
    pub omega_n: f64,
    /// ζ [-] from the speed record.
    pub zeta: f64,
    /// RMS of `Ω/Ωrm − (C.8)` at the fit [-].
    pub rms: f64,
    /// Why the (C.8) fit stopped.
    pub termination: crate::estimation::lm::Termination,
}

/// Samples between exact evaluations of the (C.8) fit's exponentials.
const C8_REANCHOR: usize = 64;

/// `Ω/Ωr` samples after breakaway for the (C.8) fit; τ of sample i is `tau_first + i·dt`.
struct SpeedC8<'a> {
    tau_first: f64,
    dt: f64,
    y: &'a [f64],
}

impl SpeedC8<'_> {
    /// Visits `(y, model, ∂/∂σ, ∂/∂ωa)` per sample. With `γ sinh(x + sinh⁻¹(1/γ)) =
    /// cosh x + (σ/ωa) sinh x` (because `γ² + 1 = σ²/ωa²`), (C.8) is
    /// `1 − e^{−στ}(cosh ωaτ + (σ/ωa) sinh ωaτ)`; the decayed hyperbolic functions are formed
    /// from the two modes `e^{−(σ∓ωa)τ}` so nothing overflows.
    fn visit(&self, p: &[f64], mut f: impl FnMut(f64, f64, f64, f64)) -> bool {
        let (sigma, wa) = match *p {
            [s, w] if s > w && w > 0.0 => (s, w),
            _ => return false,
        };
        let ratio = sigma / wa;
        let (rate_slow, rate_fast) = (-(sigma - wa), -(sigma + wa));
        // Each mode advances by its factor over one sample period, evaluated exactly again
        // every C8_REANCHOR samples (as the Eq. (33) kernels do): the products drift by a few
        // ulp at most, and two exponentials per sample were most of the check's time.
        let (step_slow, step_fast) = ((rate_slow * self.dt).exp(), (rate_fast * self.dt).exp());
        let (mut slow, mut fast) = (0.0, 0.0);
        for (i, &y) in self.y.iter().enumerate() {
            let tau = self.tau_first + i as f64 * self.dt;
            if i % C8_REANCHOR == 0 {
                slow = (rate_slow * tau).exp();
                fast = (rate_fast * tau).exp();
            }
            let (c, s) = (0.5 * (slow + fast), 0.5 * (slow - fast));
            slow *= step_slow;
            fast *= step_fast;
            let model = 1.0 - (c + ratio * s);
            // d/dσ: the decay e^{−στ} gives τ(c + ratio s); ratio = σ/ωa gives s/ωa.
            let d_sigma = tau * (c + ratio * s) - s / wa;
            // d/dωa of (c + (σ/ωa) s), with dc/dωa = τ s, ds/dωa = τ c (the decay is in σ).
            let d_wa = -(tau * s + ratio * tau * c - ratio / wa * s);
            f(y, model, d_sigma, d_wa);
        }
        true
    }
}

impl crate::estimation::lm::LeastSquares for SpeedC8<'_> {
    fn n_params(&self) -> usize {
        2
    }
    fn cost(&self, p: &[f64]) -> Option<f64> {
        let mut cost = 0.0;
        self.visit(p, |y, m, _, _| cost += (m - y).powi(2))
            .then_some(0.5 * cost)
            .filter(|c| c.is_finite())
    }
    fn normal_equations(&self, p: &[f64]) -> Option<crate::estimation::lm::NormalEquations> {
        let mut jtj = [0.0; 3];
        let mut jtr = [0.0; 2];
        let mut cost = 0.0;
        let ok = self.visit(p, |y, m, j0, j1| {
            let r = m - y;
            cost += r * r;
            jtr[0] += j0 * r;
            jtr[1] += j1 * r;
            jtj[0] += j0 * j0;
            jtj[1] += j0 * j1;
            jtj[2] += j1 * j1;
        });
        ok.then(|| crate::estimation::lm::NormalEquations {
            jtj: nalgebra::DMatrix::from_row_slice(2, 2, &[jtj[0], jtj[1], jtj[1], jtj[2]]),
            jtr: nalgebra::DVector::from_row_slice(&jtr),
            cost: 0.5 * cost,
            n_residuals: self.y.len(),
        })
    }
}

/// Fewest speed samples after breakaway that [`speed_check_c8`] fits.
const MIN_C8_SAMPLES: usize = 10;

/// Fits (C.8) to the high-voltage speed normalised by its last sample, with τ measured from the
/// breakaway instant `t0_s` \[s\] (Eq. (11) of the identified motor), starting from the (σ, ωa)
/// of the current fit. Returns ωn, ζ from the speed alone.
pub fn speed_check_c8(
    high: &crate::estimation::records::StepTest<'_>,
    t0_s: f64,
    start: Params33,
    settings: crate::estimation::lm::LmSettings,
) -> Result<SpeedCheck, FitError> {
    crate::estimation::checks::check_aligned("high-voltage test", high.channels())?;
    let speed = high.speed.ok_or_else(|| FitError::BadData {
        series: "high-voltage speed".into(),
        reason: "the (C.8) check needs a speed or position channel".into(),
    })?;
    let omega_rm = speed.last().copied().unwrap_or(f64::NAN);
    if !(omega_rm.is_finite() && omega_rm != 0.0) {
        return Err(domain(
            "Eq. (C.8)",
            format!("final speed {omega_rm} rad/s: the motor must turn"),
        ));
    }
    // First sample after breakaway.
    let first = (((t0_s - high.t_first) / high.dt).floor() + 1.0).max(0.0) as usize;
    let y: Vec<f64> = speed.iter().skip(first).map(|w| w / omega_rm).collect();
    // Beyond the record, nothing is fitted and the fit "converges" at its start with zero cost:
    // not a check.
    if y.len() < MIN_C8_SAMPLES {
        return Err(domain(
            "Eq. (C.8)",
            format!(
                "the identified motor breaks away at t0 = {t0_s:.4e} s, leaving {} speed samples of the record (at least {MIN_C8_SAMPLES} are needed)",
                y.len()
            ),
        ));
    }
    let problem = SpeedC8 {
        tau_first: high.t_first + first as f64 * high.dt - t0_s,
        dt: high.dt,
        y: &y,
    };
    let report = crate::estimation::lm::solve(&problem, &[start.sigma, start.omega_a], settings)?;
    let (sigma, wa) = (report.params[0], report.params[1]);
    let omega_n = (sigma * sigma - wa * wa).sqrt();
    Ok(SpeedCheck {
        omega_n,
        zeta: sigma / omega_n,
        rms: (2.0 * report.normal.cost / y.len().max(1) as f64).sqrt(),
        termination: report.termination,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimation::lm::LeastSquares;

    /// Jᵀr of the (C.8) problem equals the gradient of its cost by central differences
    /// (relative 1e-6: h = 1e-7 relative, cost smooth).
    #[test]
    fn speed_c8_gradient_matches_finite_differences() {
        let y: Vec<f64> = (0..3000)
            .map(|i| {
                let tau = 0.01 * i as f64;
                motor_model::paper::normalized_speed_c8(0.9, 0.52, 0.39, tau)
                    + 1e-3 * (i as f64).sin()
            })
            .collect();
        let problem = SpeedC8 {
            tau_first: 0.0,
            dt: 0.01,
            y: &y,
        };
        for p in [[0.5, 0.4], [0.53, 0.38], [1.2, 0.3]] {
            let ne = problem.normal_equations(&p).unwrap();
            for k in 0..2 {
                let h = 1e-7 * p[k];
                let (mut up, mut down) = (p, p);
                up[k] += h;
                down[k] -= h;
                let fd = (problem.cost(&up).unwrap() - problem.cost(&down).unwrap()) / (2.0 * h);
                assert!(
                    (fd - ne.jtr[k]).abs() <= 1e-6 * fd.abs().max(1e-9),
                    "{p:?} [{k}]: {fd} vs {}",
                    ne.jtr[k]
                );
            }
        }
    }
}
