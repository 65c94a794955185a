//! Logs written from a lockstep run read back whole; logs cut short read back up to their last
//! complete chunk; `log info` describes both.

mod support;

use std::sync::Arc;
use std::time::Duration;

use strata_log::{
    Derive, DerivedRecords, LogCompression, LogError, LogInfo, LogReader, McapTap, McapTapOptions,
    RecordSchema, WhenFull,
};
use strata_runtime::{Encoding, ErasedPackage, HostConfig, Package, Tap as _, ThreadedHost, Time};
use support::{CONFIG, SEED, record_demo, scratch};

#[test]
fn round_trip_keeps_every_package_in_order() {
    let dir = scratch("round-trip");
    let path = dir.join("demo.mcap");
    let (seen, summary) = record_demo(&path, 5.0, McapTapOptions::default(), CONFIG);
    assert_eq!(summary.dropped, 0);
    assert_eq!(summary.serialize_errors, 0);
    // 50 ground-truth records besides the packages.
    assert_eq!(summary.messages, seen.len() as u64 + 50);
    assert_eq!(summary.topics, 4);

    let reader = LogReader::open(&path).expect("open");
    assert!(reader.is_complete());
    assert!(reader.recovery().is_none());
    assert_eq!(reader.message_count(), summary.messages);
    assert_eq!(reader.file_bytes(), summary.bytes);

    assert_holds_what_the_tap_saw(&reader, &seen);

    let truth: Vec<_> =
        reader.messages_on(["sim/ground_truth"]).map(|m| m.expect("readable")).collect();
    assert_eq!(truth.len(), 50);
    assert_eq!(truth[0].log_time, Time::from_secs_f64(0.1));
    assert_eq!(truth[49].seq, 49);
    assert_eq!(truth[1].json().expect("json")["ball"]["x"], 0.02);

    let filter = reader.topic("filter/estimate").expect("filter topic");
    assert_eq!(filter.type_name, std::any::type_name::<support::Estimate>());
    assert_eq!(filter.message_encoding, "cdr");
    assert_eq!(filter.schema_encoding.as_deref(), Some("omgidl"));
    // Application records have no type to describe: self-describing MessagePack.
    let truth_topic = reader.topic("sim/ground_truth").expect("truth topic");
    assert_eq!(truth_topic.message_encoding, "msgpack");
    let source = reader.topic("source/reading").expect("source topic");
    assert_eq!(source.messages, 501);

    let run = reader.run_info().expect("run info").expect("present");
    assert_eq!(run.seed, SEED);
    assert_eq!(run.config.as_ref().map(|c| c.1.as_str()), Some(CONFIG));
    assert_eq!(reader.config().expect("config"), Some(support::config_value()));
    let graphs = reader.graphs().expect("graphs");
    assert_eq!(graphs.len(), 1);
    assert_eq!(graphs[0].scope, "");
    let names: Vec<&str> = graphs[0].description.modules.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["source", "filter", "monitor"]);
    let stats = reader.stats().expect("writer statistics");
    assert_eq!(stats.messages, summary.messages);
    assert_eq!(stats.dropped, 0);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn uncompressed_and_lz4_logs_read_back_the_same() {
    let dir = scratch("compression");
    let mut contents = Vec::new();
    for compression in [LogCompression::None, LogCompression::Lz4, LogCompression::Zstd] {
        let path = dir.join(format!("{compression:?}.mcap"));
        let options = McapTapOptions { compression, ..McapTapOptions::default() };
        record_demo(&path, 1.0, options, CONFIG);
        let reader = LogReader::open(&path).expect("open");
        let messages: Vec<_> =
            reader.messages().map(|m| m.expect("readable")).map(|m| (m.topic, m.data)).collect();
        contents.push(messages);
    }
    assert_eq!(contents[0], contents[1]);
    assert_eq!(contents[0], contents[2]);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// Message counts of the chunks of a complete file, and where each chunk ends, read with the
/// `mcap` crate's own summary reader (independently of `LogReader`).
fn chunk_ends_and_counts(bytes: &[u8]) -> Vec<(u64, u64)> {
    let summary = mcap::Summary::read(bytes).expect("summary").expect("present");
    let mut chunks: Vec<(u64, u64)> = summary
        .chunk_indexes
        .iter()
        .map(|index| {
            let count = summary.stream_chunk(bytes, index).expect("chunk").count() as u64;
            (index.chunk_start_offset + index.chunk_length, count)
        })
        .collect();
    chunks.sort_unstable();
    chunks
}

#[test]
fn a_truncated_log_recovers_its_complete_chunks() {
    let dir = scratch("truncated");
    let path = dir.join("full.mcap");
    // Short chunks, so cuts land between and inside many of them.
    let options =
        McapTapOptions { max_chunk_span: Duration::from_millis(100), ..Default::default() };
    let (_, summary) = record_demo(&path, 3.0, options, CONFIG);
    let bytes = std::fs::read(&path).expect("read");
    let chunks = chunk_ends_and_counts(&bytes);
    assert!(chunks.len() >= 20, "{} chunks", chunks.len());
    assert_eq!(chunks.iter().map(|c| c.1).sum::<u64>(), summary.messages);

    let mut cuts: Vec<usize> = (0..bytes.len()).step_by(997).collect();
    for &(end, _) in chunks.iter().take(6) {
        let end = end as usize;
        cuts.extend([end - 1, end, end + 1]);
    }
    cuts.extend([0, 1, 7, 8, 9, 16, bytes.len() - 1, bytes.len() - 8, bytes.len() - 30]);
    let cut_path = dir.join("cut.mcap");
    for cut in cuts {
        std::fs::write(&cut_path, &bytes[..cut]).expect("write cut");
        match LogReader::open(&cut_path) {
            Err(LogError::NotMcap { .. }) => assert!(cut < 8, "cut at {cut} not recognized"),
            Err(error) => panic!("cut at {cut}: {error}"),
            Ok(reader) => {
                let expected: u64 =
                    chunks.iter().filter(|(end, _)| *end as usize <= cut).map(|c| c.1).sum();
                assert!(!reader.is_complete(), "cut at {cut} looks complete");
                let recovery = reader.recovery().expect("recovery report");
                assert_eq!(recovery.messages, expected, "cut at {cut}");
                assert_eq!(reader.message_count(), expected, "cut at {cut}");
                let read = reader.messages().filter(Result::is_ok).count() as u64;
                assert_eq!(read, expected, "cut at {cut}");
                // Metadata precedes the first chunk: a file with a chunk has its graph.
                if expected > 0 {
                    assert_eq!(reader.graphs().expect("graph").len(), 1);
                    assert!(reader.run_info().expect("run").is_some());
                }
                let info = LogInfo::of(&reader);
                assert!(!info.complete);
                assert!(info.to_string().contains("TRUNCATED"), "{info}");
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn damaged_bytes_give_errors_or_partial_results_never_panics() {
    let dir = scratch("damaged");
    let path = dir.join("full.mcap");
    let options =
        McapTapOptions { max_chunk_span: Duration::from_millis(100), ..Default::default() };
    record_demo(&path, 1.0, options, CONFIG);
    let bytes = std::fs::read(&path).expect("read");
    let damaged_path = dir.join("damaged.mcap");
    // Every few bytes, headers, metadata, attachment, chunks and summary alike.
    for position in (0..bytes.len()).step_by(bytes.len() / 700 + 1) {
        let mut damaged = bytes.clone();
        damaged[position] ^= 0x5a;
        std::fs::write(&damaged_path, &damaged).expect("write");
        if let Ok(reader) = LogReader::open(&damaged_path) {
            let _ = LogInfo::of(&reader).to_string();
            let _ = reader.graphs();
            let _ = reader.config();
            let _ = reader.messages().take_while(Result::is_ok).count();
        }
    }
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// A message by topic and (32-bit) sequence number.
type Sent = (String, u32);

/// A chunk of a complete file: where it starts and ends, and the messages it holds.
struct Chunk {
    start: u64,
    end: u64,
    messages: Vec<Sent>,
}

/// The chunks of a complete file in file order, read with the `mcap` crate (independently of
/// `LogReader`).
fn chunk_contents(bytes: &[u8]) -> Vec<Chunk> {
    let summary = mcap::Summary::read(bytes).expect("summary").expect("present");
    let mut chunks: Vec<Chunk> = summary
        .chunk_indexes
        .iter()
        .map(|index| Chunk {
            start: index.chunk_start_offset,
            end: index.chunk_start_offset + index.chunk_length,
            messages: summary
                .stream_chunk(bytes, index)
                .expect("chunk")
                .map(|m| m.expect("message"))
                .map(|m| (m.channel.topic.clone(), m.sequence))
                .collect(),
        })
        .collect();
    chunks.sort_unstable_by_key(|c| c.start);
    chunks
}

/// The messages of every chunk but the `lost` ones, in order.
fn messages_but(chunks: &[Chunk], lost: &[usize]) -> Vec<Sent> {
    let kept = chunks.iter().enumerate().filter(|(k, _)| !lost.contains(k));
    kept.flat_map(|(_, c)| c.messages.iter().cloned()).collect()
}

fn set_u64(bytes: &mut [u8], at: usize, value: u64) {
    bytes[at..at + 8].copy_from_slice(&value.to_le_bytes());
}

/// The messages `LogReader` reads from `path`.
fn read_back(path: &std::path::Path) -> Vec<Sent> {
    let reader = LogReader::open(path).expect("open");
    reader
        .messages()
        .map(|m| m.expect("readable"))
        .map(|m| (m.topic.to_string(), m.seq as u32))
        .collect()
}

/// Damage done to a file: the file, where the chunk's length is, its length.
type Damage = fn(&mut [u8], usize, u64);

#[test]
fn recovery_passes_over_a_damaged_chunk_and_reads_on() {
    let dir = scratch("skip-damaged");
    let path = dir.join("full.mcap");
    let options =
        McapTapOptions { max_chunk_span: Duration::from_millis(100), ..Default::default() };
    record_demo(&path, 2.0, options, CONFIG);
    let bytes = std::fs::read(&path).expect("read");
    let chunks = chunk_contents(&bytes);
    assert!(chunks.len() >= 10, "{} chunks", chunks.len());
    // Chunk 0 defines the channels; chunk 3 is in the middle, with good chunks on both sides.
    let (bad, next) = (&chunks[3], &chunks[4]);
    let expected = messages_but(&chunks, &[3]);
    let damaged_path = dir.join("damaged.mcap");
    let length_at = bad.start as usize + 1;
    let length = u64::from_le_bytes(bytes[length_at..length_at + 8].try_into().expect("8 bytes"));
    // Without its footer (killed before finishing), the file is scanned. The damage: inside
    // the chunk's compressed records (its CRC or its decompression fails); in its length, which
    // then ends it early (its records are cut) or past the end of the file (the next chunk is
    // found by its header either way).
    let damages: [(&str, Damage); 3] = [
        ("records", |file, at, _| file[at + 100] ^= 0x5a),
        ("length short", |file, at, length| set_u64(file, at, length - 20)),
        ("length past the end", |file, at, length| set_u64(file, at, length + (1 << 40))),
    ];
    for (what, damage) in damages {
        let mut damaged = bytes[..bytes.len() - 8].to_vec();
        damage(&mut damaged, length_at, length);
        std::fs::write(&damaged_path, &damaged).expect("write");
        let reader = LogReader::open(&damaged_path).expect("open");
        let recovery = reader.recovery().expect("scanned").clone();
        assert_eq!(recovery.skipped_chunks, 1, "{what}: {}", recovery.stopped);
        // From the damaged chunk to the next good one: the chunk and its message indexes.
        assert_eq!(recovery.skipped_bytes, next.start - bad.start, "{what}");
        assert_eq!(recovery.chunks, chunks.len() - 1, "{what}");
        assert_eq!(recovery.messages, expected.len() as u64, "{what}");
        let first = format!("the first at byte {}", bad.start);
        assert!(recovery.stopped.contains(&first), "{what}: {}", recovery.stopped);
        assert_eq!(read_back(&damaged_path), expected, "{what}");
        // The writer's statistics come after the last chunk: read too.
        assert!(reader.stats().is_some(), "{what}");
        let text = LogInfo::of(&reader).to_string();
        assert!(text.contains("skipped 1 damaged chunks"), "{text}");
    }
    // A length that ends the chunk past its records but inside the file: the chunk reads
    // (MCAP records may carry bytes after their fields), and the scan finds the next chunk
    // by its header, past the message indexes the length ran into.
    let mut damaged = bytes[..bytes.len() - 8].to_vec();
    set_u64(&mut damaged, length_at, length + 20);
    std::fs::write(&damaged_path, &damaged).expect("write");
    let reader = LogReader::open(&damaged_path).expect("open");
    let recovery = reader.recovery().expect("scanned");
    let read = (recovery.skipped_chunks, recovery.chunks);
    assert_eq!(read, (0, chunks.len()), "{}", recovery.stopped);
    assert!(recovery.skipped_bytes > 0 && recovery.skipped_bytes < next.start - bad.end);
    assert_eq!(read_back(&damaged_path), messages_but(&chunks, &[]));
    // Two damaged chunks in a row, and one further on: each is counted, the rest is read.
    let mut damaged = bytes[..bytes.len() - 8].to_vec();
    for k in [3, 4, 7] {
        damaged[((chunks[k].start + chunks[k].end) / 2) as usize] ^= 0x5a;
    }
    std::fs::write(&damaged_path, &damaged).expect("write");
    let reader = LogReader::open(&damaged_path).expect("open");
    let recovery = reader.recovery().expect("scanned");
    assert_eq!(recovery.skipped_chunks, 3, "{}", recovery.stopped);
    let stretches = (chunks[5].start - chunks[3].start) + (chunks[8].start - chunks[7].start);
    assert_eq!(recovery.skipped_bytes, stretches);
    assert_eq!(read_back(&damaged_path), messages_but(&chunks, &[3, 4, 7]));
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn log_info_describes_complete_and_truncated_files() {
    let dir = scratch("info");
    let path = dir.join("demo.mcap");
    let options =
        McapTapOptions { max_chunk_span: Duration::from_millis(100), ..Default::default() };
    let (_, summary) = record_demo(&path, 2.0, options, CONFIG);
    let info = LogInfo::of(&LogReader::open(&path).expect("open"));
    assert!(info.complete);
    assert_eq!(info.messages, summary.messages);
    assert_eq!(info.seed, Some(SEED));
    assert!((info.duration_s() - 1.99).abs() < 0.02, "{}", info.duration_s());
    let topics: Vec<(&str, u64)> =
        info.topics.iter().map(|t| (t.name.as_str(), t.messages)).collect();
    assert_eq!(topics.len(), 4);
    assert!(topics.contains(&("source/reading", 201)));
    assert!(topics.contains(&("sim/ground_truth", 20)));
    assert_eq!(info.writer.as_ref().map(|w| w.dropped), Some(0));
    let metadata: Vec<&str> = info.metadata.iter().map(|(name, _)| name.as_str()).collect();
    assert_eq!(metadata, ["strata.run", "strata.graph", "strata.log_stats"]);
    let text = info.to_string();
    assert!(text.contains("status:    complete"), "{text}");
    assert!(text.contains("source/reading"), "{text}");
    assert!(text.contains("0 dropped"), "{text}");
    assert!(text.contains("strata.graph: graph, scope"), "{text}");

    let bytes = std::fs::read(&path).expect("read");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).expect("write");
    let info = LogInfo::of(&LogReader::open(&cut).expect("open"));
    assert!(!info.complete);
    let recovered = info.recovery.as_ref().map(|r| r.messages).expect("recovery");
    assert!(recovered > 0 && recovered < summary.messages);
    let text = info.to_string();
    assert!(text.contains(&format!("TRUNCATED: recovered {recovered} messages")), "{text}");
    assert!(text.contains("not finished"), "{text}");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn the_threaded_host_logs_through_the_same_tap() {
    let dir = scratch("threaded");
    let path = dir.join("threaded.mcap");
    let config = support::config_value();
    let graph = support::demo_graph("", &config);
    let log = Arc::new(McapTap::create(&path, McapTapOptions::default()).expect("create"));
    log.write_graph("", &graph.describe()).expect("graph");
    let mut host = ThreadedHost::new(graph, HostConfig::with_seed(SEED));
    host.set_tap(log.clone());
    let running = host.start().expect("start");
    running.run_for(Duration::from_millis(300)).expect("run");
    let summary = log.finish().expect("finish");
    let reader = LogReader::open(&path).expect("open");
    assert!(reader.is_complete());
    assert_eq!(reader.message_count(), summary.messages);
    assert!(summary.messages > 0);
    // Each output's packages keep their order.
    for topic in ["source/reading", "filter/estimate", "monitor/status"] {
        let seqs: Vec<u64> = reader.messages_on([topic]).map(|m| m.expect("ok").seq).collect();
        assert!(seqs.windows(2).all(|w| w[0] < w[1]), "{topic}: {seqs:?}");
    }
    // Finishing twice returns the same summary; later packages are counted, not written.
    assert_eq!(log.finish().expect("again"), summary);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn a_file_that_is_not_mcap_is_an_error() {
    let dir = scratch("not-mcap");
    let path = dir.join("notes.txt");
    std::fs::write(&path, "hello, this is not a log").expect("write");
    assert!(matches!(LogReader::open(&path), Err(LogError::NotMcap { .. })));
    assert!(matches!(LogReader::open(dir.join("missing.mcap")), Err(LogError::Open { .. })));
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

#[test]
fn every_message_is_an_object_with_an_object_schema_for_generic_tools() {
    let dir = scratch("generic");
    for encoding in [Encoding::MessagePack, Encoding::Json] {
        let options = McapTapOptions { encoding, ..McapTapOptions::default() };
        let path = dir.join(format!("demo-{}.mcap", encoding.mcap_name()));
        let (_, _) = record_demo(&path, 0.5, options.clone(), CONFIG);
        // Add values that are not objects: they are wrapped in the file, unwrapped when read.
        let scalars = dir.join(format!("scalars-{}.mcap", encoding.mcap_name()));
        let log = McapTap::create(&scalars, options).expect("create");
        log.record_value("game/score", Time::from_nanos(5), &(2u8, 1u8));
        log.record_value("game/phase", Time::from_nanos(6), &"Playing".to_owned());
        log.record("game/clock", "f64", Time::from_nanos(7), &serde_json::json!(599.5));
        log.finish().expect("finish");

        for file in [&path, &scalars] {
            // Read with the `mcap` crate and a decoder of the channel's encoding alone, as a
            // generic tool would.
            let bytes = std::fs::read(file).expect("read");
            let mut messages = 0;
            for message in mcap::MessageStream::new(&bytes).expect("stream") {
                let message = message.expect("message");
                assert_eq!(message.channel.message_encoding, encoding.mcap_name());
                let schema = message.channel.schema.as_ref().expect("a schema");
                assert_eq!(schema.encoding, "jsonschema");
                let schema: serde_json::Value =
                    serde_json::from_slice(&schema.data).expect("schema");
                assert_eq!(schema["type"], "object", "{}", message.channel.topic);
                assert_eq!(schema["title"], schema_name(&message), "{}", message.channel.topic);
                let value: serde_json::Value = match encoding {
                    Encoding::Json => serde_json::from_slice(&message.data).expect("json"),
                    Encoding::MessagePack => rmp_serde::from_slice(&message.data).expect("msgpack"),
                    Encoding::Cdr => unreachable!("self-describing encodings only"),
                };
                assert!(value.is_object(), "{}: {value}", message.channel.topic);
                messages += 1;
            }
            assert!(messages > 0);
        }
        let reader = LogReader::open(&scalars).expect("open");
        let values: Vec<(String, String)> = reader
            .messages()
            .map(|m| m.expect("ok"))
            .map(|m| (m.topic.to_string(), m.json().expect("decodes").to_string()))
            .collect();
        assert_eq!(
            values,
            [
                ("game/score".to_owned(), "[2,1]".to_owned()),
                ("game/phase".to_owned(), "\"Playing\"".to_owned()),
                ("game/clock".to_owned(), "599.5".to_owned()),
            ]
        );
    }
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

fn schema_name(message: &mcap::Message<'_>) -> String {
    message.channel.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default()
}

#[test]
fn chosen_modules_only_are_logged() {
    let dir = scratch("chosen");
    let path = dir.join("chosen.mcap");
    let config = support::config_value();
    let graph = support::demo_graph("r1/", &config);
    let options = McapTapOptions { modules: vec!["r1/filter".to_owned()], ..Default::default() };
    let log = Arc::new(McapTap::create(&path, options).expect("create"));
    // The host does not even show the log the other modules' packages.
    let output = |module_name| strata_runtime::TapOutput {
        host: 0,
        module: strata_runtime::ModuleId(0),
        module_name,
        port: 0,
        output: "estimate",
        type_name: "demo::Estimate",
    };
    assert!(log.wants(&output("r1/filter")));
    assert!(!log.wants(&output("r1/sensor")));
    let mut host = strata_runtime::LockstepHost::new(graph, HostConfig::with_seed(SEED));
    host.set_tap(log.clone());
    host.run_until(Time::from_secs_f64(1.0)).expect("run");
    log.record("sim/ground_truth", "demo::GroundTruth", Time::ZERO, &serde_json::json!({}));
    log.finish().expect("finish");
    let reader = LogReader::open(&path).expect("open");
    let topics: Vec<&str> = reader.topics().iter().map(|t| t.name.as_str()).collect();
    assert_eq!(topics, ["r1/filter/estimate", "sim/ground_truth"]);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// In wait mode a sender that finds the queue full waits for the writer: through a queue of
/// four, the file still holds every package, in order.
#[test]
fn a_tiny_queue_in_wait_mode_loses_nothing() {
    let dir = scratch("sender-encodes");
    let path = dir.join("tiny-queue.mcap");
    let options =
        McapTapOptions { capacity: 4, when_full: WhenFull::Wait, ..McapTapOptions::default() };
    let (seen, summary) = record_demo(&path, 2.0, options, CONFIG);
    assert_eq!((summary.dropped, summary.serialize_errors), (0, 0));
    let reader = LogReader::open(&path).expect("open");
    assert_holds_what_the_tap_saw(&reader, &seen);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// The lockstep host reaches a log through its sender (a batch of the host's own, no lock per
/// package), which it flushes when each run returns: the file holds what the log written
/// through the tap itself holds, in the same order, application records between runs
/// included.
#[test]
fn a_log_written_through_the_host_sender_is_the_same() {
    let dir = scratch("sender");
    let options = || McapTapOptions { when_full: WhenFull::Wait, ..McapTapOptions::default() };
    let through_tap = dir.join("tap.mcap");
    record_demo(&through_tap, 2.0, options(), CONFIG);

    let through_sender = dir.join("sender.mcap");
    let graph = support::demo_graph("", &support::config_value());
    let log = Arc::new(McapTap::create(&through_sender, options()).expect("create"));
    let mut host = strata_runtime::LockstepHost::new(graph, HostConfig::with_seed(SEED));
    host.set_tap(log.clone());
    for step in 1..=20u64 {
        let t = Time::from_nanos(step * 100_000_000);
        host.run_until(t).expect("run");
        let truth = serde_json::json!({ "ball": { "x": step as f64 * 0.01, "y": 0.0 } });
        log.record("sim/ground_truth", "demo::GroundTruth", t, &truth);
    }
    let summary = log.finish().expect("finish");
    assert_eq!((summary.dropped, summary.serialize_errors), (0, 0));

    let read = |path: &std::path::Path| -> Vec<_> {
        let reader = LogReader::open(path).expect("open");
        let messages = reader.messages().map(|m| m.expect("readable"));
        messages.map(|m| (m.topic, m.log_time, m.stamp, m.seq, m.data)).collect()
    };
    let (expected, written) = (read(&through_tap), read(&through_sender));
    assert!(expected.len() > 500);
    assert!(written == expected, "the logs differ");
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// An application record of a Rust type goes in CDR with its type's OMG IDL schema, like a
/// package, so that generic tools decode it; one without a type to trace, or of a type CDR
/// cannot describe, in MessagePack with a JSON Schema.
#[test]
fn typed_application_records_are_cdr_with_an_idl_schema() {
    #[derive(serde::Serialize, serde::Deserialize, Debug, PartialEq)]
    struct Score {
        home: u8,
        away: u8,
        phase: String,
        clock: Option<f64>,
    }
    let dir = scratch("typed-records");
    let path = dir.join("records.mcap");
    let log = McapTap::create(&path, McapTapOptions::default()).expect("create");
    let score = Score { home: 2, away: 1, phase: "playing".to_owned(), clock: Some(599.5) };
    log.record_value("game/score", Time::from_nanos(5), &score);
    log.record_value("game/untyped", Time::from_nanos(6), &serde_json::json!({ "a": 1 }));
    log.record("game/clock", "f64", Time::from_nanos(7), &serde_json::json!(599.5));
    let summary = log.finish().expect("finish");
    assert_eq!((summary.messages, summary.serialize_errors), (3, 0));

    let bytes = std::fs::read(&path).expect("read");
    let mut channels = Vec::new();
    for message in mcap::MessageStream::new(&bytes).expect("stream") {
        let message = message.expect("message");
        let schema = message.channel.schema.as_ref().expect("a schema");
        channels.push((
            message.channel.topic.clone(),
            message.channel.message_encoding.clone(),
            schema.encoding.clone(),
        ));
        if message.channel.topic == "game/score" {
            let idl = String::from_utf8_lossy(&schema.data);
            assert!(idl.contains("struct Score"), "{idl}");
        }
    }
    let expected = |topic: &str, encoding: &str, schema: &str| {
        (topic.to_owned(), encoding.to_owned(), schema.to_owned())
    };
    assert_eq!(
        channels,
        [
            expected("game/score", "cdr", "omgidl"),
            expected("game/untyped", "msgpack", "jsonschema"),
            expected("game/clock", "msgpack", "jsonschema"),
        ]
    );

    let reader = LogReader::open(&path).expect("open");
    let messages: Vec<_> = reader.messages().map(|m| m.expect("readable")).collect();
    assert_eq!(messages[0].decode::<Score>().expect("decodes"), score);
    assert_eq!(messages[0].json().expect("json")["clock"], 599.5);
    assert_eq!(messages[1].json().expect("json"), serde_json::json!({ "a": 1 }));
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// Records the sample count of every second estimate it is shown, and which topics it was
/// asked about.
struct EvenSamples {
    asked: Arc<std::sync::Mutex<Vec<String>>>,
    estimates: Option<u32>,
}

impl Derive for EvenSamples {
    fn wants(&mut self, id: u32, topic: &str, _type_name: &str) -> bool {
        self.asked.lock().expect("not poisoned").push(topic.to_owned());
        let wanted = topic == "filter/estimate";
        if wanted {
            self.estimates = Some(id);
        }
        wanted
    }

    fn package(
        &mut self,
        topic: u32,
        time: Time,
        package: &dyn ErasedPackage,
        records: &mut DerivedRecords,
    ) {
        assert_eq!(Some(topic), self.estimates, "shown a package of a topic it did not want");
        let estimate = package
            .as_any()
            .downcast_ref::<Package<support::Estimate>>()
            .expect("the estimate, whole");
        if estimate.value.samples % 2 == 0 {
            let record = serde_json::json!({ "samples": estimate.value.samples });
            records.record_value("derived/even_samples", time, &record);
        }
    }
}

/// A log's derived records are made on the writer thread from the packages of the topics the
/// deriver wants (whole, even where a waiting sender would encode them itself), and each is
/// written just ahead of the package it comes from.
#[test]
fn derived_records_come_just_ahead_of_their_package() {
    let dir = scratch("derive");
    let path = dir.join("derived.mcap");
    let graph = support::demo_graph("", &support::config_value());
    let options = McapTapOptions { when_full: WhenFull::Wait, ..McapTapOptions::default() };
    let log = Arc::new(McapTap::create(&path, options).expect("create"));
    let asked = Arc::default();
    log.set_derive(Box::new(EvenSamples { asked: Arc::clone(&asked), estimates: None }));
    let mut host = strata_runtime::LockstepHost::new(graph, HostConfig::with_seed(SEED));
    host.set_tap(log.clone());
    host.run_until(Time::from_secs_f64(2.0)).expect("run");
    let summary = log.finish().expect("finish");
    assert_eq!((summary.dropped, summary.serialize_errors), (0, 0));

    let mut asked = asked.lock().expect("not poisoned").clone();
    asked.sort();
    assert_eq!(asked, ["filter/estimate", "monitor/status", "source/reading"]);

    let reader = LogReader::open(&path).expect("open");
    let messages: Vec<_> = reader.messages().map(|m| m.expect("readable")).collect();
    let mut derived = 0;
    let mut even = 0;
    for (i, message) in messages.iter().enumerate() {
        match &*message.topic {
            "derived/even_samples" => {
                derived += 1;
                let next = messages.get(i + 1).expect("the package after its record");
                assert_eq!(&*next.topic, "filter/estimate");
                assert_eq!(next.log_time, message.log_time);
                let samples = &next.json().expect("estimate")["samples"];
                assert_eq!(message.json().expect("record")["samples"], *samples);
            }
            "filter/estimate" => {
                let samples = message.json().expect("estimate")["samples"].as_u64();
                if samples.expect("a count") % 2 == 0 {
                    even += 1;
                }
            }
            _ => {}
        }
    }
    assert!(even > 10, "{even} estimates with an even count");
    assert_eq!(derived, even);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// Records each estimate's sample count as a message of a schema of its own, given by name
/// and JSON Schema text (as Foxglove's `foxglove.Log` is).
struct NamedSamples;

const SAMPLES_SCHEMA: RecordSchema = RecordSchema {
    name: "demo.Samples",
    json_schema: r#"{"title":"demo.Samples","type":"object","properties":{"samples":{"type":"integer"}}}"#,
};

impl Derive for NamedSamples {
    fn wants(&mut self, _id: u32, topic: &str, _type_name: &str) -> bool {
        topic == "filter/estimate"
    }

    fn package(
        &mut self,
        _topic: u32,
        time: Time,
        package: &dyn ErasedPackage,
        records: &mut DerivedRecords,
    ) {
        if let Some(estimate) = package.as_any().downcast_ref::<Package<support::Estimate>>() {
            let record = serde_json::json!({ "samples": estimate.value.samples });
            records.record_json("derived/samples", time, SAMPLES_SCHEMA, &record);
        }
    }
}

/// A derived record with a named schema is JSON on a channel with that schema (encoding
/// `jsonschema`), whatever the log's encoding of packages (CDR here); a new file of a log
/// split at its size cap defines the channel and schema again.
#[test]
fn derived_records_with_a_named_schema_are_json_with_that_schema() {
    let dir = scratch("derive-named");
    let path = dir.join("named.mcap");
    let graph = support::demo_graph("", &support::config_value());
    let options = McapTapOptions {
        when_full: WhenFull::Wait,
        max_file_size: Some(20_000),
        ..McapTapOptions::default()
    };
    let log = Arc::new(McapTap::create(&path, options).expect("create"));
    log.set_derive(Box::new(NamedSamples));
    let mut host = strata_runtime::LockstepHost::new(graph, HostConfig::with_seed(SEED));
    host.set_tap(log.clone());
    host.run_until(Time::from_secs_f64(2.0)).expect("run");
    let summary = log.finish().expect("finish");
    assert_eq!((summary.dropped, summary.serialize_errors), (0, 0));
    assert!(summary.files.len() > 1, "{:?}", summary.files);

    for file in &summary.files {
        let bytes = std::fs::read(file).expect("read");
        let mut named = 0;
        for message in mcap::MessageStream::new(&bytes).expect("stream") {
            let message = message.expect("message");
            if message.channel.topic != "derived/samples" {
                continue;
            }
            named += 1;
            assert_eq!(message.channel.message_encoding, "json");
            let schema = message.channel.schema.as_ref().expect("a schema");
            assert_eq!(
                (schema.name.as_str(), schema.encoding.as_str()),
                ("demo.Samples", "jsonschema")
            );
            assert_eq!(&*schema.data, SAMPLES_SCHEMA.json_schema.as_bytes());
            let value: serde_json::Value = serde_json::from_slice(&message.data).expect("JSON");
            assert!(value["samples"].is_u64(), "{value}");
        }
        assert!(named > 0, "{} holds no named record", file.display());
    }
    let reader = LogReader::open(&summary.files[0]).expect("open");
    let first = reader
        .messages()
        .map(|m| m.expect("readable"))
        .find(|m| &*m.topic == "derived/samples")
        .expect("a record");
    assert!(first.json().expect("json")["samples"].is_u64());
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}

/// The log's packages (everything but the ground-truth records) are exactly what the tap saw,
/// in order.
fn assert_holds_what_the_tap_saw(reader: &LogReader, seen: &[support::SeenPackage]) {
    let packages: Vec<_> = reader
        .messages()
        .map(|m| m.expect("readable"))
        .filter(|m| &*m.topic != "sim/ground_truth")
        .map(|m| (m.topic.to_string(), m.log_time, m.stamp, m.seq, m.data))
        .collect();
    assert_eq!(packages.len(), seen.len());
    assert!(packages == seen, "the log differs from what the tap saw");
}

#[test]
fn a_chunk_whose_records_overrun_it_is_refused_not_a_panic() {
    // Found by the `log_reader` fuzz target: a footer whose summary offset points at an
    // uncompressed chunk whose last record runs past the chunk's end. mcap's reader panicked
    // on it (overflow check) before the reader checked the chunk itself.
    let (stopped, _) =
        open_damaged("chunk-overrun", include_bytes!("data/chunk_overrun_in_summary.bin"));
    assert!(stopped.contains("overruns"), "{stopped}");
}

/// Opens a damaged log written from `bytes`, which must be read by scanning, and reads every
/// message's JSON: why the scan stopped, and how many messages the log holds.
fn open_damaged(name: &str, bytes: &[u8]) -> (String, u64) {
    let dir = scratch(name);
    let path = dir.join("damaged.mcap");
    std::fs::write(&path, bytes).expect("write");
    let reader = LogReader::open(&path).expect("scanned like a file without a summary");
    let stopped = reader.recovery().expect("read by scanning").stopped.clone();
    for message in reader.messages() {
        let _ = message.map(|m| m.json());
    }
    std::fs::remove_dir_all(&dir).unwrap_or_default();
    (stopped, reader.message_count())
}

#[test]
fn a_summary_chunk_running_past_the_end_of_the_file_is_refused_not_a_panic() {
    // Found by the `log_reader` fuzz target: the footer points at a chunk whose record claims
    // 4 bytes more than the file holds; inside it, 5 bytes of uncompressed records whose first
    // record claims 40. mcap's summary reader streamed it and panicked (overflow check) taking
    // 49 bytes off 5; the chunk check passed it over, having no whole record to check.
    const MAGIC: &[u8] = b"\x89MCAP0\r\n";
    let mut chunk = Vec::new();
    chunk.extend_from_slice(&[0u8; 8 + 8 + 8 + 4]); // times, uncompressed size and CRC
    chunk.extend_from_slice(&0u32.to_le_bytes()); // compression "": none
    chunk.extend_from_slice(&5u64.to_le_bytes()); // records: 5 bytes
    chunk.push(0x05); // a message...
    chunk.extend_from_slice(&40u64.to_le_bytes()); // ...of 40 bytes
    chunk.extend_from_slice(&[0u8; 60]);
    let mut file = MAGIC.to_vec();
    file.push(0x06);
    file.extend_from_slice(&150u64.to_le_bytes()); // 4 bytes past the end of the file
    file.extend_from_slice(&chunk);
    file.push(0x02); // footer: summary at byte 8, no summary offsets, no CRC
    file.extend_from_slice(&20u64.to_le_bytes());
    file.extend_from_slice(&8u64.to_le_bytes());
    file.extend_from_slice(&0u64.to_le_bytes());
    file.extend_from_slice(&0u32.to_le_bytes());
    file.extend_from_slice(MAGIC);

    let (stopped, messages) = open_damaged("summary-past-end", &file);
    assert!(stopped.contains("runs past the footer"), "{stopped}");
    assert_eq!(messages, 0);
}

#[test]
fn a_footer_with_a_wrong_length_still_has_its_summary_checked() {
    // Found by the `log_reader` fuzz target: the footer's length field says 2068 bytes, more
    // than the file holds, and its summary is an uncompressed chunk whose only record overruns
    // it. mcap reads a footer's fixed 20 bytes whatever the length says, followed the summary
    // offset and panicked (overflow check) in that chunk; the check of summary chunks had
    // passed over a footer it could not read whole.
    let bytes = include_bytes!("data/summary_behind_a_long_footer.bin");
    let (stopped, _) = open_damaged("long-footer", bytes);
    assert!(stopped.contains("overruns"), "{stopped}");
}
