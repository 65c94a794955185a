//! The module communication library of Strata: section 3.7 of Testart et al., "A Real-Time
//! Hybrid Architecture for Biped Humanoids with Active Vision Mechanisms" (2011), for Rust.
//!
//! - A [`Module`] is a part of the software with an explicit interface: typed [`Input`]s and
//!   [`Output`]s declared when it is added to a [`GraphBuilder`].
//!   A module names its ports once, with their types ([`PortName`]): what it declares them with
//!   and what a [`Tap`] (a logger, a viewer) finds their packages by.
//! - Modules exchange [`Package`]s over connections whose [`Policy`] is one of the paper's
//!   three: overwrite ([`Policy::Latest`]), queue ([`Policy::Queue`]) or re-package
//!   ([`Policy::Merge`]).
//! - Each module runs when its [`Trigger`] fires: periodically, or on new input.
//! - The same graph runs on the [`ThreadedHost`] (a thread per module, real time) or on the
//!   [`LockstepHost`] (simulated time, deterministic, faster than real time). Modules get the
//!   time and their seeded RNG from their [`Context`] and never from the outside world.
//! - Both hosts report [`HostStats`]: per module, cycles, rates, compute time, latency, and
//!   what each connection overwrote, dropped or merged.

pub mod cdr;
mod connection;
mod encoding;
mod graph;
mod host;
mod lockstep;
mod message;
mod module;
mod package;
mod rng;
pub mod serde_duration;
pub mod shared;
pub mod signal;
mod stats;
mod tap;
mod threaded;
mod time;
mod wiring;

pub use connection::{Arrival, CombineFn, Connection, ConnectionCounters, Policy, PolicyKind};
pub use encoding::{Encoding, EncodingError};
pub use graph::{
    AsPortName, ConnectionDescription, Graph, GraphBuilder, GraphDescription, GraphError,
    GraphErrors, Input, InputMode, InputRef, ModuleDescription, Output, OutputRef, PortDescription,
    PortName, Ports, ProcessingTime, Trigger,
};
pub use host::{DEFAULT_STOP_TIMEOUT, HostConfig, HostError};
pub use lockstep::{LockstepHost, TraceEntry, TraceEvent};
pub use message::{ErasedPackage, Message};
pub use module::{Context, Module, ModuleError, Wake};
pub use package::{ModuleId, Package};
pub use rng::{module_rng, stable_hash};
pub use shared::Shared;
pub use stats::{
    DurationRecorder, HostKind, HostStats, InputStats, ModuleStats, RateStats, Scheduling,
    StatsCollector, Summary,
};
pub use tap::{Tap, TapOutput, TapRecord, TapSender, Taps};
pub use threaded::{RunningHost, StatsProbe, StopHandle, ThreadedHost};
pub use time::{Clock, ManualClock, MonotonicClock, Time};

/// The RNG type modules receive.
pub type ModuleRng = rand_chacha::ChaCha8Rng;
