//! Replay: re-run modules of a logged graph from their logged inputs, seed and parameters on
//! the lockstep host, and compare their outputs with the logged ones.
//!
//! The application provides a [`ModuleRegistry`]: for each module kind, a constructor that adds
//! the module to a [`GraphBuilder`] from the run's configuration. The replay builds a graph of
//! just the modules under test (connections between them are kept), declares every other input
//! external, and feeds it the packages the log holds for the writers of those inputs, at their
//! logged times. A module gets the same RNG stream as in the run (it depends on the seed and
//! the module's name only), so a deterministic module reproduces its outputs exactly.
//!
//! Packages that arrived at the same instant as a module's cycle are injected before or after
//! that cycle as the lockstep host ordered them in the run: events at one instant run in
//! priority order, so a package from a writer of lower priority than a periodic reader was
//! delivered before the reader's tick, and one from a writer of higher priority after it (equal
//! priorities: after, as the tick was scheduled a period earlier than the delivery). For a
//! module triggered by input, packages from writers of priority up to its own share its first
//! cycle at that instant.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;
use std::sync::{Arc, Mutex, PoisonError};

use serde::{Deserialize, Serialize};
use serde_json::Value;
use strata_runtime::cdr::{self, Format};
use strata_runtime::shared::{self, Recorder};
use strata_runtime::{
    Encoding, ErasedPackage, Graph, GraphBuilder, GraphDescription, GraphErrors, HostConfig,
    HostError, InputRef, LockstepHost, ModuleDescription, PortDescription, Tap, TapRecord, Time,
    Trigger,
};

use crate::error::LogError;
use crate::overrides::{Override, OverrideError, apply_overrides};
use crate::reader::{LogMessage, LogReader, LoggedGraph};

/// What a module constructor may fail with.
pub type BuildError = Box<dyn std::error::Error + Send + Sync>;

/// What a constructor is given to add one module.
#[derive(Debug)]
pub struct ModuleSpec<'a> {
    /// The registry key (`--module`).
    pub kind: &'a str,
    /// The name the module must get in the graph: its name in the logged graph, on which its
    /// RNG stream depends.
    pub name: &'a str,
    pub robot: Option<&'a str>,
    /// The run's configuration with the `--set` overrides applied (`{}` if none was logged).
    pub config: &'a Value,
    /// The module as it was logged (ports, trigger, priority, processing time).
    pub logged: &'a ModuleDescription,
}

type Factory =
    Box<dyn Fn(&mut GraphBuilder, &ModuleSpec<'_>) -> Result<(), BuildError> + Send + Sync>;
type Naming = Box<dyn Fn(Option<&str>, &str) -> String + Send + Sync>;

/// Constructors of the modules that can be replayed, by kind.
pub struct ModuleRegistry {
    factories: BTreeMap<String, Factory>,
    naming: Naming,
}

impl fmt::Debug for ModuleRegistry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ModuleRegistry").field("kinds", &self.factories.keys()).finish()
    }
}

impl Default for ModuleRegistry {
    fn default() -> Self {
        ModuleRegistry::new()
    }
}

impl ModuleRegistry {
    /// An empty registry; a module of kind `K` of robot `R` is looked up in the log as
    /// `R/K` (topic prefix included), or `K` when no robot is given.
    pub fn new() -> ModuleRegistry {
        ModuleRegistry {
            factories: BTreeMap::new(),
            naming: Box::new(|robot, kind| match robot {
                Some(robot) => format!("{robot}/{kind}"),
                None => kind.to_owned(),
            }),
        }
    }

