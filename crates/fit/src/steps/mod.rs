//! Step tests: the paper's method ([`paper_method`], the fit of Eq. (33) in [`model33`]), the
//! full-model fit of R, L, k, f, J, Ts to whole step records ([`full_model`]), the location
//! of the step in a record ([`step_location`]), the steady-state start ([`start`]), the
//! apparent-resistance fit of Eqs. (8), (9) ([`steady_fit`]), and the step-pair pipeline
//! that runs them in turn on a high and a low step ([`pipeline`]).

pub(crate) mod full_model;
pub(crate) mod model33;
pub(crate) mod paper_method;
pub(crate) mod pipeline;
pub(crate) mod start;
pub(crate) mod steady_fit;
pub(crate) mod step_location;
