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
use crate::graph::{Graph, Input, InputMode, InputRef, Trigger};
use crate::host::{HostConfig, HostError, panic_message};
use crate::message::{ErasedPackage, Message};
use crate::module::{Backend, Context, Wake};
use crate::package::{ModuleId, Package};
use crate::rng::{module_rng, timing_rng};
use crate::stats::{HostKind, HostStats, StatsCollector};
use crate::tap::{HostTaps, Tap, TapOutput, TapSenders};
use crate::time::Time;
use crate::wiring::{ModuleParts, Wiring, split};

/// What a queued event does. Packages wait in the host's slabs, so the queue moves small
/// copies: a match pops millions of events, and pushing and popping 56-byte entries that
/// carried the packages was a third of the host's own instructions.
#[derive(Clone, Copy, Debug)]
enum Event {
    Tick(u32),
    Cycle(u32),
    Free(u32),
    /// The next package a cycle sent becomes visible to its readers (the index of the cycle's
    /// [`Outputs`] in `LockstepHost::deliveries`). A cycle's packages have consecutive sequence
    /// numbers, so one event stands for them all: the first, then the next one, and so on.
    Deliver(u32),
    Ready {
        module: u32,
        port: u16,
    },
    /// An external package arrives (its index in `LockstepHost::injections`).
    Inject(u32),
}

/// An event and its place in the order: `time`, then `order`, which holds the rank of the
/// module priority above the sequence number (see [`EventOrder`]), so that comparing two
/// events is comparing two integers.
#[derive(Clone, Copy, Debug)]
struct Scheduled {
    time: Time,
    order: u64,
    event: Event,
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
        (other.time, other.order).cmp(&(self.time, self.order))
    }
}

/// Packs (priority, sequence number) into one `u64` that sorts the same way: the priority's
/// rank among the graph's distinct priorities in the high bits, the sequence number below.
/// The priorities are known when the host is built (each module's, and `i32::MIN` for injected
/// packages), so a few bits hold the rank and the sequence number keeps the rest (56 bits or
/// more below 256 distinct priorities: centuries of simulated matches).
#[derive(Clone, Debug)]
struct EventOrder {
    /// The distinct priorities, ascending.
    priorities: Vec<i32>,
    seq_bits: u32,
}

impl EventOrder {
    fn new(module_priorities: impl IntoIterator<Item = i32>) -> EventOrder {
        let mut priorities: Vec<i32> =
            module_priorities.into_iter().chain([INJECT_PRIORITY]).collect();
        priorities.sort_unstable();
        priorities.dedup();
        let rank_bits = usize::BITS - (priorities.len() - 1).leading_zeros();
        EventOrder { priorities, seq_bits: u64::BITS - rank_bits.max(1) }
    }

    /// The high bits of the order of every event at `priority`.
    fn base(&self, priority: i32) -> u64 {
        let rank = self.priorities.binary_search(&priority).unwrap_or_else(|_| {
            unreachable!("every priority a host schedules at is among its modules'")
        });
        (rank as u64) << self.seq_bits
    }

    /// The first sequence number that would spill into the rank bits.
    fn seq_limit(&self) -> u64 {
        1 << self.seq_bits
    }
}

/// The priority of injected packages: the lowest there is, so they arrive before every other
/// event at the same instant.
const INJECT_PRIORITY: i32 = i32::MIN;

/// The queued events. Those due at the current instant wait apart from the later ones: most
/// cycles of a robot's layers are triggered by a package and scheduled at the instant it
/// arrives, and such an event, the earliest of all, would climb the whole heap of later events
/// only to be popped straight away. Popping takes the earlier of the two heads, so the order is
/// that of one queue.
struct EventQueue {
    /// Events at `LockstepHost::now` (a handful at most).
    instant: BinaryHeap<Scheduled>,
    later: BinaryHeap<Scheduled>,
}

impl EventQueue {
    fn new() -> EventQueue {
        EventQueue { instant: BinaryHeap::new(), later: BinaryHeap::new() }
    }

    fn push(&mut self, now: Time, event: Scheduled) {
        debug_assert!(event.time >= now, "an event in the past");
        if event.time == now { self.instant.push(event) } else { self.later.push(event) }
    }

    /// The earliest event: the earlier of the two heads.
    fn peek(&self) -> Option<&Scheduled> {
        match (self.instant.peek(), self.later.peek()) {
            (Some(instant), Some(later)) => Some(if later > instant { later } else { instant }),
            (instant, later) => instant.or(later),
        }
    }

    fn pop(&mut self) -> Option<Scheduled> {
        match (self.instant.peek(), self.later.peek()) {
            (Some(instant), Some(later)) if later > instant => self.later.pop(),
            (Some(_), _) => self.instant.pop(),
            (None, _) => self.later.pop(),
        }
    }