    /// Registers the constructor of module kind `kind`. It must add exactly one module, named
    /// `spec.name`, with the ports it was logged with.
    pub fn register(
        &mut self,
        kind: &str,
        factory: impl Fn(&mut GraphBuilder, &ModuleSpec<'_>) -> Result<(), BuildError>
        + Send
        + Sync
        + 'static,
    ) -> &mut ModuleRegistry {
        self.factories.insert(kind.to_owned(), Box::new(factory));
        self
    }

    /// Changes how `(robot, kind)` maps to the module's full name in the log (its topic prefix
    /// and name in its graph).
    pub fn with_naming(
        mut self,
        naming: impl Fn(Option<&str>, &str) -> String + Send + Sync + 'static,
    ) -> ModuleRegistry {
        self.naming = Box::new(naming);
        self
    }

    pub fn kinds(&self) -> impl Iterator<Item = &str> {
        self.factories.keys().map(String::as_str)
    }

    pub fn full_name(&self, robot: Option<&str>, kind: &str) -> String {
        (self.naming)(robot, kind)
    }
}

/// What to replay.
#[derive(Clone, Debug, Default)]
pub struct ReplayOptions {
    pub robot: Option<String>,
    /// Module kinds to replay together (one module, or the modules of one layer).
    pub modules: Vec<String>,
    pub overrides: Vec<Override>,
    /// Replaces the logged seed.
    pub seed: Option<u64>,
    /// Stops at this log time instead of the log's end.
    pub until: Option<Time>,
    /// How many differences to describe (all are counted).
    pub max_differences: usize,
    /// Compares values, stamps and sequence numbers but not publication times: a log recorded
    /// in real time (the threaded host of `strata robot`) holds when the CPU finished each
    /// cycle, which a replay in simulated time cannot reproduce.
    pub ignore_time: bool,
}

/// Why a replay could not run.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Log(#[from] LogError),
    #[error("{path} holds no graph description: it was not written with a graph (`--log`)")]
    NoGraph { path: String },
    #[error(
        "{path} was cut short before its graph description: the part recovered holds none, so no module of it can be replayed"
    )]
    GraphCutOff { path: String },
    #[error("{path} holds no seed (no run metadata); give one")]
    NoSeed { path: String },
    #[error("no module named `{name}` in the log; logged modules: {}", available.join(", "))]
    UnknownModule { name: String, available: Vec<String> },
    #[error("no constructor for module kind `{kind}`; known kinds: {}", if known.is_empty() { "none".to_owned() } else { known.join(", ") })]
    NoConstructor { kind: String, known: Vec<String> },
    #[error("modules `{first}` and `{second}` belong to different logged graphs")]
    DifferentGraphs { first: String, second: String },
    #[error(transparent)]
    Override(#[from] OverrideError),
    #[error("cannot build module `{module}`: {error}")]
    Build { module: String, error: BuildError },
    #[error("the constructor of kind `{kind}` did not add a module named `{name}`")]
    NotAdded { kind: String, name: String },
    #[error("the logged graph names port `{port}`, which cannot be found: {detail}")]
    LoggedGraph { port: String, detail: String },
    #[error(
        "module `{module}` changed since the log was written: {what} (logged: {logged}; now: {now})"
    )]
    InterfaceChanged { module: String, what: String, logged: String, now: String },
    #[error(transparent)]
    Graph(#[from] GraphErrors),
    #[error(transparent)]
    Host(#[from] HostError),
}

/// How one input of the replayed modules was fed.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputFeed {
    /// `module.port`.
    pub input: String,
    /// The logged topic it was fed from; `None` if its writer was not logged.
    pub topic: Option<String>,
    pub packages: usize,
}

/// How one output compared.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputComparison {
    pub topic: String,
    pub logged: usize,
    pub replayed: usize,
    pub equal: usize,
}

/// One output package that differs between the log and the replay.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Difference {
    pub topic: String,
    /// Position among the topic's packages (0 = first).
    pub index: usize,
    pub logged_seq: Option<u64>,
    pub logged_time: Option<Time>,
    pub replayed_time: Option<Time>,
    /// What differs: `time`, `stamp`, `seq`, value paths (`$.x: 1 -> 2`), or that the package
    /// is missing on one side.
    pub details: Vec<String>,
}

