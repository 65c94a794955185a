//! `strata`: run simulated matches, experiments, the simulator server, robots, the viewer and
//! replays of the Strata architecture.

use std::io::IsTerminal as _;
use std::process::ExitCode;

use anyhow::Result;
use clap::{ArgAction, Parser, Subcommand};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::filter::LevelFilter;

/// A match allocates and frees small packages tens of thousands of times per simulated second
/// (world states, score vectors, reports); mimalloc's thread-local free lists cost a fraction
/// of the system allocator's per call.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

mod chaos_cmd;
mod demo;
mod experiment_cmd;
mod log_cmd;
mod match_cmd;
mod replay_cmd;
mod robot_cmd;
mod sim_cmd;
mod spl_cmd;
mod view_cmd;

/// What `strata --help` ends with.
const AFTER_HELP: &str = "\
Diagnostics go to stderr: warnings and errors by default, -v adds information, -vv
debugging details, -q leaves errors only. RUST_LOG, when set, decides instead (for example
RUST_LOG=strata_nao=debug). Output (text or --json) goes to stdout, never mixed with them.

Exit codes: 0 success; 1 an error (bad arguments, a file that cannot be read, a failed run);
2 `strata replay` ran and the outputs differ from the log.";

#[derive(Debug, Parser)]
#[command(
    name = "strata",
    version,
    about = "A real-time hybrid control architecture for humanoid robots",
    long_about = None,
    after_help = AFTER_HELP
)]
struct Cli {
    /// More diagnostics on stderr: -v information, -vv debugging details, -vvv everything.
    #[arg(short, long, action = ArgAction::Count, global = true)]
    verbose: u8,
    /// Errors only on stderr, no warnings.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

impl Cli {
    /// The most detailed diagnostics shown unless RUST_LOG says otherwise.
    fn level(&self) -> LevelFilter {
        match (self.quiet, self.verbose) {
            (true, _) => LevelFilter::ERROR,
            (false, 0) => LevelFilter::WARN,
            (false, 1) => LevelFilter::INFO,
            (false, 2) => LevelFilter::DEBUG,
            (false, _) => LevelFilter::TRACE,
        }
    }
}

/// Sends the libraries' diagnostics (a lost LoLA link, a refused simulator client, a team
/// message not sent) to stderr, filtered by RUST_LOG when it is set and by `level` otherwise.
fn install_diagnostics(level: LevelFilter) {
    let filter = EnvFilter::builder().with_default_directive(level.into()).from_env_lossy();
    // Fails only when a global subscriber exists already, and nothing else installs one.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
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
    /// The web viewer on a log (or, without one, on a live match): field, robots, estimates,
    /// behavior paths, score plots, timeline.
    View(view_cmd::ViewArgs),
    /// SPL wire formats: decode captured packets, listen to a port.
    #[command(subcommand)]
    Spl(spl_cmd::SplCommand),
    /// The simulator as a TCP server: the world in real time, one process per robot.
    Server(sim_cmd::ServerArgs),
    /// One robot in real time: the full soccer robot over the simulator server or a NAO, its
    /// game state and teammates through the server or a real network (--net).
    Robot(robot_cmd::RobotArgs),
    /// The paper's experiments (section 4) against baselines: goal-covering, rates, fall,
    /// team, or all. Writes a report with tables and plots, and the raw data.
    Experiment(experiment_cmd::ExperimentArgs),
    /// A real-time game under faults (kill -9, SIGSTOP, a slow client, a connection flood,
    /// garbage datagrams, a full log file), measured against its targets (docs/reliability.md).
    Chaos(chaos_cmd::ChaosArgs),
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(error) => {
            let _ = error.print();
            // Help and version are no errors; a usage error is exit code 1, as any other error
            // (clap's own 2 means "the outputs differ" here).
            return if error.use_stderr() { ExitCode::FAILURE } else { ExitCode::SUCCESS };
        }
    };
    install_diagnostics(cli.level());
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) if error.is::<replay_cmd::OutputsDiffer>() => {
            // Not an error: the replay ran and answered the question.
            eprintln!("{error}");
            ExitCode::from(replay_cmd::OUTPUTS_DIFFER_EXIT_CODE)
        }
        Err(error) => {
            // The message and its causes only: returning the error from `main` would print
            // anyhow's backtrace too whenever RUST_BACKTRACE is set (as many set it for panics),
            // burying a config or file error under frames of this program.
            let mut printed = error.to_string();
            eprintln!("error: {printed}");
            for cause in error.chain().skip(1) {
                // Many errors here quote their cause in their own message already.
                let cause = cause.to_string();
                if !printed.contains(&cause) {
                    eprintln!("  caused by: {cause}");
                    printed.push_str(&cause);
                }
            }
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Match(args) => match_cmd::run(args),
        Command::DemoRuntime(args) => demo::run(args),
        Command::Spl(cmd) => spl_cmd::run(cmd),
        Command::Log(cmd) => log_cmd::run(cmd),
        Command::Server(args) => sim_cmd::run_server(args),
        Command::Robot(args) => robot_cmd::run(args),
        Command::Experiment(args) => experiment_cmd::run(args),
        Command::Chaos(args) => chaos_cmd::run(args),
        Command::View(args) => view_cmd::run(args),
        Command::Replay(args) => replay_cmd::run(args, &strata_games::replay_registry::soccer()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory as _;

    /// The global -v/-q flags clash with no subcommand's own flags.
    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }

    /// `strata robot`'s defaults are the library's: a robot run from Rust with
    /// `RobotOptions::new` behaves as one run from the command line.
    #[test]
    fn robot_defaults_are_the_librarys() {
        let cli = Cli::try_parse_from(["strata", "robot", "--team", "3", "--player", "2"])
            .expect("parses");
        let Command::Robot(args) = cli.command else { panic!("not the robot command") };
        assert_eq!(
            args.options,
            strata_games::robot::RobotOptions::new(3, 2, strata_games::robot::PlatformKind::Sim)
        );
    }
}
