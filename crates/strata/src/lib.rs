//! The library behind the `strata` command: simulated matches and experiments, built from the
//! soccer application and the simulator (which the application itself never imports).

pub mod matches;
