//! How the reports are written: the goals' labels once per goal list (a shared value), their
//! scores every cycle, the selected goal as its place among them.

use serde::{Deserialize, Serialize};
use strata_runtime::{Shared, Time};

use super::{GoalLabels, GoalReport, GoalReports, MuxReport};
use crate::command::ResourceGroup;

/// One goal's scores of a cycle, as written.
#[derive(Serialize, Deserialize)]
#[serde(rename = "GoalScores")]
struct GoalScoresRecord {
    reactive: f64,
    final_score: f64,
    applicable: bool,
}

/// The scores of every goal, written one record each without collecting them first.
struct ScoreRecords<'a>(&'a [GoalReport]);

impl Serialize for ScoreRecords<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeSeq;
        let mut seq = serializer.serialize_seq(Some(self.0.len()))?;
        for r in self.0 {
            seq.serialize_element(&GoalScoresRecord {
                reactive: r.reactive,
                final_score: r.final_score,
                applicable: r.applicable,
            })?;
        }
        seq.end()
    }
}

#[derive(Serialize)]
#[serde(rename = "GoalReports")]
struct GoalReportsOut<'a> {
    labels: &'a Option<Shared<GoalLabels>>,
    scores: ScoreRecords<'a>,
}

#[derive(Deserialize)]
#[serde(rename = "GoalReports")]
struct GoalReportsIn {
    labels: Option<Shared<GoalLabels>>,
    scores: Vec<GoalScoresRecord>,
}

impl Serialize for GoalReports {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        GoalReportsOut { labels: &self.labels, scores: ScoreRecords(self) }.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for GoalReports {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let read = GoalReportsIn::deserialize(deserializer)?;
        let labels = read.labels.as_deref().map_or(&[][..], |labels| &labels.0[..]);
        if labels.len() != read.scores.len() {
            return Err(serde::de::Error::custom(format!(
                "{} goal scores for {} goal labels",
                read.scores.len(),
                labels.len()
            )));
        }
        let list: Vec<GoalReport> = labels
            .iter()
            .zip(read.scores)
            .map(|(label, scores)| GoalReport {
                goal: label.goal.clone(),
                objects: label.objects.clone(),
                deliberative: label.deliberative,
                reactive: scores.reactive,
                final_score: scores.final_score,
                applicable: scores.applicable,
            })
            .collect();
        Ok(GoalReports { list: (!list.is_empty()).then(|| list.into()), labels: read.labels })
    }
}

/// The selected goal, as written.
#[derive(Serialize, Deserialize)]
#[serde(rename = "SelectedGoal", rename_all = "snake_case")]
enum SelectedGoal<S> {
    /// Its place among the goals.
    Goal(u32),
    Label(S),
}

/// A multiplexer's report as written.
#[derive(Serialize, Deserialize)]
#[serde(rename = "MuxReport")]
struct MuxReportWire<G, S, P> {
    group: Option<ResourceGroup>,
    goals: G,
    selected_goal: Option<SelectedGoal<S>>,
    primitive: Option<P>,
    inhibited_by: Option<ResourceGroup>,
    scores_received: Option<Time>,
}

impl Serialize for MuxReport {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let selected_goal = self.selected_goal.as_deref().map(|selected| {
            let place = self.goals.iter().position(|g| &*g.goal == selected);
            match place.and_then(|i| u32::try_from(i).ok()) {
                Some(i) => SelectedGoal::Goal(i),
                None => SelectedGoal::Label(selected),
            }
        });
        MuxReportWire {
            group: self.group,
            goals: &self.goals,
            selected_goal,
            primitive: self.primitive.as_deref(),
            inhibited_by: self.inhibited_by,
            scores_received: self.scores_received,
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for MuxReport {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let wire = MuxReportWire::<GoalReports, String, String>::deserialize(deserializer)?;
        let selected_goal = match wire.selected_goal {
            None => None,
            Some(SelectedGoal::Label(label)) => Some(std::sync::Arc::from(label)),
            Some(SelectedGoal::Goal(i)) => match wire.goals.get(i as usize) {
                Some(goal) => Some(goal.goal.clone()),
                None => {
                    return Err(serde::de::Error::custom(format!(
                        "selected goal {i} of {} goals",
                        wire.goals.len()
                    )));
                }
            },
        };
        Ok(MuxReport {
            group: wire.group,
            goals: wire.goals,
            selected_goal,
            primitive: wire.primitive.map(std::borrow::Cow::Owned),
            inhibited_by: wire.inhibited_by,
            scores_received: wire.scores_received,
        })
    }
}
