//! Logs on real disks: a write that fails is reported at once, and a long log split at its size
//! cap loses nothing, each file whole on its own.

mod support;

use std::io::ErrorKind;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use strata_log::{
    Derive, DerivedRecords, LogCompression, LogError, LogReader, McapTap, McapTapOptions, WhenFull,
};
use strata_runtime::{
    Context, ErasedPackage, GraphBuilder, HostConfig, LockstepHost, Module, ModuleError, Output,
    Shared, Time, Trigger,
};
use support::{CONFIG, SEED, record_demo, scratch};

/// Records on one topic, one per millisecond of log time from `from`, each a few hundred bytes.
fn record_values(tap: &McapTap, from: u64, n: u64) {
    for i in from..from + n {
        let value = serde_json::json!({ "i": i, "pad": "x".repeat(200) });
        tap.record("test/values", "demo::Value", Time::from_nanos(i * 1_000_000), &value);
    }
}

/// The log's error, once the writer thread has met it (within a few seconds).
fn wait_for_error(tap: &McapTap) -> Option<LogError> {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match tap.error() {
            Some(error) => return Some(error),
            None if Instant::now() > deadline => return None,
            None => std::thread::sleep(Duration::from_millis(5)),
        }
    }
}

/// What a robot's log does once a write has failed, whatever failed: the error is visible
/// before the log is finished, records are counted as dropped at once, metadata is refused and
/// `finish` returns the error.
fn assert_reports_the_failure_at_once(tap: &McapTap, kind: ErrorKind) {
    let error = wait_for_error(tap).expect("the error is visible before finish");
    let LogError::Write { source, .. } = &error else { panic!("not a write error: {error}") };
    assert_eq!(source.kind(), kind, "{error}");
    let dropped = tap.dropped();
    record_values(tap, 1_000_000, 100);
    // The writer may still be counting what was queued before: at least these were dropped.
    assert!(tap.dropped() >= dropped + 100, "records after the failure are dropped, counted");
    let refused = tap.write_metadata("late", Default::default());
    assert!(matches!(refused, Err(LogError::Write { .. })), "{refused:?}");
    let finished = tap.finish();
    assert!(matches!(finished, Err(LogError::Write { .. })), "{finished:?}");
}

/// The options of `strata robot --log`: a real-time sender, each chunk synced.
fn robot_options() -> McapTapOptions {
    McapTapOptions {
        when_full: WhenFull::Drop,
        sync_chunks: true,
        compression: LogCompression::None,
        max_chunk_span: Duration::from_millis(20),
        ..McapTapOptions::default()
    }
}

#[test]
#[cfg(target_os = "linux")]
fn a_full_disk_is_reported_the_moment_a_write_fails() {
    // /dev/full takes the log's file like any other and fails every write with ENOSPC: the
    // first chunk's flush fails, through the very `File` and `BufWriter` a robot's log uses.
    let tap = McapTap::create("/dev/full", robot_options()).expect("created");
    record_values(&tap, 0, 1000);
    assert_reports_the_failure_at_once(&tap, ErrorKind::StorageFull);
}

/// Set in the process that runs the size-limited part of the test below.
const LIMITED: &str = "STRATA_LOG_TEST_FILE_SIZE_LIMITED";

