//! The lockstep host: determinism, processing-time model, triggers, statistics, failures.

mod common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{Collect, Counter, Recorder, Seen};
use strata_runtime::{
    Context, GraphBuilder, HostConfig, HostError, Input, LockstepHost, Module, ModuleError, Output,
    Policy, ProcessingTime, Time, Trigger,
};

const MS: Duration = Duration::from_millis(1);

/// A noisy sensor at 100 Hz, a filter averaging what it receives (Queue), a slow consumer
/// reading the newest estimate (Latest) at 7 Hz, with random processing times.
fn pipeline(seed: u64) -> (LockstepHost, Arc<Collect>, Seen) {
    struct Average {
        input: Input<u64>,
        out: Output<u64>,
        sum: u64,
        n: u64,
    }
    impl Module for Average {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            let mut stamp = ctx.now();
            for p in ctx.drain(self.input) {
                self.sum += p.value;
                self.n += 1;
                stamp = p.stamp;
            }
            if let Some(mean) = self.sum.checked_div(self.n) {
                ctx.send_stamped(self.out, mean, stamp);
            }
            Ok(())
        }
    }
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut graph = GraphBuilder::new();
    let sensor = graph.add("sensor", |p| {
        p.trigger(Trigger::every(10 * MS));
        p.processing_time(ProcessingTime::Uniform { min: MS, max: 4 * MS });
        let out = p.output("raw");
        (Counter { out, next: 0, noisy: true, limit: None }, out)
    });
    let (filter_in, filter_out) = graph.add("filter", |p| {
        let input = p.input("raw", Policy::queue(64));
        let out = p.output("estimate");
        p.trigger(Trigger::on_any([input.into()]));
        p.processing_time(ProcessingTime::Normal {
            mean: 3 * MS,
            std_dev: MS,
            min: Duration::ZERO,
        });
        (Average { input, out, sum: 0, n: 0 }, (input, out))
    });
    let consumer = graph.add("consumer", |p| {
        let input = p.input("estimate", Policy::Latest);
        p.trigger(Trigger::rate_hz(7.0));
        (Recorder { input, seen: Arc::clone(&seen), newest_only: true }, input)
    });
    graph.connect(sensor, filter_in);
    graph.connect(filter_out, consumer);
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::with_seed(seed));
    let tap = Arc::new(Collect::default());
    host.set_tap(tap.clone());
    host.record_trace(true);
    (host, tap, seen)
}

#[test]
fn same_seed_same_trace_bit_for_bit() {
    let run = |seed| {
        let (mut host, tap, seen) = pipeline(seed);
        host.run_for(Duration::from_secs(3)).expect("runs");
        let trace = host.trace().to_vec();
        let packages = tap.0.lock().expect("lock").clone();
        let seen = seen.lock().expect("lock").clone();
        (trace, packages, seen)
    };
    let a = run(7);
    let b = run(7);
    assert!(!a.0.is_empty() && !a.1.is_empty() && !a.2.is_empty());
    assert_eq!(a.0, b.0, "traces differ");
    assert_eq!(a.1, b.1, "package contents differ");
    assert_eq!(a.2, b.2, "what the consumer saw differs");
    let c = run(8);
    assert_ne!(a.1, c.1, "a different seed must change what random modules produce");
    assert_ne!(a.0, c.0, "a different seed must change random processing times");
}

