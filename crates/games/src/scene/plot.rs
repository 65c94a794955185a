//! The plot channel (`plot/layers`): per robot, the rate of each layer of the hybrid control
//! and the head multiplexer's score vector, as flat numbers a Foxglove Plot panel follows with a
//! message path (`/plot/layers.robots[:]{robot=="home/3"}.rates.reactive`).
//!
//! A layer's rate is counted from its outputs as the run sent them (planning decisions,
//! deliberative scores, reactive reports) over the last [`RATE_WINDOW`]: what the robot did,
//! not what it was configured to do, so a loaded or starved layer shows as a dip.

use std::collections::VecDeque;
use std::sync::OnceLock;

use serde::Serialize;
use serde_json::{Value, json};
use strata_log::RecordSchema;
use strata_robot::control::reactive::MuxReport;
use strata_runtime::Time;

use super::foxglove::{Timestamp, round};

/// Where the plot messages go.
pub const PLOT_TOPIC: &str = "plot/layers";
/// Seconds of log time over which a layer's outputs are counted.
pub const RATE_WINDOW: f64 = 1.0;

/// A layer of the hybrid control, as its outputs are counted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerKind {
    Planning,
    Deliberative,
    Reactive,
}

/// Outputs per second of each layer of one robot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LayerRates {
    pub planning: f64,
    pub deliberative: f64,
    pub reactive: f64,
}

/// One head goal's scores: the deliberative layer's S_d, the reactive layer's S_r and the
/// multiplexer's final score (the paper's score vector, 3.4).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GoalScore {
    pub goal: String,
    pub deliberative: f64,
    pub reactive: f64,
    #[serde(rename = "final")]
    pub final_score: f64,
}

/// What one robot plots.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotPlot {
    pub robot: String,
    pub rates: LayerRates,
    /// The head goal selected (empty when none) and every head goal offered, best first.
    pub head_goal: String,
    pub head: Vec<GoalScore>,
    /// The world model's pose and ball confidence (0 when it has none).
    pub pose_confidence: f64,
    pub ball_confidence: f64,
}

/// A message of [`PLOT_TOPIC`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LayerPlot {
    pub timestamp: Timestamp,
    pub robots: Vec<RobotPlot>,
}

/// The counts behind one robot's rates and its newest head scores.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LayerCounter {
    /// Times of the outputs within the window, per layer (planning, deliberative, reactive).
    times: [VecDeque<Time>; 3],
    head_goal: String,
    head: Vec<GoalScore>,
    /// When the head scores were last copied: at most once per plot period.
    head_copied: Option<Time>,
}

impl LayerCounter {
    /// An output of `layer` at `time`.
    pub fn output(&mut self, layer: LayerKind, time: Time) {
        let times = &mut self.times[layer as usize];
        times.push_back(time);
        Self::expire(times, time);
    }

    fn expire(times: &mut VecDeque<Time>, now: Time) {
        let window = std::time::Duration::from_secs_f64(RATE_WINDOW);
        while times.front().is_some_and(|t| now.saturating_since(*t) >= window) {
            times.pop_front();
        }
    }

    /// The head multiplexer's report of a reactive cycle at `time`; copied when the last copy
    /// is older than `period` (reports come every reactive cycle, plots ten times a second).
    pub fn head(&mut self, head: &MuxReport, time: Time, period: f64) {
        if self.head_copied.is_some_and(|t| time.saturating_since(t).as_secs_f64() < period) {
            return;
        }
        self.head_copied = Some(time);
        self.head_goal = head.selected_goal.as_deref().unwrap_or_default().to_owned();
        self.head = head
            .goals
            .iter()
            .map(|g| GoalScore {
                goal: g.goal.to_string(),
                deliberative: round(g.deliberative),
                reactive: round(g.reactive),
                final_score: round(g.final_score),
            })
            .collect();
        self.head.sort_by(|a, b| b.final_score.total_cmp(&a.final_score));
    }

    /// Outputs per second over the window ending at `now`.
    pub fn rates(&mut self, now: Time) -> LayerRates {
        let mut rate = |layer: LayerKind| {
            let times = &mut self.times[layer as usize];
            Self::expire(times, now);
            times.len() as f64 / RATE_WINDOW
        };
        LayerRates {
            planning: rate(LayerKind::Planning),
            deliberative: rate(LayerKind::Deliberative),
            reactive: rate(LayerKind::Reactive),
        }
    }

    pub fn head_goal(&self) -> &str {
        &self.head_goal
    }

    pub fn head_scores(&self) -> &[GoalScore] {
        &self.head
    }
}

