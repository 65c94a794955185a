//! The deterministic host: one thread, a discrete-event queue in simulated time.
//!
//! Semantics (the same as the threaded host's, with time made explicit):
//! - A periodic module's cycle starts at `offset + k * period`.
//! - A cycle that starts at `t` takes the module's processing time `d` (from its model, drawn
//!   from a seeded RNG): its outputs become visible to readers at `t + d`, and the module cannot
//!   start another cycle before `t + d`. A trigger that arrives while it is busy runs a cycle as
//!   soon as it is free; ticks missed while busy collapse into that one cycle.
//! - A package arriving on a triggering input schedules a cycle at the arrival time, after every
//!   other event already due at that instant, so packages that arrive together are seen
//!   together.
//! - Events at the same instant run in order of the module priority (lower first), then in the
//!   order they were scheduled. Nothing depends on hashing, addresses or wall time, so two runs
//!   with the same graph and seed produce the same trace, bit for bit.

use std::any::Any;
use std::cmp::Ordering as CmpOrdering;
use std::collections::BinaryHeap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::encoding::Encoding;
use crate::graph::{Graph, Input, InputRef, Trigger};
use crate::host::{HostConfig, HostError, panic_message};
use crate::message::{ErasedPackage, Message};
use crate::module::{Backend, Context, Wake};
use crate::package::{ModuleId, Package};
use crate::rng::{module_rng, timing_rng};
use crate::stats::{HostKind, HostStats, StatsCollector};
use crate::tap::{Tap, TapRecord};
use crate::time::Time;
use crate::wiring::{ModuleParts, Wiring, split};

enum EventKind {
    Tick(u32),
    Cycle(u32),
    Free(u32),
    Deliver { module: u32, port: u16, package: Box<dyn ErasedPackage> },
    Ready { module: u32, port: u16 },
    Inject { input: InputRef, package: Box<dyn Any + Send> },
}

struct Scheduled {
    time: Time,
    priority: i32,
    seq: u64,
    kind: EventKind,
}

impl PartialEq for Scheduled {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == CmpOrdering::Equal
    }
}
impl Eq for Scheduled {}
impl PartialOrd for Scheduled {
    fn partial_cmp(&self, other: &Self) -> Option<CmpOrdering> {
        Some(self.cmp(other))
    }
}
impl Ord for Scheduled {
    /// Reversed, so the max-heap pops the earliest event.
    fn cmp(&self, other: &Self) -> CmpOrdering {
        (other.time, other.priority, other.seq).cmp(&(self.time, self.priority, self.seq))
    }
}

/// One entry of a lockstep trace: what ran, when.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TraceEntry {
    pub time: Time,
    pub module: ModuleId,
    pub event: TraceEvent,
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum TraceEvent {
    /// A cycle ran and sent this many packages.
    Cycle { sent: usize },
    /// A package of this output became visible to its readers.
    Deliver { port: u16, seq: u64, stamp: Time },
}

struct ModuleState {
    parts: ModuleParts,
    rng: ChaCha8Rng,
    timing_rng: ChaCha8Rng,
    busy_until: Time,
    cycle_scheduled: bool,
    pending: bool,
    /// The event that frees the module at `busy_until`, not yet in the queue: its place in the
    /// order (time, priority, sequence number) is fixed when the cycle ends, but it is queued
    /// only once a trigger waits for it. Most cycles end with nothing waiting, and a third of
    /// all events were such idle frees.
    deferred_free: Option<u64>,
    trigger_time: Option<Time>,
    wakes: Vec<Wake>,
    output_seq: Vec<u64>,
    stats: StatsCollector,
}

