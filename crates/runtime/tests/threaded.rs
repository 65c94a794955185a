//! The threaded host: real concurrency, clean shutdown, failure reporting. No assertion here
//! depends on how fast the machine is: waits are for conditions, with generous limits that only
//! turn a hang into a failure.

mod common;

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Barrier, Mutex};
use std::time::{Duration, Instant};

use common::{Counter, Recorder};
use strata_runtime::{
    Context, GraphBuilder, HostConfig, HostError, Module, ModuleError, Output, Policy,
    ThreadedHost, Trigger,
};

const PATIENCE: Duration = Duration::from_secs(60);

fn wait_until(what: &str, mut condition: impl FnMut() -> bool) {
    let start = Instant::now();
    while !condition() {
        assert!(start.elapsed() < PATIENCE, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Counts cycles and how many times it was stopped.
struct Ticker {
    cycles: Arc<AtomicU64>,
    stops: Arc<AtomicUsize>,
}

impl Module for Ticker {
    fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
        self.cycles.fetch_add(1, Ordering::SeqCst);
        Ok(())
    }
    fn stop(&mut self) {
        self.stops.fetch_add(1, Ordering::SeqCst);
    }
}

/// Blocks inside its first cycle until the test releases it.
struct Blocked {
    barrier: Arc<Barrier>,
    entered: Arc<AtomicUsize>,
    stops: Arc<AtomicUsize>,
}

impl Module for Blocked {
    fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
        if self.entered.fetch_add(1, Ordering::SeqCst) == 0 {
            self.barrier.wait();
        }
        Ok(())
    }
    fn stop(&mut self) {
        self.stops.fetch_add(1, Ordering::SeqCst);
    }
}

#[test]
fn a_module_blocked_in_its_cycle_does_not_stop_another_and_shutdown_joins_all() {
    let barrier = Arc::new(Barrier::new(2));
    let entered = Arc::new(AtomicUsize::new(0));
    let cycles = Arc::new(AtomicU64::new(0));
    let stops = Arc::new(AtomicUsize::new(0));
    let mut graph = GraphBuilder::new();
    {
        let (barrier, entered, stops) =
            (Arc::clone(&barrier), Arc::clone(&entered), Arc::clone(&stops));
        graph.add("deliberative", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(1)));
            (Blocked { barrier, entered, stops }, ())
        });
    }
    {
        let (cycles, stops) = (Arc::clone(&cycles), Arc::clone(&stops));
        graph.add("reactive", move |p| {
            p.trigger(Trigger::every(Duration::from_micros(500)));
            (Ticker { cycles, stops }, ())
        });
    }
    let host = ThreadedHost::new(graph.build().expect("valid"), HostConfig::default())
        .start()
        .expect("starts");
    wait_until("the deliberative module to block", || entered.load(Ordering::SeqCst) == 1);
    let before = cycles.load(Ordering::SeqCst);
    wait_until("the reactive module to keep cycling", || {
        cycles.load(Ordering::SeqCst) >= before + 100
    });
    assert_eq!(
        entered.load(Ordering::SeqCst),
        1,
        "the blocked module is still inside its first cycle"
    );
    barrier.wait();
    let stats = host.stop().expect("clean stop");
    assert_eq!(stops.load(Ordering::SeqCst), 2, "every module thread ended and was stopped");
    assert!(stats.module("reactive").expect("reactive").cycles >= before + 100);
}

#[test]
fn packages_cross_threads_in_order_with_queue_and_newest_with_latest() {
    let queued = Arc::new(Mutex::new(Vec::new()));
    let latest = Arc::new(Mutex::new(Vec::new()));
    let mut graph = GraphBuilder::new();
    let out = graph.add("producer", |p| {
        p.trigger(Trigger::every(Duration::from_micros(200)));
        let out = p.output("n");
        (Counter { out, next: 0, noisy: false, limit: Some(500) }, out)
    });
    let queue_in = graph.add("queue_reader", |p| {
        let input = p.input("n", Policy::queue(1000));
        p.trigger(Trigger::on_any([input.into()]));
        (Recorder { input, seen: Arc::clone(&queued), newest_only: false }, input)
    });
    let latest_in = graph.add("latest_reader", |p| {
        let input = p.input("n", Policy::Latest);
        p.trigger(Trigger::on_any([input.into()]));
        (Recorder { input, seen: Arc::clone(&latest), newest_only: true }, input)
    });
    graph.fan_out(out, [queue_in, latest_in]);
    let host = ThreadedHost::new(graph.build().expect("valid"), HostConfig::default())
        .start()
        .expect("starts");
    wait_until("all 500 packages", || queued.lock().expect("lock").len() == 500);
    wait_until("the newest package", || {
        latest.lock().expect("lock").last().is_some_and(|s| s.1 == 499)
    });
    let stats = host.stop().expect("clean stop");
    let values: Vec<u64> = queued.lock().expect("lock").iter().map(|s| s.1).collect();
    assert_eq!(values, (0..500).collect::<Vec<_>>());
    let newest: Vec<u64> = latest.lock().expect("lock").iter().map(|s| s.1).collect();
    assert!(newest.windows(2).all(|w| w[0] < w[1]), "latest never goes back in time");
    let reader = stats.module("latest_reader").expect("stats");
    assert_eq!(reader.inputs[0].counters.received, 500);
    assert_eq!(reader.inputs[0].counters.delivered + reader.inputs[0].counters.overwritten, 500);
}

