//! Records without a current sensor: the voltage-to-speed model (kS, kV, kA and τe: its fit in
//! [`feedforward`], its parameters and results in [`model`], its exact solution in
//! [`simulation`], its least-squares problem in [`ff_problem`]) and what a set of records can identify from the channels it measured
//! ([`record_kind`]).

pub(crate) mod feedforward;
pub(crate) mod ff_problem;
pub(crate) mod model;
pub(crate) mod record_kind;
pub(crate) mod simulation;