/// The outcome of a replay.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReplayReport {
    /// Full names of the replayed modules.
    pub modules: Vec<String>,
    pub seed: u64,
    pub overrides: Vec<String>,
    pub end: Time,
    pub inputs: Vec<InputFeed>,
    pub outputs: Vec<OutputComparison>,
    /// The first differences, up to the requested number.
    pub differences: Vec<Difference>,
    pub total_differences: usize,
    /// Things that make the comparison less meaningful (dropped packages, unlogged inputs).
    pub warnings: Vec<String>,
}

impl ReplayReport {
    /// Every output the same, in the same order, at the same times.
    pub fn identical(&self) -> bool {
        self.total_differences == 0
    }
}

impl fmt::Display for ReplayReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "replayed {} with seed {} up to {}",
            self.modules.join(", "),
            self.seed,
            self.end
        )?;
        for o in &self.overrides {
            writeln!(f, "  --set {o}")?;
        }
        writeln!(f, "inputs:")?;
        for input in &self.inputs {
            match &input.topic {
                Some(topic) => {
                    writeln!(f, "  {:<32} <- {topic} ({} packages)", input.input, input.packages)?
                }
                None => writeln!(f, "  {:<32} <- (not logged)", input.input)?,
            }
        }
        writeln!(f, "outputs:")?;
        for o in &self.outputs {
            writeln!(
                f,
                "  {:<40} logged {:>7}  replayed {:>7}  equal {:>7}",
                o.topic, o.logged, o.replayed, o.equal
            )?;
        }
        for w in &self.warnings {
            writeln!(f, "warning: {w}")?;
        }
        if self.identical() {
            writeln!(f, "identical: every output matches the log")?;
        } else {
            writeln!(
                f,
                "{} differences; the first {}:",
                self.total_differences,
                self.differences.len()
            )?;
            for d in &self.differences {
                let seq = d.logged_seq.map_or("-".to_owned(), |s| s.to_string());
                let time =
                    d.logged_time.or(d.replayed_time).map_or("-".to_owned(), |t| t.to_string());
                writeln!(f, "  {} #{} (seq {seq}, {time}):", d.topic, d.index)?;
                for detail in &d.details {
                    writeln!(f, "      {detail}")?;
                }
            }
        }
        Ok(())
    }
}

/// One package the replayed modules sent, kept as a value: it is encoded as the logged package
/// it is compared with was.
struct Captured {
    time: Time,
    stamp: Time,
    seq: u64,
    package: Box<dyn ErasedPackage>,
}

/// Collects the replayed modules' outputs by topic.
#[derive(Default)]
struct Capture {
    scope: String,
    outputs: Mutex<HashMap<String, Vec<Captured>>>,
}

impl Tap for Capture {
    fn package(&self, record: &TapRecord<'_>) {
        let topic = format!(
            "{}{}",
            self.scope,
            crate::package_topic(record.sent_on.module_name, record.sent_on.output)
        );
        self.outputs.lock().unwrap_or_else(PoisonError::into_inner).entry(topic).or_default().push(
            Captured {
                time: record.time,
                stamp: record.package.stamp(),
                seq: record.package.seq(),
                package: record.package.clone_boxed(),
            },
        );
    }
}

/// An input of a replayed module fed from the log.
struct Feed {
    input: InputRef,
    label: String,
    topic: String,
    /// The logged writer's priority and whether the reader runs periodically, which decide
    /// whether a package at the instant of a reader's cycle goes before or after it.
    before_cycle: bool,
    reader_periodic: bool,
    packages: usize,
}

/// Finds the module and port a `module.port` name of `graph` refers to; module names may
/// themselves contain dots.
fn split_port<'g>(
    graph: &'g GraphDescription,
    name: &str,
    outputs: bool,
) -> Option<(&'g ModuleDescription, &'g PortDescription)> {
    graph.modules.iter().find_map(|m| {
        let port = name.strip_prefix(m.name.as_str())?.strip_prefix('.')?;
        let ports = if outputs { &m.outputs } else { &m.inputs };
        ports.iter().find(|p| p.name == port).map(|p| (m, p))
    })
}

