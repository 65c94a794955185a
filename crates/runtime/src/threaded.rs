//! The real-time host: one OS thread per module, each blocking on its own event queue.
//!
//! Each module thread processes, in arrival order, the two kinds of messages of paper 3.7 —
//! a package arrived on an input, a receiver of an output is ready — plus its own period ticks.
//! Sending never blocks: packages go into the reader's connection (with its policy) and an
//! event is queued only when the connection goes from empty to non-empty, so a fast writer
//! cannot flood a slow reader's queue.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};

use crate::connection::Arrival;
use crate::graph::{Graph, Trigger};
use crate::host::{HostConfig, HostError, panic_message};
use crate::message::ErasedPackage;
use crate::module::{Backend, Context, Wake};
use crate::package::ModuleId;
use crate::rng::module_rng;
use crate::stats::{HostKind, HostStats, InputStats, Scheduling, StatsCollector};
use crate::tap::{HostTaps, Tap, TapOutput};
use crate::time::{Clock, MonotonicClock};
use crate::wiring::{ModuleParts, Wiring, split};

enum Event {
    Arrived { port: u16, at: Instant },
    ReceiversReady { port: u16 },
    Stop,
}

struct Shared {
    wiring: Wiring,
    senders: Vec<Sender<Event>>,
    clock: MonotonicClock,
    taps: HostTaps,
}

enum Failure {
    Panicked { module: String, message: String },
    Failed { module: String, error: String },
}

/// Runs a graph in real time, one thread per module.
pub struct ThreadedHost {
    graph: Graph,
    config: HostConfig,
    taps: HostTaps,
}

impl std::fmt::Debug for ThreadedHost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ThreadedHost").field("graph", &self.graph).finish()
    }
}

impl ThreadedHost {
    pub fn new(graph: Graph, config: HostConfig) -> ThreadedHost {
        ThreadedHost { graph, config, taps: HostTaps::default() }
    }

    /// Shows `tap` the packages of the outputs it wants ([`Tap::wants`], asked at
    /// [`ThreadedHost::start`]), instead of the taps set so far.
    pub fn set_tap(&mut self, tap: Arc<dyn Tap>) {
        self.taps = HostTaps::default();
        self.taps.push(tap);
    }

    /// Shows `tap` too the packages of the outputs it wants; each tap is shown only its
    /// outputs.
    pub fn add_tap(&mut self, tap: Arc<dyn Tap>) {
        self.taps.push(tap);
    }

    /// Starts every module's thread.
    pub fn start(self) -> Result<RunningHost, HostError> {
        let ThreadedHost { graph, config, taps } = self;
        let (mut wiring, parts) = split(graph);
        if !taps.is_empty() {
            wiring.select_tapped(&taps);
        }
        let (senders, receivers): (Vec<_>, Vec<_>) =
            (0..wiring.names.len()).map(|_| crossbeam_channel::unbounded()).unzip();
        let shared = Arc::new(Shared { wiring, senders, clock: MonotonicClock::start(), taps });
        let (failure_tx, failure_rx) = crossbeam_channel::unbounded();
        let (stop_tx, stop_rx) = crossbeam_channel::bounded(1);
        let mut threads = Vec::new();
        let mut monitors = Vec::new();
        for (parts, events) in parts.into_iter().zip(receivers) {
            let stats = Arc::new(Mutex::new(StatsCollector::new(config.stats_window)));
            monitors.push(Monitor {
                name: parts.name.clone(),
                inputs: parts
                    .inputs
                    .iter()
                    .map(|d| (d.name.clone(), Arc::clone(&d.slot)))
                    .collect(),
                stats: Arc::clone(&stats),
            });
            let worker = Worker {
                rng: module_rng(config.seed, &parts.name),
                parts,
                events,
                shared: Arc::clone(&shared),
                stats: Arc::clone(&stats),
                failures: failure_tx.clone(),
            };
            let module = worker.parts.name.clone();
            let name = format!("strata:{module}");
            let real_time = worker.parts.real_time;
            let handle = std::thread::Builder::new()
                .name(name)
                .spawn(move || worker.run())
                .map_err(|e| HostError::Spawn(e.to_string()))?;
            if let (true, Some(priority)) = (real_time, config.real_time_priority) {
                let scheduling = make_real_time(&handle, priority);
                stats.lock().unwrap_or_else(|e| e.into_inner()).set_scheduling(scheduling);
            }
            threads.push((module, handle));
        }
        let probe = StatsProbe {
            clock: shared.clock,
            monitors: monitors.into(),
            wall_start: Instant::now(),
        };
        Ok(RunningHost {
            shared,
            threads,
            stop_timeout: config.stop_timeout,
            failures: failure_rx,
            stop_rx,
            stop: StopHandle { tx: stop_tx, requested: Arc::new(AtomicBool::new(false)) },
            probe,
        })
    }
}