#[test]
fn an_output_computed_at_t_is_seen_at_t_plus_processing_time_and_not_before() {
    struct Clock {
        out: Output<u64>,
    }
    impl Module for Clock {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            let now = ctx.now().as_nanos();
            ctx.send(self.out, now);
            Ok(())
        }
    }
    for model in [
        ProcessingTime::fixed(3 * MS),
        ProcessingTime::Uniform { min: MS, max: 9 * MS },
        ProcessingTime::fixed(Duration::ZERO),
    ] {
        let seen = Arc::new(Mutex::new(Vec::new()));
        let mut graph = GraphBuilder::new();
        let out = graph.add("producer", |p| {
            p.trigger(Trigger::every(10 * MS));
            p.processing_time(model.clone());
            let out = p.output("t");
            (Clock { out }, out)
        });
        let input = graph.add("reader", |p| {
            let input = p.input("t", Policy::queue(16));
            p.trigger(Trigger::on_any([input.into()]));
            (Recorder { input, seen: Arc::clone(&seen), newest_only: false }, input)
        });
        graph.connect(out, input);
        let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::with_seed(3));
        host.run_for(Duration::from_millis(500)).expect("runs");
        let seen = seen.lock().expect("lock");
        assert!(seen.len() >= 49, "{model:?}: {} packages", seen.len());
        for (read_at, computed_at, _) in seen.iter() {
            let delay = *read_at - Time::from_nanos(*computed_at);
            match &model {
                ProcessingTime::Fixed { duration } => assert_eq!(delay, *duration, "{model:?}"),
                ProcessingTime::Uniform { min, max } => {
                    assert!(delay >= *min && delay <= *max, "{model:?}: {delay:?}")
                }
                ProcessingTime::Normal { .. } => unreachable!(),
            }
        }
    }
}

#[test]
fn a_busy_module_runs_again_as_soon_as_it_is_free_and_sees_everything_queued() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut graph = GraphBuilder::new();
    let out = graph.add("fast", |p| {
        p.trigger(Trigger::every(MS));
        let out = p.output("n");
        (Counter { out, next: 0, noisy: false, limit: Some(100) }, out)
    });
    let input = graph.add("slow", |p| {
        let input = p.input("n", Policy::queue(1000));
        p.trigger(Trigger::on_any([input.into()]));
        p.processing_time(ProcessingTime::fixed(5 * MS));
        (Recorder { input, seen: Arc::clone(&seen), newest_only: false }, input)
    });
    graph.connect(out, input);
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    host.run_for(Duration::from_millis(200)).expect("runs");
    let seen = seen.lock().expect("lock");
    let values: Vec<u64> = seen.iter().map(|s| s.1).collect();
    assert_eq!(values, (0..100).collect::<Vec<_>>(), "every package, in order");
    let cycle_times: Vec<Time> = {
        let mut t: Vec<Time> = seen.iter().map(|s| s.0).collect();
        t.dedup();
        t
    };
    for pair in cycle_times.windows(2) {
        assert!(pair[1] - pair[0] >= 5 * MS, "cycles overlap: {pair:?}");
    }
    let stats = host.stats();
    let slow = stats.module("slow").expect("slow");
    assert!(
        slow.cycles <= 21,
        "a 5 ms module cannot run more than 21 times in 101 ms: {}",
        slow.cycles
    );
    assert!((slow.compute_time.p50_us - 5000.0).abs() < 60.0, "{:?}", slow.compute_time);
}

#[test]
fn queue_overflows_and_overwrites_are_counted_in_the_statistics() {
    let mut graph = GraphBuilder::new();
    let out = graph.add("burst", |p| {
        p.trigger(Trigger::every(MS));
        let out = p.output("n");
        (Counter { out, next: 0, noisy: false, limit: None }, out)
    });
    let seen = Arc::new(Mutex::new(Vec::new()));
    let queue_in = graph.add("queued", |p| {
        let input = p.input("n", Policy::queue(3));
        p.trigger(Trigger::every(10 * MS));
        (Recorder { input, seen: Arc::clone(&seen), newest_only: false }, input)
    });
    let latest_in = graph.add("latest", |p| {
        let input = p.input("n", Policy::Latest);
        p.trigger(Trigger::every(10 * MS));
        (Recorder { input, seen: Arc::clone(&seen), newest_only: true }, input)
    });
    graph.fan_out(out, [queue_in, latest_in]);
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    host.run_until(Time::from_nanos(1_000_000_000 - 1)).expect("runs");
    let stats = host.stats();
    let queued = &stats.module("queued").expect("queued").inputs[0];
    let latest = &stats.module("latest").expect("latest").inputs[0];
    assert_eq!(queued.counters.received, 1000);
    assert_eq!(latest.counters.received, 1000);
    // Each 10 ms window brings 10 packages: the queue keeps the newest 3 and drops 7.
    // Three packages are still pending when the run ends.
    assert_eq!(queued.counters.delivered + queued.counters.dropped + 3, 1000, "{queued:?}");
    assert!(queued.counters.dropped >= 690, "{queued:?}");
    assert!(latest.counters.overwritten >= 890, "{latest:?}");
    assert_eq!(stats.total_dropped(), queued.counters.dropped);
    let burst = stats.module("burst").expect("burst");
    assert!((burst.rate.mean_hz - 1000.0).abs() < 1.0, "{:?}", burst.rate);
    assert!((burst.rate.min_hz - 1000.0).abs() < 1.0, "{:?}", burst.rate);
}