/// Whether two triggers are the same, ignoring module ids (the module's index differs between
/// the logged graph and the replay graph).
fn same_schedule(a: &Option<Trigger>, b: &Option<Trigger>) -> bool {
    match (a, b) {
        (
            Some(Trigger::OnInput { mode: ma, inputs: ia }),
            Some(Trigger::OnInput { mode: mb, inputs: ib }),
        ) => ma == mb && ia.iter().map(|i| i.port).eq(ib.iter().map(|i| i.port)),
        _ => a == b,
    }
}

fn describe_ports(ports: &[PortDescription]) -> String {
    ports.iter().map(|p| format!("{}: {}", p.name, p.type_name)).collect::<Vec<_>>().join(", ")
}

/// Replays `options.modules` of the log.
pub fn replay(
    reader: &LogReader,
    registry: &ModuleRegistry,
    options: &ReplayOptions,
) -> Result<ReplayReport, ReplayError> {
    let path = reader.path().display().to_string();
    let graphs = reader.graphs()?;
    if graphs.is_empty() {
        return Err(if reader.is_complete() {
            ReplayError::NoGraph { path }
        } else {
            ReplayError::GraphCutOff { path }
        });
    }
    let run = reader.run_info()?;
    let seed = options
        .seed
        .or(run.as_ref().map(|r| r.seed))
        .ok_or_else(|| ReplayError::NoSeed { path: path.clone() })?;
    let mut config = reader.config()?.unwrap_or_else(|| Value::Object(Default::default()));
    apply_overrides(&mut config, &options.overrides)?;

    // Which logged modules are meant.
    let targets = find_targets(&graphs, registry, options)?;
    let Some(&(_, graph_index, _)) = targets.first() else {
        return Err(ReplayError::UnknownModule { name: String::new(), available: Vec::new() });
    };
    let scope = &graphs[graph_index].scope;

    // The graph of the modules under test.
    let mut warnings: Vec<String> = Vec::new();
    let (graph, mut feeds, unfed) =
        build_graph(registry, options, &config, &targets, &graphs[graph_index], &mut warnings)?;
    check_interfaces(&graph.describe(), &targets, &mut warnings)?;

    if let Some(stats) = reader.stats() {
        if stats.dropped > 0 {
            warnings.push(format!(
                "the log dropped {} packages while recording: inputs or outputs may be missing",
                stats.dropped
            ));
        }
    } else {
        warnings.push("the log was not finished: its last packages may be missing".to_owned());
    }

    let end = options.until.or(reader.time_range().map(|(_, end)| end)).unwrap_or(Time::ZERO);

    let (packages, injections) = logged_inputs(reader, &feeds, end, &mut warnings)?;

    let replayed = run_replay(graph, seed, scope, &packages, injections, &mut feeds, end)?;

    // Compare. Shared values the log holds are written as its references, so that equal
    // packages have equal bytes.
    let recorder = Recorder::knowing(shared::registered_ids()).install();
    let (outputs, differences, total) = compare(reader, options, &targets, scope, &replayed, end)?;
    Recorder::uninstall();
    if let Some(previous) = recorder {
        previous.install();
    }
    let mut inputs: Vec<InputFeed> = feeds
        .iter()
        .map(|f| InputFeed {
            input: f.label.clone(),
            topic: Some(f.topic.clone()),
            packages: f.packages,
        })
        .collect();
    inputs.extend(unfed.into_iter().map(|input| InputFeed { input, topic: None, packages: 0 }));
    Ok(ReplayReport {
        modules: targets.iter().map(|(_, _, m)| format!("{scope}{}", m.name)).collect(),
        seed,
        overrides: options.overrides.iter().map(|o| format!("{}={}", o.key, o.raw)).collect(),
        end,
        inputs,
        outputs,
        differences,
        total_differences: total,
        warnings,
    })
}