/// The schema of [`LayerPlot`] messages (JSON Schema; Strata's own type, not one of Foxglove's
/// well-known ones: the Plot panel needs no schema to follow a number).
pub fn layer_plot_schema() -> RecordSchema {
    static TEXT: OnceLock<String> = OnceLock::new();
    let text = TEXT.get_or_init(|| layer_plot_json_schema().to_string());
    RecordSchema { name: "strata.LayerPlot", json_schema: text }
}

fn layer_plot_json_schema() -> Value {
    let number = json!({ "type": "number" });
    let string = json!({ "type": "string" });
    let object = |properties: Value| json!({ "type": "object", "properties": properties });
    json!({
        "title": "strata.LayerPlot",
        "description": "Per robot: each layer's outputs per second over the last second, the head multiplexer's score vector, the pose and ball confidence",
        "type": "object",
        "properties": {
            "timestamp": object(json!({
                "sec": { "type": "integer", "minimum": 0 },
                "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 },
            })),
            "robots": {
                "type": "array",
                "items": object(json!({
                    "robot": string,
                    "rates": object(json!({
                        "planning": number,
                        "deliberative": number,
                        "reactive": number,
                    })),
                    "head_goal": string,
                    "head": {
                        "type": "array",
                        "items": object(json!({
                            "goal": string,
                            "deliberative": number,
                            "reactive": number,
                            "final": number,
                        })),
                    },
                    "pose_confidence": number,
                    "ball_confidence": number,
                })),
            },
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_layer_rate_counts_its_outputs_over_the_last_second() {
        let mut counter = LayerCounter::default();
        // Reactive at 100 Hz and deliberative at 2 Hz for three seconds, planning once.
        for k in 0..300u64 {
            let t = Time::from_nanos(k * 10_000_000);
            counter.output(LayerKind::Reactive, t);
            if k % 50 == 0 {
                counter.output(LayerKind::Deliberative, t);
            }
        }
        counter.output(LayerKind::Planning, Time::from_secs_f64(0.5));
        let rates = counter.rates(Time::from_secs_f64(2.995));
        assert_eq!(rates.reactive, 100.0);
        assert_eq!(rates.deliberative, 2.0);
        assert_eq!(rates.planning, 0.0, "the decision at 0.5 s is out of the window");
        // A layer that stops drops to nothing one window later.
        assert_eq!(counter.rates(Time::from_secs_f64(4.0)).reactive, 0.0);
    }

    /// Every field a message writes is declared by the schema, and the other way round.
    #[test]
    fn plot_messages_write_exactly_the_fields_of_their_schema() {
        fn schema_paths(schema: &Value, prefix: &str, out: &mut Vec<String>) {
            if let Some(properties) = schema["properties"].as_object() {
                for (name, inner) in properties {
                    out.push(format!("{prefix}.{name}"));
                    schema_paths(inner, &format!("{prefix}.{name}"), out);
                }
            }
            if schema["items"].is_object() {
                schema_paths(&schema["items"], &format!("{prefix}[]"), out);
            }
        }
        fn value_paths(value: &Value, prefix: &str, out: &mut Vec<String>) {
            match value {
                Value::Object(map) => {
                    for (name, inner) in map {
                        out.push(format!("{prefix}.{name}"));
                        value_paths(inner, &format!("{prefix}.{name}"), out);
                    }
                }
                Value::Array(items) => {
                    for item in items {
                        value_paths(item, &format!("{prefix}[]"), out);
                    }
                }
                _ => {}
            }
        }
        let plot = LayerPlot {
            timestamp: Timestamp::from_secs_f64(1.5),
            robots: vec![RobotPlot {
                robot: "home/1".to_owned(),
                rates: LayerRates { planning: 1.0, deliberative: 2.0, reactive: 100.0 },
                head_goal: "observe ball".to_owned(),
                head: vec![GoalScore {
                    goal: "observe ball".to_owned(),
                    deliberative: 0.5,
                    reactive: 0.9,
                    final_score: 0.45,
                }],
                pose_confidence: 0.9,
                ball_confidence: 0.8,
            }],
        };
        let schema: Value =
            serde_json::from_str(layer_plot_schema().json_schema).unwrap_or_else(|e| panic!("{e}"));
        let mut declared = Vec::new();
        schema_paths(&schema, "", &mut declared);
        let mut written = Vec::new();
        value_paths(
            &serde_json::to_value(&plot).unwrap_or_else(|e| panic!("{e}")),
            "",
            &mut written,
        );
        declared.sort();
        declared.dedup();
        written.sort();
        written.dedup();
        assert_eq!(declared, written);
    }
}
