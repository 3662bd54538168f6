//! The effects the benchmark plant can carry, each in a "same shape" and an "other shape" form.
//!
//! The formulas are listed in the module docs of [`crate::withheld`]; each variant's doc repeats
//! its own.

use serde::{Deserialize, Serialize};

use crate::error::{finite, positive, ModelError};
use crate::params::MotorParams;

/// Whether an effect follows the formula of SPEC section 5 or another shape of the same physics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Form {
    /// (a): the SPEC section 5 formula, the diagnoser's own model of the effect.
    SameShape,
    /// (b): a functional form different in shape, not only in parameters.
    OtherShape,
}

/// One physical effect of the benchmark plant, with its functional form and parameters (SI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "form", rename_all = "snake_case", deny_unknown_fields)]
pub enum PlantEffect {
    /// `stribeck_friction` (a): sliding friction `T_c(Ω) = Ts + (Tst − Ts) exp(−(Ω/Ωs)²)`
    /// \[N·m\]; the rotor breaks away when `|k I − T_cog| > Tst`.
    StribeckGaussian {
        /// Static (breakaway) torque Tst \[N·m\], above the motor's Ts.
        static_torque_nm: f64,
        /// Stribeck speed Ωs \[rad/s\].
        stribeck_speed_rad_s: f64,
    },
    /// `stribeck_friction` (b): LuGre friction with bristle state z \[rad\],
    /// `ż = Ω − σ0 |Ω| z / g(Ω)`, `g(Ω) = Ts + (Tst − Ts) exp(−|Ω/Ωs|^δ)`,
    /// `T_f = σ0 z + σ1 ż + σ2 Ω` \[N·m\], σ2 being the motor's viscous f.
    #[serde(rename = "lugre")]
    LuGre {
        /// Static level Tst of g(0) \[N·m\], above the motor's Ts (the sliding level).
        static_torque_nm: f64,
        /// Stribeck speed Ωs \[rad/s\].
        stribeck_speed_rad_s: f64,
        /// Stribeck exponent δ \[-\] (2 would be the Gaussian shape; the benchmark uses 0.5 or 1).
        stribeck_exponent: f64,
        /// Bristle stiffness σ0 \[N·m/rad\].
        bristle_stiffness_nm_per_rad: f64,
        /// Bristle damping σ1 \[N·m·s/rad\].
        bristle_damping_nms_per_rad: f64,
    },
    /// `cogging_torque` (a): `T_cog(θ) = A sin(N θ + φ)` \[N·m\].
    CoggingSine {
        /// Amplitude A \[N·m\].
        amplitude_nm: f64,
        /// Periods per revolution N \[-\].
        periods_per_rev: u32,
        /// Phase φ \[rad\].
        phase_rad: f64,
    },
    /// `cogging_torque` (b): three harmonics,
    /// `T_cog(θ) = A [sin(Nθ + φ) + a2 sin(2Nθ + φ2) + a3 sin(3Nθ + φ3)]` \[N·m\].
    CoggingHarmonics {
        /// Amplitude A of the fundamental \[N·m\].
        amplitude_nm: f64,
        /// Periods per revolution N of the fundamental \[-\].
        periods_per_rev: u32,
        /// Phase φ of the fundamental \[rad\].
        phase_rad: f64,
        /// Relative amplitude a2 of the second harmonic \[-\].
        second_ratio: f64,
        /// Phase φ2 of the second harmonic \[rad\].
        second_phase_rad: f64,
        /// Relative amplitude a3 of the third harmonic \[-\].
        third_ratio: f64,
        /// Phase φ3 of the third harmonic \[rad\].
        third_phase_rad: f64,
    },
    /// `current_sensor_lag` (a): first-order sensor, `τf İs = I − Is` \[A\].
    SensorFirstOrder {
        /// Time constant τf \[s\].
        tau_f_s: f64,
    },
    /// `current_sensor_lag` (b): critically damped second-order sensor,
    /// `Ïs + 2ωc İs + ωc² Is = ωc² I` \[A\] (its mean delay is `2/ωc`).
    SensorSecondOrder {
        /// Natural pulsation ωc \[rad/s\].
        natural_pulsation_rad_s: f64,
    },
    /// `thermal_drift` (a): one thermal node, `Cth dΔT/dt = I² R − ΔT/Rth`, `R = R0 (1 + α ΔT)`.
    ThermalOneNode {
        /// Thermal resistance winding → ambient Rth \[K/W\].
        thermal_resistance_k_per_w: f64,
        /// Thermal capacity Cth \[J/K\].
        thermal_capacity_j_per_k: f64,
        /// Temperature coefficient α \[1/K\].
        alpha_per_k: f64,
    },
    /// `thermal_drift` (b): winding and housing nodes,
    /// `Cw dTw/dt = I² R − (Tw − Th)/Rwh`, `Ch dTh/dt = (Tw − Th)/Rwh − Th/Rha`,
    /// `R = R0 (1 + α Tw)` (temperatures as rises over ambient \[K\]).
    ThermalTwoNode {
        /// Winding capacity Cw \[J/K\].
        winding_capacity_j_per_k: f64,
        /// Winding → housing resistance Rwh \[K/W\].
        winding_to_housing_k_per_w: f64,
        /// Housing capacity Ch \[J/K\].
        housing_capacity_j_per_k: f64,
        /// Housing → ambient resistance Rha \[K/W\].
        housing_to_ambient_k_per_w: f64,
        /// Temperature coefficient α \[1/K\].
        alpha_per_k: f64,
    },
    /// `quadratic_drag` (a): load torque `c Ω|Ω|` \[N·m\].
    DragQuadratic {
        /// Coefficient c \[N·m·s²/rad²\].
        c_nms2_per_rad2: f64,
    },
    /// `quadratic_drag` (b): load torque `c |Ω|^1.5 sign(Ω)` \[N·m\] (drag between the laminar
    /// and the turbulent law).
    DragPowerOneAndHalf {
        /// Coefficient c \[N·m·(s/rad)^1.5\].
        c_nm_per_rad_s_pow: f64,
    },
    /// `brush_drop` (a): `V_b(I) = Vb clamp(I/I_knee, −1, 1)` \[V\].
    BrushClamp {
        /// Drop Vb at full conduction \[V\].
        drop_v: f64,
        /// Knee current I_knee \[A\].
        knee_current_a: f64,
    },
    /// `brush_drop` (b): a contact drop growing logarithmically with the current,
    /// `V_b(I) = Vb ln(1 + |I|/I0) sign(I)` \[V\].
    BrushLogarithmic {
        /// Scale Vb \[V\] (the drop at `|I| = (e − 1) I0`).
        drop_v: f64,
        /// Onset current I0 \[A\].
        onset_current_a: f64,
    },
    /// `inductance_saturation` (a): `L(I) = L0 (r + (1 − r)/(1 + (I/I_sat)²))` \[H\].
    SaturationLorentzian {
        /// Saturation current I_sat \[A\].
        saturation_current_a: f64,
        /// Ratio r = L(∞)/L0 \[-\], in (0, 1].
        min_ratio: f64,
    },
    /// `inductance_saturation` (b): an inductance falling from `I = 0` on, linearly in `|I|` at
    /// first, `L(I) = L0 (r + (1 − r)/(1 + |I|ε/I_sat))` \[H\] (the (a) form is flat at 0), with
    /// `|I|ε = √(I² + ε²) − ε`, ε = 0.02 I_sat, rounding the cusp at zero.
    SaturationAbsolute {
        /// Saturation current I_sat \[A\].
        saturation_current_a: f64,
        /// Ratio r = L(∞)/L0 \[-\], in (0, 1].
        min_ratio: f64,
    },
}