/// A logged module to replay: its kind (`--module`), the index of its graph among the log's,
/// and how it was logged.
type Target<'o, 'g> = (&'o str, usize, &'g ModuleDescription);

/// The logged modules `options.modules` name, all of one graph.
fn find_targets<'o, 'g>(
    graphs: &'g [LoggedGraph],
    registry: &ModuleRegistry,
    options: &'o ReplayOptions,
) -> Result<Vec<Target<'o, 'g>>, ReplayError> {
    let mut targets: Vec<(&str, usize, &ModuleDescription)> = Vec::new();
    for kind in &options.modules {
        let full = registry.full_name(options.robot.as_deref(), kind);
        let found = graphs.iter().enumerate().find_map(|(g, graph)| {
            graph
                .description
                .modules
                .iter()
                .find(|m| format!("{}{}", graph.scope, m.name) == full)
                .map(|m| (g, m))
        });
        let Some((g, module)) = found else {
            let available = graphs
                .iter()
                .flat_map(|g| {
                    g.description.modules.iter().map(|m| format!("{}{}", g.scope, m.name))
                })
                .collect();
            return Err(ReplayError::UnknownModule { name: full, available });
        };
        if let Some((_, first_graph, first)) = targets.first()
            && *first_graph != g
        {
            return Err(ReplayError::DifferentGraphs {
                first: first.name.clone(),
                second: module.name.clone(),
            });
        }
        targets.push((kind.as_str(), g, module));
    }
    Ok(targets)
}

/// The graph of the modules under test: connections between them kept, every other input
/// external, fed from the log where the logged graph had a writer for it (`feeds`) and
/// receiving nothing where it had none (`unfed`).
fn build_graph(
    registry: &ModuleRegistry,
    options: &ReplayOptions,
    config: &Value,
    targets: &[Target<'_, '_>],
    logged: &LoggedGraph,
    warnings: &mut Vec<String>,
) -> Result<(Graph, Vec<Feed>, Vec<String>), ReplayError> {
    let LoggedGraph { scope, description } = logged;
    let mut builder = GraphBuilder::new();
    for (kind, _, module) in targets {
        let factory = registry.factories.get(*kind).ok_or_else(|| ReplayError::NoConstructor {
            kind: (*kind).to_owned(),
            known: registry.kinds().map(str::to_owned).collect(),
        })?;
        let spec = ModuleSpec {
            kind,
            name: &module.name,
            robot: options.robot.as_deref(),
            config,
            logged: module,
        };
        factory(&mut builder, &spec)
            .map_err(|error| ReplayError::Build { module: module.name.clone(), error })?;
        if builder.module_id(&module.name).is_none() {
            return Err(ReplayError::NotAdded {
                kind: (*kind).to_owned(),
                name: module.name.clone(),
            });
        }
    }
    let names: HashSet<&str> = targets.iter().map(|(_, _, m)| m.name.as_str()).collect();
    let mut feeds: Vec<Feed> = Vec::new();
    let mut unfed: Vec<String> = Vec::new();
    for (_, _, module) in targets {
        for port in &module.inputs {
            let to = format!("{}.{}", module.name, port.name);
            let graph_error = |e: strata_runtime::GraphError| ReplayError::LoggedGraph {
                port: to.clone(),
                detail: e.to_string(),
            };
            match description.connections.iter().find(|c| c.to == to) {
                Some(connection) => {
                    let (writer, output) = split_port(description, &connection.from, true)
                        .ok_or_else(|| ReplayError::LoggedGraph {
                            port: connection.from.clone(),
                            detail: "no such output in the logged graph".to_owned(),
                        })?;
                    if names.contains(writer.name.as_str()) {
                        builder
                            .connect_by_name(&writer.name, &output.name, &module.name, &port.name)
                            .map_err(graph_error)?;
                        continue;
                    }
                    let input =
                        builder.external_by_name(&module.name, &port.name).map_err(graph_error)?;
                    let reader_periodic = matches!(module.trigger, Some(Trigger::Periodic { .. }));
                    let before_cycle = if reader_periodic {
                        writer.priority < module.priority
                    } else {
                        writer.priority <= module.priority
                    };
                    feeds.push(Feed {
                        input,
                        label: to.clone(),
                        topic: format!(
                            "{scope}{}",
                            crate::package_topic(&writer.name, &output.name)
                        ),
                        before_cycle,
                        reader_periodic,
                        packages: 0,
                    });
                }
                None => {
                    builder.external_by_name(&module.name, &port.name).map_err(graph_error)?;
                    warnings.push(format!(
                        "input `{to}` had no writer in the logged graph: it receives nothing"
                    ));
                    unfed.push(to);
                }
            }
        }
    }
    Ok((builder.build()?, feeds, unfed))
}

