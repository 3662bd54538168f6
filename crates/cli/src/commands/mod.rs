pub mod demo;
pub mod emps;
pub mod figures;
pub mod identify;
pub mod model;
pub mod montecarlo;
pub mod simulate;
