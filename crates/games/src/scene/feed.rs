//! Which of a run's packages the scene follows, and the dispatch of each to the
//! [`SceneRecorder`]: what a log's writer and a live server share, so that the two derive the
//! same scene from the same packages.

use strata_runtime::{ErasedPackage, Time};

use super::plot::LayerKind;
use super::{SceneConfig, SceneOutput, SceneRecorder};
use crate::outputs::{DECISION, GROUND_TRUTH, REPORT, SCORES, WORLD_STATE};

/// What a package is to the scene; the index is the robot's among [`SceneTopics::robots`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneSource {
    /// The simulator's ground truth: true poses, the ball, the game's events.
    GroundTruth,
    /// A robot's world state: its estimates.
    World(usize),
    /// A robot's planning decision: its role, and the planning layer's rate.
    Decision(usize),
    /// A robot's deliberative scores: the deliberative layer's rate.
    Scores(usize),
    /// A robot's reactive report: the reactive layer's rate and the head's score vector.
    Report(usize),
}

/// Which topics (`{module}/{output}`, as a log names them) the scene follows: the ground truth
/// and the world states and each layer's output of the robots followed.
#[derive(Clone, Debug)]
pub struct SceneTopics {
    /// Module prefixes (`home/3`, `t10/3`) and the topics of their world states, planning
    /// decisions, deliberative scores and reactive reports.
    robots: Vec<(String, [String; 4])>,
}

impl SceneTopics {
    /// The topics of `robots` (module prefixes) and any ground truth.
    pub fn new(robots: impl IntoIterator<Item = String>) -> SceneTopics {
        let robots = robots
            .into_iter()
            .map(|robot| {
                let topics = [
                    format!("{robot}/world/{WORLD_STATE}"),
                    format!("{robot}/planning/{DECISION}"),
                    format!("{robot}/deliberative/{SCORES}"),
                    format!("{robot}/reactive/{REPORT}"),
                ];
                (robot, topics)
            })
            .collect();
        SceneTopics { robots }
    }

    /// The robots followed, by the index [`SceneSource`] gives.
    pub fn robots(&self) -> impl Iterator<Item = &str> {
        self.robots.iter().map(|(name, _)| name.as_str())
    }

    fn robot(&self, index: usize) -> Option<&str> {
        self.robots.get(index).map(|(name, _)| name.as_str())
    }

    /// What the packages of `topic` are to the scene; `None`: nothing.
    pub fn source(&self, topic: &str) -> Option<SceneSource> {
        let output = topic.rsplit_once('/').map(|(_, output)| output);
        if output == Some(GROUND_TRUTH.name()) {
            return Some(SceneSource::GroundTruth);
        }
        self.robots.iter().enumerate().find_map(|(index, (_, topics))| {
            let kinds = [
                SceneSource::World(index),
                SceneSource::Decision(index),
                SceneSource::Scores(index),
                SceneSource::Report(index),
            ];
            topics.iter().zip(kinds).find_map(|(t, kind)| (t == topic).then_some(kind))
        })
    }
}

/// A [`SceneRecorder`] fed with the packages of the [`SceneTopics`].
#[derive(Debug)]
pub struct SceneFeed {
    recorder: SceneRecorder,
    topics: SceneTopics,
}

impl SceneFeed {
    /// Follows the estimates and roles of `robots` (module prefixes) and any ground truth.
    pub fn new(config: SceneConfig, robots: impl IntoIterator<Item = String>) -> SceneFeed {
        let topics = SceneTopics::new(robots);
        let recorder = SceneRecorder::new(config, topics.robots().map(str::to_owned));
        SceneFeed { recorder, topics }
    }

    pub fn topics(&self) -> &SceneTopics {
        &self.topics
    }

    /// See [`SceneTopics::source`].
    pub fn source(&self, topic: &str) -> Option<SceneSource> {
        self.topics.source(topic)
    }

    /// A package of a topic `source` classified, visible at `time`: what to write. A package
    /// of another type than the topic's is ignored.
    pub fn package(
        &mut self,
        source: SceneSource,
        time: Time,
        package: &dyn ErasedPackage,
    ) -> SceneOutput {
        // Split borrows: the recorder is changed while the robot's name is read.
        let SceneFeed { recorder, topics } = self;
        let name = |index: usize| topics.robot(index);
        match source {
            SceneSource::GroundTruth => match GROUND_TRUTH.downcast(package) {
                Some(truth) => recorder.truth(time, &truth.value),
                None => SceneOutput::default(),
            },
            SceneSource::World(index) => match (name(index), WORLD_STATE.downcast(package)) {
                (Some(robot), Some(state)) => recorder.world(robot, time, &state.value),
                _ => SceneOutput::default(),
            },
            SceneSource::Decision(index) => match (name(index), DECISION.downcast(package)) {
                (Some(robot), Some(decision)) => {
                    recorder.layer(robot, time, LayerKind::Planning);
                    recorder.role(robot, time, decision.value.assignment.role.name())
                }
                _ => SceneOutput::default(),
            },
            SceneSource::Scores(index) => {
                if let (Some(robot), Some(_)) = (name(index), SCORES.downcast(package)) {
                    recorder.layer(robot, time, LayerKind::Deliberative);
                }
                SceneOutput::default()
            }
            SceneSource::Report(index) => {
                if let (Some(robot), Some(report)) = (name(index), REPORT.downcast(package)) {
                    recorder.layer(robot, time, LayerKind::Reactive);
                    recorder.head(robot, time, &report.value.head);
                }
                SceneOutput::default()
            }
        }
    }

    /// An output of a layer's topic (`Decision`, `Scores` or `Report`) at `time`, counted for
    /// its rate without its package: what a live server does between the reports it copies.
    pub fn layer_output(&mut self, source: SceneSource, time: Time) {
        let (index, layer) = match source {
            SceneSource::Decision(i) => (i, LayerKind::Planning),
            SceneSource::Scores(i) => (i, LayerKind::Deliberative),
            SceneSource::Report(i) => (i, LayerKind::Reactive),
            SceneSource::GroundTruth | SceneSource::World(_) => return,
        };
        if let Some(robot) = self.topics.robot(index) {
            self.recorder.layer(robot, time, layer);
        }
    }

    /// See [`SceneRecorder::restart`].
    pub fn restart(&mut self) {
        self.recorder.restart();
    }
}