/// Refuses a module whose inputs or outputs differ from the logged ones; warns when its
/// schedule does.
fn check_interfaces(
    now: &GraphDescription,
    targets: &[Target<'_, '_>],
    warnings: &mut Vec<String>,
) -> Result<(), ReplayError> {
    for (_, _, logged) in targets {
        let Some(current) = now.modules.iter().find(|m| m.name == logged.name) else { continue };
        for (what, a, b) in [
            ("inputs", &logged.inputs, &current.inputs),
            ("outputs", &logged.outputs, &current.outputs),
        ] {
            let same = a.len() == b.len()
                && a.iter().zip(b).all(|(x, y)| x.name == y.name && x.type_name == y.type_name);
            if !same {
                return Err(ReplayError::InterfaceChanged {
                    module: logged.name.clone(),
                    what: format!("its {what} differ"),
                    logged: describe_ports(a),
                    now: describe_ports(b),
                });
            }
        }
        if !same_schedule(&current.trigger, &logged.trigger) || current.priority != logged.priority
        {
            warnings.push(format!(
                "module `{}` is now scheduled differently (trigger or priority) than when it was logged",
                logged.name
            ));
        }
    }
    Ok(())
}

/// A logged package injected into a fed input: the instant, where it falls relative to the
/// readers' cycles at that instant (see [`replay`]), the package's index and the feed's.
type Injection = (Time, u8, usize, usize);

/// The logged packages of the fed inputs up to `end`, and every injection of one into an input.
fn logged_inputs(
    reader: &LogReader,
    feeds: &[Feed],
    end: Time,
    warnings: &mut Vec<String>,
) -> Result<(Vec<LogMessage>, Vec<Injection>), ReplayError> {
    // The logged input packages, in log-time order (a threaded host's log is only nearly
    // sorted: module threads hand packages to the tap concurrently).
    let topics: Vec<&str> = {
        let mut t: Vec<&str> = feeds.iter().map(|f| f.topic.as_str()).collect();
        t.sort_unstable();
        t.dedup();
        t
    };
    let mut packages = Vec::new();
    for message in reader.messages_on(topics.iter().copied()) {
        let message = message?;
        if message.log_time <= end {
            packages.push(message);
        }
    }
    packages.sort_by_key(|m| m.log_time);
    for topic in &topics {
        if !packages.iter().any(|m| &*m.topic == *topic) {
            warnings.push(format!("no package was logged on `{topic}`"));
        }
    }

    // Every (package, input) injection, ordered by instant, then by where it falls relative
    // to the readers' cycles at that instant, then as logged.
    let mut injections: Vec<Injection> = Vec::new();
    for (m, message) in packages.iter().enumerate() {
        for (f, feed) in feeds.iter().enumerate().filter(|(_, f)| *f.topic == *message.topic) {
            let class = match (feed.before_cycle, feed.reader_periodic) {
                (true, true) => 0,
                (true, false) => 1,
                (false, _) => 2,
            };
            injections.push((message.log_time, class, m, f));
        }
    }
    injections.sort_unstable();
    Ok((packages, injections))
}

