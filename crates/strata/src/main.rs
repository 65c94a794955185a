//! `strata`: run simulated matches, experiments, the simulator server, robots, the viewer and
//! replays of the Strata architecture.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod demo;
mod spl_cmd;

#[derive(Debug, Parser)]
#[command(name = "strata", version, about = "A real-time hybrid control architecture for humanoid robots", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a small module graph on both hosts and print their statistics.
    DemoRuntime(demo::DemoArgs),
    /// SPL wire formats: decode captured packets, listen to a port.
    #[command(subcommand)]
    Spl(spl_cmd::SplCommand),
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::DemoRuntime(args) => demo::run(args),
        Command::Spl(cmd) => spl_cmd::run(cmd),
    }
}
