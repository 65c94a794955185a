//! Strata's soccer robots composed with a world, as a library: what the `strata` command and
//! the experiments (`strata-experiments`) build on, and what a user calls from Rust.
//!
//! - [`matches`]: a match on the built-in simulator, `Match::new(config)?.play(progress)`;
//! - [`physics`]: a game of T1s in rcssservermj, `physics::game::play(&config, progress)`, and
//!   the robot processes it starts;
//! - [`links`]: a robot's network links (team messages over UDP, GameController packets);
//! - [`logging`]: the run configuration written at the start of every log, and match logs;
//! - [`replay_registry`]: which modules of a logged robot `strata replay` can re-run;
//! - [`robot`]: one robot in real time on its platform (the simulator server, a NAO, a T1 in
//!   rcssservermj), what `strata robot` runs;
//! - [`children`]: child processes that end with their parent;
//! - [`outputs`]: the typed names of the outputs taps read.
//!
//! The soccer application (`strata-soccer`) never imports the simulator; this crate is where
//! the two meet.

pub mod children;
pub mod links;
pub mod logging;
pub mod matches;
pub mod outputs;
pub mod pacing;
pub mod physics;
pub mod replay_registry;
pub mod robot;
pub mod scene;