/// Moves a running module thread to `SCHED_FIFO`. Its first cycles may have run with the
/// default policy; a module's first cycle waits for its first input or period anyway.
#[cfg(unix)]
fn make_real_time(handle: &JoinHandle<()>, priority: u8) -> Scheduling {
    use std::os::unix::thread::JoinHandleExt;
    use thread_priority::{
        RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
        set_thread_priority_and_policy,
    };
    let refused = |reason: String| Scheduling::RealTimeRefused { priority, reason };
    let value = match ThreadPriorityValue::try_from(priority) {
        Ok(value) => value,
        Err(reason) => return refused(format!("priority {priority}: {reason}")),
    };
    match set_thread_priority_and_policy(
        handle.as_pthread_t(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    ) {
        Ok(()) => Scheduling::RealTime { priority },
        Err(thread_priority::Error::OS(code)) => {
            refused(std::io::Error::from_raw_os_error(code).to_string())
        }
        Err(error) => refused(format!("{error:?}")),
    }
}

#[cfg(not(unix))]
fn make_real_time(_handle: &JoinHandle<()>, priority: u8) -> Scheduling {
    Scheduling::RealTimeRefused { priority, reason: "only implemented on Unix".into() }
}

/// Asks a running host to stop; cheap to clone and usable from any thread.
#[derive(Clone, Debug)]
pub struct StopHandle {
    tx: Sender<()>,
    requested: Arc<AtomicBool>,
}

impl StopHandle {
    pub fn stop(&self) {
        self.requested.store(true, Ordering::SeqCst);
        let _ = self.tx.try_send(());
    }

    pub fn is_stop_requested(&self) -> bool {
        self.requested.load(Ordering::SeqCst)
    }
}

struct Monitor {
    name: String,
    inputs: Vec<(String, Arc<dyn crate::message::ErasedInput>)>,
    stats: Arc<Mutex<StatsCollector>>,
}

/// Reads a running host's statistics from any thread: a process that reports its rates while
/// it runs does so from a thread other than the one waiting in [`RunningHost::wait`]. Cheap to
/// clone; it holds the statistics only, not the modules.
#[derive(Clone)]
pub struct StatsProbe {
    clock: MonotonicClock,
    monitors: Arc<[Monitor]>,
    wall_start: Instant,
}

impl std::fmt::Debug for StatsProbe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StatsProbe").field("modules", &self.monitors.len()).finish()
    }
}

impl StatsProbe {
    /// A snapshot of every module's statistics (as [`RunningHost::stats`]).
    pub fn stats(&self) -> HostStats {
        HostStats {
            host: HostKind::Threaded,
            elapsed_s: self.clock.now().as_secs_f64(),
            wall_s: self.wall_start.elapsed().as_secs_f64(),
            modules: self
                .monitors
                .iter()
                .map(|m| {
                    let inputs = m
                        .inputs
                        .iter()
                        .map(|(name, slot)| InputStats {
                            port: name.clone(),
                            policy: slot.policy(),
                            counters: slot.counters(),
                        })
                        .collect();
                    m.stats.lock().unwrap_or_else(|e| e.into_inner()).snapshot(&m.name, inputs)
                })
                .collect(),
        }
    }
}

