//! `strata view [FILE.mcap]`: the web viewer on a log (or, without a file, on a live match).

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::{Context as _, Result};
use clap::Args;
use strata_view::{ViewServer, load_log};

use crate::match_cmd;

#[derive(Debug, Args)]
pub struct ViewArgs {
    /// A log written with `--log`. Without one, a match is played and shown live (as
    /// `strata match --view`, with the default match options).
    pub file: Option<PathBuf>,
    /// The port to serve on, on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
}

pub fn run(args: ViewArgs) -> Result<()> {
    let Some(file) = args.file else {
        let mut live = match_cmd::MatchArgs::defaults();
        live.view = true;
        live.port = args.port;
        return match_cmd::run(live);
    };
    let data = load_log(&file)?;
    let server = ViewServer::start(data, args.port)
        .with_context(|| format!("serving the viewer on 127.0.0.1:{}", args.port))?;
    println!("viewer: {} (showing {}; Ctrl-C to stop)", server.url(), file.display());
    wait_for_interrupt()?;
    drop(server);
    Ok(())
}

/// Blocks until Ctrl-C.
pub fn wait_for_interrupt() -> Result<()> {
    let interrupt = strata_runtime::signal::interrupt_flag().map_err(anyhow::Error::msg)?;
    while !interrupt.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(())
}
