//! What the reactive layer decided, for debugging and logs: each goal's scores and each
//! multiplexer's decision (the whole cycle's report, with the labels it shares, is defined in
//! `mod.rs`).

use std::fmt::Debug;

use serde::{Deserialize, Serialize};
use strata_runtime::{Shared, Time};

use super::{GoalLabel, GoalLabels};
use crate::command::ResourceGroup;

/// One goal as the activation function scored it this cycle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GoalReport {
    /// Shared with the multiplexer's cache: reports are made every cycle and must not copy
    /// strings they already have.
    pub goal: std::sync::Arc<str>,
    pub objects: std::sync::Arc<[String]>,
    /// S_d
    pub deliberative: f64,
    /// S_r
    pub reactive: f64,
    /// combine(S_d, S_r), before the hysteresis bonus.
    pub final_score: f64,
    /// Whether a (non-deactivated) primitive could pursue it now.
    pub applicable: bool,
}

/// The goals a multiplexer scored in one cycle, in the order it scored them: a list shared
/// with the multiplexer, since consecutive cycles on one world state score the same goals the
/// same way and must not copy their reports. Reads as a slice.
///
/// Serialized as the goals' labels — what they are, which changes with the score vector or
/// the split of its goals, seldom at the reactive layer's rate: a [`Shared`] value a log stores
/// once — and each goal's scores of this cycle.
#[derive(Clone, Default)]
pub struct GoalReports {
    pub(super) list: Option<std::sync::Arc<[GoalReport]>>,
    /// The labels of `list`'s goals; `None` when there are none.
    pub(super) labels: Option<Shared<GoalLabels>>,
}

impl std::ops::Deref for GoalReports {
    type Target = [GoalReport];

    fn deref(&self) -> &[GoalReport] {
        self.list.as_deref().unwrap_or_default()
    }
}

impl<'a> IntoIterator for &'a GoalReports {
    type Item = &'a GoalReport;
    type IntoIter = std::slice::Iter<'a, GoalReport>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl GoalReports {
    /// Replaces the list with `reports`' (leaving `reports` empty, its capacity kept): in
    /// place when nobody else holds the list any longer and it is as long, as it is when a
    /// multiplexer assesses the same goals on a new world state after the previous cycle's
    /// report was dropped. The labels are kept when the goals are the same.
    pub(super) fn replace(&mut self, reports: &mut Vec<GoalReport>) {
        let same_labels = self.labels.as_ref().is_some_and(|labels| {
            labels.len() == reports.len()
                && labels.iter().zip(reports.iter()).all(|(l, r)| l.labels(r))
        });
        if !same_labels {
            self.labels = GoalReports::labels_of(reports);
        }
        if let Some(list) = self.list.as_mut().and_then(std::sync::Arc::get_mut)
            && list.len() == reports.len()
        {
            for (slot, report) in list.iter_mut().zip(reports.drain(..)) {
                *slot = report;
            }
            return;
        }
        self.list = (!reports.is_empty()).then(|| reports.drain(..).collect());
    }

    fn labels_of(reports: &[GoalReport]) -> Option<Shared<GoalLabels>> {
        (!reports.is_empty()).then(|| {
            Shared::new(GoalLabels(
                reports
                    .iter()
                    .map(|r| GoalLabel {
                        goal: r.goal.clone(),
                        objects: r.objects.clone(),
                        deliberative: r.deliberative,
                    })
                    .collect(),
            ))
        })
    }
}

impl From<Vec<GoalReport>> for GoalReports {
    fn from(reports: Vec<GoalReport>) -> GoalReports {
        let labels = GoalReports::labels_of(&reports);
        GoalReports { list: (!reports.is_empty()).then(|| reports.into()), labels }
    }
}

impl PartialEq for GoalReports {
    fn eq(&self, other: &GoalReports) -> bool {
        **self == **other
    }
}

impl Debug for GoalReports {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        (**self).fmt(f)
    }
}

/// One multiplexer's decision in one cycle: the debugging view of the reactive layer.
///
/// Serialized with the selected goal as its place among `goals` (their labels are written once
/// per goal list, see [`GoalReports`]), or as its label when it is not one of them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MuxReport {
    pub group: Option<ResourceGroup>,
    pub goals: GoalReports,
    pub selected_goal: Option<std::sync::Arc<str>>,
    pub primitive: Option<std::borrow::Cow<'static, str>>,
    /// The multiplexer whose selection inhibited this one.
    pub inhibited_by: Option<ResourceGroup>,
    /// When the score vector in use was received.
    pub scores_received: Option<Time>,
}
