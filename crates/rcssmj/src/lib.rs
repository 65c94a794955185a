//! The Booster T1 humanoid in rcssservermj, the RoboCup soccer simulation league's MuJoCo
//! server, as a Strata platform.

pub mod policy;
pub mod protocol;
