//! Patrol: the proof that the Strata architecture is general — a second application, not
//! soccer, built on `strata-robot` without changing it.
//!
//! Service robots patrol an office floor: each walks its beat of waypoints, inspects the points
//! of interest on it (where is the extinguisher, really?), and when the operator's console
//! raises an alarm, the planning layer sends exactly one of them — the one with the shortest
//! walk — to see what is there, while the others keep patrolling.
//!
//! | paper | here |
//! |---|---|
//! | missions and roles (Table 1) | [`planning`]: Patrol / Respond; Patroller / Responder |
//! | planning layer, external device (3.3) | [`planning::PatrolPlanning`], [`console::OperatorConsole`] |
//! | deliberative behaviors, state machines with behavior trees (3.4, Table 2) | [`behaviors`] |
//! | value functions, active vision (3.4, 3.6) | [`value`]: inspection quality, route progress |
//! | goals and resources (Table 3) | [`goals`] |
//! | primitive behaviors, activation functions (3.5, Table 4) | [`primitives`], [`activation`] |
//! | objects of interest, world modeling (3.1) | [`world_config`] |
//! | platform (3.7) | [`sim`]: the building on `strata-worldsim`, the robots' platform module |
//!
//! See `README.md` for the whole mapping and how to run it.

pub mod activation;
pub mod behaviors;
pub mod building;
pub mod console;
pub mod goals;
pub mod observer;
pub mod planning;
pub mod primitives;
pub mod robot;
pub mod run;
pub mod sim;
pub mod value;
pub mod world_config;

pub use run::{Outcome, PatrolRun, demo_scenario};
