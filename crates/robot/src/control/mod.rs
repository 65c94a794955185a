//! Hybrid control (paper 3.2–3.6): the planning, deliberative and reactive layers, the resource
//! multiplexers, value functions and active vision.

pub mod active_vision;
pub mod bt;
pub mod deliberative;
pub mod hsm;
pub mod modules;
pub mod planning;
pub mod planning_module;
pub mod primitives;
pub mod reactive;
pub mod scores;
