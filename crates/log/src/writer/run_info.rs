//! The run a log records: seed, command line, version and configuration text.

use serde::{Deserialize, Serialize};

/// The format of the configuration text stored with a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ConfigFormat {
    Toml,
    Json,
}

impl ConfigFormat {
    pub fn extension(self) -> &'static str {
        match self {
            ConfigFormat::Toml => "toml",
            ConfigFormat::Json => "json",
        }
    }

    pub(super) fn media_type(self) -> &'static str {
        match self {
            ConfigFormat::Toml => "application/toml",
            ConfigFormat::Json => "application/json",
        }
    }
}

/// What replay needs to rebuild a run besides the graph: the seed, the configuration the
/// modules were built from (store the effective one, defaults filled in, so `--set` can reach
/// every parameter), and where it came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    pub seed: u64,
    pub command_line: Vec<String>,
    /// The program's version (no git: a release's crate version and build profile).
    pub version: String,
    /// The configuration text as given, and its format.
    pub config: Option<(ConfigFormat, String)>,
}

impl RunInfo {
    /// A run of this process: its command line and the version of this crate.
    pub fn current(seed: u64) -> RunInfo {
        RunInfo {
            seed,
            command_line: std::env::args().collect(),
            version: format!(
                "strata {} ({})",
                env!("CARGO_PKG_VERSION"),
                if cfg!(debug_assertions) { "debug" } else { "release" }
            ),
            config: None,
        }
    }

    pub fn with_config(mut self, format: ConfigFormat, text: impl Into<String>) -> RunInfo {
        self.config = Some((format, text.into()));
        self
    }
}
