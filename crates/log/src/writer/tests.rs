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
