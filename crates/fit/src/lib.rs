//! Identification of DC motor parameters by Levenberg–Marquardt (through `argmin`).
//!
//! This crate will own, building on [`motor_model`]:
//! - a Levenberg–Marquardt solver written as an `argmin` `Solver`, with analytic Jacobians,
//!   parameter scaling and a termination reason in every result;
//! - the seed paper's identification method: the fit of Eq. (33) to the normalised
//!   high-voltage current, Eqs. (34)–(44), the low-voltage test (46)–(51), and the
//!   steady-state apparent-resistance fit (8), (9);
//! - the full-model identification of R, L, k, f, J, Ts from current and speed records, with
//!   covariance, 95 % confidence intervals and correlations.
//!
//! It does no I/O: records come in as slices, results go out as values.
#![warn(missing_docs)]

pub use motor_model::MotorParams;
