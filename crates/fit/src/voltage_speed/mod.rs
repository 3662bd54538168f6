//! Records without a current sensor: the voltage-to-speed model (kS, kV, kA and τe,
//! [`feedforward`]) and what a set of records can identify from the channels it measured
//! ([`record_kind`]).

pub(crate) mod feedforward;
pub(crate) mod record_kind;