/// A host whose module threads are running.
pub struct RunningHost {
    shared: Arc<Shared>,
    /// Each module's name and thread.
    threads: Vec<(String, JoinHandle<()>)>,
    stop_timeout: Duration,
    failures: Receiver<Failure>,
    stop_rx: Receiver<()>,
    stop: StopHandle,
    probe: StatsProbe,
}

impl std::fmt::Debug for RunningHost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunningHost").field("threads", &self.threads.len()).finish()
    }
}

impl RunningHost {
    pub fn stop_handle(&self) -> StopHandle {
        self.stop.clone()
    }

    /// Stops the host on Ctrl-C / SIGTERM.
    pub fn stop_on_interrupt(&self) -> Result<(), HostError> {
        crate::signal::stop_on_interrupt(self.stop.clone()).map_err(HostError::Signal)
    }

    /// The modules that asked for a real-time priority and did not get it, with the reason
    /// (for the caller to warn about: the host runs on, with the default policy).
    pub fn real_time_refusals(&self) -> Vec<(String, String)> {
        self.probe
            .monitors
            .iter()
            .filter_map(|m| match &m.stats.lock().unwrap_or_else(|e| e.into_inner()).scheduling {
                Scheduling::RealTimeRefused { reason, .. } => {
                    Some((m.name.clone(), reason.clone()))
                }
                _ => None,
            })
            .collect()
    }

    /// A snapshot of every module's statistics, while running.
    pub fn stats(&self) -> HostStats {
        self.probe.stats()
    }

    /// Reads the statistics while another thread waits for the host to end.
    pub fn stats_probe(&self) -> StatsProbe {
        self.probe.clone()
    }

    /// Blocks until the host is asked to stop (stop handle, Ctrl-C) or a module fails, then
    /// stops every module and joins its thread, waiting at most [`HostConfig::stop_timeout`]:
    /// modules still running then are named in [`HostError::StopTimeout`].
    pub fn wait(self) -> Result<HostStats, HostError> {
        let failure = crossbeam_channel::select! {
            recv(self.failures) -> f => f.ok(),
            recv(self.stop_rx) -> _ => None,
        };
        self.shutdown(failure)
    }

    /// Runs for `duration` (or until stopped or failed), then stops.
    pub fn run_for(self, duration: Duration) -> Result<HostStats, HostError> {
        let failure = crossbeam_channel::select! {
            recv(self.failures) -> f => f.ok(),
            recv(self.stop_rx) -> _ => None,
            default(duration) => None,
        };
        self.shutdown(failure)
    }

    /// Stops now (as [`RunningHost::wait`] does once asked to).
    pub fn stop(self) -> Result<HostStats, HostError> {
        let failure = self.failures.try_recv().ok();
        self.shutdown(failure)
    }

    fn shutdown(mut self, failure: Option<Failure>) -> Result<HostStats, HostError> {
        let threads = std::mem::take(&mut self.threads);
        let stuck = stop_threads(&self.shared, threads, self.stop_timeout);
        let failure = failure.or_else(|| self.failures.try_recv().ok());
        let stats = self.stats();
        match failure {
            Some(failure) => {
                // The failure is the news; modules left running are worth a line beside it.
                if !stuck.is_empty() {
                    warn_stuck(&stuck, self.stop_timeout);
                }
                Err(failure_error(failure, stats))
            }
            None if stuck.is_empty() => Ok(stats),
            None => Err(HostError::StopTimeout {
                modules: stuck,
                timeout: self.stop_timeout,
                stats: Box::new(stats),
            }),
        }
    }
}

