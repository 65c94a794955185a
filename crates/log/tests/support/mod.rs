//! A small module graph with randomness, queues, latest-value inputs and same-instant events,
//! logged and replayed by the tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::RngExt;
use serde::{Deserialize, Serialize};
use strata_log::replay::{BuildError, ModuleRegistry, ModuleSpec};
use strata_log::{ConfigFormat, LogSummary, McapTap, McapTapOptions, RunInfo};
use strata_runtime::{
    Context, Graph, GraphBuilder, HostConfig, Input, LockstepHost, Module, ModuleError, Output,
    Policy, ProcessingTime, Tap, TapRecord, Time, Trigger,
};

pub const CONFIG: &str = r#"
[source]
amplitude = 1.0

[filter]
gain = 0.3
jitter = 0.01

[monitor]
priority = 10
"#;

pub const SEED: u64 = 42;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    pub value: f64,
    pub index: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    pub value: f64,
    pub samples: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Status {
    pub reading: Option<u64>,
    pub estimate: Option<f64>,
    pub label: String,
}

/// A noisy periodic sensor.
struct Source {
    amplitude: f64,
    reading: Output<Reading>,
    index: u64,
}

impl Module for Source {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let noise: f64 = ctx.rng().random_range(-0.1..0.1);
        let value = self.amplitude * (self.index as f64 * 0.05).sin() + noise;
        ctx.send(self.reading, Reading { value, index: self.index });
        self.index += 1;
        Ok(())
    }
}

/// Filters every reading in order, with a random jitter from its own RNG.
struct Filter {
    gain: f64,
    jitter: f64,
    readings: Input<Reading>,
    estimate: Output<Estimate>,
    value: f64,
    samples: u64,
}

impl Module for Filter {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let mut stamp = None;
        for reading in ctx.drain(self.readings) {
            let jitter: f64 = ctx.rng().random_range(-self.jitter..=self.jitter);
            self.value += self.gain * (reading.value.value + jitter - self.value);
            self.samples += 1;
            stamp = Some(reading.stamp);
        }
        if let Some(stamp) = stamp {
            ctx.send_stamped(
                self.estimate,
                Estimate { value: self.value, samples: self.samples },
                stamp,
            );
        }
        Ok(())
    }
}

/// Runs periodically; with a higher priority number than the source (the default), a reading
/// sent at the instant of its tick is delivered before the tick, with a lower one after it.
struct Monitor {
    reading: Input<Reading>,
    estimate: Input<Estimate>,
    status: Output<Status>,
}

impl Module for Monitor {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let reading = ctx.latest(self.reading).map(|p| p.value.index);
        let estimate = ctx.latest(self.estimate).map(|p| p.value.value);
        let label = match reading {
            Some(i) if i % 2 == 0 => "even".to_owned(),
            Some(_) => "odd".to_owned(),
            None => "none".to_owned(),
        };
        ctx.send(self.status, Status { reading, estimate, label });
        Ok(())
    }
}

fn param(config: &serde_json::Value, section: &str, key: &str) -> Result<f64, BuildError> {
    config[section][key]
        .as_f64()
        .ok_or_else(|| format!("configuration has no number `{section}.{key}`").into())
}

pub fn add_source(
    graph: &mut GraphBuilder,
    name: &str,
    config: &serde_json::Value,
) -> Result<Output<Reading>, BuildError> {
    let amplitude = param(config, "source", "amplitude")?;
    Ok(graph.add(name, |p| {
        p.trigger(Trigger::every(Duration::from_millis(10)));
        let reading = p.output("reading");
        (Source { amplitude, reading, index: 0 }, reading)
    }))
}

pub fn add_filter(
    graph: &mut GraphBuilder,
    name: &str,
    config: &serde_json::Value,
) -> Result<(Input<Reading>, Output<Estimate>), BuildError> {
    let gain = param(config, "filter", "gain")?;
    let jitter = param(config, "filter", "jitter")?;
    Ok(graph.add(name, |p| {
        let readings = p.input("readings", Policy::queue(64));
        let estimate = p.output("estimate");
        p.trigger(Trigger::on_any([readings.into()]));
        p.processing_time(ProcessingTime::Uniform {
            min: Duration::from_millis(1),
            max: Duration::from_millis(3),
        });
        let module = Filter { gain, jitter, readings, estimate, value: 0.0, samples: 0 };
        (module, (readings, estimate))
    }))
}