/// Runs the modules under test on the lockstep host, injecting the logged packages; the
/// outputs they sent, by topic.
fn run_replay(
    graph: Graph,
    seed: u64,
    scope: &str,
    packages: &[LogMessage],
    injections: Vec<Injection>,
    feeds: &mut [Feed],
    end: Time,
) -> Result<HashMap<String, Vec<Captured>>, ReplayError> {
    let mut host = LockstepHost::new(graph, HostConfig::with_seed(seed));
    let capture = Arc::new(Capture { scope: scope.to_owned(), ..Capture::default() });
    host.set_tap(capture.clone());
    for (t, class, m, f) in injections {
        match class {
            // Before a periodic reader's tick at `t`: stop just short of the instant (the
            // reader is not triggered by the package, so arriving a nanosecond early is the
            // same to it).
            0 if host.now() < t => host.run_until(Time::from_nanos(t.as_nanos() - 1))?,
            // Before an input-triggered reader's cycle: the cycle is only scheduled by what
            // is injected, so everything up to `t` can run first.
            1 if host.now() < t => host.run_until(t)?,
            0 | 1 => {}
            // After the readers' cycles at `t`, each such package triggering its own.
            _ => host.run_until(t)?,
        }
        let (message, feed) = (&packages[m], &mut feeds[f]);
        host.inject_encoded(
            feed.input,
            message.encoding,
            &message.data,
            message.stamp,
            message.seq,
        )?;
        feed.packages += 1;
    }
    host.run_until(end)?;
    host.stop();
    Ok(std::mem::take(&mut *capture.outputs.lock().unwrap_or_else(PoisonError::into_inner)))
}

/// Compares the replayed outputs with the logged ones up to `end`: per output, and the
/// differences (at most `options.max_differences`) and how many there are.
fn compare(
    reader: &LogReader,
    options: &ReplayOptions,
    targets: &[Target<'_, '_>],
    scope: &str,
    replayed: &HashMap<String, Vec<Captured>>,
    end: Time,
) -> Result<(Vec<OutputComparison>, Vec<Difference>, usize), ReplayError> {
    let mut outputs = Vec::new();
    let mut differences = Vec::new();
    let mut total = 0usize;
    for (_, _, module) in targets {
        for port in &module.outputs {
            let topic = format!("{scope}{}", crate::package_topic(&module.name, &port.name));
            let mut logged = Vec::new();
            for message in reader.messages_on([topic.as_str()]) {
                let message = message?;
                if message.log_time <= end {
                    logged.push(message);
                }
            }
            let ours = replayed.get(&topic).map(Vec::as_slice).unwrap_or(&[]);
            let mut equal = 0;
            for index in 0..logged.len().max(ours.len()) {
                let details = match (logged.get(index), ours.get(index)) {
                    (Some(a), Some(b)) => package_differences(a, b, options.ignore_time),
                    (Some(_), None) => vec!["missing in the replay".to_owned()],
                    (None, Some(_)) => vec!["sent by the replay, not in the log".to_owned()],
                    (None, None) => Vec::new(),
                };
                if details.is_empty() {
                    equal += 1;
                    continue;
                }
                total += 1;
                if differences.len() < options.max_differences {
                    differences.push(Difference {
                        topic: topic.clone(),
                        index,
                        logged_seq: logged.get(index).map(|m| m.seq),
                        logged_time: logged.get(index).map(|m| m.log_time),
                        replayed_time: ours.get(index).map(|c| c.time),
                        details,
                    });
                }
            }
            outputs.push(OutputComparison {
                topic,
                logged: logged.len(),
                replayed: ours.len(),
                equal,
            });
        }
    }
    Ok((outputs, differences, total))
}

