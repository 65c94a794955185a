//! `strata.run_match`: a game on the built-in simulator, as `strata match` plays it.

use std::path::PathBuf;

use pyo3::prelude::*;
use serde::Deserialize;
use strata_games::logging::{LogSettings, MatchLog};
use strata_games::matches::{Match, MatchConfig};
use strata_sim::NoiseLevel;
use strata_soccer::team::TeamConfig;

use crate::{config_error, from_json, run_error, to_json};

/// The match's settings: `strata match`'s options of the same names.
#[derive(Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct MatchSpec {
    players: u8,
    seed: u64,
    /// A built-in team or a team TOML file.
    home: String,
    away: String,
    /// Length of a half, simulated s.
    half: f64,
    /// Stop after this many simulated seconds.
    duration: Option<f64>,
    noise: NoiseLevel,
    field: String,
    packet_loss: f64,
    no_delay: bool,
    /// Record every package into this MCAP file (`strata match --log`).
    log: Option<PathBuf>,
}

impl Default for MatchSpec {
    fn default() -> Self {
        MatchSpec {
            players: 7,
            seed: 1,
            home: "full".into(),
            away: "full".into(),
            half: 600.0,
            duration: None,
            noise: NoiseLevel::Default,
            field: "spl".into(),
            packet_loss: 0.0,
            no_delay: false,
            log: None,
        }
    }
}

impl MatchSpec {
    fn config(&self) -> PyResult<MatchConfig> {
        let team = |field: &str, name: &str| {
            TeamConfig::resolve(name).map_err(|e| config_error(format!("field `{field}`: {e:#}")))
        };
        if !(0.0..=1.0).contains(&self.packet_loss) {
            return Err(config_error("field `packet_loss`: must be in [0, 1]"));
        }
        if !(self.half.is_finite() && self.half > 0.0) {
            return Err(config_error("field `half`: must be a positive number of seconds"));
        }
        if self.duration.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
            return Err(config_error("field `duration`: must be a positive number of seconds"));
        }
        Ok(MatchConfig {
            players: self.players,
            seed: self.seed,
            home: team("home", &self.home)?,
            away: team("away", &self.away)?,
            half_duration: self.half,
            limit: self.duration,
            noise: self.noise,
            field: self.field.clone(),
            packet_loss: self.packet_loss,
            realtime: false,
            sim: None,
            no_delay: self.no_delay,
        })
    }
}

/// Plays the match `config_json` describes (lockstep, as fast as the machine goes, without the
/// GIL) and returns its report as JSON (`strata match --json`).
#[pyfunction]
pub fn run_match(py: Python<'_>, config_json: &str) -> PyResult<String> {
    let spec: MatchSpec = from_json(config_json, "match config")?;
    let config = spec.config()?;
    let report = py.detach(|| -> anyhow::Result<_> {
        let mut game = Match::new(config)?;
        let log = match &spec.log {
            Some(path) => Some(MatchLog::attach(&mut game, &LogSettings::full(path))?),
            None => None,
        };
        let report = game.play(&mut |_, _| {})?;
        if let Some(log) = &log {
            log.finish()?;
        }
        Ok(report)
    });
    to_json(&report.map_err(run_error)?)
}
