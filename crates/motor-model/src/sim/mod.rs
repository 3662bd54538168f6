pub(crate) mod dynamics;
pub(crate) mod effects;
pub(crate) mod input;
pub(crate) mod simulator;
