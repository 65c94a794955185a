//! Strata on the Booster T1 in rcssservermj (docs/rcssservermj.md): what games and experiments
//! in physics share. Each robot is a `strata robot --platform rcssservermj` process, as it
//! would be on a real robot: its own threaded host, its own CPU time, and a robot that fails
//! ends alone; the server is [`strata_rcssmj::server::ServerProcess`].
//!
//! - [`robot`]: starting, following and stopping robot processes;
//! - [`cpu`]: the CPU time a process has used (the server's physics against Strata's share).

pub mod cpu;
pub mod game;
pub mod robot;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use clap::ValueEnum;
use serde::{Deserialize, Serialize};

/// Fails once the user pressed Ctrl-C or the process got SIGTERM. Games and experiments in
/// physics call it in every wait: the error stops them the way any failure does, with their
/// robots stopped and the server killed, instead of the process dying with its children still
/// running (a server in sync mode and robots waiting for it). The first call installs the
/// handler, so each command calls it once as it starts.
pub fn check_interrupt() -> anyhow::Result<()> {
    static FLAG: OnceLock<Option<Arc<AtomicBool>>> = OnceLock::new();
    let flag = FLAG.get_or_init(|| strata_runtime::signal::interrupt_flag().ok());
    if flag.as_ref().is_some_and(|f| f.load(Ordering::SeqCst)) {
        anyhow::bail!("interrupted (Ctrl-C or SIGTERM): robots stopped, server ended");
    }
    Ok(())
}

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