#[test]
fn a_panicking_module_is_reported_by_name_and_the_host_stops_cleanly() {
    struct Faulty {
        cycles: u32,
    }
    impl Module for Faulty {
        fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
            self.cycles += 1;
            if self.cycles == 3 {
                panic!("covariance is not positive definite");
            }
            Ok(())
        }
    }
    let stops = Arc::new(AtomicUsize::new(0));
    let cycles = Arc::new(AtomicU64::new(0));
    let mut graph = GraphBuilder::new();
    graph.add("world", |p| {
        p.trigger(Trigger::every(Duration::from_millis(1)));
        (Faulty { cycles: 0 }, ())
    });
    {
        let (cycles, stops) = (Arc::clone(&cycles), Arc::clone(&stops));
        graph.add("reactive", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(1)));
            (Ticker { cycles, stops }, ())
        });
    }
    let host = ThreadedHost::new(graph.build().expect("valid"), HostConfig::default())
        .start()
        .expect("starts");
    match host.wait() {
        Err(HostError::ModulePanicked { module, message, .. }) => {
            assert_eq!(module, "world");
            assert_eq!(message, "covariance is not positive definite");
        }
        other => panic!("expected a panic report, got {other:?}"),
    }
    assert_eq!(stops.load(Ordering::SeqCst), 1, "the healthy module was stopped and joined");
}

#[test]
fn a_module_error_is_reported_with_its_message() {
    struct Disconnected;
    impl Module for Disconnected {
        fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
            Err("LoLA socket closed".into())
        }
    }
    let mut graph = GraphBuilder::new();
    graph.add("perception", |p| {
        p.trigger(Trigger::every(Duration::from_millis(1)));
        (Disconnected, ())
    });
    let host = ThreadedHost::new(graph.build().expect("valid"), HostConfig::default())
        .start()
        .expect("starts");
    let err = host.wait().expect_err("fails");
    assert_eq!(err.to_string(), "module `perception` failed: LoLA socket closed");
}

#[test]
fn a_stop_handle_ends_wait_from_another_thread() {
    let cycles = Arc::new(AtomicU64::new(0));
    let stops = Arc::new(AtomicUsize::new(0));
    let mut graph = GraphBuilder::new();
    {
        let (cycles, stops) = (Arc::clone(&cycles), Arc::clone(&stops));
        graph.add("planning", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(5)));
            (Ticker { cycles, stops }, ())
        });
    }
    let host = ThreadedHost::new(graph.build().expect("valid"), HostConfig::default())
        .start()
        .expect("starts");
    let handle = host.stop_handle();
    let waiter = std::thread::spawn(move || host.wait());
    wait_until("a few cycles", || cycles.load(Ordering::SeqCst) >= 3);
    handle.stop();
    let stats = waiter.join().expect("joins").expect("clean stop");
    assert!(stats.module("planning").expect("stats").cycles >= 3);
    assert_eq!(stops.load(Ordering::SeqCst), 1);
}

/// A probe reads the statistics from another thread while the host's owner waits in `wait`,
/// as a robot process's monitor does for its status lines.
#[test]
fn a_stats_probe_reads_a_host_that_another_thread_waits_for() {
    let cycles = Arc::new(AtomicU64::new(0));
    let stops = Arc::new(AtomicUsize::new(0));
    let mut graph = GraphBuilder::new();
    {
        let (cycles, stops) = (Arc::clone(&cycles), Arc::clone(&stops));
        graph.add("reactive", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(5)));
            (Ticker { cycles, stops }, ())
        });
    }
    let host = ThreadedHost::new(graph.build().expect("valid"), HostConfig::default())
        .start()
        .expect("starts");
    let (probe, handle) = (host.stats_probe(), host.stop_handle());
    let waiter = std::thread::spawn(move || host.wait());
    let seen = |probe: &strata_runtime::StatsProbe| {
        probe.stats().module("reactive").map_or(0, |m| m.cycles)
    };
    wait_until("cycles seen through the probe", || seen(&probe) >= 3);
    let before = seen(&probe);
    wait_until("more cycles", || seen(&probe) > before);
    handle.stop();
    let stats = waiter.join().expect("joins").expect("clean stop");
    assert!(stats.module("reactive").expect("stats").cycles >= seen(&probe));
    // The probe outlives the host: its last reading is the final one.
    assert_eq!(seen(&probe), stats.module("reactive").expect("stats").cycles);
}

