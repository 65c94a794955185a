//! The viewer in a real browser: a short match is recorded, `strata view`'s server is started on
//! it, and Debian's headless Chromium loads the page at two times of the timeline. The page
//! writes what it drew (field coordinates and canvas pixels) into `#drawn`, which Chromium's
//! `--dump-dom` returns: robots and ball must be drawn where the log says, at the pixels the
//! field transform gives, and move with the timeline. A screenshot is saved as
//! `target/test-artifacts/viewer.png`.
//!
//! Needs `chromium` (`./scripts/test` installs it). Without it the test says so and passes,
//! unless `STRATA_REQUIRE_CHROMIUM` is set (the test script sets it once Chromium is there), in
//! which case it fails. Nothing asserts how long anything took.

mod view_support;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;
use strata_games::logging::LogSettings;
use view_support::{get_json, record_match, required_tool, scratch};

/// How long one Chromium run may take before it is stopped (a hung browser must not hang the
/// suite); generous, this is no timing check.
const CHROMIUM_LIMIT: Duration = Duration::from_secs(120);

fn find_chromium() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .flat_map(|dir| ["chromium", "chromium-browser"].map(|name| dir.join(name)))
        .find(|candidate| candidate.is_file())
}

/// Runs headless Chromium with a fresh profile; returns its standard output.
fn chromium(binary: &Path, profile: &Path, args: &[String]) -> String {
    let _ = std::fs::remove_dir_all(profile);
    let mut child = Command::new(binary)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--disable-quic",
            "--hide-scrollbars",
            "--window-size=1280,800",
            // Virtual time: the page's requests and timers run until they are done (or this
            // much page time passed), then the DOM or screenshot is taken.
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start chromium");
    let mut stdout = child.stdout.take().expect("stdout");
    let reader = std::thread::spawn(move || {
        let mut out = String::new();
        let _ = std::io::Read::read_to_string(&mut stdout, &mut out);
        out
    });
    let start = Instant::now();
    loop {
        match child.try_wait().expect("wait for chromium") {
            Some(status) => {
                assert!(status.success(), "chromium failed: {status}");
                break;
            }
            None if start.elapsed() > CHROMIUM_LIMIT => {
                let _ = child.kill();
                let _ = child.wait();
                panic!("chromium did not finish within {CHROMIUM_LIMIT:?}");
            }
            None => std::thread::sleep(Duration::from_millis(50)),
        }
    }
    reader.join().expect("chromium's output")
}

/// The JSON the page put into `<pre id="drawn">`.
fn drawn(dom: &str) -> Value {
    let start = dom.find("id=\"drawn\"").unwrap_or_else(|| panic!("no #drawn in the page: {dom}"));
    let open = start + dom[start..].find('>').expect("end of the tag") + 1;
    let close = open + dom[open..].find("</pre>").expect("</pre>");
    let text = dom[open..close]
        .replace("&quot;", "\"")
        .replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&#39;", "'")
        .replace("&amp;", "&");
    assert!(!text.is_empty(), "the page drew nothing (no frame loaded?): {dom}");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("#drawn is not JSON ({e}): {text}"))
}

fn number(value: &Value, what: &str) -> f64 {
    value.as_f64().unwrap_or_else(|| panic!("{what} is not a number: {value}"))
}

