//! Strata on the Booster T1 in rcssservermj (docs/rcssservermj.md): what games and experiments
//! in physics share. Each robot is a `strata robot --platform rcssservermj` process, as it
//! would be on a real robot: its own threaded host, its own CPU time, and a robot that fails
//! ends alone; the server is [`strata_rcssmj::server::ServerProcess`].
//!
//! - [`robot`]: starting, following and stopping robot processes;
//! - [`cpu`]: the CPU time a process has used (the server's physics against Strata's share).

pub mod cpu;
pub mod experiments;
pub mod game;
pub mod robot;

use clap::ValueEnum;
use serde::{Deserialize, Serialize};

/// Which world a match or an experiment runs in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Engine {
    /// Strata's own 2D simulator: deterministic, lockstep, hundreds of times real time.
    #[default]
    Sim,
    /// Booster T1s in rcssservermj, the RoboCup simulation league's MuJoCo server
    /// (`scripts/setup-rcssservermj` installs it).
    Rcssservermj,
}
