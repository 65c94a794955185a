//! Building a module graph: typed ports, connections, triggers, and the checks made when the
//! graph is built.
//!
//! A module declares its ports in the closure that creates it; the typed handles it gets back
//! are both what it reads and writes through and what the graph is wired with:
//!
//! ```
//! use strata_runtime::{GraphBuilder, Policy, Trigger, Module, Context, ModuleError};
//! # use std::time::Duration;
//! struct Counter { out: strata_runtime::Output<u64>, n: u64 }
//! impl Module for Counter {
//!     fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
//!         self.n += 1;
//!         ctx.send(self.out, self.n);
//!         Ok(())
//!     }
//! }
//! struct Sum { input: strata_runtime::Input<u64>, total: u64 }
//! impl Module for Sum {
//!     fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
//!         for p in ctx.drain(self.input) { self.total += p.value; }
//!         Ok(())
//!     }
//! }
//! let mut graph = GraphBuilder::new();
//! let counts = graph.add("counter", |p| {
//!     p.trigger(Trigger::every(Duration::from_millis(10)));
//!     let out = p.output::<u64>("count");
//!     (Counter { out, n: 0 }, out)
//! });
//! let sum_in = graph.add("sum", |p| {
//!     let input = p.input("count", Policy::queue(16));
//!     p.trigger(Trigger::on_any([input.into()]));
//!     (Sum { input, total: 0 }, input)
//! });
//! graph.connect(counts, sum_in);
//! let graph = graph.build().expect("a valid graph");
//! assert_eq!(graph.module_names().count(), 2);
//! ```
//!
//! Wiring by typed handles makes a type mismatch impossible at compile time; tools that wire
//! by name (replay, configuration-driven graphs) use [`GraphBuilder::connect_by_name`], which
//! checks the types when the graph is built. A module whose ports are also read from outside
//! the graph names them with [`PortName`] constants, which carry the type too.

use std::any::TypeId;
use std::collections::HashMap;
use std::fmt;
use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::connection::{Policy, PolicyKind};
use crate::message::{ErasedInput, InputSlot, Message};
use crate::module::Module;
use crate::package::ModuleId;

/// A typed input port of a module. Cheap to copy; only meaningful in the graph that made it.
pub struct Input<T> {
    pub(crate) module: ModuleId,
    pub(crate) port: u16,
    _value: PhantomData<fn() -> T>,
}

/// A typed output port of a module.
pub struct Output<T> {
    pub(crate) module: ModuleId,
    pub(crate) port: u16,
    _value: PhantomData<fn() -> T>,
}

macro_rules! port_handle_impls {
    ($name:ident, $untyped:ident) => {
        impl<T> Clone for $name<T> {
            fn clone(&self) -> Self {
                *self
            }
        }
        impl<T> Copy for $name<T> {}
        impl<T> fmt::Debug for $name<T> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}(module {}, port {})", stringify!($name), self.module.0, self.port)
            }
        }
        impl<T> PartialEq for $name<T> {
            fn eq(&self, other: &Self) -> bool {
                self.module == other.module && self.port == other.port
            }
        }
        impl<T> Eq for $name<T> {}
        impl<T> $name<T> {
            pub(crate) fn new(module: ModuleId, port: u16) -> Self {
                $name { module, port, _value: PhantomData }
            }
            pub fn module(&self) -> ModuleId {
                self.module
            }
        }
        impl<T> From<$name<T>> for $untyped {
            fn from(handle: $name<T>) -> $untyped {
                $untyped { module: handle.module, port: handle.port }
            }
        }
    };
}

/// An input port without its type (triggers, diagnostics).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct InputRef {
    pub module: ModuleId,
    pub port: u16,
}

/// An output port without its type.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct OutputRef {
    pub module: ModuleId,
    pub port: u16,
}

port_handle_impls!(Input, InputRef);
port_handle_impls!(Output, OutputRef);