/// Runs a graph in simulated time, as fast as the CPU allows or paced to real time.
pub struct LockstepHost {
    wiring: Wiring,
    modules: Vec<ModuleState>,
    queue: BinaryHeap<Scheduled>,
    now: Time,
    seq: u64,
    externals: Vec<InputRef>,
    tap: Option<Arc<dyn Tap>>,
    trace: Option<Vec<TraceEntry>>,
    pacing: Option<Pacing>,
    interrupt: Option<Arc<AtomicBool>>,
    wall_start: Instant,
    stopped: bool,
    /// Buffers of one cycle's outputs and one delivery's arrivals, kept between events: a
    /// match runs tens of thousands of cycles per simulated minute.
    published: Vec<(u16, Box<dyn ErasedPackage>)>,
    emptied: Vec<u16>,
    arrivals: Vec<InputRef>,
}

#[derive(Clone, Copy)]
struct Pacing {
    speed: f64,
    wall_origin: Instant,
    sim_origin: Time,
}

impl std::fmt::Debug for LockstepHost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LockstepHost")
            .field("now", &self.now)
            .field("modules", &self.wiring.names)
            .field("pending_events", &self.queue.len())
            .finish()
    }
}

struct LockstepBackend<'a> {
    module: u32,
    wiring: &'a Wiring,
    published: &'a mut Vec<(u16, Box<dyn ErasedPackage>)>,
    emptied: &'a mut Vec<u16>,
}

impl Backend for LockstepBackend<'_> {
    fn publish(&mut self, port: u16, package: Box<dyn ErasedPackage>) {
        self.published.push((port, package));
    }

    fn input_emptied(&mut self, port: u16) {
        self.emptied.push(port);
    }

    fn receivers_ready(&self, port: u16) -> bool {
        self.wiring.outputs[self.module as usize]
            .get(usize::from(port))
            .is_some_and(|o| o.readers.iter().all(|r| !r.slot.has_pending()))
    }
}

impl LockstepHost {
    pub fn new(graph: Graph, config: HostConfig) -> LockstepHost {
        let externals = graph.externals.clone();
        let (wiring, parts) = split(graph);
        let modules = parts
            .into_iter()
            .map(|parts| ModuleState {
                rng: module_rng(config.seed, &parts.name),
                timing_rng: timing_rng(config.seed, &parts.name),
                busy_until: Time::ZERO,
                cycle_scheduled: false,
                pending: false,
                deferred_free: None,
                trigger_time: None,
                wakes: Vec::new(),
                output_seq: vec![0; wiring.outputs[parts.id.index()].len()],
                stats: StatsCollector::new(config.stats_window),
                parts,
            })
            .collect();
        let mut host = LockstepHost {
            wiring,
            modules,
            queue: BinaryHeap::new(),
            now: Time::ZERO,
            seq: 0,
            externals,
            tap: None,
            trace: None,
            pacing: None,
            interrupt: None,
            wall_start: Instant::now(),
            stopped: false,
            published: Vec::new(),
            emptied: Vec::new(),
            arrivals: Vec::new(),
        };
        for m in 0..host.modules.len() {
            if let Trigger::Periodic { offset, .. } = host.modules[m].parts.trigger {
                let priority = host.modules[m].parts.priority;
                host.schedule(Time::ZERO + offset, priority, EventKind::Tick(m as u32));
            }
        }
        host
    }

    pub fn set_tap(&mut self, tap: Arc<dyn Tap>) {
        self.tap = Some(tap);
    }

    /// Records every cycle and delivery (for determinism checks and debugging).
    pub fn record_trace(&mut self, enabled: bool) {
        self.trace = enabled.then(Vec::new);
    }

    pub fn trace(&self) -> &[TraceEntry] {
        self.trace.as_deref().unwrap_or(&[])
    }

    /// Paces simulated time to `speed` times real time (`Some(1.0)`: real time); `None` runs
    /// as fast as the CPU allows.
    pub fn set_pacing(&mut self, speed: Option<f64>) {
        self.pacing = speed.filter(|s| *s > 0.0).map(|speed| Pacing {
            speed,
            wall_origin: Instant::now(),
            sim_origin: self.now,
        });
    }

