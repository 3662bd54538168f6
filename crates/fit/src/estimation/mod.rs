//! The estimation core every route shares: the Levenberg–Marquardt solver ([`lm`]), the
//! statistics behind the intervals ([`stats`]), the parameter tables and their transforms
//! ([`parameters`], [`intervals`]), the record and channel types and noise levels
//! ([`records`]), the weighted two-stage fit ([`weighted`]), the fitted result ([`fitted`]),
//! the checks of records before a fit ([`checks`]) and the judgement of a fit after it
//! ([`plausibility`]), the filters ([`signal`]), speeds from encoder angles ([`speed`]),
//! clipped samples ([`clipping`]) and accuracy summaries ([`accuracy`]).
//!
//! Nothing here knows a route: step tests, records of any excitation, current-driven axes,
//! voltage-and-speed records and the diagnosis all build on it, never the other way round.

pub(crate) mod accuracy;
pub(crate) mod checks;
pub(crate) mod clipping;
pub(crate) mod fitted;
pub(crate) mod intervals;
pub(crate) mod lm;
pub(crate) mod parameters;
pub(crate) mod plausibility;
pub(crate) mod records;
pub(crate) mod refusal;
pub(crate) mod signal;
pub(crate) mod speed;
pub(crate) mod stats;
pub(crate) mod weighted;
