//! Robot soccer on the Strata architecture: the missions and roles, deliberative behaviors,
//! goals and primitive behaviors of the paper's Tables 1 to 4, the value functions of active
//! vision, and the team message of Fig. 2.

pub mod catalog;
pub mod goals;
pub mod message;