fn failure_error(failure: Failure, stats: HostStats) -> HostError {
    match failure {
        Failure::Panicked { module, message } => {
            HostError::ModulePanicked { module, message, stats: Box::new(stats) }
        }
        Failure::Failed { module, error } => {
            HostError::ModuleFailed { module, error, stats: Box::new(stats) }
        }
    }
}

fn warn_stuck(modules: &[String], timeout: Duration) {
    tracing::warn!(
        ?modules,
        "modules did not stop within {} s (the host's stop timeout) and were left running",
        timeout.as_secs_f64()
    );
}

/// Asks every module thread to stop and waits for them, `timeout` at most in all. Returns the
/// modules whose thread was still running then; those threads are left detached (a thread
/// cannot be killed), and end on their own if their cycle ever returns.
fn stop_threads(
    shared: &Shared,
    threads: Vec<(String, JoinHandle<()>)>,
    timeout: Duration,
) -> Vec<String> {
    for sender in &shared.senders {
        let _ = sender.send(Event::Stop);
    }
    let deadline = Instant::now() + timeout;
    let mut running = threads;
    loop {
        let (ended, still): (Vec<_>, Vec<_>) =
            running.into_iter().partition(|(_, thread)| thread.is_finished());
        for (_, thread) in ended {
            // A worker catches its module's panics, so a join error would be a bug of ours;
            // the stats are still worth returning.
            let _ = thread.join();
        }
        running = still;
        if running.is_empty() || Instant::now() >= deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    running.into_iter().map(|(module, _)| module).collect()
}

impl Drop for RunningHost {
    fn drop(&mut self) {
        if !self.threads.is_empty() {
            let threads = std::mem::take(&mut self.threads);
            let stuck = stop_threads(&self.shared, threads, self.stop_timeout);
            if !stuck.is_empty() {
                warn_stuck(&stuck, self.stop_timeout);
            }
        }
    }
}

struct Worker {
    parts: ModuleParts,
    events: Receiver<Event>,
    shared: Arc<Shared>,
    stats: Arc<Mutex<StatsCollector>>,
    failures: Sender<Failure>,
    rng: rand_chacha::ChaCha8Rng,
}

struct ThreadedBackend<'a> {
    module: ModuleId,
    shared: &'a Shared,
}

impl Backend for ThreadedBackend<'_> {
    fn publish(&mut self, port: u16, package: Box<dyn ErasedPackage>) {
        let output = &self.shared.wiring.outputs[self.module.index()][usize::from(port)];
        let package = if output.tapped != 0 {
            let tapped = TapOutput {
                host: self.shared.wiring.host,
                module: self.module,
                module_name: &self.shared.wiring.names[self.module.index()],
                port,
                output: &output.name,
                type_name: output.type_name,
            };
            let (now, read) = (self.shared.clock.now(), !output.readers.is_empty());
            match self.shared.taps.offer(None, output.tapped, &tapped, now, package, read) {
                Some(package) => package,
                None => return,
            }
        } else {
            package
        };
        let at = Instant::now();
        let notify = |reader: &crate::wiring::Reader, arrival: Option<Arrival>| {
            if arrival == Some(Arrival::First) {
                let _ = self.shared.senders[reader.input.module.index()]
                    .send(Event::Arrived { port: reader.input.port, at });
            }
        };
        if let Some((last, others)) = output.readers.split_last() {
            for reader in others {
                notify(reader, reader.slot.push_cloned(package.as_any()));
            }
            notify(last, last.slot.push_owned(package.into_any()));
        }
    }

    fn input_emptied(&mut self, port: u16) {
        if let Some(Some((writer, true))) =
            self.shared.wiring.writers[self.module.index()].get(usize::from(port))
        {
            let _ = self.shared.senders[writer.module.index()]
                .send(Event::ReceiversReady { port: writer.port });
        }
    }

    fn receivers_ready(&self, port: u16) -> bool {
        self.shared.wiring.outputs[self.module.index()]
            .get(usize::from(port))
            .is_some_and(|o| o.readers.iter().all(|r| !r.slot.has_pending()))
    }
}