/// How a replayed package differs from the logged one (time, stamp, sequence number, value).
fn package_differences(a: &LogMessage, b: &Captured, ignore_time: bool) -> Vec<String> {
    let mut details = Vec::new();
    if !ignore_time && a.log_time != b.time {
        details.push(format!("time: {} -> {}", a.log_time, b.time));
    }
    if a.stamp != b.stamp {
        details.push(format!("stamp: {} -> {}", a.stamp, b.stamp));
    }
    if a.seq != b.seq {
        details.push(format!("seq: {} -> {}", a.seq, b.seq));
    }
    let mut ours = Vec::new();
    // A value that cannot be encoded stays empty: it differs from the log.
    let _ = b.package.encode(a.encoding, &mut ours);
    if a.data != ours {
        details.extend(value_differences(a.encoding, a.format.as_deref(), &a.data, &ours, 8));
    }
    details
}

/// Where two encoded values differ, as `path: old -> new` lines (at most `limit`); `format`
/// reads CDR values.
pub fn value_differences(
    encoding: Encoding,
    format: Option<&Format>,
    logged: &[u8],
    replayed: &[u8],
    limit: usize,
) -> Vec<String> {
    let json = |bytes: &[u8]| -> Result<Value, String> {
        match (encoding, format) {
            (Encoding::Cdr, Some(format)) => cdr::to_json(format, bytes).map_err(|e| e.to_string()),
            _ => encoding.decode::<Value>(bytes).map_err(|e| e.to_string()),
        }
    };
    match (json(logged), json(replayed)) {
        (Ok(a), Ok(b)) => {
            let mut out = Vec::new();
            let mut count = 0usize;
            diff_values(&a, &b, "$", &mut out, &mut count, limit);
            if count > out.len() {
                out.push(format!("... and {} more", count - out.len()));
            }
            if out.is_empty() {
                // Same value, different text (e.g. float formatting): still a difference.
                out.push("value: same value, different bytes".to_owned());
            }
            out
        }
        _ => vec![format!("value: not comparable (invalid {} on one side)", encoding.mcap_name())],
    }
}

fn short(value: &Value) -> String {
    let mut text = value.to_string();
    if text.len() > 60 {
        let mut cut = 57;
        while !text.is_char_boundary(cut) {
            cut -= 1;
        }
        text.truncate(cut);
        text.push_str("...");
    }
    text
}

fn diff_values(
    a: &Value,
    b: &Value,
    path: &str,
    out: &mut Vec<String>,
    count: &mut usize,
    limit: usize,
) {
    let mut push = |line: String| {
        *count += 1;
        if out.len() < limit {
            out.push(line);
        }
    };
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for (key, va) in x {
                match y.get(key) {
                    Some(vb) => diff_values(va, vb, &format!("{path}.{key}"), out, count, limit),
                    None => {
                        *count += 1;
                        if out.len() < limit {
                            out.push(format!("{path}.{key}: {} -> (absent)", short(va)));
                        }
                    }
                }
            }
            for (key, vb) in y {
                if !x.contains_key(key) {
                    *count += 1;
                    if out.len() < limit {
                        out.push(format!("{path}.{key}: (absent) -> {}", short(vb)));
                    }
                }
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (va, vb)) in x.iter().zip(y).enumerate() {
                diff_values(va, vb, &format!("{path}[{i}]"), out, count, limit);
            }
        }
        _ if a != b => push(format!("{path}: {} -> {}", short(a), short(b))),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_differences_name_paths() {
        let a = br#"{"x":1.0,"y":[1,2],"z":"a","gone":1}"#;
        let b = br#"{"x":1.5,"y":[1,3],"z":"a","new":2}"#;
        let diff = value_differences(Encoding::Json, None, a, b, 8);
        assert_eq!(
            diff,
            vec![
                "$.gone: 1 -> (absent)".to_owned(),
                "$.x: 1.0 -> 1.5".to_owned(),
                "$.y[1]: 2 -> 3".to_owned(),
                "$.new: (absent) -> 2".to_owned(),
            ]
        );
    }
}
