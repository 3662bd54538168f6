//! Records of any excitation (staircases, PRBS, sines): the output-error fit through the
//! stick-slip simulator ([`output_error`], its problem in [`oe_problem`], its start from the
//! equation error in [`equation_error`], the voltage waveform from a measured column in
//! [`voltage`]), records that do not start at rest
//! ([`initial_state`]), and the measured step levels as inputs whose uncertainty enters the
//! intervals ([`input_uncertainty`]).

pub(crate) mod equation_error;
pub(crate) mod initial_state;
pub(crate) mod input_uncertainty;
pub(crate) mod oe_problem;
pub(crate) mod output_error;
pub(crate) mod voltage;