#[test]
fn all_mode_waits_for_every_listed_input() {
    struct Pair {
        a: Input<u64>,
        b: Input<u64>,
        out: Arc<Mutex<Vec<(u64, u64)>>>,
    }
    impl Module for Pair {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            let a = ctx.latest(self.a).map(|p| p.value);
            let b = ctx.latest(self.b).map(|p| p.value);
            if let (Some(a), Some(b)) = (a, b) {
                self.out.lock().expect("lock").push((a, b));
            } else {
                panic!("ran without both inputs: {a:?} {b:?}");
            }
            Ok(())
        }
    }
    let pairs = Arc::new(Mutex::new(Vec::new()));
    let mut graph = GraphBuilder::new();
    let fast = graph.add("fast", |p| {
        p.trigger(Trigger::every(MS));
        let out = p.output("n");
        (Counter { out, next: 0, noisy: false, limit: None }, out)
    });
    let slow = graph.add("slow", |p| {
        p.trigger(Trigger::every(10 * MS));
        let out = p.output("n");
        (Counter { out, next: 0, noisy: false, limit: None }, out)
    });
    let (a, b) = graph.add("pair", |p| {
        let a = p.input("a", Policy::Latest);
        let b = p.input("b", Policy::Latest);
        p.trigger(Trigger::on_all([a.into(), b.into()]));
        (Pair { a, b, out: Arc::clone(&pairs) }, (a, b))
    });
    graph.connect(fast, a);
    graph.connect(slow, b);
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    host.run_for(Duration::from_millis(100)).expect("runs");
    let pairs = pairs.lock().expect("lock");
    // The slow module sends at 0, 10, ..., 100 ms (the end instant is included).
    assert_eq!(pairs.len(), 11, "one cycle per slow package: {pairs:?}");
    assert!(pairs.iter().enumerate().all(|(i, (_, b))| *b == i as u64));
}

#[test]
fn external_inputs_receive_injected_packages_at_the_given_time() {
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut graph = GraphBuilder::new();
    let input = graph.add("reader", |p| {
        let input = p.input("n", Policy::queue(8));
        p.trigger(Trigger::on_any([input.into()]));
        (Recorder { input, seen: Arc::clone(&seen), newest_only: false }, input)
    });
    graph.external(input);
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    host.inject(input, 42, Time::from_nanos(5), Time::from_secs_f64(0.25)).expect("external");
    host.run_for(Duration::from_secs(1)).expect("runs");
    let seen = seen.lock().expect("lock");
    assert_eq!(seen.as_slice(), &[(Time::from_secs_f64(0.25), 42, Time::from_nanos(5))]);
}

