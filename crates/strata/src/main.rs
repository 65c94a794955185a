//! `strata`: run simulated matches, experiments, the simulator server, robots, the viewer and
//! replays of the Strata architecture.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod demo;
mod log_cmd;
mod match_cmd;
mod replay_cmd;
mod spl_cmd;

#[derive(Debug, Parser)]
#[command(name = "strata", version, about = "A real-time hybrid control architecture for humanoid robots", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Play a complete simulated game: every robot runs the full architecture.
    Match(match_cmd::MatchArgs),
    /// Run a small module graph on both hosts and print their statistics.
    DemoRuntime(demo::DemoArgs),
    /// Look into logs written with --log.
    #[command(subcommand)]
    Log(log_cmd::LogCommand),
    /// Re-run modules of one robot from a log and compare their outputs with the logged ones.
    Replay(replay_cmd::ReplayArgs),
    /// SPL wire formats: decode captured packets, listen to a port.
    #[command(subcommand)]
    Spl(spl_cmd::SplCommand),
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Match(args) => match_cmd::run(args),
        Command::DemoRuntime(args) => demo::run(args),
        Command::Spl(cmd) => spl_cmd::run(cmd),
        Command::Log(cmd) => log_cmd::run(cmd),
        Command::Replay(args) => replay_cmd::run(args, &strata_log::replay::ModuleRegistry::new()),
    }
}
