//! Shared by the logging and viewer tests: recording a short match, a scratch directory, and a
//! minimal HTTP client for the viewer's endpoints.

#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use strata_games::logging::{LogSettings, MatchLog};
use strata_games::matches::{Match, MatchConfig};
use strata_runtime::Tap;
use strata_sim::NoiseLevel;

/// A fresh directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("strata-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch directory");
    dir
}

/// A tool a test needs from outside the repository, when `found`; otherwise the test is
/// skipped with `why` printed — unless `./scripts/test` set `required` (it installs the
/// tools, so a missing one there is a failure, not a skip).
pub fn required_tool<T>(found: Option<T>, required: &str, test: &str, why: &str) -> Option<T> {
    if found.is_none() {
        assert!(std::env::var_os(required).is_none(), "{required} is set but {why}");
        eprintln!("SKIPPED {test}: {why} (./scripts/test installs it)");
    }
    found
}

/// Plays `seconds` of a `players`-a-side match with `seed` on the lockstep host, logged with
/// `settings` (and seen by `extra`, if given).
pub fn record_match(
    settings: &LogSettings,
    players: u8,
    seconds: f64,
    seed: u64,
    extra: Option<Arc<dyn Tap>>,
) {
    let config = MatchConfig {
        players,
        seed,
        limit: Some(seconds),
        noise: NoiseLevel::Default,
        // Seconds-long recordings need robots that move from the start: without
        // GameController3's delays Ready begins after 2 s, not after 12 s of Initial and
        // Standby.
        no_delay: true,
        ..MatchConfig::default()
    };
    let mut game = Match::new(config).expect("match");
    let log = MatchLog::attach(&mut game, settings).expect("log");
    if let Some(tap) = extra {
        game.add_tap(tap);
    }
    game.play(&mut |_, _| {}).expect("play");
    let summary = log.finish().expect("finish");
    assert_eq!(summary.dropped, 0);
}

/// GET `url` (`http://127.0.0.1:PORT/path`): the status and body.
pub fn get(url: &str) -> (u16, String) {
    let rest = url.strip_prefix("http://").expect("an http URL");
    let (host, path) =
        rest.split_once('/').map_or((rest, "/".to_owned()), |(h, p)| (h, format!("/{p}")));
    let mut stream = TcpStream::connect(host).expect("connect");
    stream.set_read_timeout(Some(Duration::from_secs(60))).expect("timeout");
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n")
        .expect("send");
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("read");
    let (head, body) = response.split_once("\r\n\r\n").expect("a response head");
    let status =
        head.split_whitespace().nth(1).and_then(|s| s.parse().ok()).expect("a status code");
    (status, body.to_owned())
}

/// GET `url`, expecting `200` and JSON.
pub fn get_json(url: &str) -> serde_json::Value {
    let (status, body) = get(url);
    assert_eq!(status, 200, "{url}: {body}");
    serde_json::from_str(&body).unwrap_or_else(|e| panic!("{url}: {e}: {body}"))
}
