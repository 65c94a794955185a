//! The web viewer (`strata view`, `strata match --view`): the field with the robots, true and
//! estimated poses and balls, team ball, gaze targets and behavior paths, plots of the
//! activation scores and the ball confidence (the paper's Fig. 5), and a timeline
//! (`docs/viewer.md`).
//!
//! - [`data::ViewData`] holds what is shown, fed from a log ([`load_log`]) or live from a
//!   match's tap ([`LiveTap`]);
//! - [`server::ViewServer`] serves the page (static files compiled into the binary) and the
//!   JSON endpoints `/api/info`, `/api/frame?t=` and `/api/series?robot=&from=&to=`.

pub mod data;
pub mod request;
pub mod server;

use std::path::Path;
use std::sync::{Arc, PoisonError, RwLock};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use strata_log::LogReader;
use strata_runtime::{Tap, TapOutput, TapRecord};
use strata_spl::field::Field;

use data::ViewData;
pub use server::ViewServer;
use strata_games::logging::{RobotRunConfig, RunConfig};
use strata_games::matches::Match;
use strata_games::outputs;
use strata_games::pacing::Pacer;

/// The outputs whose packages the viewer shows (`data::classify` tells which module's).
const SHOWN_OUTPUTS: [&str; 5] = [
    outputs::GROUND_TRUTH.name(),
    outputs::WORLD_STATE.name(),
    outputs::REPORT.name(),
    outputs::SCORES.name(),
    outputs::DECISION.name(),
];

/// How many messages the loader ingests between two releases of the lock, so that the page can
/// be served while a long log is read.
const LOAD_BATCH: usize = 2000;

/// Opens a log for viewing: its configuration now, its packages on a background thread (the
/// page shows what has been read so far; `/api/info` says `growing` until the end).
pub fn load_log(path: &Path) -> Result<Arc<RwLock<ViewData>>> {
    let reader = LogReader::open(path).with_context(|| format!("opening {}", path.display()))?;
    let config = reader.config().ok().flatten();
    // A robot's own log holds one robot's configuration, an experiment's one per robot: either
    // gives the field and the camera a match's configuration would.
    let robot: Option<RobotRunConfig> = config.as_ref().and_then(|c| {
        let one = c.get("robots").and_then(|r| r.as_object()?.values().next()).unwrap_or(c);
        serde_json::from_value(one.clone()).ok()
    });
    let run: Option<RunConfig> = config.and_then(|c| serde_json::from_value(c).ok());
    let dimensions = match (&run, &robot) {
        (Some(run), _) => Some(run.field.clone()),
        (None, Some(robot)) => Some(robot.field.clone()),
        (None, None) => None,
    };
    let field = match dimensions {
        Some(dimensions) => {
            Field::new(dimensions, "the logged field").context("the log's field cannot be used")?
        }
        None => Field::preset("spl").context("the built-in SPL field")?,
    };
    let mut data = ViewData::new("log", Some(path.display().to_string()), &field);
    data.set_seed(reader.run_info().ok().flatten().map(|r| r.seed));
    match (&run, &robot) {
        (Some(run), _) => {
            data.set_teams([run.home.name.clone(), run.away.name.clone()]);
            data.set_camera(run.platform.camera_fov, run.platform.camera_range);
        }
        (None, Some(robot)) => {
            data.set_teams([robot.team.name.clone(), String::new()]);
            data.set_camera(robot.platform.camera_fov, robot.platform.camera_range);
        }
        (None, None) => data.warn(
            "the log holds no configuration: the SPL field and the default camera are shown"
                .to_owned(),
        ),
    }
    if let Some(recovery) = reader.recovery() {
        data.warn(format!(
            "the log was not finished: showing the {} messages recovered from it",
            recovery.messages
        ));
        if recovery.skipped_chunks > 0 {
            data.warn(format!(
                "{} damaged chunks of the log were skipped: their messages are missing",
                recovery.skipped_chunks
            ));
        }
    }
    let data = Arc::new(RwLock::new(data));
    let shared = Arc::clone(&data);
    std::thread::Builder::new()
        .name("strata-view-load".to_owned())
        .spawn(move || {
            let mut batch = Vec::with_capacity(LOAD_BATCH);
            let mut messages = reader.messages();
            loop {
                batch.clear();
                let mut failure = None;
                for message in messages.by_ref() {
                    match message {
                        Ok(m) => batch.push(m),
                        Err(e) => {
                            failure = Some(e);
                            break;
                        }
                    }
                    if batch.len() >= LOAD_BATCH {
                        break;
                    }
                }
                let mut data = shared.write().unwrap_or_else(PoisonError::into_inner);
                for m in &batch {
                    let value = data::Incoming::Logged {
                        encoding: m.encoding,
                        format: m.format.as_deref(),
                        bytes: &m.data,
                    };
                    data.ingest(&m.topic, m.log_time, value);
                }
                if let Some(e) = failure {
                    data.warn(format!("reading stopped early: {e}"));
                    data.set_complete();
                    return;
                }
                if batch.is_empty() {
                    data.set_complete();
                    return;
                }
            }
        })
        .context("starting the log reader thread")?;
    Ok(data)
}

/// Waits (up to `limit`) until a log is read completely; true if it was.
pub fn wait_loaded(data: &RwLock<ViewData>, limit: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if !data.read().unwrap_or_else(PoisonError::into_inner).info().growing {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

/// Feeds a live match's packages to the viewer, and paces a lockstep match to `speed` times real
/// time so that it can be watched (the lockstep host otherwise runs as fast as it can).
pub struct LiveTap {
    data: Arc<RwLock<ViewData>>,
    /// `None`: unpaced.
    pacer: Option<Pacer>,
}

impl std::fmt::Debug for LiveTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveTap").field("pacer", &self.pacer).finish_non_exhaustive()
    }
}

impl LiveTap {
    /// The viewer's store for `game`, and a tap that fills it. `speed`: pace a lockstep match
    /// at this many times real time.
    pub fn for_match(game: &Match, speed: Option<f64>) -> (Arc<RwLock<ViewData>>, LiveTap) {
        let run = RunConfig::of(game);
        let field = game.sim.lock().field().clone();
        let mut data = ViewData::new("live", None, &field);
        data.set_teams([run.home.name.clone(), run.away.name.clone()]);
        data.set_camera(run.platform.camera_fov, run.platform.camera_range);
        data.set_seed(Some(run.seed));
        let data = Arc::new(RwLock::new(data));
        let tap = LiveTap { data: Arc::clone(&data), pacer: speed.and_then(Pacer::new) };
        (data, tap)
    }
}

impl Tap for LiveTap {
    /// The host then shows the viewer only the outputs it draws: a match sends thousands of
    /// packages per simulated second, most of which it would look at only to skip.
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        SHOWN_OUTPUTS.contains(&output.output)
    }

    fn package(&self, record: &TapRecord<'_>) {
        // Most packages are of no interest to the viewer: skip them before any allocation.
        if !SHOWN_OUTPUTS.contains(&record.sent_on.output) {
            return;
        }
        let topic = strata_log::package_topic(record.sent_on.module_name, record.sent_on.output);
        let wanted =
            self.data.read().unwrap_or_else(PoisonError::into_inner).wants(&topic, record.time);
        if wanted {
            self.data.write().unwrap_or_else(PoisonError::into_inner).ingest(
                &topic,
                record.time,
                data::Incoming::Live(record.package),
            );
        }
        if record.sent_on.output == outputs::GROUND_TRUTH.name()
            && let Some(pacer) = &self.pacer
        {
            pacer.pace(record.time);
        }
    }
}