/// Checks that what the page drew at `t` is where the frame endpoint (the log) puts it;
/// returns the drawn robots' positions by name.
fn check_drawn(drawn: &Value, frame: &Value, t: f64) -> Vec<(String, f64, f64)> {
    assert!((number(&drawn["t"], "drawn t") - t).abs() < 1e-6, "drawn at {} for {t}", drawn["t"]);
    let width = number(&drawn["canvas"]["width"], "width");
    let height = number(&drawn["canvas"]["height"], "height");
    let scale = number(&drawn["scale"], "scale");
    let pixel = |x: f64, y: f64| (width / 2.0 + x * scale, height / 2.0 - y * scale);
    let check = |what: &str, shown: &Value, x: f64, y: f64| {
        assert_eq!(number(&shown["x"], what), x, "{what} x");
        assert_eq!(number(&shown["y"], what), y, "{what} y");
        let (px, py) = pixel(x, y);
        let (dx, dy) = (number(&shown["px"], what), number(&shown["py"], what));
        assert!(
            (dx - px).abs() < 1e-6 && (dy - py).abs() < 1e-6,
            "{what} drawn at ({dx}, {dy}), expected ({px}, {py})"
        );
        assert!(
            (0.0..=width).contains(&dx) && (0.0..=height).contains(&dy),
            "{what} off the canvas"
        );
    };
    let ball = &frame["ball"];
    check("ball", &drawn["ball"], number(&ball["x"], "ball x"), number(&ball["y"], "ball y"));
    let mut positions = Vec::new();
    for robot in frame["robots"].as_array().expect("robots") {
        let name = robot["name"].as_str().expect("name");
        if robot["present"] != true || !robot["pose"].is_object() {
            continue;
        }
        let shown = drawn["robots"]
            .as_array()
            .and_then(|r| r.iter().find(|d| d["name"] == name))
            .unwrap_or_else(|| panic!("{name} was not drawn: {drawn}"));
        let (x, y) = (number(&robot["pose"]["x"], "x"), number(&robot["pose"]["y"], "y"));
        check(name, shown, x, y);
        if robot["estimate"].is_object() {
            let e = &robot["estimate"];
            check(
                &format!("{name} estimate"),
                &shown["estimate"],
                number(&e["x"], "x"),
                number(&e["y"], "y"),
            );
        }
        positions.push((name.to_owned(), x, y));
    }
    assert!(!positions.is_empty(), "no robot on the field");
    positions
}

#[test]
fn the_viewer_draws_robots_and_ball_where_the_log_says() {
    let Some(binary) = required_tool(
        find_chromium(),
        "STRATA_REQUIRE_CHROMIUM",
        "viewer_browser",
        "`chromium` is not on the PATH (apt-get install chromium)",
    ) else {
        return;
    };
    let dir = scratch("viewer-browser");
    let log = dir.join("match.mcap");
    record_match(&LogSettings::full(&log), 2, 7.0, 21, None);
    let data = strata_view::load_log(&log).expect("load");
    assert!(strata_view::wait_loaded(&data, Duration::from_secs(120)), "the log was not read");
    let server = strata_view::ViewServer::start(data, 0).expect("serve");
    let base = server.url();
    let profile = dir.join("chromium-profile");

    // Two instants of the Ready state, when every robot walks to its kick-off position.
    let times = [3.0, 6.5];
    let mut seen = Vec::new();
    for t in times {
        let url = format!("{base}?t={t:.3}&robot=home%2F1");
        let dom = chromium(&binary, &profile, &["--dump-dom".to_owned(), url]);
        let frame = get_json(&format!("{base}api/frame?t={t:.3}"));
        seen.push(check_drawn(&drawn(&dom), &frame, t));
    }
    // The timeline moved them: some robot is elsewhere at the second time, drawn where the log
    // says it is then (checked above).
    let moved = seen[0].iter().any(|(name, x, y)| {
        seen[1].iter().any(|(n, x2, y2)| n == name && (x2 - x).hypot(y2 - y) > 0.1)
    });
    assert!(moved, "no robot moved between {times:?}: {seen:?}");

    let artifacts = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .map_or_else(|| dir.clone(), |target| target.join("test-artifacts"));
    std::fs::create_dir_all(&artifacts).expect("artifact directory");
    let screenshot = artifacts.join("viewer.png");
    let _ = std::fs::remove_file(&screenshot);
    chromium(
        &binary,
        &profile,
        &[
            format!("--screenshot={}", screenshot.display()),
            format!("{base}?t={:.3}&robot=home%2F1", times[1]),
        ],
    );
    let png = std::fs::read(&screenshot).expect("the screenshot was written");
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    assert!(png.len() > 20_000, "a suspiciously small screenshot ({} bytes)", png.len());
    eprintln!("screenshot: {}", screenshot.display());
    drop(server);
    std::fs::remove_dir_all(&dir).unwrap_or_default();
}