#[test]
fn a_writer_can_wait_until_its_receiver_is_ready() {
    /// Sends the next number only when the previous one was taken (the paper's second kind of
    /// message), so even a `Latest` connection loses nothing.
    struct OnDemand {
        out: Output<u64>,
        next: u64,
    }
    impl Module for OnDemand {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            if ctx.receivers_ready(self.out) {
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
        // A slow tick only starts the exchange; readiness drives it afterwards.
        p.trigger(Trigger::every(Duration::from_secs(10)));
        (OnDemand { out, next: 0 }, out)
    });
    let input = graph.add("consumer", |p| {
        let input = p.input("n", Policy::Latest);
        p.trigger(Trigger::on_any([input.into()]));
        p.processing_time(ProcessingTime::fixed(4 * MS));
        (Recorder { input, seen: Arc::clone(&seen), newest_only: false }, input)
    });
    graph.connect(out, input);
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    host.run_for(Duration::from_millis(100)).expect("runs");
    let stats = host.stats();
    let values: Vec<u64> = seen.lock().expect("lock").iter().map(|s| s.1).collect();
    assert!(values.len() >= 20, "{values:?}");
    assert_eq!(values, (0..values.len() as u64).collect::<Vec<_>>());
    assert_eq!(stats.module("consumer").expect("consumer").inputs[0].counters.overwritten, 0);
}

#[test]
fn a_failing_module_stops_the_run_with_its_name() {
    struct Failing;
    impl Module for Failing {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            if ctx.now() >= Time::from_secs_f64(0.05) {
                return Err("lost the sensor".into());
            }
            Ok(())
        }
    }
    struct Panicking;
    impl Module for Panicking {
        fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
            panic!("index out of range in the filter");
        }
    }
    let mut graph = GraphBuilder::new();
    graph.add("perception", |p| {
        p.trigger(Trigger::every(10 * MS));
        (Failing, ())
    });
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    match host.run_for(Duration::from_secs(1)) {
        Err(HostError::ModuleFailed { module, error, stats }) => {
            assert_eq!(module, "perception");
            assert_eq!(error, "lost the sensor");
            assert_eq!(stats.module("perception").expect("stats").errors, 1);
        }
        other => panic!("expected a module failure, got {other:?}"),
    }
    let mut graph = GraphBuilder::new();
    graph.add("world", |p| {
        p.trigger(Trigger::every(10 * MS));
        (Panicking, ())
    });
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    let err = host.run_for(Duration::from_secs(1)).expect_err("panics");
    assert!(err.to_string().contains("`world` panicked: index out of range"), "{err}");
}

#[test]
fn simultaneous_events_follow_module_priority() {
    let order = Arc::new(Mutex::new(Vec::new()));
    struct Mark {
        name: &'static str,
        order: Arc<Mutex<Vec<&'static str>>>,
    }
    impl Module for Mark {
        fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
            self.order.lock().expect("lock").push(self.name);
            Ok(())
        }
    }
    let mut graph = GraphBuilder::new();
    for (name, priority) in [("robot", 0), ("simulator", -100)] {
        let order = Arc::clone(&order);
        graph.add(name, move |p| {
            p.trigger(Trigger::every(12 * MS));
            p.priority(priority);
            (Mark { name, order }, ())
        });
    }
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    host.run_for(Duration::from_millis(30)).expect("runs");
    assert_eq!(
        *order.lock().expect("lock"),
        ["simulator", "robot", "simulator", "robot", "simulator", "robot"]
    );
}

/// A tap that wants one output is shown only that output's packages, and the same ones a tap
/// wanting everything sees of it, also when the host has such a tap too; a `Taps` (several
/// taps as one) shows each of its taps everything any of them wants.
#[test]
fn a_tap_sees_only_the_outputs_it_wants() {
    struct Only {
        output: &'static str,
        inner: Collect,
    }
    impl strata_runtime::Tap for Only {
        fn package(&self, record: &strata_runtime::TapRecord<'_>) {
            self.inner.package(record);
        }
        fn wants(&self, output: &strata_runtime::TapOutput<'_>) -> bool {
            output.output == self.output
        }
    }
    let run = |how: u8| {
        let (mut host, everything, _) = pipeline(3);
        let only = Arc::new(Only { output: "estimate", inner: Collect::default() });
        match how {
            0 => host.set_tap(only.clone()),
            1 => {
                host.set_tap(everything.clone());
                host.add_tap(only.clone());
            }
            _ => {
                let taps = strata_runtime::Taps(vec![everything.clone(), only.clone()]);
                host.set_tap(Arc::new(taps));
            }
        }
        host.run_for(Duration::from_secs(1)).expect("runs");
        let only = only.inner.0.lock().expect("lock").clone();
        let everything = everything.0.lock().expect("lock").clone();
        (only, everything)
    };
    let (only, _) = run(0);
    let (beside, everything) = run(1);
    let (inside_taps, _) = run(2);
    assert!(!only.is_empty());
    assert!(only.iter().all(|(_, _, output, ..)| output == "estimate"), "{only:?}");
    let estimates: Vec<_> =
        everything.iter().filter(|(_, _, output, ..)| output == "estimate").cloned().collect();
    assert_eq!(only, estimates);
    assert!(everything.iter().any(|(_, _, output, ..)| output == "raw"));
    assert_eq!(beside, only, "a tap beside a logger still sees only its output");
    assert_eq!(inside_taps, everything, "a tap inside `Taps` with a logger sees everything");
}