    /// Stops `run_until` early when the flag becomes true (Ctrl-C).
    pub fn set_interrupt(&mut self, flag: Arc<AtomicBool>) {
        self.interrupt = Some(flag);
    }

    pub fn now(&self) -> Time {
        self.now
    }

    pub fn module_names(&self) -> &[String] {
        &self.wiring.names
    }

    fn schedule(&mut self, time: Time, priority: i32, kind: EventKind) {
        self.seq += 1;
        self.queue.push(Scheduled { time, priority, seq: self.seq, kind });
    }

    /// Feeds a package to an external input, visible at `at` (not before the current time).
    pub fn inject<T: Message>(
        &mut self,
        input: Input<T>,
        value: T,
        stamp: Time,
        at: Time,
    ) -> Result<(), HostError> {
        let input_ref: InputRef = input.into();
        self.check_external(input_ref)?;
        let package = Package::new(value, stamp, 0, ModuleId(u32::MAX));
        let at = at.max(self.now);
        self.schedule(
            at,
            i32::MIN,
            EventKind::Inject { input: input_ref, package: Box::new(package) },
        );
        Ok(())
    }

    /// Feeds a logged (encoded) package to an external input, now (replay).
    pub fn inject_encoded(
        &mut self,
        input: InputRef,
        encoding: Encoding,
        bytes: &[u8],
        stamp: Time,
        seq: u64,
    ) -> Result<(), HostError> {
        self.check_external(input)?;
        let name = self.input_name(input);
        let slot = &self.modules[input.module.index()].parts.inputs[usize::from(input.port)].slot;
        slot.push_encoded(encoding, bytes, stamp, seq, ModuleId(u32::MAX))
            .map_err(|e| HostError::Decode { input: name, error: e.to_string() })?;
        self.after_arrival(input, self.now);
        Ok(())
    }

    fn input_name(&self, input: InputRef) -> String {
        let parts = &self.modules[input.module.index()].parts;
        format!("{}.{}", parts.name, parts.inputs[usize::from(input.port)].name)
    }

    fn check_external(&self, input: InputRef) -> Result<(), HostError> {
        if self.externals.contains(&input) {
            Ok(())
        } else {
            Err(HostError::NotExternal { input: self.input_name(input) })
        }
    }

    /// Runs every event due up to and including `end`; the clock then reads `end`.
    pub fn run_until(&mut self, end: Time) -> Result<(), HostError> {
        let mut since_check = 0u32;
        while self.queue.peek().is_some_and(|e| e.time <= end) {
            since_check += 1;
            if since_check >= 1024 {
                since_check = 0;
                if self.interrupt.as_ref().is_some_and(|f| f.load(Ordering::Relaxed)) {
                    return Ok(());
                }
            }
            self.step()?;
        }
        self.now = self.now.max(end);
        Ok(())
    }

    pub fn run_for(&mut self, duration: Duration) -> Result<(), HostError> {
        self.run_until(self.now + duration)
    }

    /// Whether an interrupt (Ctrl-C) cut the last run short.
    pub fn interrupted(&self) -> bool {
        self.interrupt.as_ref().is_some_and(|f| f.load(Ordering::Relaxed))
    }