pub fn add_monitor(
    graph: &mut GraphBuilder,
    name: &str,
    config: &serde_json::Value,
) -> Result<MonitorPorts, BuildError> {
    let priority = param(config, "monitor", "priority")? as i32;
    Ok(graph.add(name, |p| {
        let reading = p.input("reading", Policy::Latest);
        let estimate = p.input("estimate", Policy::Latest);
        let status = p.output("status");
        p.trigger(Trigger::every(Duration::from_millis(20)));
        p.priority(priority);
        (Monitor { reading, estimate, status }, (reading, estimate, status))
    }))
}

/// The demo graph, modules named with `prefix` (e.g. `"r1/"`).
pub fn demo_graph(prefix: &str, config: &serde_json::Value) -> Graph {
    let mut graph = GraphBuilder::new();
    let reading = add_source(&mut graph, &format!("{prefix}source"), config).expect("source");
    let (readings, estimate) =
        add_filter(&mut graph, &format!("{prefix}filter"), config).expect("filter");
    let (monitor_reading, monitor_estimate, _) =
        add_monitor(&mut graph, &format!("{prefix}monitor"), config).expect("monitor");
    graph.fan_out(reading, [readings, monitor_reading]);
    graph.connect(estimate, monitor_estimate);
    graph.build().expect("a valid demo graph")
}

pub fn config_value() -> serde_json::Value {
    let table: toml::Table = toml::from_str(CONFIG).expect("demo config");
    serde_json::to_value(table).expect("as JSON")
}

/// The registry the `strata` binary would provide, for the demo modules.
pub fn registry() -> ModuleRegistry {
    let mut registry = ModuleRegistry::new();
    registry
        .register("source", |graph: &mut GraphBuilder, spec: &ModuleSpec<'_>| {
            add_source(graph, spec.name, spec.config).map(|_| ())
        })
        .register("filter", |graph: &mut GraphBuilder, spec: &ModuleSpec<'_>| {
            add_filter(graph, spec.name, spec.config).map(|_| ())
        })
        .register("monitor", |graph: &mut GraphBuilder, spec: &ModuleSpec<'_>| {
            add_monitor(graph, spec.name, spec.config).map(|_| ())
        });
    registry
}

/// One package as a tap saw it: topic, time, stamp, seq, value (in the logs' default
/// encoding).
pub type SeenPackage = (String, Time, Time, u64, Vec<u8>);
pub type Seen = Arc<Mutex<Vec<SeenPackage>>>;
pub type MonitorPorts = (Input<Reading>, Input<Estimate>, Output<Status>);

/// Forwards every package to the log and remembers it.
pub struct Tee {
    pub log: Arc<McapTap>,
    pub seen: Seen,
}

impl Tap for Tee {
    fn package(&self, record: &TapRecord<'_>) {
        self.log.package(record);
        let mut value = Vec::new();
        record
            .package
            .encode(McapTapOptions::default().encoding, &mut value)
            .expect("serializable");
        self.seen.lock().expect("not poisoned").push((
            format!("{}/{}", record.sent_on.module_name, record.sent_on.output),
            record.time,
            record.package.stamp(),
            record.package.seq(),
            value,
        ));
    }
}

/// A fresh directory for one test's files.
pub fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("strata-log-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// Runs the demo graph for `seconds` with a log at `path`, recording ground truth every
/// 100 ms; returns what the tap saw and the log's summary.
pub fn record_demo(
    path: &Path,
    seconds: f64,
    options: McapTapOptions,
    config_text: &str,
) -> (Vec<SeenPackage>, LogSummary) {
    let table: toml::Table = toml::from_str(config_text).expect("config");
    let config = serde_json::to_value(table).expect("as JSON");
    let graph = demo_graph("", &config);
    let log = Arc::new(McapTap::create(path, options).expect("create log"));
    log.write_run_info(&RunInfo::current(SEED).with_config(ConfigFormat::Toml, config_text))
        .expect("run info");
    log.write_graph("", &graph.describe()).expect("graph");
    let seen: Seen = Arc::default();
    let mut host = LockstepHost::new(graph, HostConfig::with_seed(SEED));
    host.set_tap(Arc::new(Tee { log: log.clone(), seen: seen.clone() }));
    let steps = (seconds * 10.0).round() as u64;
    for step in 1..=steps {
        let t = Time::from_nanos(step * 100_000_000);
        host.run_until(t).expect("run");
        log.record(
            "sim/ground_truth",
            "demo::GroundTruth",
            t,
            &serde_json::json!({ "ball": { "x": step as f64 * 0.01, "y": 0.0 } }),
        );
    }
    host.stop();
    let summary = log.finish().expect("finish");
    let seen = seen.lock().expect("not poisoned").clone();
    (seen, summary)
}