#[test]
fn receiver_ready_messages_drive_a_pull_flow_across_threads() {
    struct OnDemand {
        out: Output<u64>,
        next: u64,
    }
    impl Module for OnDemand {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            if self.next < 200 && ctx.receivers_ready(self.out) {
                ctx.send(self.out, self.next);
                self.next += 1;
            }
            Ok(())
        }
    }
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut graph = GraphBuilder::new();
    let out = graph.add("producer", |p| {
        let out = p.output("n");
        p.wake_when_receivers_ready(out);
        p.trigger(Trigger::every(Duration::from_millis(50)));
        (OnDemand { out, next: 0 }, out)
    });
    let input = graph.add("consumer", |p| {
        let input = p.input("n", Policy::Latest);
        p.trigger(Trigger::on_any([input.into()]));
        (Recorder { input, seen: Arc::clone(&seen), newest_only: true }, input)
    });
    graph.connect(out, input);
    let host = ThreadedHost::new(graph.build().expect("valid"), HostConfig::default())
        .start()
        .expect("starts");
    wait_until("200 packages", || seen.lock().expect("lock").len() == 200);
    let stats = host.stop().expect("clean stop");
    let values: Vec<u64> = seen.lock().expect("lock").iter().map(|s| s.1).collect();
    assert_eq!(values, (0..200).collect::<Vec<_>>());
    assert_eq!(stats.module("consumer").expect("stats").inputs[0].counters.overwritten, 0);
}

/// Whether a thread ran under a real-time policy; None until its module's first cycle.
type RealTimeSeen = Arc<Mutex<Option<bool>>>;

/// Records the scheduling policy its thread runs under, as the operating system reports it.
struct PolicyProbe {
    real_time: RealTimeSeen,
}

impl Module for PolicyProbe {
    fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
        use thread_priority::unix::{ThreadSchedulePolicy, thread_schedule_policy};
        let policy = thread_schedule_policy().map_err(|e| format!("{e:?}"))?;
        *self.real_time.lock().expect("lock") =
            Some(matches!(policy, ThreadSchedulePolicy::Realtime(_)));
        Ok(())
    }
}

fn probe_graph() -> (strata_runtime::Graph, RealTimeSeen, RealTimeSeen) {
    let sensor_path = Arc::new(Mutex::new(None));
    let background = Arc::new(Mutex::new(None));
    let mut graph = GraphBuilder::new();
    {
        let real_time = Arc::clone(&sensor_path);
        graph.add("reactive", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(2)));
            p.real_time();
            (PolicyProbe { real_time }, ())
        });
    }
    {
        let real_time = Arc::clone(&background);
        graph.add("deliberative", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(2)));
            (PolicyProbe { real_time }, ())
        });
    }
    (graph.build().expect("valid"), sensor_path, background)
}

#[cfg(unix)]
#[test]
fn modules_declared_real_time_get_a_real_time_policy_or_say_why_not() {
    use strata_runtime::Scheduling;
    let (graph, sensor_path, background) = probe_graph();
    let config = HostConfig { real_time_priority: Some(10), ..HostConfig::default() };
    let host = ThreadedHost::new(graph, config).start().expect("starts");
    wait_until("both modules to cycle", || {
        sensor_path.lock().expect("lock").is_some() && background.lock().expect("lock").is_some()
    });
    let refusals = host.real_time_refusals();
    let stats = host.stop().expect("clean stop");
    let reactive = &stats.module("reactive").expect("reactive").scheduling;
    // Whether the system grants SCHED_FIFO depends on the permissions the tests run with;
    // both outcomes must be reported truthfully.
    match reactive {
        Scheduling::RealTime { priority } => {
            assert_eq!(*priority, 10);
            assert_eq!(
                *sensor_path.lock().expect("lock"),
                Some(true),
                "the thread runs SCHED_FIFO"
            );
            assert!(refusals.is_empty());
        }
        Scheduling::RealTimeRefused { priority, reason } => {
            assert_eq!(*priority, 10);
            assert!(!reason.is_empty());
            assert_eq!(*sensor_path.lock().expect("lock"), Some(false));
            assert_eq!(refusals, vec![("reactive".to_owned(), reason.clone())]);
        }
        Scheduling::Default => panic!("a real-time module was left at the default policy"),
    }
    assert_eq!(stats.module("deliberative").expect("deliberative").scheduling, Scheduling::Default);
    assert_eq!(
        *background.lock().expect("lock"),
        Some(false),
        "undeclared modules keep the default"
    );
}

