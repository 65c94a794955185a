//! The library behind the `strata` command: simulated matches and experiments, built from the
//! soccer application and the simulator (which the application itself never imports), their
//! logs, the replay registry and the web viewer.

pub mod chaos;
pub mod children;
pub mod experiments;
pub mod links;
pub mod logging;
pub mod matches;
pub mod physics;
pub mod replay_registry;
pub mod view;