#[test]
#[cfg(target_os = "linux")]
fn a_size_limited_file_fails_mid_run_and_keeps_its_chunks() {
    // A file that takes writes until it reaches a size limit, as on a disk that fills during a
    // run, through the log's own file writing: the process's file size limit (RLIMIT_FSIZE)
    // makes writes past it fail with EFBIG once SIGXFSZ is ignored. Both are process-wide, so
    // this test runs itself again in a child process set up by the shell (`ulimit -f`, in
    // 512-byte blocks, and `trap '' XFSZ`: an ignored signal stays ignored through exec).
    if std::env::var_os(LIMITED).is_some() {
        return size_limited_run();
    }
    let exe = std::env::current_exe().expect("the test binary");
    let output = std::process::Command::new("sh")
        .arg("-c")
        .arg(r#"trap '' XFSZ; ulimit -f 256 && exec "$0" "$@""#)
        .arg(exe)
        .args(["a_size_limited_file_fails_mid_run_and_keeps_its_chunks", "--exact"])
        .args(["--nocapture", "--test-threads=1"])
        .env(LIMITED, "1")
        .output()
        .expect("sh runs");
    let text = String::from_utf8_lossy(&output.stdout).into_owned()
        + &String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{text}");
    assert!(text.contains("1 passed"), "the child ran the test: {text}");
}

fn size_limited_run() {
    const LIMIT: u64 = 256 * 512;
    let dir = scratch("size-limited");
    let path = dir.join("robot.mcap");
    let tap = McapTap::create(&path, robot_options()).expect("created");
    // About ten times the limit, handed over as a robot's modules would, without waiting.
    record_values(&tap, 0, 6000);
    assert_reports_the_failure_at_once(&tap, ErrorKind::FileTooLarge);
    let size = std::fs::metadata(&path).expect("the file").len();
    assert!(size <= LIMIT, "{size} bytes");
    // The chunks written before the failure read back, in order.
    let reader = LogReader::open(&path).expect("recovered");
    assert!(!reader.is_complete());
    let read: Vec<u64> = reader
        .messages()
        .map(|m| m.expect("readable").json().expect("json")["i"].as_u64().expect("i"))
        .collect();
    assert!(read.len() > 100, "{} messages recovered", read.len());
    assert!(read.len() < 6000);
    assert_eq!(read, (0..read.len() as u64).collect::<Vec<_>>());
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn a_log_past_its_size_cap_goes_on_in_parts_that_lose_nothing() {
    let dir = scratch("parts");
    let path = dir.join("demo.mcap");
    const CAP: u64 = 16 << 10;
    let options = McapTapOptions {
        when_full: WhenFull::Wait,
        compression: LogCompression::None,
        max_chunk_span: Duration::from_millis(100),
        max_file_size: Some(CAP),
        ..McapTapOptions::default()
    };
    let (seen, summary) = record_demo(&path, 5.0, options, CONFIG);
    let files = &summary.files;
    assert!(files.len() >= 4, "{files:?}");
    for (part, file) in files.iter().enumerate() {
        assert_eq!(*file, McapTap::part_path(&path, part as u32));
    }
    assert_eq!(files[1], dir.join("demo-1.mcap"));
    let mut packages = Vec::new();
    let mut truth = Vec::new();
    let mut bytes = 0;
    for (part, file) in files.iter().enumerate() {
        let reader = LogReader::open(file).expect("open");
        assert!(reader.is_complete(), "{}", file.display());
        bytes += reader.file_bytes();
        // Every file but the last ends at the first chunk boundary past the cap.
        if part + 1 < files.len() {
            assert!(
                reader.file_bytes() >= CAP,
                "{}: {} bytes",
                file.display(),
                reader.file_bytes()
            );
        }
        assert!(reader.file_bytes() < 2 * CAP, "{}: {} bytes", file.display(), reader.file_bytes());
        // Each file replays on its own: the run, its configuration and the graph.
        let run = reader.run_info().expect("run").expect("present");
        assert_eq!((run.seed, run.config.map(|c| c.1)), (SEED, Some(CONFIG.to_owned())));
        assert_eq!(reader.graphs().expect("graph").len(), 1);
        // The writer's statistics are the file's own.
        let stats = reader.stats().expect("stats");
        assert_eq!(stats.messages, reader.message_count());
        for message in reader.messages() {
            let m = message.expect("readable");
            if &*m.topic == "sim/ground_truth" {
                truth.push(m.seq);
            } else {
                packages.push((m.topic.to_string(), m.log_time, m.stamp, m.seq, m.data));
            }
        }
    }
    assert_eq!(bytes, summary.bytes);
    assert!(packages == seen, "the files hold what the tap saw, in order");
    assert_eq!(truth, (0..50).collect::<Vec<_>>());
    assert_eq!(summary.messages, (seen.len() + truth.len()) as u64);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// A package holding a shared value, as a world state holds its layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Labeled {
    labels: Shared<Vec<String>>,
    n: u64,
}

struct Talker {
    labels: Shared<Vec<String>>,
    out: Output<Labeled>,
    n: u64,
}

impl Module for Talker {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        self.n += 1;
        ctx.send(self.out, Labeled { labels: self.labels.clone(), n: self.n });
        Ok(())
    }
}

/// Writes a record on `marks` when it sees its first package, and again in each new file.
#[derive(Default)]
struct FirstOfEachFile {
    pending: bool,
    files: Arc<Mutex<u32>>,
}

impl Derive for FirstOfEachFile {
    fn wants(&mut self, _id: u32, topic: &str, _type_name: &str) -> bool {
        topic == "talker/out"
    }

    fn package(
        &mut self,
        _topic: u32,
        time: Time,
        _package: &dyn ErasedPackage,
        records: &mut DerivedRecords,
    ) {
        if std::mem::take(&mut self.pending) {
            records.record_value("marks", time, &"first".to_owned());
        }
    }

    fn next_file(&mut self) {
        self.pending = true;
        *self.files.lock().expect("not poisoned") += 1;
    }
}

#[test]
fn each_part_holds_its_shared_values_and_derived_records_again() {
    let dir = scratch("parts-shared");
    let path = dir.join("talk.mcap");
    let options = McapTapOptions {
        when_full: WhenFull::Wait,
        max_chunk_span: Duration::from_millis(50),
        max_file_size: Some(8 << 10),
        ..McapTapOptions::default()
    };
    let mut graph = GraphBuilder::new();
    let labels = Shared::new((0..20).map(|i| format!("label {i}")).collect::<Vec<_>>());
    graph.add("talker", |p| {
        p.trigger(Trigger::every(Duration::from_millis(5)));
        let out = p.output("out");
        (Talker { labels, out, n: 0 }, ())
    });
    let graph = graph.build().expect("graph");
    let log = Arc::new(McapTap::create(&path, options).expect("create"));
    log.write_graph("", &graph.describe()).expect("graph");
    let new_files = Arc::new(Mutex::new(0));
    log.set_derive(Box::new(FirstOfEachFile { pending: true, files: new_files.clone() }));
    let mut host = LockstepHost::new(graph, HostConfig::with_seed(SEED));
    host.set_tap(log.clone());
    host.run_until(Time::from_secs_f64(5.0)).expect("run");
    host.stop();
    let summary = log.finish().expect("finish");
    assert!(summary.files.len() >= 3, "{:?}", summary.files);
    assert_eq!(*new_files.lock().expect("not poisoned") as usize, summary.files.len() - 1);
    let mut n = Vec::new();
    for file in &summary.files {
        let reader = LogReader::open(file).expect("open");
        let count = |topic: &str| reader.topic(topic).map_or(0, |t| t.messages);
        assert_eq!(count("shared/Vec"), 1, "{}", file.display());
        assert_eq!(count("marks"), 1, "{}", file.display());
        assert_eq!(reader.graphs().expect("graph").len(), 1);
        for message in reader.messages_on(["talker/out"]) {
            let value = message.expect("readable").json().expect("json");
            n.push(value["n"].as_u64().expect("n"));
        }
    }
    assert_eq!(n, (1..=n.len() as u64).collect::<Vec<_>>());
    // A package every 5 ms from 0 to 5 s.
    assert_eq!(n.len(), 1001);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
