//! Thread-to-thread package hand-off on the threaded host, per connection policy, against a raw
//! `crossbeam-channel` hand-off measured in the same run.
//!
//! Latency: one package in flight at a time (the writer sends the next when the paper's
//! "receiver ready" message arrives; the raw baseline waits for an acknowledgement), so the
//! figure is the hand-off itself, not queueing. Throughput: the writer sends batches whenever
//! its reader has taken the previous one.
//!
//! Run: `cargo bench -p strata-runtime --bench handoff`

use std::hint::black_box;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use hdrhistogram::Histogram;
use strata_runtime::{
    Context, GraphBuilder, HostConfig, Input, Module, ModuleError, Output, Policy, ThreadedHost,
    Time, Trigger,
};

const LATENCY_SAMPLES: u64 = 50_000;
const THROUGHPUT_PACKAGES: u64 = 2_000_000;
const BATCH: u64 = 64;

fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 10_000_000_000, 3).expect("valid bounds")
}

struct Figures {
    p50_us: f64,
    p99_us: f64,
    throughput_per_s: f64,
}

fn raw_crossbeam() -> Figures {
    let origin = Instant::now();
    let (tx, rx) = crossbeam_channel::bounded::<u64>(1);
    let (ack_tx, ack_rx) = crossbeam_channel::bounded::<()>(1);
    let receiver = std::thread::spawn(move || {
        let mut h = histogram();
        for _ in 0..LATENCY_SAMPLES {
            let Ok(sent) = rx.recv() else { break };
            let now = origin.elapsed().as_nanos() as u64;
            let _ = h.record(now.saturating_sub(sent).max(1));
            let _ = ack_tx.send(());
        }
        h
    });
    for _ in 0..LATENCY_SAMPLES {
        let _ = tx.send(origin.elapsed().as_nanos() as u64);
        let _ = ack_rx.recv();
    }
    let h = receiver.join().expect("receiver");

    let (tx, rx) = crossbeam_channel::unbounded::<u64>();
    let start = Instant::now();
    let receiver = std::thread::spawn(move || {
        let mut sum = 0u64;
        for _ in 0..THROUGHPUT_PACKAGES {
            sum = sum.wrapping_add(rx.recv().unwrap_or(0));
        }
        black_box(sum)
    });
    for i in 0..THROUGHPUT_PACKAGES {
        let _ = tx.send(i);
    }
    let _ = receiver.join();
    let elapsed = start.elapsed();
    Figures {
        p50_us: h.value_at_quantile(0.5) as f64 / 1000.0,
        p99_us: h.value_at_quantile(0.99) as f64 / 1000.0,
        throughput_per_s: THROUGHPUT_PACKAGES as f64 / elapsed.as_secs_f64(),
    }
}

/// Sends its cycle's start time whenever its reader has taken the previous package.
struct Ping {
    out: Output<u64>,
    sent: u64,
    limit: u64,
    batch: u64,
}

impl Module for Ping {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        if self.sent < self.limit && ctx.receivers_ready(self.out) {
            for _ in 0..self.batch.min(self.limit - self.sent) {
                let now = ctx.now().as_nanos();
                ctx.send(self.out, now);
                self.sent += 1;
            }
        }
        Ok(())
    }
}

struct Pong {
    input: Input<u64>,
    histogram: Arc<Mutex<Histogram<u64>>>,
    received: Arc<Mutex<(u64, Option<Instant>)>>,
    record: bool,
}

impl Module for Pong {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let packages = ctx.drain(self.input);
        if self.record {
            let mut h = self.histogram.lock().expect("histogram");
            for p in &packages {
                let _ = h.record((now - Time::from_nanos(p.value)).as_nanos().max(1) as u64);
            }
        }
        let mut received = self.received.lock().expect("counter");
        received.0 += packages.len() as u64;
        received.1 = Some(Instant::now());
        Ok(())
    }
}

