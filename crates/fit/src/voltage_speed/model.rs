//! The voltage-to-speed model's parameters (kS, kV, kA and what J, f, Ts follow from them with
//! R and k known), its records, settings and fitted result.

use motor_model::{Input, MotorParams};

use crate::estimation::lm::{LmSettings, Termination};
use crate::estimation::parameters::ParameterEstimate;
use crate::estimation::records::ChannelQuality;
use crate::excitation::input_uncertainty::LevelPrior;

/// The voltage-to-speed constants of a motor (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedforwardParams {
    /// Static (dead-band) voltage kS = R Ts/k \[V\].
    pub ks_v: f64,
    /// Velocity constant kV = k + R f/k \[V·s/rad\].
    pub kv_v_s_per_rad: f64,
    /// Acceleration constant kA = R J/k \[V·s²/rad\].
    pub ka_v_s2_per_rad: f64,
}

/// J, f and Ts of a motor from its feedforward constants and a given R and k.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MechanicalFromFeedforward {
    /// Inertia J = kA k/R \[kg·m²\].
    pub j_kgm2: f64,
    /// Viscous friction f = (kV − k) k/R \[N·m·s/rad\].
    pub f_nms_per_rad: f64,
    /// Coulomb torque Ts = kS k/R \[N·m\].
    pub ts_nm: f64,
}

impl FeedforwardParams {
    /// The constants of a motor (module docs; exact when L = 0).
    pub fn of_motor(p: &MotorParams) -> Self {
        FeedforwardParams {
            ks_v: p.r_ohm * p.ts_nm / p.k_nm_per_a,
            kv_v_s_per_rad: p.k_nm_per_a + p.r_ohm * p.f_nms_per_rad / p.k_nm_per_a,
            ka_v_s2_per_rad: p.r_ohm * p.j_kgm2 / p.k_nm_per_a,
        }
    }

    /// J, f and Ts given R \[Ω\] and k \[N·m/A\]. `f` comes out negative when kV < k: the k
    /// given is larger than the records allow.
    pub fn mechanical(&self, r_ohm: f64, k_nm_per_a: f64) -> MechanicalFromFeedforward {
        let scale = k_nm_per_a / r_ohm;
        MechanicalFromFeedforward {
            j_kgm2: self.ka_v_s2_per_rad * scale,
            f_nms_per_rad: (self.kv_v_s_per_rad - k_nm_per_a) * scale,
            ts_nm: self.ks_v * scale,
        }
    }

    /// Mechanical time constant τm = kA/kV \[s\].
    pub fn tau_m_s(&self) -> f64 {
        self.ka_v_s2_per_rad / self.kv_v_s_per_rad
    }
}

/// One record of voltage and speed.
#[derive(Debug, Clone, Copy)]
pub struct SpeedRecord<'a> {
    /// The armature voltage applied, time from the record's first sample
    /// ([`crate::voltage_input`] builds it from a measured column).
    pub input: &'a Input,
    /// Sample period \[s\].
    pub dt: f64,
    /// Tachometer speed \[rad/s\], if measured. Not used when `position` is given.
    pub speed: Option<&'a [f64]>,
    /// Encoder angle \[rad\], if measured.
    pub position: Option<&'a [f64]>,
    /// Samples to leave out (a rail, a glitch), if any.
    pub exclude: Option<&'a [bool]>,
    /// What the record leaves unknown of each level of a piecewise-constant `input` (from
    /// [`crate::voltage_levels`], one per level), or empty: the fit then moves the levels and
    /// their instants within these priors and its intervals carry what remains unknown.
    pub priors: &'a [LevelPrior],
    /// How the record starts: `Some(true)` at rest, `Some(false)` in steady motion at a
    /// fitted speed, `None` as its speed shows (at rest when the first sample, or the mean of
    /// the first five, is within three noise levels of zero).
    pub at_rest: Option<bool>,
}

/// Result of [`identify_feedforward`](crate::identify_feedforward).
#[derive(Debug, Clone, PartialEq)]
pub struct FeedforwardFit {
    /// The fitted constants.
    pub params: FeedforwardParams,
    /// 95 % intervals of kS, kV, kA (same order and units as the fields of
    /// [`FeedforwardParams`]; Newey–West sandwich, each standard error at least the
    /// model-based one, delta method from the logarithms); `None` when they cannot be
    /// computed.
    pub ci95: Option<[[f64; 2]; 3]>,
    /// What the records said of the electrical time constant.
    pub tau_e: TauE,
    /// Initial speed of each record \[rad/s\]: 0 for a record that starts at rest, else fitted.
    pub initial_speed_rad_s: Vec<f64>,
    /// Fit quality of each record's speed channel.
    pub quality: Vec<ChannelQuality>,
    /// Each record's residual RMS over its noise as its samples show it (second differences,
    /// [`crate::noise_std`]): about 1 where the model explains the record; well above
    /// [`EXPLAINED_RATIO`](crate::EXPLAINED_RATIO) it does not (τe far from every start, an unmodelled effect).
    pub residual_over_noise: Vec<f64>,
    /// Accepted iterations (every stage).
    pub iterations: u64,
    /// Why the solver stopped.
    pub termination: Termination,
}

/// Names of the feedforward constants as reports give them, in the order of
/// [`FeedforwardFit::ci95`].
pub const FEEDFORWARD_NAMES: [&str; 3] = ["kS", "kV", "kA"];

/// SI units of [`FEEDFORWARD_NAMES`].
pub const FEEDFORWARD_UNITS: [&str; 3] = ["V", "V·s/rad", "V·s²/rad"];

