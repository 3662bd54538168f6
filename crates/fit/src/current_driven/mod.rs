//! Current-driven axes: the inverse model (IDIM-LS) of J, f, Ts and an offset from the
//! measured torque (current × torque constant) and the axis' position ([`mechanical`]).

pub(crate) mod mechanical;