    /// Processes the next event; false when nothing is scheduled.
    pub fn step(&mut self) -> Result<bool, HostError> {
        let Some(event) = self.queue.pop() else { return Ok(false) };
        if let Some(pacing) = self.pacing {
            let sim_elapsed = event.time.saturating_since(pacing.sim_origin).as_secs_f64();
            let target = pacing.wall_origin + Duration::from_secs_f64(sim_elapsed / pacing.speed);
            let wall = Instant::now();
            if target > wall {
                std::thread::sleep(target - wall);
            }
        }
        self.now = event.time;
        match event.kind {
            EventKind::Tick(m) => {
                if let Trigger::Periodic { period, .. } = self.modules[m as usize].parts.trigger {
                    let priority = self.modules[m as usize].parts.priority;
                    self.schedule(self.now + period, priority, EventKind::Tick(m));
                }
                let module = &self.modules[m as usize];
                if module.busy_until <= self.now && !module.cycle_scheduled {
                    // Nothing can precede a tick's own cycle at this instant: run it now.
                    let state = &mut self.modules[m as usize];
                    state.wakes.push(Wake::Tick);
                    state.trigger_time = Some(self.now);
                    self.run_cycle(m)?;
                } else {
                    self.request_cycle(m, Wake::Tick, self.now);
                }
            }
            EventKind::Cycle(m) => {
                self.modules[m as usize].cycle_scheduled = false;
                self.run_cycle(m)?;
            }
            EventKind::Free(m) => {
                let state = &mut self.modules[m as usize];
                if state.pending && state.busy_until <= self.now {
                    state.pending = false;
                    state.cycle_scheduled = true;
                    let priority = state.parts.priority;
                    self.schedule(self.now, priority, EventKind::Cycle(m));
                }
            }
            EventKind::Deliver { module, port, package } => self.deliver(module, port, package),
            EventKind::Ready { module, port } => {
                let wake = self.wiring.outputs[module as usize]
                    .get(usize::from(port))
                    .is_some_and(|o| o.wake_on_ready);
                if wake {
                    self.request_cycle(module, Wake::ReceiversReady(port), self.now);
                }
            }
            EventKind::Inject { input, package } => {
                let slot =
                    &self.modules[input.module.index()].parts.inputs[usize::from(input.port)].slot;
                let _ = slot.push_owned(package);
                self.after_arrival(input, self.now);
            }
        }
        Ok(true)
    }

    fn deliver(&mut self, module: u32, port: u16, package: Box<dyn ErasedPackage>) {
        let output = &self.wiring.outputs[module as usize][usize::from(port)];
        if let Some(trace) = &mut self.trace {
            trace.push(TraceEntry {
                time: self.now,
                module: ModuleId(module),
                event: TraceEvent::Deliver { port, seq: package.seq(), stamp: package.stamp() },
            });
        }
        if let Some(tap) = &self.tap {
            tap.package(&TapRecord {
                time: self.now,
                module: ModuleId(module),
                module_name: &self.wiring.names[module as usize],
                output: &output.name,
                type_name: output.type_name,
                package: package.as_ref(),
            });
        }
        let mut arrivals = std::mem::take(&mut self.arrivals);
        if let Some((last, others)) = output.readers.split_last() {
            for reader in others {
                reader.slot.push_cloned(package.as_any());
                if reader.triggers {
                    arrivals.push(reader.input);
                }
            }
            last.slot.push_owned(package.into_any());
            if last.triggers {
                arrivals.push(last.input);
            }
        }
        for input in arrivals.drain(..) {
            self.after_arrival(input, self.now);
        }
        self.arrivals = arrivals;
    }

    fn after_arrival(&mut self, input: InputRef, at: Time) {
        if self.modules[input.module.index()].parts.triggered_by_arrival(input.port) {
            self.request_cycle(input.module.0, Wake::Input(input.port), at);
        }
    }

    fn request_cycle(&mut self, m: u32, wake: Wake, trigger_time: Time) {
        let now = self.now;
        let state = &mut self.modules[m as usize];
        state.wakes.push(wake);
        state.trigger_time = Some(state.trigger_time.map_or(trigger_time, |t| t.min(trigger_time)));
        if state.cycle_scheduled {
            return;
        }
        if state.busy_until > now {
            state.pending = true;
            if let Some(seq) = state.deferred_free.take() {
                let (time, priority) = (state.busy_until, state.parts.priority);
                self.queue.push(Scheduled { time, priority, seq, kind: EventKind::Free(m) });
            }
            return;
        }
        state.cycle_scheduled = true;
        let priority = state.parts.priority;
        self.schedule(now, priority, EventKind::Cycle(m));
    }

