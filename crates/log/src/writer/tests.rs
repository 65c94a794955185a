use std::sync::Arc;
use std::time::{Duration, Instant};

use strata_runtime::{Tap, TapOutput, Time};

use super::{BATCH, McapTap, McapTapOptions, WhenFull};

#[test]
fn a_full_queue_drops_and_counts_instead_of_blocking() {
    let dir = std::env::temp_dir().join(format!("strata-log-drop-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_default();
    let path = dir.join("drop.mcap");
    let options = McapTapOptions { capacity: 4, ..McapTapOptions::default() };
    let tap = McapTap::create(&path, options).expect("create");
    tap.gate().set_closed(true);
    let sent = 100u64;
    for i in 0..sent {
        tap.record("test/values", "u64", Time::from_nanos(i * 1000), &serde_json::json!(i));
    }
    let dropped = tap.dropped();
    // The queue holds 4 and the paused writer at most one more.
    assert!(dropped >= sent - 5, "dropped {dropped}");
    tap.gate().set_closed(false);
    let summary = tap.finish().expect("finish");
    assert_eq!(summary.messages + summary.dropped, sent);
    assert_eq!(summary.dropped_by_topic.get("test/values").copied(), Some(summary.dropped));
    let reader = crate::LogReader::open(&path).expect("open");
    assert!(reader.is_complete());
    assert_eq!(reader.message_count(), summary.messages);
    assert_eq!(reader.stats().map(|s| s.dropped), Some(summary.dropped));
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn a_waiting_sender_batches_and_waits_for_a_held_writer() {
    use strata_runtime::{ModuleId, Package};
    let dir = std::env::temp_dir().join(format!("strata-log-hold-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_default();
    let path = dir.join("hold.mcap");
    // Room for one batch in the queue.
    let options =
        McapTapOptions { capacity: 8, when_full: WhenFull::Wait, ..McapTapOptions::default() };
    let tap = Arc::new(McapTap::create(&path, options).expect("create"));
    let values: Vec<(u32, String)> = (0..3 * BATCH as u32).map(|i| (i, format!("v{i}"))).collect();
    fn send(tap: &McapTap, values: &[(u32, String)], from: usize, to: usize) {
        for (i, value) in values.iter().enumerate().take(to).skip(from) {
            let package =
                Package::new(value.clone(), Time::from_nanos(i as u64), i as u64, ModuleId(0));
            let sent_on = TapOutput {
                host: 0,
                module: ModuleId(0),
                module_name: "m",
                port: 0,
                output: "out",
                type_name: "(u32, String)",
            };
            tap.package(&sent_on.record(Time::from_nanos(i as u64), &package));
        }
    }
    // Less than a batch stays with the sender.
    send(&tap, &values, 0, BATCH - 1);
    assert!(tap.shared.sender.is_empty(), "a partial batch is not handed over");
    // The writer takes the first batch and is held there; the next fills the queue and
    // the third makes the sender wait.
    tap.gate().set_closed(true);
    let sender = {
        let (tap, values) = (Arc::clone(&tap), values.clone());
        std::thread::spawn(move || send(&tap, &values, BATCH - 1, values.len()))
    };
    let deadline = Instant::now() + Duration::from_secs(10);
    while !tap.shared.sender.is_full() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(tap.shared.sender.is_full(), "the queue filled while the writer was held");
    assert!(!sender.is_finished(), "the sender waits for room");
    tap.gate().set_closed(false);
    sender.join().expect("the sender ends once the writer goes on");
    let summary = tap.finish().expect("finish");
    assert_eq!((summary.messages, summary.dropped), (values.len() as u64, 0));
    let reader = crate::LogReader::open(&path).expect("open");
    let read: Vec<(u32, String)> =
        reader.messages().map(|m| m.expect("ok").decode().expect("decodes")).collect();
    assert_eq!(read, values);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn wait_mode_loses_nothing_through_a_tiny_queue() {
    let dir = std::env::temp_dir().join(format!("strata-log-wait-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_default();
    let path = dir.join("wait.mcap");
    let options =
        McapTapOptions { capacity: 2, when_full: WhenFull::Wait, ..McapTapOptions::default() };
    let tap = McapTap::create(&path, options).expect("create");
    for i in 0..2000u64 {
        tap.record("test/values", "u64", Time::from_nanos(i), &serde_json::json!(i));
    }
    let summary = tap.finish().expect("finish");
    assert_eq!((summary.messages, summary.dropped), (2000, 0));
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// Records on one topic, one per millisecond of log time.
fn record_values(tap: &McapTap, n: u64) {
    for i in 0..n {
        tap.record("test/values", "u64", Time::from_nanos(i * 1_000_000), &serde_json::json!(i));
    }
}

#[test]
fn each_chunk_is_synced_when_asked_and_only_then() {
    let dir = std::env::temp_dir().join(format!("strata-log-sync-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_default();
    for sync_chunks in [true, false] {
        let path = dir.join(format!("sync-{sync_chunks}.mcap"));
        let options = McapTapOptions {
            sync_chunks,
            when_full: WhenFull::Wait,
            max_chunk_span: Duration::from_millis(10),
            ..McapTapOptions::default()
        };
        let tap = McapTap::create(&path, options).expect("create");
        tap.write_metadata("test.setup", [("k".to_owned(), "v".to_owned())].into())
            .expect("metadata");
        record_values(&tap, 500);
        let summary = tap.finish().expect("finish");
        assert_eq!(summary.messages, 500);
        let chunks = crate::LogReader::open(&path).expect("open").chunk_count() as u64;
        assert!(chunks >= 40, "{chunks} chunks");
        // Every chunk once written, the metadata record, and the finished file.
        let expected = if sync_chunks { chunks + 2 } else { 0 };
        assert_eq!(tap.shared.syncs.load(std::sync::atomic::Ordering::Relaxed), expected);
    }
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
#[cfg(target_os = "linux")]
fn a_file_that_cannot_be_synced_is_written_without() {
    // fsync(2) on /dev/null fails with EINVAL, as on a pipe: nothing to sync, no failure.
    let options = McapTapOptions { sync_chunks: true, ..McapTapOptions::default() };
    let tap = McapTap::create("/dev/null", options).expect("create");
    record_values(&tap, 1000);
    assert!(tap.finish().is_ok(), "{:?}", tap.error());
    assert!(tap.error().is_none());
    assert_eq!(tap.shared.syncs.load(std::sync::atomic::Ordering::Relaxed), 0);
}

#[test]
#[cfg(target_os = "linux")]
fn after_a_failed_write_records_are_dropped_at_the_sender() {
    // /dev/full fails every write with ENOSPC: the first chunk's flush fails.
    let options = McapTapOptions { max_chunk_span: Duration::from_millis(5), ..Default::default() };
    let tap = McapTap::create("/dev/full", options).expect("create");
    record_values(&tap, 100);
    let deadline = Instant::now() + Duration::from_secs(10);
    while (tap.error().is_none() || !tap.shared.sender.is_empty()) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(1));
    }
    assert!(tap.error().is_some(), "the failure is known before finish");
    assert!(tap.shared.sender.is_empty(), "the writer took what was queued");
    // Held, the writer would leave in the queue whatever was still queued for it.
    tap.gate().set_closed(true);
    let dropped = tap.dropped();
    record_values(&tap, 50);
    let (queued, counted) = (!tap.shared.sender.is_empty(), tap.dropped() - dropped);
    // Opened before asserting: a held writer would keep the tap's drop from finishing.
    tap.gate().set_closed(false);
    assert!(!queued, "nothing is queued for a writer that cannot write");
    assert!(counted >= 50, "{counted} dropped");
    assert!(matches!(tap.finish(), Err(crate::LogError::Write { .. })));
}
