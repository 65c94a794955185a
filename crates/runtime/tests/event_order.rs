//! The lockstep host's event order, pinned: a graph that exercises every rule at the top of
//! `lockstep.rs` at once (simultaneous events of several priorities, cycles that send several
//! packages, readers that run at the instant a package arrives and preempt the rest of a
//! cycle's packages, busy modules, writers woken when their readers are ready, injected
//! packages) runs for a few simulated seconds, and everything observable (the trace, every
//! tapped package, what every module saw, the statistics) is folded into one digest.
//!
//! The digest was taken from the host as it was before its event queue was made compact; the
//! queue's representation is free to change, the order is not. A change of the digest means
//! a trace changed: find out which rule moved before updating it.

mod common;

use std::fmt::Write as _;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::Collect;
use strata_runtime::{
    Context, GraphBuilder, HostConfig, Input, LockstepHost, Module, ModuleError, Output, Policy,
    ProcessingTime, Time, Trigger,
};

const MS: Duration = Duration::from_millis(1);

type Log = Arc<Mutex<String>>;

/// Sends up to `most` packages on `a` and one on `b` every cycle, from its RNG.
struct Burst {
    a: Output<u64>,
    b: Output<u64>,
    most: u64,
}

impl Module for Burst {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        use rand::RngExt;
        let count = ctx.rng().random_range(0..=self.most);
        for _ in 0..count {
            let v = ctx.rng().random_range(0..1000u64);
            ctx.send(self.a, v);
        }
        let v = ctx.rng().random_range(0..1000u64);
        ctx.send(self.b, v);
        Ok(())
    }
}

/// Takes what is pending (one at a time, all, or the newest), logs it with what woke it, and
/// forwards the sum.
struct Relay {
    name: &'static str,
    inputs: Vec<(Input<u64>, Take)>,
    out: Option<Output<u64>>,
    log: Log,
}

#[derive(Clone, Copy)]
enum Take {
    One,
    All,
    Newest,
}

impl Module for Relay {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let mut sum = 0u64;
        let mut line = format!("{} {} {:?}:", ctx.now().as_nanos(), self.name, ctx.woken_by());
        for (input, take) in self.inputs.clone() {
            let packages = match take {
                Take::One => ctx.take(input).into_iter().collect(),
                Take::All => ctx.drain(input),
                Take::Newest => ctx.latest(input).into_iter().collect(),
            };
            for p in packages {
                sum = sum.wrapping_add(p.value);
                let _ = write!(line, " {}@{}#{}", p.value, p.stamp.as_nanos(), p.seq);
            }
        }
        line.push('\n');
        self.log.lock().unwrap_or_else(|e| e.into_inner()).push_str(&line);
        if let Some(out) = self.out
            && (sum > 0 || ctx.receivers_ready(out))
        {
            ctx.send(out, sum);
        }
        Ok(())
    }
}

/// Sends a counter only when its reader took the previous one.
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

fn relay(name: &'static str, log: &Log) -> Relay {
    Relay { name, inputs: Vec::new(), out: None, log: Arc::clone(log) }
}