#[cfg(unix)]
#[test]
fn without_a_real_time_priority_in_the_config_every_thread_keeps_the_default_policy() {
    use strata_runtime::Scheduling;
    let (graph, sensor_path, background) = probe_graph();
    let host = ThreadedHost::new(graph, HostConfig::default()).start().expect("starts");
    wait_until("both modules to cycle", || {
        sensor_path.lock().expect("lock").is_some() && background.lock().expect("lock").is_some()
    });
    assert!(host.real_time_refusals().is_empty());
    let stats = host.stop().expect("clean stop");
    for module in ["reactive", "deliberative"] {
        assert_eq!(stats.module(module).expect(module).scheduling, Scheduling::Default);
    }
    assert_eq!(*sensor_path.lock().expect("lock"), Some(false));
}

/// Stays inside its first cycle until the test sends on (or drops) `release`.
struct Stuck {
    release: crossbeam_channel::Receiver<()>,
    entered: Arc<AtomicUsize>,
    stops: Arc<AtomicUsize>,
}

impl Module for Stuck {
    fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
        if self.entered.fetch_add(1, Ordering::SeqCst) == 0 {
            let _ = self.release.recv();
        }
        Ok(())
    }
    fn stop(&mut self) {
        self.stops.fetch_add(1, Ordering::SeqCst);
    }
}

/// A graph of a module stuck in its first cycle ("deliberative") and a ticking one
/// ("reactive"), on a host that waits `stop_timeout` for its threads.
fn stuck_host(
    stop_timeout: Duration,
) -> (strata_runtime::RunningHost, crossbeam_channel::Sender<()>, Arc<AtomicUsize>, Arc<AtomicUsize>)
{
    let (release_tx, release) = crossbeam_channel::bounded(1);
    let entered = Arc::new(AtomicUsize::new(0));
    let stops = Arc::new(AtomicUsize::new(0));
    let mut graph = GraphBuilder::new();
    {
        let (entered, stops) = (Arc::clone(&entered), Arc::clone(&stops));
        graph.add("deliberative", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(1)));
            (Stuck { release, entered, stops }, ())
        });
    }
    {
        let (cycles, stops) = (Arc::new(AtomicU64::new(0)), Arc::clone(&stops));
        graph.add("reactive", move |p| {
            p.trigger(Trigger::every(Duration::from_millis(1)));
            (Ticker { cycles, stops }, ())
        });
    }
    let config = HostConfig { stop_timeout, ..HostConfig::default() };
    let host = ThreadedHost::new(graph.build().expect("valid"), config).start().expect("starts");
    wait_until("the deliberative module to be stuck", || entered.load(Ordering::SeqCst) == 1);
    (host, release_tx, entered, stops)
}

#[test]
fn stopping_gives_up_on_a_module_stuck_in_its_cycle_after_the_stop_timeout_and_names_it() {
    let (host, release, _, stops) = stuck_host(Duration::from_millis(200));
    // On another thread, so that a stop that never returns fails the test instead of hanging it.
    let (done_tx, done) = crossbeam_channel::bounded(1);
    std::thread::spawn(move || {
        let _ = done_tx.send(host.stop());
    });
    let result = done.recv_timeout(PATIENCE);
    let Ok(result) = result else {
        let _ = release.send(());
        panic!("stop did not return while a module was stuck in its cycle");
    };
    match &result {
        Err(HostError::StopTimeout { modules, timeout, stats }) => {
            assert_eq!(modules, &["deliberative".to_owned()]);
            assert_eq!(*timeout, Duration::from_millis(200));
            assert!(stats.module("reactive").expect("reactive").cycles > 0);
        }
        other => panic!("expected a stop timeout naming the stuck module, got {other:?}"),
    }
    let message = result.expect_err("a stop timeout").to_string();
    assert_eq!(
        message,
        "module `deliberative` did not stop within 0.2 s (the host's stop timeout) and was left running"
    );
    assert_eq!(stops.load(Ordering::SeqCst), 1, "the healthy module was stopped and joined");
    // The module left running stops on its own once its cycle returns.
    release.send(()).expect("the stuck module still waits");
    wait_until("the released module to stop", || stops.load(Ordering::SeqCst) == 2);
}

#[test]
fn dropping_a_host_with_a_module_stuck_in_its_cycle_returns_after_the_stop_timeout() {
    let (host, release, _, stops) = stuck_host(Duration::from_millis(200));
    let (done_tx, done) = crossbeam_channel::bounded(1);
    std::thread::spawn(move || {
        drop(host);
        let _ = done_tx.send(());
    });
    let dropped = done.recv_timeout(PATIENCE);
    let _ = release.send(());
    assert!(dropped.is_ok(), "dropping the host did not return while a module was stuck");
    assert!(stops.load(Ordering::SeqCst) >= 1, "the healthy module was stopped");
}