impl Worker {
    fn run(mut self) {
        let period = match self.parts.trigger {
            Trigger::Periodic { period, offset } => {
                Some((period, self.shared.clock.instant(crate::Time::ZERO) + offset))
            }
            Trigger::OnInput { .. } => None,
        };
        let mut next_tick = period.map(|(_, first)| first);
        let mut wakes: Vec<Wake> = Vec::new();
        let mut output_seq = vec![0u64; self.shared.wiring.outputs[self.parts.id.index()].len()];
        loop {
            let event = match next_tick {
                Some(deadline) => match self.events.recv_deadline(deadline) {
                    Ok(event) => Some(event),
                    Err(RecvTimeoutError::Timeout) => None,
                    Err(RecvTimeoutError::Disconnected) => break,
                },
                None => match self.events.recv() {
                    Ok(event) => Some(event),
                    Err(_) => break,
                },
            };
            let trigger_at = match event {
                Some(Event::Stop) => break,
                None => {
                    let (Some(deadline), Some((period, _))) = (next_tick, period) else { break };
                    wakes.push(Wake::Tick);
                    // Keep the phase; skip ticks missed while a cycle overran.
                    let mut next = deadline + period;
                    let now = Instant::now();
                    if next < now {
                        let behind = now.duration_since(next).as_nanos() / period.as_nanos().max(1);
                        next += period * u32::try_from(behind + 1).unwrap_or(u32::MAX);
                    }
                    next_tick = Some(next);
                    deadline
                }
                Some(Event::Arrived { port, at }) => {
                    if !self.parts.triggered_by_arrival(port, false) {
                        continue;
                    }
                    wakes.push(Wake::Input(port));
                    at
                }
                Some(Event::ReceiversReady { port }) => {
                    let wake = self.shared.wiring.outputs[self.parts.id.index()]
                        .get(usize::from(port))
                        .is_some_and(|o| o.wake_on_ready);
                    if !wake {
                        continue;
                    }
                    wakes.push(Wake::ReceiversReady(port));
                    Instant::now()
                }
            };
            if !self.cycle(trigger_at, &wakes, &mut output_seq) {
                break;
            }
            wakes.clear();
        }
        self.parts.module.stop();
    }

    /// Runs one cycle; false if the module failed and the thread must end.
    fn cycle(&mut self, trigger_at: Instant, wakes: &[Wake], output_seq: &mut [u64]) -> bool {
        let start = Instant::now();
        let now = self.shared.clock.at(start);
        let mut backend = ThreadedBackend { module: self.parts.id, shared: &self.shared };
        let mut ctx = Context {
            module: self.parts.id,
            name: &self.parts.name,
            now,
            rng: &mut self.rng,
            inputs: &self.parts.inputs,
            output_seq,
            backend: &mut backend,
            woken_by: wakes,
            sent: 0,
        };
        let module = &mut self.parts.module;
        let result = catch_unwind(AssertUnwindSafe(|| module.cycle(&mut ctx)));
        let sent = ctx.sent;
        let end = Instant::now();
        {
            let mut stats = self.stats.lock().unwrap_or_else(|e| e.into_inner());
            stats.record_cycle(
                now,
                end.duration_since(start),
                (sent > 0).then(|| end.saturating_duration_since(trigger_at)),
            );
            if !matches!(result, Ok(Ok(()))) {
                stats.record_error();
            }
        }
        let failure = match result {
            Ok(Ok(())) => return true,
            Ok(Err(error)) => {
                Failure::Failed { module: self.parts.name.clone(), error: error.to_string() }
            }
            Err(payload) => Failure::Panicked {
                module: self.parts.name.clone(),
                message: panic_message(payload.as_ref()),
            },
        };
        let _ = self.failures.send(failure);
        false
    }
}
