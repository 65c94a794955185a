//! What both hosts share: configuration and errors.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::stats::HostStats;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HostConfig {
    /// Seeds every module's RNG (and, on the lockstep host, the processing-time models).
    pub seed: u64,
    /// The span over which min/max rates are measured.
    #[serde(with = "crate::serde_duration")]
    pub stats_window: Duration,
    /// Threaded host: run the threads of the modules declared real-time (the sensor path, see
    /// [`crate::Ports::real_time`]) under `SCHED_FIFO` at this priority (1-99). `None`: every
    /// thread keeps the operating system's default policy. When the system refuses (no
    /// permission, another OS), the module runs with the default policy and its statistics say
    /// why ([`crate::Scheduling::RealTimeRefused`]); nothing else changes.
    #[serde(default)]
    pub real_time_priority: Option<u8>,
    /// Threaded host: how long stopping waits for the module threads after asking them to
    /// stop. A module still inside a cycle then is left running, detached, and named in
    /// [`HostError::StopTimeout`]: a module blocked in a read must not hang its process's exit.
    #[serde(default = "default_stop_timeout", with = "crate::serde_duration")]
    pub stop_timeout: Duration,
}

/// A deliberative cycle takes tens to hundreds of milliseconds; this leaves ample margin.
pub const DEFAULT_STOP_TIMEOUT: Duration = Duration::from_secs(5);

fn default_stop_timeout() -> Duration {
    DEFAULT_STOP_TIMEOUT
}

impl Default for HostConfig {
    fn default() -> Self {
        HostConfig {
            seed: 0,
            stats_window: Duration::from_secs(1),
            real_time_priority: None,
            stop_timeout: DEFAULT_STOP_TIMEOUT,
        }
    }
}

impl HostConfig {
    pub fn with_seed(seed: u64) -> HostConfig {
        HostConfig { seed, ..HostConfig::default() }
    }
}

/// Why a host stopped other than by request. Carries the statistics gathered until then.
#[derive(Debug, thiserror::Error)]
pub enum HostError {
    #[error("module `{module}` panicked: {message}")]
    ModulePanicked { module: String, message: String, stats: Box<HostStats> },
    #[error("module `{module}` failed: {error}")]
    ModuleFailed { module: String, error: String, stats: Box<HostStats> },
    #[error("{}", not_stopped(.modules, *.timeout))]
    StopTimeout { modules: Vec<String>, timeout: Duration, stats: Box<HostStats> },
    #[error("cannot start a module thread: {0}")]
    Spawn(String),
    #[error("{0}")]
    Signal(String),
    #[error(
        "input `{input}` is not declared external: only external inputs can be fed from outside the graph"
    )]
    NotExternal { input: String },
    #[error("cannot decode a package for input `{input}`: {error}")]
    Decode { input: String, error: String },
}

impl HostError {
    /// The statistics gathered before the failure, if any.
    pub fn stats(&self) -> Option<&HostStats> {
        match self {
            HostError::ModulePanicked { stats, .. }
            | HostError::ModuleFailed { stats, .. }
            | HostError::StopTimeout { stats, .. } => Some(stats),
            _ => None,
        }
    }
}

fn not_stopped(modules: &[String], timeout: Duration) -> String {
    let names: Vec<String> = modules.iter().map(|m| format!("`{m}`")).collect();
    let (which, were) = if names.len() == 1 { ("module", "was") } else { ("modules", "were") };
    format!(
        "{which} {} did not stop within {} s (the host's stop timeout) and {were} left running",
        names.join(", "),
        timeout.as_secs_f64()
    )
}

pub(crate) fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_owned()
    }
}