/// The name of a port with the type of what it carries, declared once by the module that has
/// the port (`PerceptionPorts::PERCEPTS`). The module declares the port with it, so the port
/// cannot have another type; a consumer outside the graph finds the port's packages with it
/// ([`crate::TapRecord::value`]), so it follows a renamed port and does not compile against a
/// retyped one.
///
/// ```
/// use strata_runtime::{Output, PortName, Ports};
/// const COUNT: PortName<u64> = PortName::new("count");
/// fn declare(p: &mut Ports<'_>) -> Output<u64> {
///     p.output(COUNT)
/// }
/// // and in a tap: `record.value_from("counter", COUNT)`, an `Option<&u64>`.
/// ```
///
/// A port declared with another type than its name's does not compile:
///
/// ```compile_fail
/// use strata_runtime::{Output, PortName, Ports};
/// const COUNT: PortName<u64> = PortName::new("count");
/// fn declare(p: &mut Ports<'_>) -> Output<f64> {
///     p.output(COUNT)
/// }
/// ```
pub struct PortName<T> {
    name: &'static str,
    _type: PhantomData<fn() -> T>,
}

impl<T> PortName<T> {
    pub const fn new(name: &'static str) -> PortName<T> {
        PortName { name, _type: PhantomData }
    }

    pub const fn name(self) -> &'static str {
        self.name
    }
}

impl<T: Message> PortName<T> {
    /// `package` as this port's type, if it has it. The port's name is not checked: this is
    /// for a package whose output is known otherwise (a log's topic); a tap has
    /// [`crate::TapRecord::package`].
    pub fn downcast(self, package: &dyn crate::ErasedPackage) -> Option<&crate::Package<T>> {
        package.as_any().downcast_ref()
    }
}

// By hand: derived impls would require `T` to have them too.
impl<T> Clone for PortName<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for PortName<T> {}
impl<T> PartialEq for PortName<T> {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
    }
}
impl<T> Eq for PortName<T> {}
impl<T> std::hash::Hash for PortName<T> {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.name.hash(state);
    }
}
impl<T> fmt::Debug for PortName<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PortName<{}>({:?})", std::any::type_name::<T>(), self.name)
    }
}
impl<T> fmt::Display for PortName<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name)
    }
}

/// What names a port of type `T` where [`Ports`] declares one: a [`PortName<T>`], or a string
/// for a name made at run time (the simulator's ports of each robot it serves), whose type
/// comes from the policy or the handle's use instead.
pub trait AsPortName<T> {
    fn as_port_name(&self) -> &str;
}

impl<T> AsPortName<T> for PortName<T> {
    fn as_port_name(&self) -> &str {
        self.name
    }
}

impl<T, S: AsRef<str> + ?Sized> AsPortName<T> for &S {
    fn as_port_name(&self) -> &str {
        (**self).as_ref()
    }
}

/// When a module's cycle runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Trigger {
    /// At a fixed rate: cycles start at `offset`, `offset + period`, ... A cycle that overruns
    /// delays the next one; missed ticks are not replayed in a burst.
    Periodic { period: Duration, offset: Duration },
    /// When new data is pending on any (or all) of the listed inputs of this module.
    OnInput { mode: InputMode, inputs: Vec<InputRef> },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum InputMode {
    /// A package pending on any listed input starts a cycle.
    Any,
    /// A cycle starts once every listed input has a pending package.
    All,
}

impl Trigger {
    pub fn every(period: Duration) -> Trigger {
        Trigger::Periodic { period: period.max(Duration::from_nanos(1)), offset: Duration::ZERO }
    }

    pub fn rate_hz(hz: f64) -> Trigger {
        Trigger::every(Duration::from_secs_f64(1.0 / hz.max(1e-9)))
    }

    pub fn with_offset(self, offset: Duration) -> Trigger {
        match self {
            Trigger::Periodic { period, .. } => Trigger::Periodic { period, offset },
            other => other,
        }
    }

    pub fn on_any(inputs: impl IntoIterator<Item = InputRef>) -> Trigger {
        Trigger::OnInput { mode: InputMode::Any, inputs: inputs.into_iter().collect() }
    }

    pub fn on_all(inputs: impl IntoIterator<Item = InputRef>) -> Trigger {
        Trigger::OnInput { mode: InputMode::All, inputs: inputs.into_iter().collect() }
    }

    pub(crate) fn triggered_by(&self, port: u16) -> bool {
        self.mode_of(port).is_some()
    }