impl FeedforwardFit {
    /// kS, kV, kA with names, units and 95 % intervals; and, given `known` = (R \[Ω\],
    /// k \[N·m/A\]), J, f, Ts ([`FeedforwardParams::mechanical`]) with the intervals of kA, kV,
    /// kS mapped through the same linear relations (R and k taken as exact: their own
    /// uncertainty is not in these intervals).
    pub fn estimates(&self, known: Option<(f64, f64)>) -> Vec<ParameterEstimate> {
        let p = &self.params;
        let values = [p.ks_v, p.kv_v_s_per_rad, p.ka_v_s2_per_rad];
        let mut out: Vec<ParameterEstimate> = (0..3)
            .map(|i| ParameterEstimate {
                name: FEEDFORWARD_NAMES[i],
                unit: FEEDFORWARD_UNITS[i],
                value: values[i],
                ci95: self.ci95.map(|c| c[i]),
            })
            .collect();
        if let Some((r_ohm, k)) = known {
            let m = p.mechanical(r_ohm, k);
            let scale = k / r_ohm;
            let map = |i: usize, shift: f64| {
                self.ci95
                    .map(|c| [(c[i][0] - shift) * scale, (c[i][1] - shift) * scale])
            };
            for (name, unit, value, ci95) in [
                ("J", "kg·m²", m.j_kgm2, map(2, 0.0)),
                ("f", "N·m·s/rad", m.f_nms_per_rad, map(1, k)),
                ("Ts", "N·m", m.ts_nm, map(0, 0.0)),
            ] {
                out.push(ParameterEstimate {
                    name,
                    unit,
                    value,
                    ci95,
                });
            }
        }
        out
    }
}

/// The electrical time constant in a [`FeedforwardFit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TauE {
    /// Fitted: τe = L/R \[s\] with its 95 % interval.
    Fitted {
        /// τe \[s\].
        value_s: f64,
        /// 95 % interval \[s\].
        ci95_s: [f64; 2],
    },
    /// Fitted, but not significantly above 0 (its interval reaches 0): below `upper_s` \[s\],
    /// the upper end of that interval. kS, kV and kA are those of the fit with τe, so their
    /// intervals carry what τe leaves unknown.
    NotResolved {
        /// Upper end of τe's 95 % interval \[s\].
        upper_s: f64,
    },
    /// The fit with τe failed (no convergence, or no intervals): the reduced model (τe = 0) is
    /// used. kA then holds about `(kV − k) τe` of the true τe on top of `R J/k`, and at every
    /// reversal kS trades against τe.
    Unfitted,
    /// Fitted, but with no torque constant given the records cannot split kA from τe. The
    /// model's speed answers the voltage through `1/(kA τe s² + (kA + τe (kV − k)) s + kV)`:
    /// the records fix the two coefficients, `kA τe` and `lead = kA + τe (kV − k)`, and with
    /// the viscous share `b = kV − k` unknown, a kA fits them as well as any other wherever
    /// `τe = (kA τe)/kA` and `b = (lead − kA)/τe` are physical (`0 ≤ b ≤ kV`): every such kA
    /// lies in `(0, lead]` (all of it when `lead² ≤ 4 (kA τe) kV`). kS and kV are determined;
    /// kA's interval in [`FeedforwardFit::ci95`] is then `[0, upper end of lead's interval]`.
    /// Giving k (the torque constant, [`FeedforwardSettings::torque_constant`]) splits them.
    Traded {
        /// `lead = kA + τe (kV − k)` \[V·s²/rad\]: the largest kA the records allow.
        lead_v_s2_per_rad: f64,
        /// 95 % interval of `lead` \[V·s²/rad\].
        lead_ci95: [f64; 2],
        /// `kA τe` \[V·s³/rad\].
        product_v_s3_per_rad: f64,
        /// 95 % interval of `kA τe` \[V·s³/rad\].
        product_ci95: [f64; 2],
    },
    /// Not asked for ([`FeedforwardSettings::electrical`] false): the reduced model.
    Neglected,
}

/// Settings of [`identify_feedforward`](crate::identify_feedforward).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedforwardSettings {
    /// The solver's settings.
    pub lm: LmSettings,
    /// Fit the electrical time constant τe too (default), or neglect it.
    pub electrical: bool,
    /// The torque constant k \[N·m/A\] (the back-EMF constant, V·s/rad) if known: with τe, the
    /// viscous share of kV is `kV − k`. Unknown, k is taken as kV (viscous friction small
    /// against the back-EMF), which affects only how τe couples to the speed.
    pub torque_constant: Option<f64>,
}

impl Default for FeedforwardSettings {
    fn default() -> Self {
        FeedforwardSettings {
            lm: LmSettings::default(),
            electrical: true,
            torque_constant: None,
        }
    }
}

/// The voltage-to-speed model with the electrical time constant: the constants, `τe = L/R`
/// and the back-EMF constant `k` (module docs). `tau_e_s = 0` is the reduced model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageSpeedModel {
    /// kS, kV, kA.
    pub constants: FeedforwardParams,
    /// Electrical time constant τe = L/R \[s\]; 0 neglects it.
    pub tau_e_s: f64,
    /// Back-EMF constant k \[V·s/rad\] (= the torque constant in N·m/A), at most kV: the rest
    /// of kV, `kV − k = R f/k`, is the viscous friction's share. Only matters when τe > 0.
    pub back_emf_v_s_per_rad: f64,
}