/// The SPEC section 5 names of the seven effects ([`crate::EFFECT_NAMES`] without `none`), in
/// the order of the benchmark's case mix.
pub fn withheld_effect_names() -> Vec<&'static str> {
    crate::EFFECT_NAMES
        .iter()
        .copied()
        .filter(|name| *name != "none")
        .collect()
}

/// The size of an effect, as the case table prints it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Magnitude {
    /// What is measured, e.g. `Tst - Ts`.
    pub quantity: &'static str,
    /// Its value in `unit`.
    pub value: f64,
    /// The SI unit.
    pub unit: &'static str,
}

impl PlantEffect {
    /// The SPEC section 5 name of the physics this effect belongs to.
    pub fn name(&self) -> &'static str {
        match self {
            PlantEffect::StribeckGaussian { .. } | PlantEffect::LuGre { .. } => "stribeck_friction",
            PlantEffect::CoggingSine { .. } | PlantEffect::CoggingHarmonics { .. } => {
                "cogging_torque"
            }
            PlantEffect::SensorFirstOrder { .. } | PlantEffect::SensorSecondOrder { .. } => {
                "current_sensor_lag"
            }
            PlantEffect::ThermalOneNode { .. } | PlantEffect::ThermalTwoNode { .. } => {
                "thermal_drift"
            }
            PlantEffect::DragQuadratic { .. } | PlantEffect::DragPowerOneAndHalf { .. } => {
                "quadratic_drag"
            }
            PlantEffect::BrushClamp { .. } | PlantEffect::BrushLogarithmic { .. } => "brush_drop",
            PlantEffect::SaturationLorentzian { .. } | PlantEffect::SaturationAbsolute { .. } => {
                "inductance_saturation"
            }
        }
    }

    /// Whether this is the SPEC formula (a) or another shape (b).
    pub fn form(&self) -> Form {
        match self {
            PlantEffect::StribeckGaussian { .. }
            | PlantEffect::CoggingSine { .. }
            | PlantEffect::SensorFirstOrder { .. }
            | PlantEffect::ThermalOneNode { .. }
            | PlantEffect::DragQuadratic { .. }
            | PlantEffect::BrushClamp { .. }
            | PlantEffect::SaturationLorentzian { .. } => Form::SameShape,
            _ => Form::OtherShape,
        }
    }

    /// A short label of the functional form, e.g. `lugre (delta = 0.5)`.
    pub fn form_label(&self) -> String {
        match self {
            PlantEffect::StribeckGaussian { .. } => "gaussian stribeck".into(),
            PlantEffect::LuGre {
                stribeck_exponent, ..
            } => format!("lugre, delta {stribeck_exponent}"),
            PlantEffect::CoggingSine {
                periods_per_rev, ..
            } => format!("sine, N {periods_per_rev}"),
            PlantEffect::CoggingHarmonics {
                periods_per_rev, ..
            } => format!("N+2N+3N, N {periods_per_rev}"),
            PlantEffect::SensorFirstOrder { .. } => "1st order".into(),
            PlantEffect::SensorSecondOrder { .. } => "2nd order, crit.".into(),
            PlantEffect::ThermalOneNode { .. } => "one node".into(),
            PlantEffect::ThermalTwoNode { .. } => "winding+housing".into(),
            PlantEffect::DragQuadratic { .. } => "c W|W|".into(),
            PlantEffect::DragPowerOneAndHalf { .. } => "c |W|^1.5".into(),
            PlantEffect::BrushClamp { .. } => "clamp knee".into(),
            PlantEffect::BrushLogarithmic { .. } => "logarithmic".into(),
            PlantEffect::SaturationLorentzian { .. } => "lorentzian L(I)".into(),
            PlantEffect::SaturationAbsolute { .. } => "1/(1+|I|/Isat)".into(),
        }
    }

    /// The effect's size: the quantity the benchmark scales to make it visible.
    pub fn magnitude(&self, motor: &MotorParams) -> Magnitude {
        let m = |quantity, value, unit| Magnitude {
            quantity,
            value,
            unit,
        };
        match *self {
            PlantEffect::StribeckGaussian {
                static_torque_nm, ..
            }
            | PlantEffect::LuGre {
                static_torque_nm, ..
            } => m("Tst - Ts", static_torque_nm - motor.ts_nm, "N·m"),
            PlantEffect::CoggingSine { amplitude_nm, .. }
            | PlantEffect::CoggingHarmonics { amplitude_nm, .. } => m("A", amplitude_nm, "N·m"),
            PlantEffect::SensorFirstOrder { tau_f_s } => m("delay", tau_f_s, "s"),
            PlantEffect::SensorSecondOrder {
                natural_pulsation_rad_s,
            } => m("delay", 2.0 / natural_pulsation_rad_s, "s"),
            PlantEffect::ThermalOneNode {
                thermal_capacity_j_per_k,
                ..
            } => m("1/C", 1.0 / thermal_capacity_j_per_k, "K/J"),
            PlantEffect::ThermalTwoNode {
                winding_capacity_j_per_k,
                ..
            } => m("1/C", 1.0 / winding_capacity_j_per_k, "K/J"),
            PlantEffect::DragQuadratic { c_nms2_per_rad2 } => m("c", c_nms2_per_rad2, "N·m·s²"),
            PlantEffect::DragPowerOneAndHalf { c_nm_per_rad_s_pow } => {
                m("c", c_nm_per_rad_s_pow, "N·m·s^1.5")
            }
            PlantEffect::BrushClamp { drop_v, .. }
            | PlantEffect::BrushLogarithmic { drop_v, .. } => m("Vb", drop_v, "V"),
            PlantEffect::SaturationLorentzian { min_ratio, .. }
            | PlantEffect::SaturationAbsolute { min_ratio, .. } => m("1 - r", 1.0 - min_ratio, "-"),
        }
    }

    /// The same effect with its magnitude multiplied by `factor` > 0 (the shape parameters
    /// kept): Tst − Ts (and a LuGre friction's presliding displacement with it: the bristles
    /// are the rest of its departure from Coulomb friction), A, the sensor delay, the heating
    /// rate 1/C (thermal time constants kept), c, Vb, and 1 − r (capped at 0.8).
    pub fn scaled(&self, factor: f64, motor: &MotorParams) -> Self {
        let mut e = *self;
        match &mut e {
            PlantEffect::StribeckGaussian {
                static_torque_nm, ..
            } => *static_torque_nm = motor.ts_nm + factor * (*static_torque_nm - motor.ts_nm),
            PlantEffect::LuGre {
                static_torque_nm,
                bristle_stiffness_nm_per_rad,
                bristle_damping_nms_per_rad,
                ..
            } => {
                // The bristles' departure from Coulomb friction scales too: their presliding
                // displacement g(0)/σ0, with the bristle's damping ratio σ1/(2√(σ0 J)) kept.
                // (The excess is capped at 0.45 of the low step's torque margin against a
                // first guess of 0.3: the presliding ends at most 1.5 times its draw.)
                let presliding = *static_torque_nm / *bristle_stiffness_nm_per_rad * factor;
                *static_torque_nm = motor.ts_nm + factor * (*static_torque_nm - motor.ts_nm);
                let stiffness = *static_torque_nm / presliding;
                *bristle_damping_nms_per_rad *= (stiffness / *bristle_stiffness_nm_per_rad).sqrt();
                *bristle_stiffness_nm_per_rad = stiffness;
            }
            PlantEffect::CoggingSine { amplitude_nm, .. }
            | PlantEffect::CoggingHarmonics { amplitude_nm, .. } => *amplitude_nm *= factor,
            PlantEffect::SensorFirstOrder { tau_f_s } => *tau_f_s *= factor,
            PlantEffect::SensorSecondOrder {
                natural_pulsation_rad_s,
            } => *natural_pulsation_rad_s /= factor,
            PlantEffect::ThermalOneNode {
                thermal_resistance_k_per_w,
                thermal_capacity_j_per_k,
                ..
            } => {
                *thermal_capacity_j_per_k /= factor;
                *thermal_resistance_k_per_w *= factor;
            }
            PlantEffect::ThermalTwoNode {
                winding_capacity_j_per_k,
                winding_to_housing_k_per_w,
                housing_capacity_j_per_k,
                housing_to_ambient_k_per_w,
                ..
            } => {
                *winding_capacity_j_per_k /= factor;
                *winding_to_housing_k_per_w *= factor;
                *housing_capacity_j_per_k /= factor;
                *housing_to_ambient_k_per_w *= factor;
            }
            PlantEffect::DragQuadratic { c_nms2_per_rad2 } => *c_nms2_per_rad2 *= factor,
            PlantEffect::DragPowerOneAndHalf { c_nm_per_rad_s_pow } => {
                *c_nm_per_rad_s_pow *= factor
            }
            PlantEffect::BrushClamp { drop_v, .. }
            | PlantEffect::BrushLogarithmic { drop_v, .. } => *drop_v *= factor,
            PlantEffect::SaturationLorentzian { min_ratio, .. }
            | PlantEffect::SaturationAbsolute { min_ratio, .. } => {
                *min_ratio = 1.0 - ((1.0 - *min_ratio) * factor).min(MAX_INDUCTANCE_FALL)
            }
        }
        e
    }

    /// Checks every parameter against `motor` (e.g. Tst ≥ Ts), naming the first bad one.
    pub fn validate(&self, motor: &MotorParams) -> Result<(), ModelError> {
        let name = self.name();
        let pos = |key: &str, v: f64| positive(&format!("{name} {key}"), v).map(|_| ());
        let fin = |key: &str, v: f64| finite(&format!("{name} {key}"), v).map(|_| ());
        let ratio = |v: f64| {
            if v.is_finite() && v > 0.0 && v <= 1.0 {
                Ok(())
            } else {
                Err(ModelError::InvalidSetting {
                    name: format!("{name} ratio"),
                    value: v,
                    expected: "a ratio L(inf)/L0 in (0, 1]",
                })
            }
        };
        match *self {
            PlantEffect::StribeckGaussian {
                static_torque_nm,
                stribeck_speed_rad_s,
            } => {
                static_at_least_ts(static_torque_nm, motor)?;
                pos("stribeck speed", stribeck_speed_rad_s)
            }
            PlantEffect::LuGre {
                static_torque_nm,
                stribeck_speed_rad_s,
                stribeck_exponent,
                bristle_stiffness_nm_per_rad,
                bristle_damping_nms_per_rad,
            } => {
                static_at_least_ts(static_torque_nm, motor)?;
                if motor.ts_nm <= 0.0 {
                    return Err(ModelError::InvalidSetting {
                        name: "lugre Ts".into(),
                        value: motor.ts_nm,
                        expected: "a motor with Coulomb friction Ts > 0 (g(Ω) must stay positive)",
                    });
                }
                pos("stribeck speed", stribeck_speed_rad_s)?;
                pos("stribeck exponent", stribeck_exponent)?;
                pos("sigma0", bristle_stiffness_nm_per_rad)?;
                crate::error::non_negative("lugre sigma1", bristle_damping_nms_per_rad).map(|_| ())
            }
            PlantEffect::CoggingSine {
                amplitude_nm,
                periods_per_rev,
                phase_rad,
            } => {
                crate::error::non_negative("cogging amplitude", amplitude_nm)?;
                pos("periods per revolution", f64::from(periods_per_rev))?;
                fin("phase", phase_rad)
            }
            PlantEffect::CoggingHarmonics {
                amplitude_nm,
                periods_per_rev,
                phase_rad,
                second_ratio,
                second_phase_rad,
                third_ratio,
                third_phase_rad,
            } => {
                crate::error::non_negative("cogging amplitude", amplitude_nm)?;
                pos("periods per revolution", f64::from(periods_per_rev))?;
                for (k, v) in [
                    ("phase", phase_rad),
                    ("second ratio", second_ratio),
                    ("second phase", second_phase_rad),
                    ("third ratio", third_ratio),
                    ("third phase", third_phase_rad),
                ] {
                    fin(k, v)?;
                }
                Ok(())
            }
            PlantEffect::SensorFirstOrder { tau_f_s } => pos("tau", tau_f_s),
            PlantEffect::SensorSecondOrder {
                natural_pulsation_rad_s,
            } => pos("natural pulsation", natural_pulsation_rad_s),
            PlantEffect::ThermalOneNode {
                thermal_resistance_k_per_w,
                thermal_capacity_j_per_k,
                alpha_per_k,
            } => {
                pos("rth", thermal_resistance_k_per_w)?;
                pos("cth", thermal_capacity_j_per_k)?;
                crate::error::non_negative("thermal alpha", alpha_per_k).map(|_| ())
            }
            PlantEffect::ThermalTwoNode {
                winding_capacity_j_per_k,
                winding_to_housing_k_per_w,
                housing_capacity_j_per_k,
                housing_to_ambient_k_per_w,
                alpha_per_k,
            } => {
                pos("cw", winding_capacity_j_per_k)?;
                pos("rwh", winding_to_housing_k_per_w)?;
                pos("ch", housing_capacity_j_per_k)?;
                pos("rha", housing_to_ambient_k_per_w)?;
                crate::error::non_negative("thermal alpha", alpha_per_k).map(|_| ())
            }
            PlantEffect::DragQuadratic { c_nms2_per_rad2 } => {
                crate::error::non_negative("drag c", c_nms2_per_rad2).map(|_| ())
            }
            PlantEffect::DragPowerOneAndHalf { c_nm_per_rad_s_pow } => {
                crate::error::non_negative("drag c", c_nm_per_rad_s_pow).map(|_| ())
            }
            PlantEffect::BrushClamp {
                drop_v,
                knee_current_a,
            } => {
                crate::error::non_negative("brush vb", drop_v)?;
                pos("knee current", knee_current_a)
            }
            PlantEffect::BrushLogarithmic {
                drop_v,
                onset_current_a,
            } => {
                crate::error::non_negative("brush vb", drop_v)?;
                pos("onset current", onset_current_a)
            }
            PlantEffect::SaturationLorentzian {
                saturation_current_a,
                min_ratio,
            }
            | PlantEffect::SaturationAbsolute {
                saturation_current_a,
                min_ratio,
            } => {
                pos("saturation current", saturation_current_a)?;
                ratio(min_ratio)
            }
        }
    }
}

/// Largest fall of the inductance, `1 − r`, the scaling allows \[-\].
const MAX_INDUCTANCE_FALL: f64 = 0.8;

fn static_at_least_ts(static_torque_nm: f64, motor: &MotorParams) -> Result<(), ModelError> {
    if static_torque_nm.is_finite() && static_torque_nm >= motor.ts_nm {
        Ok(())
    } else {
        Err(ModelError::InvalidSetting {
            name: "stribeck_friction static torque".into(),
            value: static_torque_nm,
            expected: "a static torque at least the motor's Coulomb torque Ts",
        })
    }
}