/// A tap finds an output by its typed name: not another output of the same type, not an output
/// of the same name and another type, and, asked for one module's, not another module's.
#[test]
fn a_tap_finds_an_output_by_its_typed_name() {
    use strata_runtime::{PortName, Tap, TapOutput, TapRecord};
    const KEPT: PortName<u64> = PortName::new("kept");
    const OTHER: PortName<u64> = PortName::new("other");
    const KEPT_TEXT: PortName<String> = PortName::new("kept");
    struct Twins {
        kept: Output<u64>,
        other: Output<u64>,
        next: u64,
    }
    impl Module for Twins {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            self.next += 1;
            ctx.send(self.kept, self.next);
            ctx.send(self.other, self.next + 500);
            Ok(())
        }
    }
    struct Text {
        out: Output<String>,
    }
    impl Module for Text {
        fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
            ctx.send(self.out, "text".to_owned());
            Ok(())
        }
    }
    #[derive(Default)]
    struct Found {
        kept: Mutex<Vec<u64>>,
        from_twins: Mutex<Vec<u64>>,
        texts: Mutex<Vec<String>>,
        kept_outputs: Mutex<Vec<String>>,
    }
    impl Tap for Found {
        fn package(&self, record: &TapRecord<'_>) {
            if let Some(value) = record.value(KEPT) {
                self.kept.lock().expect("lock").push(*value);
            }
            if let Some(value) = record.value_from("twins", KEPT) {
                self.from_twins.lock().expect("lock").push(*value);
            }
            if let Some(text) = record.value(KEPT_TEXT) {
                self.texts.lock().expect("lock").push(text.clone());
            }
        }
        fn wants(&self, output: &TapOutput<'_>) -> bool {
            if output.is(KEPT) {
                self.kept_outputs.lock().expect("lock").push(output.module_name.to_owned());
            }
            true
        }
    }
    let mut graph = GraphBuilder::new();
    for (name, base) in [("twins", 0), ("copy", 1000)] {
        graph.add(name, |p| {
            p.trigger(Trigger::every(10 * MS));
            let (kept, other) = (p.output(KEPT), p.output(OTHER));
            (Twins { kept, other, next: base }, ())
        });
    }
    graph.add("text", |p| {
        p.trigger(Trigger::every(10 * MS));
        (Text { out: p.output(KEPT_TEXT) }, ())
    });
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::default());
    let found = Arc::new(Found::default());
    host.set_tap(found.clone());
    host.run_for(Duration::from_millis(100)).expect("runs");

    let from_twins = found.from_twins.lock().expect("lock").clone();
    assert!(from_twins.len() >= 5, "{from_twins:?}");
    assert_eq!(from_twins, (1..=from_twins.len() as u64).collect::<Vec<_>>());
    let mut kept = found.kept.lock().expect("lock").clone();
    kept.sort_unstable();
    let copies: Vec<u64> = (1001..=1000 + from_twins.len() as u64).collect();
    assert_eq!(kept, [from_twins.clone(), copies].concat(), "only the `kept` outputs");
    let texts = found.texts.lock().expect("lock").clone();
    assert_eq!(texts.len(), from_twins.len());
    assert!(texts.iter().all(|t| t == "text"));
    let mut kept_outputs = found.kept_outputs.lock().expect("lock").clone();
    kept_outputs.sort();
    assert_eq!(kept_outputs, ["copy", "twins"], "`is` tells the `String` output apart");
}

