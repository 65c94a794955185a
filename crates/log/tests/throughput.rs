//! Measurements, not checks: what logging costs the demo graph and how large its logs are.
//! Run with `cargo test -p strata-log --test throughput -- --ignored --nocapture`.

mod support;

use std::sync::Arc;
use std::time::{Duration, Instant};

use strata_log::{LogCompression, LogReader, McapTap, McapTapOptions, WhenFull};
use strata_runtime::{HostConfig, LockstepHost, Tap, TapRecord, Time};

/// Serializes like the log does, writes nothing: the tap's cost on the sending thread alone.
struct SerializeOnly;

impl Tap for SerializeOnly {
    fn package(&self, record: &TapRecord<'_>) {
        let mut json = Vec::with_capacity(256);
        let _ = record.package.write_json(&mut json);
        std::hint::black_box(json);
    }
}

fn run(seconds: f64, tap: Option<Arc<dyn Tap>>) -> Duration {
    let config = support::config_value();
    let mut host = LockstepHost::new(support::demo_graph("", &config), HostConfig::with_seed(1));
    if let Some(tap) = tap {
        host.set_tap(tap);
    }
    let start = Instant::now();
    host.run_until(Time::from_secs_f64(seconds)).expect("run");
    start.elapsed()
}

#[test]
#[ignore = "a measurement; run by hand"]
fn logging_cost_and_size() {
    let dir = support::scratch("throughput");
    let seconds = 600.0;
    let bare = run(seconds, None);
    let serialize = run(seconds, Some(Arc::new(SerializeOnly)));
    println!("demo graph, {seconds} s simulated");
    println!("  no tap:          {:>8.3} s wall", bare.as_secs_f64());
    println!("  serialize only:  {:>8.3} s wall", serialize.as_secs_f64());
    for (compression, when_full) in [
        (LogCompression::Zstd, WhenFull::Drop),
        (LogCompression::Zstd, WhenFull::Wait),
        (LogCompression::Lz4, WhenFull::Wait),
        (LogCompression::None, WhenFull::Wait),
    ] {
        let path = dir.join(format!("{compression:?}-{when_full:?}.mcap"));
        let options = McapTapOptions { compression, when_full, ..McapTapOptions::default() };
        let tap = Arc::new(McapTap::create(&path, options).expect("create"));
        let wall = run(seconds, Some(tap.clone()));
        let start = Instant::now();
        let summary = tap.finish().expect("finish");
        let drain = start.elapsed();
        let reader = LogReader::open(&path).expect("open");
        let start = Instant::now();
        let read = reader.messages().count();
        let read_time = start.elapsed();
        println!(
            "  {compression:?}, {when_full:?}: {:>8.3} s wall (+{:.3} s to finish), {} messages, {} dropped, {:.2} MB ({:.3} MB per simulated minute, {:.1} bytes per message); read back in {:.3} s",
            wall.as_secs_f64(),
            drain.as_secs_f64(),
            summary.messages,
            summary.dropped,
            summary.bytes as f64 / 1e6,
            summary.bytes as f64 / 1e6 / (seconds / 60.0),
            summary.bytes as f64 / summary.messages.max(1) as f64,
            read_time.as_secs_f64(),
        );
        assert_eq!(read as u64, summary.messages);
    }
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