    /// The mode of the trigger `port` is an input of, if it is one.
    pub(crate) fn mode_of(&self, port: u16) -> Option<InputMode> {
        match self {
            Trigger::Periodic { .. } => None,
            Trigger::OnInput { mode, inputs } => {
                inputs.iter().any(|i| i.port == port).then_some(*mode)
            }
        }
    }
}

/// How long a module's cycle takes on the lockstep host: its outputs become visible that much
/// after the cycle starts, and it cannot start another cycle before. (The threaded host measures
/// the real time instead.)
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum ProcessingTime {
    Fixed {
        #[serde(with = "crate::serde_duration")]
        duration: Duration,
    },
    /// Uniform between `min` and `max`, drawn from the module's seeded timing RNG.
    Uniform {
        #[serde(with = "crate::serde_duration")]
        min: Duration,
        #[serde(with = "crate::serde_duration")]
        max: Duration,
    },
    /// Normal, clamped below at `min` (a cycle never takes negative time).
    Normal {
        #[serde(with = "crate::serde_duration")]
        mean: Duration,
        #[serde(with = "crate::serde_duration")]
        std_dev: Duration,
        #[serde(with = "crate::serde_duration")]
        min: Duration,
    },
}

impl Default for ProcessingTime {
    fn default() -> Self {
        ProcessingTime::Fixed { duration: Duration::ZERO }
    }
}

impl ProcessingTime {
    pub fn fixed(duration: Duration) -> ProcessingTime {
        ProcessingTime::Fixed { duration }
    }

    pub(crate) fn sample(&self, rng: &mut rand_chacha::ChaCha8Rng) -> Duration {
        use rand::RngExt;
        use rand_distr::Distribution;
        match self {
            ProcessingTime::Fixed { duration } => *duration,
            ProcessingTime::Uniform { min, max } => {
                if max <= min {
                    *min
                } else {
                    let span = (*max - *min).as_nanos() as u64;
                    *min + Duration::from_nanos(rng.random_range(0..=span))
                }
            }
            ProcessingTime::Normal { mean, std_dev, min } => {
                let normal = rand_distr::Normal::new(mean.as_secs_f64(), std_dev.as_secs_f64())
                    .unwrap_or_else(|_| {
                        rand_distr::Normal::new(mean.as_secs_f64(), 0.0)
                            .unwrap_or_else(|_| unreachable!("zero deviation is always valid"))
                    });
                Duration::from_secs_f64(normal.sample(rng).max(min.as_secs_f64()).max(0.0))
            }
        }
    }
}

pub(crate) struct InputDecl {
    pub(crate) name: String,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) optional: bool,
    pub(crate) slot: Arc<dyn ErasedInput>,
    /// Whether the output writing this input asked to be woken when its readers took what it
    /// sent ([`Ports::wake_when_receivers_ready`]; set by [`GraphBuilder::build`]): a take
    /// that empties the input tells the host only then, instead of every time for the host to
    /// look the writer up.
    pub(crate) wakes_writer: bool,
}

pub(crate) struct OutputDecl {
    pub(crate) name: String,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) wake_on_ready: bool,
}

pub(crate) struct ModuleDecl {
    pub(crate) name: String,
    pub(crate) module: Option<Box<dyn Module>>,
    pub(crate) trigger: Option<Trigger>,
    pub(crate) priority: i32,
    pub(crate) real_time: bool,
    pub(crate) processing_time: ProcessingTime,
    pub(crate) inputs: Vec<InputDecl>,
    pub(crate) outputs: Vec<OutputDecl>,
}

/// Declares a module's ports and scheduling; handed to the closure given to [`GraphBuilder::add`].
pub struct Ports<'a> {
    id: ModuleId,
    decl: &'a mut ModuleDecl,
    problems: &'a mut Vec<GraphError>,
}

impl fmt::Debug for Ports<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Ports").field("module", &self.decl.name).finish()
    }
}

