//! Sim-to-real diagnosis: where an identified model still disagrees with the records, which
//! unmodelled effect (SPEC section 5) causes it, and how far the gap shrinks once that effect is
//! modelled.
//!
//! The diagnosis lives here, in the library, so that control software can run it on its own
//! records; `motorid diagnose` only loads the records, calls it and prints.
//!
//! - [`localise`]: *where* — the residual of a model on every record and channel against the
//!   noise floor estimated from the records themselves, located in time (phases of each record,
//!   the windows of largest excess), in operating region (speed and current bands, trends), in
//!   frequency and shaft angle, with the whiteness and input cross-correlation of MATLAB's
//!   `resid`. Each part carries a test that separates a real gap from noise.
//! - [`diagnose`] ([`run`]): the whole diagnosis — the nominal fit, the localisation, every
//!   candidate screened, the best refitted with the motor on training data and judged on
//!   held-out data, stage after stage. What it is asked and answers is in [`report`]; its
//!   parts, private to the crate: `nominal` (the nominal fit and its localisation), `heldout`
//!   (the held-out blocks and the statistics judged on them), `jumps` (the voltage jumps'
//!   instants), `starts` (where each candidate's refit starts), `stage` (one stage: screening,
//!   refits, verdict) and `base` (the model a stage builds on).
//! - [`screen`]: the score test of every candidate at the base model, which decides the few
//!   that are refitted in full.
//! - `benchmark` (with the feature `benchmark`): the diagnosis scored on cases whose effect it
//!   is not told (`motor_model::withheld`, with that crate's feature `withheld`).
//! - [`inverse`]: the same for a current-driven axis, on the torque residual of the inverse
//!   model (IDIM-LS), its candidates regressor columns refitted by least squares.
//! - [`propose`]: for an ambiguous verdict, the step record (voltage, duration) whose
//!   predictions by the two fitted alternatives differ most relative to the noise floor.
//! - [`verdict`]: *which* — candidate effects ranked by their held-out improvement, each with a
//!   paired test against the noise, `none` when nothing is significant, an ambiguous verdict
//!   when the best two cannot be told apart.
//!
//! Like the rest of the crate it does no I/O: records come in as slices, results go out as
//! values (serialisable with `serde`).

mod base;
#[cfg(feature = "benchmark")]
pub mod benchmark;
mod heldout;
pub mod inverse;
mod jumps;
pub mod localise;
mod nominal;
pub mod propose;
pub mod report;
pub mod run;
pub mod screen;
mod stage;
mod starts;
pub mod verdict;

pub use inverse::{
    diagnose_inverse, named_effects, AxisGeometry, InverseDiagnoseSettings, InverseDiagnosis,
    TorqueTrace,
};
pub use nominal::localise_fit;
pub use propose::{separating_test, SeparatingTest};
pub use report::{
    Assessment, CandidateReport, DiagnoseError, DiagnoseProgress, DiagnoseSettings, Diagnosis,
    EffectParam, ParamShift, Stage,
};
pub use run::diagnose;

/// The name of each of `n` records in reports: `names[k]`, or `record k+1` (counted from 1)
/// where `names` has none.
pub(crate) fn record_names(names: &[&str], n: usize) -> Vec<String> {
    (0..n)
        .map(|k| {
            names
                .get(k)
                .map_or_else(|| format!("record {}", k + 1), |s| s.to_string())
        })
        .collect()
}
