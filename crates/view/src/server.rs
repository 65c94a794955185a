//! A small HTTP/1.1 server for the viewer on localhost: the page's static files (compiled into
//! the binary) and three JSON endpoints. One short-lived thread per request and
//! `Connection: close`: a viewer has one or two clients polling a few times a second, which
//! does not justify an async runtime (`docs/viewer.md`).

use std::io::{self, BufReader, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, PoisonError, RwLock};
use std::thread::JoinHandle;
use std::time::Duration;

use serde::Serialize;

use super::data::ViewData;
use super::request::{MAX_REQUEST_BYTES, Target, read_request};

const INDEX_HTML: &str = include_str!("assets/index.html");
const VIEWER_JS: &str = include_str!("assets/viewer.js");
const VIEWER_CSS: &str = include_str!("assets/viewer.css");

/// Requests served at once; more get `503` (a viewer is not a public web server).
const MAX_CONNECTIONS: usize = 32;
/// Points per series at most, unless the request asks for fewer.
const MAX_SERIES_POINTS: usize = 4000;

/// A running viewer server. Dropping it stops it.
#[derive(Debug)]
pub struct ViewServer {
    address: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl ViewServer {
    /// Serves `data` on `127.0.0.1:port` (port 0: any free port).
    pub fn start(data: Arc<RwLock<ViewData>>, port: u16) -> io::Result<ViewServer> {
        let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, port))?;
        let address = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let active = Arc::new(AtomicUsize::new(0));
        let thread = {
            let stop = Arc::clone(&stop);
            std::thread::Builder::new().name("strata-view".to_owned()).spawn(move || {
                for stream in listener.incoming() {
                    if stop.load(Ordering::Acquire) {
                        break;
                    }
                    // A failed accept (a client gone before it was accepted) concerns that
                    // client only.
                    let Ok(stream) = stream else { continue };
                    if active.fetch_add(1, Ordering::AcqRel) >= MAX_CONNECTIONS {
                        active.fetch_sub(1, Ordering::AcqRel);
                        let _ = respond(&stream, 503, "text/plain", b"busy\n");
                        continue;
                    }
                    let data = Arc::clone(&data);
                    let done = Arc::clone(&active);
                    let spawned = std::thread::Builder::new()
                        .name("strata-view-request".to_owned())
                        .spawn(move || {
                            // A client that goes away mid-request concerns that client only.
                            let _ = handle(&stream, &data);
                            done.fetch_sub(1, Ordering::AcqRel);
                        });
                    if spawned.is_err() {
                        // No thread: the request (and its stream) is dropped unanswered.
                        active.fetch_sub(1, Ordering::AcqRel);
                    }
                }
            })?
        };
        Ok(ViewServer { address, stop, thread: Some(thread) })
    }

    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// `http://127.0.0.1:PORT/`
    pub fn url(&self) -> String {
        format!("http://{}/", self.address)
    }

    /// Stops accepting requests (those being served finish on their own).
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // Wake the accept loop.
        let _ = TcpStream::connect_timeout(&self.address, Duration::from_secs(1));
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for ViewServer {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Reads one request and answers it. Errors are the client's connection failing.
fn handle(stream: &TcpStream, data: &RwLock<ViewData>) -> io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    stream.set_write_timeout(Some(Duration::from_secs(10)))?;
    let mut reader = BufReader::new(stream.take_limited());
    let request = match read_request(&mut reader)? {
        None => return Ok(()),
        Some(Ok(request)) => request,
        Some(Err(rejection)) => {
            return respond(
                stream,
                rejection.status(),
                "text/plain",
                rejection.message().as_bytes(),
            );
        }
    };
    let (status, content_type, body) = route(&request.target, data);
    if request.head_only {
        return respond(stream, status, content_type, b"");
    }
    respond(stream, status, content_type, &body)
}

/// What to answer: status, content type and body.
fn route(target: &Target, data: &RwLock<ViewData>) -> (u16, &'static str, Vec<u8>) {
    let read = || data.read().unwrap_or_else(PoisonError::into_inner);
    match target.path.as_str() {
        "/" | "/index.html" => (200, "text/html; charset=utf-8", INDEX_HTML.as_bytes().to_vec()),
        "/viewer.js" => (200, "text/javascript; charset=utf-8", VIEWER_JS.as_bytes().to_vec()),
        "/viewer.css" => (200, "text/css; charset=utf-8", VIEWER_CSS.as_bytes().to_vec()),
        "/api/info" => json(200, &read().info()),
        "/api/frame" => match target.number("t") {
            Ok(t) => json(200, &read().frame(t)),
            Err(e) => error(400, &e),
        },
        "/api/series" => {
            let Some(robot) = target.get("robot") else {
                return error(400, "give the robot: /api/series?robot=home/1");
            };
            let (from, to) = match (target.number("from"), target.number("to")) {
                (Ok(from), Ok(to)) => (from, to),
                (Err(e), _) | (_, Err(e)) => return error(400, &e),
            };
            let points = match target.get("points").map(str::parse::<usize>) {
                None => MAX_SERIES_POINTS,
                Some(Ok(n)) if n > 0 => n.min(MAX_SERIES_POINTS),
                Some(_) => return error(400, "`points` must be a positive integer"),
            };
            match read().series(robot, from, to, points) {
                Some(series) => json(200, &series),
                None => error(404, &format!("no robot `{robot}` in this view")),
            }
        }
        "/favicon.ico" => (204, "text/plain", Vec::new()),
        _ => error(404, &format!("nothing at `{}`", target.path)),
    }
}

fn json<T: Serialize>(status: u16, value: &T) -> (u16, &'static str, Vec<u8>) {
    match serde_json::to_vec(value) {
        Ok(body) => (status, "application/json", body),
        Err(e) => error(500, &format!("cannot serialize the answer: {e}")),
    }
}

fn error(status: u16, message: &str) -> (u16, &'static str, Vec<u8>) {
    let body = serde_json::to_vec(&serde_json::json!({ "error": message })).unwrap_or_default();
    (status, "application/json", body)
}

fn respond(mut stream: &TcpStream, status: u16, content_type: &str, body: &[u8]) -> io::Result<()> {
    let reason = match status {
        200 => "OK",
        204 => "No Content",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "",
    };
    let head = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(body)?;
    stream.flush()
}

/// Reading a request never takes more than [`MAX_REQUEST_BYTES`] (plus a line) from a client.
trait TakeLimited {
    fn take_limited(&self) -> io::Take<&TcpStream>;
}

impl TakeLimited for TcpStream {
    fn take_limited(&self) -> io::Take<&TcpStream> {
        io::Read::take(self, (MAX_REQUEST_BYTES + 1024) as u64)
    }
}