impl Ports<'_> {
    pub fn id(&self) -> ModuleId {
        self.id
    }

    pub fn name(&self) -> &str {
        &self.decl.name
    }

    /// An input that must be connected to exactly one writer.
    pub fn input<T: Message>(&mut self, name: impl AsPortName<T>, policy: Policy<T>) -> Input<T> {
        self.declare_input(name.as_port_name(), policy, false)
    }

    /// An input that may stay unconnected (e.g. team messages on a robot without a network).
    pub fn optional_input<T: Message>(
        &mut self,
        name: impl AsPortName<T>,
        policy: Policy<T>,
    ) -> Input<T> {
        self.declare_input(name.as_port_name(), policy, true)
    }

    fn declare_input<T: Message>(
        &mut self,
        name: &str,
        policy: Policy<T>,
        optional: bool,
    ) -> Input<T> {
        if self.decl.inputs.iter().any(|i| i.name == name) {
            self.problems.push(GraphError::DuplicatePort {
                module: self.decl.name.clone(),
                port: name.to_owned(),
            });
        }
        let port = u16::try_from(self.decl.inputs.len()).unwrap_or(u16::MAX);
        self.decl.inputs.push(InputDecl {
            name: name.to_owned(),
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            optional,
            slot: Arc::new(InputSlot::new(policy)),
            wakes_writer: false,
        });
        Input::new(self.id, port)
    }

    pub fn output<T: Message>(&mut self, name: impl AsPortName<T>) -> Output<T> {
        let name = name.as_port_name();
        if self.decl.outputs.iter().any(|o| o.name == name) {
            self.problems.push(GraphError::DuplicatePort {
                module: self.decl.name.clone(),
                port: name.to_owned(),
            });
        }
        let port = u16::try_from(self.decl.outputs.len()).unwrap_or(u16::MAX);
        self.decl.outputs.push(OutputDecl {
            name: name.to_owned(),
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            wake_on_ready: false,
        });
        Output::new(self.id, port)
    }

    /// Runs a cycle when the readers of `output` have taken what it last sent (the paper's
    /// "receiver is ready" message). Without this, the module can still ask
    /// [`crate::Context::receivers_ready`] during its cycles.
    pub fn wake_when_receivers_ready<T>(&mut self, output: Output<T>) {
        if let Some(decl) = self.decl.outputs.get_mut(usize::from(output.port)) {
            decl.wake_on_ready = true;
        }
    }

    pub fn trigger(&mut self, trigger: Trigger) {
        self.decl.trigger = Some(trigger);
    }

    /// Breaks ties between events at the same instant on the lockstep host: lower runs first
    /// (a simulator stepping its world before the robots read their sensors).
    pub fn priority(&mut self, priority: i32) {
        self.decl.priority = priority;
    }

    /// Marks the module as part of the sensor path (paper 3.7: perception, world modeling, the
    /// reactive layer, actuation), whose rate must not depend on slower modules. The threaded
    /// host runs such a module's thread at a real-time priority when its config asks for one
    /// ([`crate::HostConfig::real_time_priority`]), so a deliberative cycle busy for hundreds of
    /// milliseconds cannot delay it on a machine without a free core. The lockstep host ignores
    /// it: there, processing time is modelled, not contended for.
    pub fn real_time(&mut self) {
        self.decl.real_time = true;
    }

    pub fn processing_time(&mut self, model: ProcessingTime) {
        self.decl.processing_time = model;
    }
}

/// A problem found while building a graph. Every variant names the modules and ports involved.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum GraphError {
    #[error("two modules are named `{name}`")]
    DuplicateModule { name: String },
    #[error("module `{module}` declares port `{port}` twice")]
    DuplicatePort { module: String, port: String },
    #[error("no module named `{name}`")]
    UnknownModule { name: String },
    #[error("module `{module}` has no {direction} port named `{port}`")]
    UnknownPort { module: String, port: String, direction: &'static str },
    #[error(
        "input `{input}` ({type_name}) has no writer: connect an output to it or declare it optional"
    )]
    InputWithoutWriter { input: String, type_name: &'static str },
    #[error("input `{input}` has more than one writer: {}", writers.join(", "))]
    MultipleWriters { input: String, writers: Vec<String> },
    #[error(
        "type mismatch: output `{output}` sends {output_type} but input `{input}` expects {input_type}"
    )]
    TypeMismatch {
        output: String,
        output_type: &'static str,
        input: String,
        input_type: &'static str,
    },
    #[error("cycle of same-tick dependencies: {} (every module in it is triggered by the previous one's output; make one of these inputs non-triggering or one module periodic)", path.join(" -> "))]
    SameTickCycle { path: Vec<String> },
    #[error("module `{module}` never runs: it has no trigger and no inputs")]
    NeverTriggered { module: String },
    #[error("module `{module}` is triggered by `{input}`, which is not one of its inputs")]
    ForeignTriggerInput { module: String, input: String },
}

