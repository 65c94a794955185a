//! The tap on a run's host: on the match thread (or a module's thread), it only picks the
//! packages the scene follows and hands copies of them to the server's worker thread.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use crossbeam_channel::{Sender, TrySendError};
use strata_runtime::{ErasedPackage, ModuleId, Tap, TapOutput, TapRecord, Time};

use crate::outputs::{DECISION, GROUND_TRUTH, WORLD_STATE};
use crate::pacing::Pacer;
use crate::scene::feed::{SceneSource, SceneTopics};

/// What the worker thread is handed.
pub(super) enum Work {
    Package {
        source: SceneSource,
        time: Time,
        package: Box<dyn ErasedPackage>,
    },
    /// Everything before was handed on: publish it and stop.
    Stop,
}

/// The outputs the scene reads (which of their modules' packages it follows, the
/// [`SceneTopics`] tell).
const SCENE_OUTPUTS: [&str; 3] = [GROUND_TRUTH.name(), WORLD_STATE.name(), DECISION.name()];

/// Feeds a [`super::SceneServer`]. A package the worker cannot take at once (its queue is
/// full: it fell behind) is dropped and counted, never waited for: the run must not slow down
/// for its viewers. Paces a lockstep match when built with a [`Pacer`].
pub struct SceneTap {
    topics: SceneTopics,
    /// By host, module and output: what the output's packages are to the scene. Filled as
    /// outputs show up; the key spares the match thread a topic name per package.
    sources: Mutex<HashMap<(u64, ModuleId, u16), Option<SceneSource>>>,
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
        SceneTap { topics, sources: Mutex::default(), work, dropped, pacer }
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
        let work =
            Work::Package { source, time: record.time, package: record.package.clone_boxed() };
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
