pub(crate) mod dynamics;
pub(crate) mod effects;
pub(crate) mod exact;
pub(crate) mod input;
pub(crate) mod simulator;
pub(crate) mod trace;
