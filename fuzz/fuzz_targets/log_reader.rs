//! Any bytes as a log file: the log reader (crates/log/src/reader) opens it or says why not,
//! never panics, and every message of a log it opens decodes to JSON or to an error.
//!
//! The viewer and `strata log` open any file a user names, so a damaged or hostile file must
//! cost an error, not the process. The reader takes a path: each input is written to one
//! temporary file per fuzzing process.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use strata_log::LogReader;

fn scratch() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        std::env::temp_dir().join(format!("strata-fuzz-log-{}.mcap", std::process::id()))
    })
}

fuzz_target!(|bytes: &[u8]| {
    let path = scratch();
    if std::fs::write(path, bytes).is_err() {
        return;
    }
    let Ok(reader) = LogReader::open(path) else { return };
    let _ = reader.run_info();
    let _ = reader.config();
    let _ = reader.graphs();
    let _ = reader.stats();
    for message in reader.messages().take(10_000).flatten() {
        let _ = message.json();
    }
});
