//! Child processes a command starts (`strata robot` processes of an experiment or a chaos run):
//! their output read line by line as it comes, each stdout line stamped with when it arrived,
//! and the process killed if it is still running when its guard is dropped — on an error, a
//! failed check or Ctrl-C alike, no robot is left behind.

use std::io::{BufRead as _, BufReader, Read};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

/// One line a child wrote to its stdout, and when it was read.
#[derive(Clone, Debug)]
pub struct Line {
    pub at: Instant,
    pub text: String,
}

/// A running child process; killed when dropped while it runs.
#[derive(Debug)]
pub struct Child {
    name: String,
    child: std::process::Child,
    stdout: Arc<Mutex<Vec<Line>>>,
    stderr: Arc<Mutex<Vec<String>>>,
    readers: Vec<JoinHandle<()>>,
    status: Option<ExitStatus>,
}

impl Child {
    /// Starts `command` with stdin closed and stdout and stderr read by two threads, so a full
    /// pipe never blocks the child.
    pub fn spawn(name: &str, command: &mut Command) -> Result<Child> {
        let mut child = command
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("starting {name}"))?;
        let stdout = Arc::new(Mutex::new(Vec::new()));
        let stderr = Arc::new(Mutex::new(Vec::new()));
        let mut readers = Vec::new();
        if let Some(pipe) = child.stdout.take() {
            let sink = Arc::clone(&stdout);
            readers.push(read_lines(pipe, move |text| {
                lock(&sink).push(Line { at: Instant::now(), text });
            }));
        }
        if let Some(pipe) = child.stderr.take() {
            let sink = Arc::clone(&stderr);
            readers.push(read_lines(pipe, move |text| lock(&sink).push(text)));
        }
        Ok(Child { name: name.to_owned(), child, stdout, stderr, readers, status: None })
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Stdout lines from index `from` on (lines are only ever appended).
    pub fn lines_from(&self, from: usize) -> Vec<Line> {
        lock(&self.stdout).get(from..).map(<[Line]>::to_vec).unwrap_or_default()
    }

    /// Everything written to stdout so far.
    pub fn stdout(&self) -> String {
        let lines = lock(&self.stdout);
        let mut text = String::new();
        for line in lines.iter() {
            text.push_str(&line.text);
            text.push('\n');
        }
        text
    }

    /// Everything written to stderr so far.
    pub fn stderr(&self) -> String {
        let mut text = lock(&self.stderr).join("\n");
        if !text.is_empty() {
            text.push('\n');
        }
        text
    }

    /// The exit status once the child has ended; then every line it wrote has been read.
    pub fn try_wait(&mut self) -> Result<Option<ExitStatus>> {
        if self.status.is_none() {
            self.status =
                self.child.try_wait().with_context(|| format!("waiting for {}", self.name))?;
            if self.status.is_some() {
                self.join_readers();
            }
        }
        Ok(self.status)
    }

    /// The exit status, if the child is known to have ended.
    pub fn exit_status(&self) -> Option<ExitStatus> {
        self.status
    }

    pub fn is_running(&mut self) -> bool {
        matches!(self.try_wait(), Ok(None))
    }

    /// Sends `signal`; a child that has ended already is no error.
    pub fn signal(&mut self, signal: Signal) -> Result<()> {
        if self.try_wait()?.is_some() {
            return Ok(());
        }
        let pid = i32::try_from(self.child.id()).context("a process id beyond i32")?;
        kill(Pid::from_raw(pid), signal)
            .with_context(|| format!("sending {signal} to {}", self.name))
    }

    /// Waits for the child to end; every line it wrote has been read when this returns.
    pub fn wait(&mut self) -> Result<ExitStatus> {
        if let Some(status) = self.status {
            return Ok(status);
        }
        let status = self.child.wait().with_context(|| format!("waiting for {}", self.name))?;
        self.status = Some(status);
        self.join_readers();
        Ok(status)
    }

    /// Waits up to `within` for the child to end; `None` if it still runs.
    pub fn wait_for(&mut self, within: Duration) -> Result<Option<ExitStatus>> {
        let deadline = Instant::now() + within;
        loop {
            if let Some(status) = self.try_wait()? {
                return Ok(Some(status));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Asks the child to stop with `signal` and gives it `grace` to do so (a robot writes its
    /// report and finishes its log); kills it after that. Returns its status and whether it
    /// had to be killed.
    pub fn stop(&mut self, signal: Signal, grace: Duration) -> Result<(ExitStatus, bool)> {
        self.signal(signal)?;
        if let Some(status) = self.wait_for(grace)? {
            return Ok((status, false));
        }
        self.kill()?;
        Ok((self.wait()?, true))
    }

    /// SIGKILL (continues a stopped child too: the kernel delivers it regardless).
    pub fn kill(&mut self) -> Result<()> {
        if self.try_wait()?.is_some() {
            return Ok(());
        }
        self.child.kill().with_context(|| format!("killing {}", self.name))
    }

    fn join_readers(&mut self) {
        for reader in self.readers.drain(..) {
            let _ = reader.join();
        }
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        if self.status.is_none() && matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Reads `pipe` to its end, a line at a time; bytes that are not UTF-8 are replaced rather
/// than ending the reading.
fn read_lines(
    pipe: impl Read + Send + 'static,
    mut sink: impl FnMut(String) + Send + 'static,
) -> JoinHandle<()> {
    std::thread::spawn(move || {
        let mut reader = BufReader::new(pipe);
        let mut buffer = Vec::new();
        loop {
            buffer.clear();
            match reader.read_until(b'\n', &mut buffer) {
                Ok(0) | Err(_) => return,
                Ok(_) => {
                    let line = String::from_utf8_lossy(&buffer);
                    sink(line.trim_end_matches(['\n', '\r']).to_owned());
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_arrive_and_a_dropped_child_is_killed() {
        let mut child = Child::spawn(
            "sh",
            Command::new("sh").args(["-c", "echo one; echo two >&2; echo three; exec sleep 30"]),
        )
        .expect("sh starts");
        let deadline = Instant::now() + Duration::from_secs(10);
        while child.lines_from(0).len() < 2 && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
        }
        let texts: Vec<String> = child.lines_from(0).into_iter().map(|l| l.text).collect();
        assert_eq!(texts, ["one", "three"]);
        assert_eq!(child.lines_from(1).len(), 1);
        assert!(child.lines_from(5).is_empty());
        let pid = child.pid();
        assert!(child.is_running());
        drop(child);
        // Reaped by the guard: no such process any more (or a recycled id, never a zombie of ours).
        let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
        assert!(!status.contains("State:\tS"), "{status}");
    }

    #[test]
    fn stop_signals_then_reports_the_status() {
        let mut child = Child::spawn("sleep", Command::new("sleep").arg("30")).expect("starts");
        let (status, killed) = child.stop(Signal::SIGTERM, Duration::from_secs(10)).expect("stops");
        assert!(!status.success());
        assert!(!killed, "sleep ends on SIGTERM");
        assert!(child.stderr().is_empty());
    }
}
