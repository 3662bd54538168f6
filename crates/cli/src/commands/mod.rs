pub mod demo;
pub mod model;
pub mod simulate;
