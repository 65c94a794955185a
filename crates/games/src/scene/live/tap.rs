//! The tap on a run's host: on the match thread (or a module's thread), it only picks the
//! packages the scene follows and hands copies of them to the server's worker thread.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use crossbeam_channel::{Sender, TrySendError};
use strata_runtime::{ErasedPackage, ModuleId, Tap, TapOutput, TapRecord, Time};

use crate::outputs::{DECISION, GROUND_TRUTH, REPORT, SCORES, WORLD_STATE};
use crate::pacing::Pacer;
use crate::scene::feed::{SceneSource, SceneTopics};

/// What the worker thread is handed.
pub(super) enum Work {
    Package {
        source: SceneSource,
        time: Time,
        package: Box<dyn ErasedPackage>,
    },
    /// A layer's output, counted for its rate without a copy of its package.
    Layer {
        source: SceneSource,
        time: Time,
    },
    /// Everything before was handed on: publish it and stop.
    Stop,
}

/// The outputs the scene reads (which of their modules' packages it follows, the
/// [`SceneTopics`] tell).
const SCENE_OUTPUTS: [&str; 5] =
    [GROUND_TRUTH.name(), WORLD_STATE.name(), DECISION.name(), SCORES.name(), REPORT.name()];

/// A robot's reactive report is copied for its head scores at most this often, s (the plot's
/// period); the others are only counted: a report comes every reactive cycle of every robot.
const REPORT_COPY_PERIOD: f64 = 0.1;

/// Feeds a [`super::SceneServer`]. A package the worker cannot take at once (its queue is
/// full: it fell behind) is dropped and counted, never waited for: the run must not slow down
/// for its viewers. Paces a lockstep match when built with a [`Pacer`].
pub struct SceneTap {
    topics: SceneTopics,
    /// By host, module and output: what the output's packages are to the scene. Filled as
    /// outputs show up; the key spares the match thread a topic name per package.
    sources: Mutex<HashMap<(u64, ModuleId, u16), Option<SceneSource>>>,
    /// When each robot's reactive report was last copied.
    reports_copied: Mutex<HashMap<usize, Time>>,
    work: Sender<Work>,
    dropped: Arc<AtomicU64>,
    pacer: Option<Pacer>,
}

impl std::fmt::Debug for SceneTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneTap").field("pacer", &self.pacer).finish_non_exhaustive()
    }
}

impl SceneTap {
    pub(super) fn new(
        topics: SceneTopics,
        work: Sender<Work>,
        dropped: Arc<AtomicU64>,
        pacer: Option<Pacer>,
    ) -> SceneTap {
        SceneTap {
            topics,
            sources: Mutex::default(),
            reports_copied: Mutex::default(),
            work,
            dropped,
            pacer,
        }
    }

    fn source(&self, output: &TapOutput<'_>) -> Option<SceneSource> {
        let key = (output.host, output.module, output.port);
        let mut sources = self.sources.lock().unwrap_or_else(PoisonError::into_inner);
        *sources.entry(key).or_insert_with(|| {
            self.topics.source(&strata_log::package_topic(output.module_name, output.output))
        })
    }
}

impl Tap for SceneTap {
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        SCENE_OUTPUTS.contains(&output.output)
    }

    fn package(&self, record: &TapRecord<'_>) {
        if !SCENE_OUTPUTS.contains(&record.sent_on.output) {
            return;
        }
        let Some(source) = self.source(&record.sent_on) else { return };
        let time = record.time;
        let copy = match source {
            SceneSource::Scores(_) => false,
            SceneSource::Report(robot) => {
                let mut copied = self.reports_copied.lock().unwrap_or_else(PoisonError::into_inner);
                let due = copied
                    .get(&robot)
                    .is_none_or(|t| time.saturating_since(*t).as_secs_f64() >= REPORT_COPY_PERIOD);
                if due {
                    copied.insert(robot, time);
                }
                due
            }
            _ => true,
        };
        let work = if copy {
            Work::Package { source, time, package: record.package.clone_boxed() }
        } else {
            Work::Layer { source, time }
        };
        match self.work.try_send(work) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
            // The server was finished: nothing is served any more.
            Err(TrySendError::Disconnected(_)) => {}
        }
        if source == SceneSource::GroundTruth
            && let Some(pacer) = &self.pacer
        {
            pacer.pace(record.time);
        }
    }
}