    fn len(&self) -> usize {
        self.instant.len() + self.later.len()
    }
}

/// Payloads of queued events, by index. A released entry keeps its allocations for the next
/// payload, so a long run allocates only as many entries as are ever queued at once.
struct Slab<T> {
    entries: Vec<T>,
    vacant: Vec<u32>,
}

impl<T: Default> Slab<T> {
    fn new() -> Slab<T> {
        Slab { entries: Vec::new(), vacant: Vec::new() }
    }

    /// An entry to fill: a released one (as its last user left it) or a new default one.
    fn vacant_entry(&mut self) -> (u32, &mut T) {
        let index = match self.vacant.pop() {
            Some(index) => index,
            None => {
                self.entries.push(T::default());
                u32::try_from(self.entries.len() - 1)
                    .unwrap_or_else(|_| panic!("more than 2^32 payloads queued at once"))
            }
        };
        (index, &mut self.entries[index as usize])
    }

    fn get_mut(&mut self, index: u32) -> &mut T {
        &mut self.entries[index as usize]
    }

    fn release(&mut self, index: u32) {
        self.vacant.push(index);
    }
}

/// The packages one cycle sent, becoming visible to their readers in the order they were sent.
#[derive(Default)]
struct Outputs {
    module: u32,
    /// Reversed: the next package to deliver is the last.
    packages: Vec<(u16, Box<dyn ErasedPackage>)>,
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
    /// The high bits of the order of this module's events (its priority's rank).
    order_base: u64,
    rng: ChaCha8Rng,
    timing_rng: ChaCha8Rng,
    busy_until: Time,
    cycle_scheduled: bool,
    pending: bool,
    /// The order of the event that frees the module at `busy_until`, not yet in the queue: its
    /// place in the order (time, priority, sequence number) is fixed when the cycle ends, but it
    /// is queued only once a trigger waits for it. Most cycles end with nothing waiting, and a
    /// third of all events were such idle frees.
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
    queue: EventQueue,
    deliveries: Slab<Outputs>,
    injections: Slab<Option<(InputRef, Box<dyn Any + Send>)>>,
    now: Time,
    seq: u64,
    seq_limit: u64,
    inject_order_base: u64,
    externals: Vec<InputRef>,
    taps: HostTaps,
    /// The senders of the taps that have one ([`Tap::sender`]).
    tap_senders: TapSenders,
    trace: Option<Vec<TraceEntry>>,
    pacing: Option<Pacing>,
    interrupt: Option<Arc<AtomicBool>>,
    wall_start: Instant,
    stopped: bool,
    /// Buffers of one cycle's outputs and one delivery's arrivals, kept between events: a
    /// match runs tens of thousands of cycles per simulated minute.
    published: Vec<(u16, Box<dyn ErasedPackage>)>,
    emptied: Vec<u16>,
    /// Each triggering input a package arrived on, its trigger's mode, and whether the package
    /// was stored there.
    arrivals: Vec<(InputRef, InputMode, bool)>,
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
        let order = EventOrder::new(parts.iter().map(|p| p.priority));
        let modules = parts
            .into_iter()
            .map(|parts| ModuleState {
                order_base: order.base(parts.priority),
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
            queue: EventQueue::new(),
            deliveries: Slab::new(),
            injections: Slab::new(),
            now: Time::ZERO,
            seq: 0,
            seq_limit: order.seq_limit(),
            inject_order_base: order.base(INJECT_PRIORITY),
            externals,
            taps: HostTaps::default(),
            tap_senders: TapSenders::default(),
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
                let base = host.modules[m].order_base;
                host.schedule(Time::ZERO + offset, base, Event::Tick(m as u32));
            }
        }
        host
    }

    /// Shows `tap` the packages of the outputs it wants ([`Tap::wants`], asked now), instead
    /// of the taps set so far.
    pub fn set_tap(&mut self, tap: Arc<dyn Tap>) {
        self.tap_senders.flush();
        self.tap_senders = TapSenders::default();
        self.taps = HostTaps::default();
        self.add_tap(tap);
    }

    /// Shows `tap` too the packages of the outputs it wants ([`Tap::wants`], asked now); each
    /// tap is shown only its outputs.
    pub fn add_tap(&mut self, tap: Arc<dyn Tap>) {
        self.taps.push_with_sender(tap, &mut self.tap_senders);
        self.wiring.select_tapped(&self.taps);
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

    /// The next `count` sequence numbers (the first is returned): events at the same instant
    /// and priority run in this order.
    fn next_seqs(&mut self, count: u64) -> u64 {
        let first = self.seq + 1;
        self.seq += count;
        assert!(self.seq < self.seq_limit, "the lockstep host ran out of sequence numbers");
        first
    }

    /// Queues `event` at `time`, after every event already queued at the same instant and
    /// priority (`order_base`, from [`EventOrder::base`]).
    fn schedule(&mut self, time: Time, order_base: u64, event: Event) {
        let order = order_base | self.next_seqs(1);
        self.queue.push(self.now, Scheduled { time, order, event });
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
        let (index, entry) = self.injections.vacant_entry();
        *entry = Some((input_ref, Box::new(package)));
        self.schedule(at, self.inject_order_base, Event::Inject(index));
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
        self.after_arrival(input, true);
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
        let result = self.run_events_until(end);
        self.tap_senders.flush();
        result
    }

    fn run_events_until(&mut self, end: Time) -> Result<(), HostError> {
        let mut since_check = 0u32;
        while self.queue.peek().is_some_and(|e| e.time <= end) {
            since_check += 1;
            if since_check >= 1024 {
                since_check = 0;
                if self.interrupt.as_ref().is_some_and(|f| f.load(Ordering::Relaxed)) {
                    return Ok(());
                }
            }
            self.next_event()?;
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

    /// Processes the next event; false when nothing is scheduled. The packages one cycle sent
    /// are delivered in one step as long as no other event comes between them.
    pub fn step(&mut self) -> Result<bool, HostError> {
        let result = self.next_event();
        self.tap_senders.flush();
        result
    }

    fn next_event(&mut self) -> Result<bool, HostError> {
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
        match event.event {
            Event::Tick(m) => {
                if let Trigger::Periodic { period, .. } = self.modules[m as usize].parts.trigger {
                    let base = self.modules[m as usize].order_base;
                    self.schedule(self.now + period, base, Event::Tick(m));
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
            Event::Cycle(m) => {
                self.modules[m as usize].cycle_scheduled = false;
                self.run_cycle(m)?;
            }
            Event::Free(m) => {
                let state = &mut self.modules[m as usize];
                if state.pending && state.busy_until <= self.now {
                    state.pending = false;
                    state.cycle_scheduled = true;
                    let base = state.order_base;
                    self.schedule(self.now, base, Event::Cycle(m));
                }
            }
            Event::Deliver(index) => self.deliver_outputs(index, event.order),
            Event::Ready { module, port } => {
                let wake = self.wiring.outputs[module as usize]
                    .get(usize::from(port))
                    .is_some_and(|o| o.wake_on_ready);
                if wake {
                    self.request_cycle(module, Wake::ReceiversReady(port), self.now);
                }
            }
            Event::Inject(index) => {
                let Some((input, package)) = self.injections.get_mut(index).take() else {
                    unreachable!("an injected package is delivered once")
                };
                self.injections.release(index);
                let slot =
                    &self.modules[input.module.index()].parts.inputs[usize::from(input.port)].slot;
                let stored = slot.push_owned(package).is_some();
                self.after_arrival(input, stored);
            }
        }
        Ok(true)
    }

    /// Delivers the packages of one cycle from the next one on, each in its own place in the
    /// order (`order` is the next one's, the others' follow): as long as nothing the deliveries
    /// scheduled comes before the next package's place, it is delivered at once; otherwise it is
    /// queued again in that place.
    fn deliver_outputs(&mut self, index: u32, mut order: u64) {
        loop {
            let outputs = self.deliveries.get_mut(index);
            let module = outputs.module;
            let Some((port, package)) = outputs.packages.pop() else {
                unreachable!("a cycle's outputs are queued only while some are undelivered")
            };
            let more = !outputs.packages.is_empty();
            self.deliver(module, port, package);
            if !more {
                self.deliveries.release(index);
                return;
            }
            order += 1;
            let next = Scheduled { time: self.now, order, event: Event::Deliver(index) };
            if self.queue.peek().is_some_and(|first| *first > next) {
                self.queue.push(self.now, next);
                return;
            }
        }
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
        let package = if output.tapped != 0 {
            let tapped = TapOutput {
                host: self.wiring.host,
                module: ModuleId(module),
                module_name: &self.wiring.names[module as usize],
                port,
                output: &output.name,
                type_name: output.type_name,
            };
            let read = !output.readers.is_empty();
            match self.taps.offer(
                Some(&mut self.tap_senders),
                output.tapped,
                &tapped,
                self.now,
                package,
                read,
            ) {
                Some(package) => package,
                None => return,
            }
        } else {
            package
        };
        let mut arrivals = std::mem::take(&mut self.arrivals);
        if let Some((last, others)) = output.readers.split_last() {
            for reader in others {
                let stored = reader.slot.push_cloned(package.as_any()).is_some();
                if let Some(mode) = reader.trigger {
                    arrivals.push((reader.input, mode, stored));
                }
            }
            let stored = last.slot.push_owned(package.into_any()).is_some();
            if let Some(mode) = last.trigger {
                arrivals.push((last.input, mode, stored));
            }
        }
        for (input, mode, stored) in arrivals.drain(..) {
            // A package stored on an input of an `Any` trigger starts a cycle whatever the other
            // inputs hold: the module's trigger, which lies apart in memory, need not be read.
            if mode == InputMode::Any && stored {
                self.request_cycle(input.module.0, Wake::Input(input.port), self.now);
            } else {
                self.after_arrival(input, stored);
            }
        }
        self.arrivals = arrivals;
    }

    /// A package arrived on `input` now (`stored`: and is pending there).
    fn after_arrival(&mut self, input: InputRef, stored: bool) {
        if self.modules[input.module.index()].parts.triggered_by_arrival(input.port, stored) {
            self.request_cycle(input.module.0, Wake::Input(input.port), self.now);
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
            if let Some(order) = state.deferred_free.take() {
                let time = state.busy_until;
                self.queue.push(now, Scheduled { time, order, event: Event::Free(m) });
            }
            return;
        }
        state.cycle_scheduled = true;
        let base = state.order_base;
        self.schedule(now, base, Event::Cycle(m));
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
        let order_base = state.order_base;
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
        if !published.is_empty() {
            let first = self.next_seqs(published.len() as u64);
            let (index, outputs) = self.deliveries.vacant_entry();
            outputs.module = m;
            // The released entry's empty buffer becomes the next cycle's.
            std::mem::swap(&mut outputs.packages, &mut published);
            outputs.packages.reverse();
            let next = Scheduled {
                time: visible,
                order: order_base | first,
                event: Event::Deliver(index),
            };
            self.queue.push(now, next);
        }
        self.published = published;
        for port in emptied.drain(..) {
            if let Some(Some((writer, true))) =
                self.wiring.writers[m as usize].get(usize::from(port)).copied()
            {
                let writer_base = self.modules[writer.module.index()].order_base;
                self.schedule(
                    now,
                    writer_base,
                    Event::Ready { module: writer.module.0, port: writer.port },
                );
            }
        }
        self.emptied = emptied;
        if duration > Duration::ZERO {
            let order = order_base | self.next_seqs(1);
            self.modules[m as usize].deferred_free = Some(order);
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
        self.tap_senders.flush();
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

#[cfg(test)]
mod tests {
    use std::cmp::Reverse;

    use proptest::prelude::*;

    use super::*;

    /// The plain order of the semantics: time, then priority, then sequence number.
    fn plain_key(time: u64, priority: i32, seq: u64) -> (u64, i32, u64) {
        (time, priority, seq)
    }

    proptest! {
        #[test]
        fn packed_orders_sort_like_priority_then_sequence(
            priorities in proptest::collection::vec(any::<i32>(), 1..300),
            events in proptest::collection::vec((0usize..300, 1u64..1 << 40), 2..40),
        ) {
            let order = EventOrder::new(priorities.iter().copied());
            let keyed: Vec<_> = events
                .iter()
                .map(|&(m, seq)| {
                    let priority = priorities[m % priorities.len()];
                    (plain_key(0, priority, seq), order.base(priority) | seq)
                })
                .collect();
            prop_assert!(order.seq_limit() > 1 << 40);
            for a in &keyed {
                for b in &keyed {
                    prop_assert_eq!(a.0.cmp(&b.0), a.1.cmp(&b.1), "{:?} {:?}", a, b);
                }
            }
        }

        /// Random pushes (due now or later, at random priorities) and pops, as the host does
        /// them: the two-lane queue pops exactly what one heap of all events pops.
        #[test]
        fn the_instant_lane_keeps_the_order_of_one_queue(
            ops in proptest::collection::vec((0u8..4, 0u64..3, -2i32..3), 1..400),
        ) {
            let order = EventOrder::new(-2..3);
            let mut queue = EventQueue::new();
            let mut plain = BinaryHeap::new();
            let mut now = Time::ZERO;
            let mut seq = 0u64;
            for (op, delay, priority) in ops {
                if op == 0 {
                    let popped = queue.pop();
                    let expected = plain.pop().map(|Reverse(key)| key);
                    prop_assert_eq!(
                        popped.map(|e| (e.time.as_nanos(), e.order)),
                        expected.map(|(t, p, s)| (t, order.base(p) | s))
                    );
                    prop_assert_eq!(queue.len(), plain.len());
                    if let Some(e) = popped {
                        now = e.time;
                    }
                } else {
                    seq += 1;
                    let time = now + Duration::from_nanos(delay);
                    let event = Event::Tick(0);
                    queue.push(now, Scheduled { time, order: order.base(priority) | seq, event });
                    plain.push(Reverse(plain_key(time.as_nanos(), priority, seq)));
                }
                prop_assert_eq!(
                    queue.peek().map(|e| (e.time.as_nanos(), e.order)),
                    plain.peek().map(|Reverse((t, p, s))| (*t, order.base(*p) | s))
                );
            }
        }
    }
}