/// Every problem found in a graph, reported together.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GraphErrors(pub Vec<GraphError>);

impl fmt::Display for GraphErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "the module graph is invalid:")?;
        for error in &self.0 {
            write!(f, "\n  - {error}")?;
        }
        Ok(())
    }
}

impl std::error::Error for GraphErrors {}

/// Collects modules and connections; [`GraphBuilder::build`] checks them.
pub struct GraphBuilder {
    modules: Vec<ModuleDecl>,
    names: HashMap<String, ModuleId>,
    connections: Vec<(OutputRef, InputRef)>,
    externals: Vec<InputRef>,
    problems: Vec<GraphError>,
}

impl fmt::Debug for GraphBuilder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GraphBuilder")
            .field("modules", &self.modules.iter().map(|m| &m.name).collect::<Vec<_>>())
            .field("connections", &self.connections.len())
            .finish()
    }
}

impl Default for GraphBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl GraphBuilder {
    pub fn new() -> GraphBuilder {
        GraphBuilder {
            modules: Vec::new(),
            names: HashMap::new(),
            connections: Vec::new(),
            externals: Vec::new(),
            problems: Vec::new(),
        }
    }

    /// Adds a module. `declare` declares its ports and returns the module together with
    /// whatever port handles the caller needs to wire it (often a small struct of them).
    pub fn add<M, R>(&mut self, name: &str, declare: impl FnOnce(&mut Ports<'_>) -> (M, R)) -> R
    where
        M: Module,
    {
        let id = ModuleId(u32::try_from(self.modules.len()).unwrap_or(u32::MAX));
        if self.names.insert(name.to_owned(), id).is_some() {
            self.problems.push(GraphError::DuplicateModule { name: name.to_owned() });
        }
        let mut decl = ModuleDecl {
            name: name.to_owned(),
            module: None,
            trigger: None,
            priority: 0,
            real_time: false,
            processing_time: ProcessingTime::default(),
            inputs: Vec::new(),
            outputs: Vec::new(),
        };
        let (module, handles) = {
            let mut ports = Ports { id, decl: &mut decl, problems: &mut self.problems };
            declare(&mut ports)
        };
        decl.module = Some(Box::new(module));
        self.modules.push(decl);
        handles
    }

    /// Connects an output to an input of the same type.
    pub fn connect<T: Message>(&mut self, from: Output<T>, to: Input<T>) {
        self.connections.push((from.into(), to.into()));
    }

    /// Connects one output to several inputs.
    pub fn fan_out<T: Message>(&mut self, from: Output<T>, to: impl IntoIterator<Item = Input<T>>) {
        for input in to {
            self.connect(from, input);
        }
    }

    /// Connects ports by module and port names; types are checked by [`GraphBuilder::build`].
    pub fn connect_by_name(
        &mut self,
        from_module: &str,
        from_port: &str,
        to_module: &str,
        to_port: &str,
    ) -> Result<(), GraphError> {
        let output = self.output_ref(from_module, from_port)?;
        let input = self.input_ref(to_module, to_port)?;
        self.connections.push((output, input));
        Ok(())
    }

    /// Declares that `input` is fed from outside the graph (by [`crate::LockstepHost::inject`]
    /// or a replayed log) instead of by a module.
    pub fn external<T: Message>(&mut self, input: Input<T>) {
        self.externals.push(input.into());
    }

    pub fn external_by_name(&mut self, module: &str, port: &str) -> Result<InputRef, GraphError> {
        let input = self.input_ref(module, port)?;
        self.externals.push(input);
        Ok(input)
    }

    pub fn module_id(&self, name: &str) -> Option<ModuleId> {
        self.names.get(name).copied()
    }

    /// Replaces the processing-time model of a module already added (one that a library
    /// function created, say). False if there is no such module.
    pub fn set_processing_time(&mut self, module: &str, model: ProcessingTime) -> bool {
        match self.names.get(module) {
            Some(id) => {
                self.modules[id.index()].processing_time = model;
                true
            }
            None => false,
        }
    }

    /// Marks a module already added as part of the sensor path ([`Ports::real_time`]).
    pub fn set_real_time(&mut self, module: &str) -> bool {
        match self.names.get(module) {
            Some(id) => {
                self.modules[id.index()].real_time = true;
                true
            }
            None => false,
        }
    }

    /// Replaces the tie-break priority of a module already added.
    pub fn set_priority(&mut self, module: &str, priority: i32) -> bool {
        match self.names.get(module) {
            Some(id) => {
                self.modules[id.index()].priority = priority;
                true
            }
            None => false,
        }
    }

    fn module_by_name(&self, name: &str) -> Result<(ModuleId, &ModuleDecl), GraphError> {
        let id = self
            .names
            .get(name)
            .copied()
            .ok_or_else(|| GraphError::UnknownModule { name: name.to_owned() })?;
        Ok((id, &self.modules[id.index()]))
    }

    pub fn output_ref(&self, module: &str, port: &str) -> Result<OutputRef, GraphError> {
        let (id, decl) = self.module_by_name(module)?;
        let index = decl.outputs.iter().position(|o| o.name == port).ok_or_else(|| {
            GraphError::UnknownPort {
                module: module.to_owned(),
                port: port.to_owned(),
                direction: "output",
            }
        })?;
        Ok(OutputRef { module: id, port: index as u16 })
    }

    pub fn input_ref(&self, module: &str, port: &str) -> Result<InputRef, GraphError> {
        let (id, decl) = self.module_by_name(module)?;
        let index = decl.inputs.iter().position(|i| i.name == port).ok_or_else(|| {
            GraphError::UnknownPort {
                module: module.to_owned(),
                port: port.to_owned(),
                direction: "input",
            }
        })?;
        Ok(InputRef { module: id, port: index as u16 })
    }

    fn input_name(&self, input: InputRef) -> String {
        let module = &self.modules[input.module.index()];
        format!("{}.{}", module.name, module.inputs[usize::from(input.port)].name)
    }

    fn output_name(&self, output: OutputRef) -> String {
        let module = &self.modules[output.module.index()];
        format!("{}.{}", module.name, module.outputs[usize::from(output.port)].name)
    }

    /// Checks the graph and freezes it. Reports every problem at once.
    pub fn build(mut self) -> Result<Graph, GraphErrors> {
        let mut problems = std::mem::take(&mut self.problems);
        let module_count = self.modules.len();

        let mut writer_of: Vec<Vec<Vec<OutputRef>>> =
            self.modules.iter().map(|m| vec![Vec::new(); m.inputs.len()]).collect();
        for &(output, input) in &self.connections {
            let out_decl = &self.modules[output.module.index()].outputs[usize::from(output.port)];
            let in_decl = &self.modules[input.module.index()].inputs[usize::from(input.port)];
            if out_decl.type_id != in_decl.type_id {
                problems.push(GraphError::TypeMismatch {
                    output: self.output_name(output),
                    output_type: out_decl.type_name,
                    input: self.input_name(input),
                    input_type: in_decl.type_name,
                });
                continue;
            }
            let writers = &mut writer_of[input.module.index()][usize::from(input.port)];
            if !writers.contains(&output) {
                writers.push(output);
            }
        }
        for (m, module) in self.modules.iter().enumerate() {
            for (p, input) in module.inputs.iter().enumerate() {
                let input_ref = InputRef { module: ModuleId(m as u32), port: p as u16 };
                let writers = &writer_of[m][p];
                let external = self.externals.contains(&input_ref);
                if writers.len() > 1 || (external && !writers.is_empty()) {
                    let mut names: Vec<String> =
                        writers.iter().map(|w| self.output_name(*w)).collect();
                    if external {
                        names.push("<external>".to_owned());
                    }
                    problems.push(GraphError::MultipleWriters {
                        input: self.input_name(input_ref),
                        writers: names,
                    });
                } else if writers.is_empty() && !input.optional && !external {
                    problems.push(GraphError::InputWithoutWriter {
                        input: self.input_name(input_ref),
                        type_name: input.type_name,
                    });
                }
            }
            match &module.trigger {
                None if module.inputs.is_empty() => {
                    problems.push(GraphError::NeverTriggered { module: module.name.clone() })
                }
                Some(Trigger::OnInput { inputs, .. }) => {
                    if inputs.is_empty() {
                        problems.push(GraphError::NeverTriggered { module: module.name.clone() });
                    }
                    for input in inputs {
                        if input.module.index() != m
                            || usize::from(input.port) >= module.inputs.len()
                        {
                            let name = if input.module.index() < module_count
                                && usize::from(input.port)
                                    < self.modules[input.module.index()].inputs.len()
                            {
                                self.input_name(*input)
                            } else {
                                format!("{input:?}")
                            };
                            problems.push(GraphError::ForeignTriggerInput {
                                module: module.name.clone(),
                                input: name,
                            });
                        }
                    }
                }
                _ => {}
            }
        }
        // A module without an explicit trigger runs on any of its inputs.
        for module in &mut self.modules {
            if module.trigger.is_none() && !module.inputs.is_empty() {
                let id = self.names.get(&module.name).copied().unwrap_or(ModuleId(0));
                module.trigger = Some(Trigger::on_any(
                    (0..module.inputs.len()).map(|p| InputRef { module: id, port: p as u16 }),
                ));
            }
        }
        if let Some(path) = self.find_trigger_cycle(&writer_of) {
            problems.push(GraphError::SameTickCycle { path });
        }
        if !problems.is_empty() {
            return Err(GraphErrors(problems));
        }

        let mut readers: Vec<Vec<Vec<InputRef>>> =
            self.modules.iter().map(|m| vec![Vec::new(); m.outputs.len()]).collect();
        let mut writers: Vec<Vec<Option<OutputRef>>> =
            self.modules.iter().map(|m| vec![None; m.inputs.len()]).collect();
        for (m, per_input) in writer_of.iter().enumerate() {
            for (p, w) in per_input.iter().enumerate() {
                if let Some(&output) = w.first() {
                    readers[output.module.index()][usize::from(output.port)]
                        .push(InputRef { module: ModuleId(m as u32), port: p as u16 });
                    writers[m][p] = Some(output);
                    let writer = &self.modules[output.module.index()].outputs;
                    let wake = writer[usize::from(output.port)].wake_on_ready;
                    self.modules[m].inputs[p].wakes_writer = wake;
                }
            }
        }
        Ok(Graph { modules: self.modules, readers, writers, externals: self.externals })
    }

    /// Finds a cycle in which every edge is a connection into an input that triggers its
    /// reader: such a loop would run without simulated time advancing.
    fn find_trigger_cycle(&self, writer_of: &[Vec<Vec<OutputRef>>]) -> Option<Vec<String>> {
        let n = self.modules.len();
        // edges[a] = (b, output of a, input of b) where that input triggers b.
        let mut edges: Vec<Vec<(usize, OutputRef, InputRef)>> = vec![Vec::new(); n];
        for (m, per_input) in writer_of.iter().enumerate() {
            let Some(trigger) = &self.modules[m].trigger else { continue };
            for (p, writers) in per_input.iter().enumerate() {
                if !trigger.triggered_by(p as u16) {
                    continue;
                }
                for w in writers {
                    edges[w.module.index()].push((
                        m,
                        *w,
                        InputRef { module: ModuleId(m as u32), port: p as u16 },
                    ));
                }
            }
        }
        #[derive(Clone, Copy, PartialEq)]
        enum Mark {
            New,
            OnPath,
            Done,
        }
        let mut marks = vec![Mark::New; n];
        let mut path: Vec<(OutputRef, InputRef)> = Vec::new();
        fn visit(
            node: usize,
            edges: &[Vec<(usize, OutputRef, InputRef)>],
            marks: &mut [Mark],
            path: &mut Vec<(OutputRef, InputRef)>,
        ) -> Option<usize> {
            marks[node] = Mark::OnPath;
            for &(next, output, input) in &edges[node] {
                path.push((output, input));
                match marks[next] {
                    Mark::OnPath => return Some(next),
                    Mark::New => {
                        if let Some(start) = visit(next, edges, marks, path) {
                            return Some(start);
                        }
                    }
                    Mark::Done => {}
                }
                path.pop();
            }
            marks[node] = Mark::Done;
            None
        }
        for start in 0..n {
            if marks[start] != Mark::New {
                continue;
            }
            if let Some(cycle_start) = visit(start, &edges, &mut marks, &mut path) {
                let from = path.iter().position(|(o, _)| o.module.index() == cycle_start)?;
                return Some(
                    path[from..]
                        .iter()
                        .map(|(o, i)| {
                            format!("{} -> {}", self.output_name(*o), self.input_name(*i))
                        })
                        .collect(),
                );
            }
        }
        None
    }
}

/// A checked module graph, ready to be run by a host.
pub struct Graph {
    pub(crate) modules: Vec<ModuleDecl>,
    /// Per module, per output: the inputs it writes to.
    pub(crate) readers: Vec<Vec<Vec<InputRef>>>,
    /// Per module, per input: its writer, if any.
    pub(crate) writers: Vec<Vec<Option<OutputRef>>>,
    pub(crate) externals: Vec<InputRef>,
}

impl fmt::Debug for Graph {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Graph")
            .field("modules", &self.modules.iter().map(|m| &m.name).collect::<Vec<_>>())
            .finish()
    }
}

impl Graph {
    pub fn module_names(&self) -> impl Iterator<Item = &str> {
        self.modules.iter().map(|m| m.name.as_str())
    }