fn run(seed: u64) -> String {
    let log: Log = Arc::new(Mutex::new(String::new()));
    let mut graph = GraphBuilder::new();
    let (a, b) = graph.add("burst", |p| {
        p.trigger(Trigger::every(5 * MS));
        p.processing_time(ProcessingTime::Uniform { min: Duration::ZERO, max: 2 * MS });
        let a = p.output("a");
        let b = p.output("b");
        (Burst { a, b, most: 3 }, (a, b))
    });
    // Runs at the instant each `a` arrives (higher priority, no processing time), before the
    // burst's remaining packages become visible.
    let (urgent_in, urgent_out) = graph.add("urgent", |p| {
        let input = p.input("a", Policy::queue(4));
        let out = p.output("c");
        p.trigger(Trigger::on_any([input.into()]));
        p.priority(-5);
        let mut r = relay("urgent", &log);
        r.inputs.push((input, Take::One));
        r.out = Some(out);
        (r, (input, out))
    });
    // Also runs at the instant each `a` arrives, but at the burst's own priority: after the
    // burst's remaining packages.
    let peer_in = graph.add("peer", |p| {
        let input = p.input("a", Policy::queue(4));
        p.trigger(Trigger::on_any([input.into()]));
        let mut r = relay("peer", &log);
        r.inputs.push((input, Take::One));
        (r, input)
    });
    // Needs both outputs of the burst; busy for a random while, so triggers pile up.
    let (late_a, late_b, late_out) = graph.add("late", |p| {
        let a = p.input("a", Policy::queue(3));
        let b = p.input("b", Policy::Latest);
        let out = p.output("d");
        p.trigger(Trigger::on_all([a.into(), b.into()]));
        p.priority(5);
        p.processing_time(ProcessingTime::Normal { mean: 4 * MS, std_dev: 2 * MS, min: MS });
        let mut r = relay("late", &log);
        r.inputs.push((a, Take::All));
        r.inputs.push((b, Take::Newest));
        r.out = Some(out);
        (r, (a, b, out))
    });
    let (sink_c, sink_d, sink_x) = graph.add("sink", |p| {
        let c = p.input("c", Policy::Latest);
        let d = p.input("d", Policy::queue(2));
        let x = p.input("x", Policy::queue(8));
        p.trigger(Trigger::on_any([c.into(), d.into(), x.into()]));
        p.processing_time(ProcessingTime::fixed(MS));
        let mut r = relay("sink", &log);
        r.inputs.push((c, Take::Newest));
        r.inputs.push((d, Take::One));
        r.inputs.push((x, Take::All));
        (r, (c, d, x))
    });
    // Periodic at the burst's period, offset to coincide with some of its outputs.
    let watch_c = graph.add("watch", |p| {
        let c = p.input("c", Policy::Latest);
        p.trigger(Trigger::every(5 * MS).with_offset(MS));
        p.priority(-5);
        let mut r = relay("watch", &log);
        r.inputs.push((c, Take::Newest));
        (r, c)
    });
    let pacer = graph.add("pacer", |p| {
        let out = p.output("n");
        p.wake_when_receivers_ready(out);
        p.trigger(Trigger::every(50 * MS));
        p.priority(3);
        (OnDemand { out, next: 0 }, out)
    });
    let slow_in = graph.add("slow", |p| {
        let input = p.input("n", Policy::Latest);
        p.trigger(Trigger::on_any([input.into()]));
        p.processing_time(ProcessingTime::fixed(7 * MS));
        let mut r = relay("slow", &log);
        r.inputs.push((input, Take::Newest));
        (r, input)
    });
    graph.fan_out(a, [urgent_in, peer_in, late_a]);
    graph.connect(b, late_b);
    graph.fan_out(urgent_out, [sink_c, watch_c]);
    graph.connect(late_out, sink_d);
    graph.connect(pacer, slow_in);
    graph.external(sink_x);
    let mut host = LockstepHost::new(graph.build().expect("valid"), HostConfig::with_seed(seed));
    let tap = Arc::new(Collect::default());
    host.set_tap(tap.clone());
    host.record_trace(true);
    for k in 0..20u64 {
        // Some injections coincide with the burst's ticks.
        let at = Time::from_nanos(k * 2_500_000);
        host.inject(sink_x, 10_000 + k, Time::from_nanos(k), at).expect("external");
    }
    host.run_for(Duration::from_millis(1500)).expect("runs");
    let mut out = String::new();
    for entry in host.trace() {
        let _ = writeln!(out, "{entry:?}");
    }
    for tapped in tap.0.lock().expect("lock").iter() {
        let _ = writeln!(out, "{tapped:?}");
    }
    out.push_str(&log.lock().expect("lock"));
    let stats = host.stats();
    let _ = writeln!(out, "{}", serde_json::to_string(&stats.modules).expect("serializable"));
    out
}

/// FNV-1a: stable across Rust versions, unlike the standard hasher.
fn digest(text: &str) -> u64 {
    text.bytes()
        .fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3))
}

#[test]
fn the_event_order_is_the_documented_one() {
    let text = run(3);
    assert_eq!(text, run(3), "the same seed must give the same run");
    assert!(text.lines().count() > 3000, "the run is too short to pin anything");
    assert_eq!(digest(&text), 169_169_596_985_151_270, "digest of {} lines", text.lines().count());
}
