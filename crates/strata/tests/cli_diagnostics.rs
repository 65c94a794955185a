//! What the command line tells a user beside its output: diagnostics on stderr (warnings by
//! default, more with -v, errors only with -q, RUST_LOG honoured) that never mix with the
//! output on stdout.

mod common;

use common::cli::{run, stderr, strata, temp_dir};

use std::io::Write as _;
use std::os::unix::net::UnixListener;
use std::path::Path;
use std::process::Output;
use std::thread::JoinHandle;

/// A LoLA socket that accepts one robot, sends it a few bytes that are no sensor packet and
/// hangs up: the robot's LoLA thread notes the malformed data (debug) and warns that the link
/// is lost, and the robot stops with an error (no first packet).
fn hanging_up_lola(path: &Path) -> JoinHandle<()> {
    let listener = UnixListener::bind(path).expect("the LoLA socket binds");
    std::thread::spawn(move || {
        if let Ok((mut stream, _)) = listener.accept() {
            let _ = stream.write_all(b"not msgpack");
        }
    })
}

/// `strata robot` on a NAO whose LoLA hangs up, with `extra` flags and `RUST_LOG` if given.
fn robot_on_a_lost_lola(name: &str, extra: &[&str], rust_log: Option<&str>) -> Output {
    let dir = temp_dir(name);
    let socket = dir.join("lola.sock");
    let lola = hanging_up_lola(&socket);
    let socket = socket.to_string_lossy().into_owned();
    let mut command = strata(&["robot", "--platform", "nao", "--team", "10", "--player", "2"]);
    command.args(["--socket", &socket, "--gc-wait", "0", "--real-time-priority", "0"]).args(extra);
    if let Some(filter) = rust_log {
        command.env("RUST_LOG", filter);
    }
    let output = run(&mut command);
    lola.join().expect("the LoLA thread ends");
    let _ = std::fs::remove_dir_all(&dir);
    output
}

#[test]
fn warnings_reach_stderr_by_default_and_quiet_keeps_errors_only() {
    let output = robot_on_a_lost_lola("default", &[], None);
    let text = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{text}");
    assert!(text.contains("WARN") && text.contains("LoLA link lost"), "{text}");
    assert!(!text.contains("malformed LoLA data"), "debug is not shown by default:\n{text}");
    assert!(text.contains("error: "), "{text}");

    for quiet in ["-q", "--quiet"] {
        let output = robot_on_a_lost_lola("quiet", &[quiet], None);
        let text = stderr(&output);
        assert_eq!(output.status.code(), Some(1), "{text}");
        assert!(!text.contains("LoLA link lost"), "{quiet} hides warnings:\n{text}");
        assert!(text.contains("error: "), "{quiet} keeps the error:\n{text}");
    }

    // RUST_LOG chooses what is shown when set.
    let output = robot_on_a_lost_lola("rust-log-off", &[], Some("off"));
    assert!(!stderr(&output).contains("LoLA link lost"), "{}", stderr(&output));
    let output = robot_on_a_lost_lola("rust-log-nao", &["-q"], Some("strata_nao=warn"));
    assert!(stderr(&output).contains("LoLA link lost"), "{}", stderr(&output));
}

#[test]
fn verbose_adds_details_and_json_on_stdout_stays_clean() {
    let output = run(&mut strata(&["match", "--players", "2", "--duration", "2", "--json", "-vv"]));
    assert!(output.status.success(), "{}", stderr(&output));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let report: serde_json::Value = serde_json::from_str(&stdout)
        .unwrap_or_else(|e| panic!("stdout is one JSON object ({e}):\n{stdout}"));
    assert!(report.is_object());

    // The flags go after the subcommand as well as before it.
    let output = robot_on_a_lost_lola("verbose", &["-v"], None);
    let text = stderr(&output);
    assert!(text.contains("LoLA link lost"), "{text}");
    assert!(!text.contains("malformed LoLA data"), "-v is not debug:\n{text}");
    let output = robot_on_a_lost_lola("very-verbose", &["-vv"], None);
    let text = stderr(&output);
    assert!(text.contains("DEBUG") && text.contains("malformed LoLA data"), "{text}");
    let output = run(&mut strata(&["-v", "-q", "match"]));
    assert!(!output.status.success(), "-v and -q conflict: {}", stderr(&output));
}