/// Passes each number on, times ten, on an output nobody reads.
struct Relay {
    input: Input<u64>,
    out: Output<u64>,
}

impl Module for Relay {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        for p in ctx.drain(self.input) {
            ctx.send_stamped(self.out, p.value * 10, p.stamp);
        }
        Ok(())
    }
}

/// A counter every 10 ms, read by a relay whose output nobody reads.
fn relayed_counter_host() -> LockstepHost {
    let mut graph = GraphBuilder::new();
    let sensor = graph.add("sensor", |p| {
        p.trigger(Trigger::every(10 * MS));
        let out = p.output("raw");
        (Counter { out, next: 0, noisy: false, limit: None }, out)
    });
    let (input, _unread) = graph.add("relay", |p| {
        let input = p.input("raw", Policy::queue(8));
        let out = p.output::<u64>("unread");
        p.trigger(Trigger::on_any([input.into()]));
        (Relay { input, out }, (input, out))
    });
    graph.connect(sensor, input);
    LockstepHost::new(graph.build().expect("valid"), HostConfig::with_seed(5))
}

/// What a tap saw of a package: output, sequence number, given (`true`) or shown.
type TapEntry = (String, u64, bool);

/// A tap that records what it sees, itself or through its sender (which keeps its records
/// until it is flushed).
struct Buffered {
    with_sender: bool,
    direct: Mutex<Vec<TapEntry>>,
    pending: Arc<Mutex<Vec<TapEntry>>>,
    flushed: Arc<Mutex<Vec<TapEntry>>>,
}

struct BufferSender {
    pending: Arc<Mutex<Vec<TapEntry>>>,
    flushed: Arc<Mutex<Vec<TapEntry>>>,
}

impl strata_runtime::Tap for Buffered {
    fn package(&self, record: &strata_runtime::TapRecord<'_>) {
        let entry = (record.sent_on.output.to_owned(), record.package.seq(), false);
        self.direct.lock().expect("lock").push(entry);
    }

    fn package_owned(
        &self,
        output: &strata_runtime::TapOutput<'_>,
        _time: Time,
        package: Box<dyn strata_runtime::ErasedPackage>,
    ) {
        self.direct.lock().expect("lock").push((output.output.to_owned(), package.seq(), true));
    }

    fn sender(&self) -> Option<Box<dyn strata_runtime::TapSender>> {
        self.with_sender.then(|| {
            let (pending, flushed) = (Arc::clone(&self.pending), Arc::clone(&self.flushed));
            Box::new(BufferSender { pending, flushed }) as Box<_>
        })
    }
}

impl strata_runtime::TapSender for BufferSender {
    fn package(&mut self, record: &strata_runtime::TapRecord<'_>) {
        let entry = (record.sent_on.output.to_owned(), record.package.seq(), false);
        self.pending.lock().expect("lock").push(entry);
    }

    fn package_owned(
        &mut self,
        output: &strata_runtime::TapOutput<'_>,
        _time: Time,
        package: Box<dyn strata_runtime::ErasedPackage>,
    ) {
        self.pending.lock().expect("lock").push((output.output.to_owned(), package.seq(), true));
    }

    fn flush(&mut self) {
        self.flushed.lock().expect("lock").append(&mut self.pending.lock().expect("lock"));
    }
}

