//! `strata log`: look into MCAP logs written with `--log` (`docs/logging.md`).

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;
use strata_log::{LogInfo, LogReader};

/// The `log` subcommands.
#[derive(Debug, Subcommand)]
pub enum LogCommand {
    /// Say what a log holds: complete or truncated (and how much was recovered), duration,
    /// messages per topic and their types, metadata, packages dropped while recording.
    Info {
        /// The log (MCAP).
        file: PathBuf,
        /// Print the description as JSON.
        #[arg(long)]
        json: bool,
    },
    /// Print messages as JSON lines: topic, log time, stamp, sequence number, value.
    Cat {
        /// The log (MCAP).
        file: PathBuf,
        /// Only these topics (repeatable); all by default.
        #[arg(long = "topic")]
        topics: Vec<String>,
        /// Stop after this many messages.
        #[arg(long)]
        limit: Option<usize>,
    },
}

/// Runs a `log` subcommand.
pub fn run(cmd: LogCommand) -> Result<()> {
    match cmd {
        LogCommand::Info { file, json } => {
            let reader = LogReader::open(&file)?;
            let info = LogInfo::of(&reader);
            let text = if json {
                format!("{}\n", serde_json::to_string_pretty(&info)?)
            } else {
                info.to_string()
            };
            // A closed pipe (`| head`) ends the description, not with a panic.
            let _ = std::io::stdout().lock().write_all(text.as_bytes());
            Ok(())
        }
        LogCommand::Cat { file, topics, limit } => {
            let reader = LogReader::open(&file)?;
            if let Some(recovery) = reader.recovery() {
                eprintln!(
                    "note: {} was not finished; reading the {} messages recovered from it",
                    file.display(),
                    recovery.messages
                );
            }
            for topic in &topics {
                if reader.topic(topic).is_none() {
                    eprintln!("note: {} has no topic `{topic}`", file.display());
                }
            }
            let messages = if topics.is_empty() {
                reader.messages()
            } else {
                reader.messages_on(topics.iter().map(String::as_str))
            };
            let stdout = std::io::stdout();
            let mut out = stdout.lock();
            for message in messages.take(limit.unwrap_or(usize::MAX)) {
                let message = message?;
                let value: serde_json::Value = message.json().with_context(|| {
                    format!(
                        "message {} of `{}` is not valid {}",
                        message.seq,
                        message.topic,
                        message.encoding.mcap_name()
                    )
                })?;
                let line = serde_json::json!({
                    "topic": &*message.topic,
                    "time": message.log_time.as_secs_f64(),
                    "stamp": message.stamp.as_secs_f64(),
                    "seq": message.seq,
                    "value": value,
                });
                // A closed pipe (`| head`) ends the listing, not with an error.
                if writeln!(out, "{line}").is_err() {
                    break;
                }
            }
            Ok(())
        }
    }
}