fn strata(
    policy: fn() -> Policy<u64>,
    limit: u64,
    batch: u64,
    record: bool,
) -> (Histogram<u64>, u64, Duration) {
    let histogram = Arc::new(Mutex::new(histogram()));
    let received = Arc::new(Mutex::new((0u64, None)));
    let mut graph = GraphBuilder::new();
    let out = graph.add("ping", |p| {
        let out = p.output::<u64>("stamp");
        p.wake_when_receivers_ready(out);
        p.trigger(Trigger::every(Duration::from_millis(100)));
        (Ping { out, sent: 0, limit, batch }, out)
    });
    let input = graph.add("pong", |p| {
        let input = p.input("stamp", policy());
        p.trigger(Trigger::on_any([input.into()]));
        let module = Pong {
            input,
            histogram: Arc::clone(&histogram),
            received: Arc::clone(&received),
            record,
        };
        (module, input)
    });
    graph.connect(out, input);
    let host = ThreadedHost::new(graph.build().expect("valid graph"), HostConfig::default())
        .start()
        .expect("host starts");
    let start = Instant::now();
    let expected_cycles = limit.div_ceil(batch);
    loop {
        std::thread::sleep(Duration::from_millis(5));
        let stats = host.stats();
        let ping_cycles = stats.module("ping").map_or(0, |m| m.cycles);
        let done = received.lock().expect("counter").0 >= limit
            || (ping_cycles > expected_cycles + 1
                && received
                    .lock()
                    .expect("counter")
                    .1
                    .is_some_and(|t| t.elapsed() > Duration::from_millis(200)));
        if done || start.elapsed() > Duration::from_secs(120) {
            break;
        }
    }
    let _ = host.stop();
    let (count, last) = *received.lock().expect("counter");
    let elapsed = last.map_or(start.elapsed(), |l| l.duration_since(start));
    let h = histogram.lock().expect("histogram").clone();
    (h, count, elapsed)
}

fn main() {
    // `cargo bench` passes `--bench`; anything else (`cargo test --benches`) is a quick smoke run.
    let quick = !std::env::args().any(|a| a == "--bench");
    if quick {
        let (h, count, _) = strata(|| Policy::Latest, 200, 1, true);
        assert_eq!(count, 200);
        assert!(h.len() == 200);
        println!("handoff: smoke run ok");
        return;
    }
    println!(
        "Package hand-off between two module threads ({} samples, one in flight)",
        LATENCY_SAMPLES
    );
    let raw = raw_crossbeam();
    type MakePolicy = fn() -> Policy<u64>;
    let policies: [(&str, MakePolicy); 3] = [
        ("latest", || Policy::Latest),
        ("queue(1024)", || Policy::queue(1024)),
        ("merge(sum)", || Policy::merge(|a: &mut u64, b| *a = a.wrapping_add(b))),
    ];
    println!(
        "{:<22} {:>9} {:>9} {:>12} {:>16} {:>12}",
        "connection", "p50 us", "p99 us", "p50 ratio", "throughput/s", "thr. ratio"
    );
    println!(
        "{:<22} {:>9.2} {:>9.2} {:>12} {:>16.0} {:>12}",
        "raw crossbeam (base)", raw.p50_us, raw.p99_us, "1.00x", raw.throughput_per_s, "1.00x"
    );
    for (name, policy) in policies {
        let (h, count, _) = strata(policy, LATENCY_SAMPLES, 1, true);
        assert_eq!(count, LATENCY_SAMPLES, "{name}: every package arrived");
        let (_, delivered, elapsed) = strata(policy, THROUGHPUT_PACKAGES, BATCH, false);
        let figures = Figures {
            p50_us: h.value_at_quantile(0.5) as f64 / 1000.0,
            p99_us: h.value_at_quantile(0.99) as f64 / 1000.0,
            throughput_per_s: THROUGHPUT_PACKAGES as f64 / elapsed.as_secs_f64(),
        };
        println!(
            "{:<22} {:>9.2} {:>9.2} {:>11.2}x {:>16.0} {:>11.2}x   ({} packages taken)",
            format!("strata {name}"),
            figures.p50_us,
            figures.p99_us,
            figures.p50_us / raw.p50_us,
            figures.throughput_per_s,
            figures.throughput_per_s / raw.throughput_per_s,
            delivered
        );
    }
}