/// The lockstep host reaches a tap that has a sender through the sender only, shows and gives
/// it what it would show and give the tap, and flushes it before each run call returns.
#[test]
fn a_tap_with_a_sender_is_reached_through_it_and_flushed_after_each_run() {
    let tap = |with_sender| {
        Arc::new(Buffered {
            with_sender,
            direct: Mutex::default(),
            pending: Arc::default(),
            flushed: Arc::default(),
        })
    };
    let (plain, buffered) = (tap(false), tap(true));
    let mut plain_host = relayed_counter_host();
    plain_host.set_tap(plain.clone());
    plain_host.run_for(Duration::from_millis(400)).expect("runs");
    let expected = plain.direct.lock().expect("lock").clone();
    assert!(expected.iter().any(|(_, _, given)| *given) && expected.iter().any(|e| !e.2));

    let mut host = relayed_counter_host();
    host.set_tap(buffered.clone());
    for _ in 0..2 {
        host.run_for(Duration::from_millis(100)).expect("runs");
        assert!(buffered.pending.lock().expect("lock").is_empty(), "flushed when a run returns");
    }
    let mut steps = 0;
    while host.now() < Time::from_secs_f64(0.3) {
        host.step().expect("steps");
        assert!(buffered.pending.lock().expect("lock").is_empty(), "flushed after each step");
        steps += 1;
    }
    assert!(steps > 10);
    assert!(buffered.direct.lock().expect("lock").is_empty(), "never called itself");
    let flushed = buffered.flushed.lock().expect("lock").clone();
    assert!(flushed.len() > expected.len() / 2);
    assert_eq!(flushed[..], expected[..flushed.len()], "what the tap itself would see, in order");
}

/// A package of an output nobody reads is given to a tap to keep (one of the taps that want
/// it, the last; the others are shown it), and it is the package the others see: same value,
/// stamp and sequence number. Packages of read outputs are only shown.
#[test]
fn a_package_nobody_reads_is_given_to_the_last_tap_that_wants_it() {
    /// Records how each package came: given (`true`) or shown.
    #[derive(Default)]
    struct Keeper(Mutex<Vec<(String, u64, u64, bool)>>);
    impl strata_runtime::Tap for Keeper {
        fn package(&self, record: &strata_runtime::TapRecord<'_>) {
            let value = record
                .package
                .as_any()
                .downcast_ref::<strata_runtime::Package<u64>>()
                .map(|p| p.value);
            let entry =
                (record.sent_on.output.to_owned(), record.package.seq(), value.unwrap_or(0), false);
            self.0.lock().expect("lock").push(entry);
        }
        fn package_owned(
            &self,
            output: &strata_runtime::TapOutput<'_>,
            _time: Time,
            package: Box<dyn strata_runtime::ErasedPackage>,
        ) {
            let seq = package.seq();
            let kept = package
                .into_any()
                .downcast::<strata_runtime::Package<u64>>()
                .expect("a u64 package");
            self.0.lock().expect("lock").push((output.output.to_owned(), seq, kept.value, true));
        }
    }
    let run = |how: u8| {
        let mut host = relayed_counter_host();
        let (keeper, other) = (Arc::new(Keeper::default()), Arc::new(Keeper::default()));
        match how {
            0 => host.set_tap(keeper.clone()),
            1 => {
                host.set_tap(other.clone());
                host.add_tap(keeper.clone());
            }
            _ => host.set_tap(Arc::new(strata_runtime::Taps(vec![other.clone(), keeper.clone()]))),
        }
        host.run_for(Duration::from_millis(200)).expect("runs");
        let keeper = keeper.0.lock().expect("lock").clone();
        let other = other.0.lock().expect("lock").clone();
        (keeper, other)
    };
    let (alone, _) = run(0);
    assert!(alone.iter().any(|(output, ..)| output == "unread"));
    for (output, _, _, given) in &alone {
        assert_eq!(*given, output == "unread", "{output}: given only when nobody reads it");
    }
    for how in [1, 2] {
        let (keeper, other) = run(how);
        assert_eq!(keeper, alone, "the last tap is given what it would be given alone");
        assert!(other.iter().all(|(.., given)| !given), "the others are shown");
        let strip = |v: &[(String, u64, u64, bool)]| -> Vec<(String, u64, u64)> {
            v.iter().map(|(o, s, x, _)| (o.clone(), *s, *x)).collect()
        };
        assert_eq!(strip(&other), strip(&keeper), "shown and given: the same packages");
    }
}