    fn run_cycle(&mut self, m: u32) -> Result<(), HostError> {
        let now = self.now;
        let mut published = std::mem::take(&mut self.published);
        let mut emptied = std::mem::take(&mut self.emptied);
        let state = &mut self.modules[m as usize];
        let result = {
            let mut backend = LockstepBackend {
                module: m,
                wiring: &self.wiring,
                published: &mut published,
                emptied: &mut emptied,
            };
            let mut ctx = Context {
                module: state.parts.id,
                name: &state.parts.name,
                now,
                rng: &mut state.rng,
                inputs: &state.parts.inputs,
                output_seq: &mut state.output_seq,
                backend: &mut backend,
                woken_by: &state.wakes,
                sent: 0,
            };
            let module = &mut state.parts.module;
            catch_unwind(AssertUnwindSafe(|| module.cycle(&mut ctx)))
        };
        state.wakes.clear();
        let trigger_time = state.trigger_time.take().unwrap_or(now);
        let duration = state.parts.processing_time.sample(&mut state.timing_rng);
        let visible = now + duration;
        let sent = published.len();
        state.stats.record_cycle(now, duration, (sent > 0).then(|| visible - trigger_time));
        state.busy_until = visible;
        let priority = state.parts.priority;
        if let Some(trace) = &mut self.trace {
            trace.push(TraceEntry {
                time: now,
                module: ModuleId(m),
                event: TraceEvent::Cycle { sent },
            });
        }
        match result {
            Ok(Ok(())) => {}
            Ok(Err(error)) => {
                self.modules[m as usize].stats.record_error();
                return Err(HostError::ModuleFailed {
                    module: self.wiring.names[m as usize].clone(),
                    error: error.to_string(),
                    stats: Box::new(self.stats()),
                });
            }
            Err(payload) => {
                self.modules[m as usize].stats.record_error();
                return Err(HostError::ModulePanicked {
                    module: self.wiring.names[m as usize].clone(),
                    message: panic_message(payload.as_ref()),
                    stats: Box::new(self.stats()),
                });
            }
        }
        for (port, package) in published.drain(..) {
            self.schedule(visible, priority, EventKind::Deliver { module: m, port, package });
        }
        self.published = published;
        for port in emptied.drain(..) {
            if let Some(Some((writer, true))) =
                self.wiring.writers[m as usize].get(usize::from(port)).copied()
            {
                let writer_priority = self.modules[writer.module.index()].parts.priority;
                self.schedule(
                    now,
                    writer_priority,
                    EventKind::Ready { module: writer.module.0, port: writer.port },
                );
            }
        }
        self.emptied = emptied;
        if duration > Duration::ZERO {
            self.seq += 1;
            self.modules[m as usize].deferred_free = Some(self.seq);
        } else {
            self.modules[m as usize].deferred_free = None;
        }
        if duration == Duration::ZERO && self.modules[m as usize].pending {
            self.modules[m as usize].pending = false;
            self.request_cycle(m, Wake::Tick, now);
        }
        Ok(())
    }

    /// Every module's statistics so far.
    pub fn stats(&self) -> HostStats {
        HostStats {
            host: HostKind::Lockstep,
            elapsed_s: self.now.as_secs_f64(),
            wall_s: self.wall_start.elapsed().as_secs_f64(),
            modules: self
                .modules
                .iter()
                .map(|m| m.stats.snapshot(&m.parts.name, m.parts.input_stats()))
                .collect(),
        }
    }

    /// Tells every module the run is over (closes files, releases hardware). Idempotent.
    pub fn stop(&mut self) {
        if !self.stopped {
            self.stopped = true;
            for state in &mut self.modules {
                state.parts.module.stop();
            }
        }
    }
}

impl Drop for LockstepHost {
    fn drop(&mut self) {
        self.stop();
    }
}