    pub fn module_id(&self, name: &str) -> Option<ModuleId> {
        self.modules.iter().position(|m| m.name == name).map(|i| ModuleId(i as u32))
    }

    /// The whole graph as data: modules, ports with their types and policies, connections.
    pub fn describe(&self) -> GraphDescription {
        let modules = self
            .modules
            .iter()
            .map(|m| ModuleDescription {
                name: m.name.clone(),
                trigger: m.trigger.clone(),
                priority: m.priority,
                real_time: m.real_time,
                processing_time: m.processing_time.clone(),
                inputs: m
                    .inputs
                    .iter()
                    .map(|i| PortDescription {
                        name: i.name.clone(),
                        type_name: i.type_name.to_owned(),
                        policy: Some(i.slot.policy()),
                    })
                    .collect(),
                outputs: m
                    .outputs
                    .iter()
                    .map(|o| PortDescription {
                        name: o.name.clone(),
                        type_name: o.type_name.to_owned(),
                        policy: None,
                    })
                    .collect(),
            })
            .collect();
        let mut connections = Vec::new();
        for (m, per_output) in self.readers.iter().enumerate() {
            for (p, readers) in per_output.iter().enumerate() {
                for r in readers {
                    connections.push(ConnectionDescription {
                        from: format!(
                            "{}.{}",
                            self.modules[m].name, self.modules[m].outputs[p].name
                        ),
                        to: format!(
                            "{}.{}",
                            self.modules[r.module.index()].name,
                            self.modules[r.module.index()].inputs[usize::from(r.port)].name
                        ),
                        policy: self.modules[r.module.index()].inputs[usize::from(r.port)]
                            .slot
                            .policy(),
                    });
                }
            }
        }
        GraphDescription { modules, connections }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GraphDescription {
    pub modules: Vec<ModuleDescription>,
    pub connections: Vec<ConnectionDescription>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ModuleDescription {
    pub name: String,
    pub trigger: Option<Trigger>,
    pub priority: i32,
    /// Declared part of the sensor path ([`Ports::real_time`]). Absent in logs written before it.
    #[serde(default)]
    pub real_time: bool,
    pub processing_time: ProcessingTime,
    pub inputs: Vec<PortDescription>,
    pub outputs: Vec<PortDescription>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PortDescription {
    pub name: String,
    pub type_name: String,
    pub policy: Option<PolicyKind>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ConnectionDescription {
    pub from: String,
    pub to: String,
    pub policy: PolicyKind,
}
