//! Reading one HTTP request from a viewer client: the request line, the headers (of which only
//! `Host` matters), the target with its query. Pure over any reader, so that it can be tested
//! and fuzzed without a socket (`fuzz/fuzz_targets/view_request.rs`).

use std::io::{self, BufRead};

/// The request line and headers together; a GET has no body.
pub const MAX_REQUEST_BYTES: usize = 16 * 1024;

/// A request the viewer answers.
#[derive(Debug, PartialEq)]
pub struct Request {
    /// `HEAD` is answered like `GET`, without the body.
    pub head_only: bool,
    pub target: Target,
}

/// Why a request is refused, with the status that says so.
#[derive(Debug, PartialEq)]
pub enum Rejection {
    /// 400: no method and target.
    Malformed,
    /// 405: anything but GET and HEAD.
    Method,
    /// 431: request line and headers beyond [`MAX_REQUEST_BYTES`].
    TooLarge,
    /// 403: a `Host` that is not this machine's loopback name. A page on another site that
    /// resolves its own name to 127.0.0.1 (DNS rebinding) would otherwise read the viewer.
    ForeignHost(String),
}

impl Rejection {
    pub fn status(&self) -> u16 {
        match self {
            Rejection::Malformed => 400,
            Rejection::Method => 405,
            Rejection::TooLarge => 431,
            Rejection::ForeignHost(_) => 403,
        }
    }

    pub fn message(&self) -> String {
        match self {
            Rejection::Malformed => "malformed request line\n".to_owned(),
            Rejection::Method => "only GET is served\n".to_owned(),
            Rejection::TooLarge => "request headers too large\n".to_owned(),
            Rejection::ForeignHost(host) => {
                format!("the viewer answers requests to localhost only, not to `{host}`\n")
            }
        }
    }
}

/// Reads one request. `Ok(None)`: the client closed before sending anything. An I/O error is
/// the connection failing; a request the viewer will not answer is a [`Rejection`].
pub fn read_request(reader: &mut impl BufRead) -> io::Result<Option<Result<Request, Rejection>>> {
    let mut request_line = String::new();
    if read_line_lossy(reader, &mut request_line)? == 0 {
        return Ok(None);
    }
    let mut total = request_line.len();
    let mut host = None;
    loop {
        let mut line = String::new();
        let n = read_line_lossy(reader, &mut line)?;
        total += n;
        if n == 0 || line == "\r\n" || line == "\n" {
            break;
        }
        if total > MAX_REQUEST_BYTES {
            return Ok(Some(Err(Rejection::TooLarge)));
        }
        if let Some((name, value)) = line.split_once(':')
            && name.trim().eq_ignore_ascii_case("host")
        {
            host = Some(value.trim().to_owned());
        }
    }
    let mut parts = request_line.split_whitespace();
    let (Some(method), Some(target)) = (parts.next(), parts.next()) else {
        return Ok(Some(Err(Rejection::Malformed)));
    };
    if method != "GET" && method != "HEAD" {
        return Ok(Some(Err(Rejection::Method)));
    }
    // HTTP/1.0 clients may send no Host; browsers always do.
    if let Some(host) = host
        && !is_loopback_host(&host)
    {
        return Ok(Some(Err(Rejection::ForeignHost(host))));
    }
    Ok(Some(Ok(Request { head_only: method == "HEAD", target: Target::parse(target) })))
}

/// Reads a line as text whatever its bytes: a client's invalid UTF-8 is its problem, not an
/// I/O error.
fn read_line_lossy(reader: &mut impl BufRead, line: &mut String) -> io::Result<usize> {
    let mut bytes = Vec::new();
    let n = reader.read_until(b'\n', &mut bytes)?;
    line.push_str(&String::from_utf8_lossy(&bytes));
    Ok(n)
}

/// `localhost`, `127.0.0.1` or `[::1]`, with or without a port.
fn is_loopback_host(host: &str) -> bool {
    let name = if let Some(rest) = host.strip_prefix('[') {
        rest.split_once(']').map_or(rest, |(inside, _)| inside)
    } else {
        host.rsplit_once(':').map_or(host, |(name, _)| name)
    };
    let name = name.trim_end_matches('.');
    name.eq_ignore_ascii_case("localhost") || name == "127.0.0.1" || name == "::1"
}

/// A parsed request target.
#[derive(Debug, PartialEq)]
pub struct Target {
    pub path: String,
    pub query: Vec<(String, String)>,
}

impl Target {
    pub fn parse(target: &str) -> Target {
        let (path, query) = target.split_once('?').unwrap_or((target, ""));
        Target {
            path: percent_decode(path),
            query: query
                .split('&')
                .filter(|p| !p.is_empty())
                .map(|pair| {
                    let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
                    (percent_decode(k), percent_decode(v))
                })
                .collect(),
        }
    }

    pub fn get(&self, key: &str) -> Option<&str> {
        self.query.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// A number parameter: absent is `None`, malformed is an error naming it.
    pub fn number(&self, key: &str) -> Result<Option<f64>, String> {
        match self.get(key) {
            None | Some("") => Ok(None),
            Some(text) => text
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .map(Some)
                .ok_or_else(|| format!("`{key}` must be a number of seconds, got `{text}`")),
        }
    }
}

fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'+' => out.push(b' '),
            b'%' if i + 2 < bytes.len() => {
                let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok();
                match hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
                    Some(b) => {
                        out.push(b);
                        i += 3;
                        continue;
                    }
                    None => out.push(b'%'),
                }
            }
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &[u8]) -> Option<Result<Request, Rejection>> {
        read_request(&mut &text[..]).expect("reading a slice does not fail")
    }

    #[test]
    fn targets_are_decoded() {
        let t = Target::parse("/api/series?robot=home%2F2&from=1.5&to=&x");
        assert_eq!(t.path, "/api/series");
        assert_eq!(t.get("robot"), Some("home/2"));
        assert_eq!(t.number("from"), Ok(Some(1.5)));
        assert_eq!(t.number("to"), Ok(None));
        assert_eq!(t.get("x"), Some(""));
        assert!(t.number("robot").is_err());
        assert_eq!(percent_decode("a%zz%4"), "a%zz%4");
        assert_eq!(percent_decode("%41+b"), "A b");
    }

    #[test]
    fn requests_to_localhost_are_answered_and_others_refused() {
        for host in ["localhost:8080", "127.0.0.1:5", "[::1]:80", "LOCALHOST", "localhost."] {
            let text = format!("GET /api/info HTTP/1.1\r\nHost: {host}\r\n\r\n");
            let request = read(text.as_bytes()).expect("a request").expect("answered");
            assert_eq!(request.target.path, "/api/info", "{host}");
            assert!(!request.head_only);
        }
        let rebound = read(b"GET /api/info HTTP/1.1\r\nhost: evil.example:8080\r\n\r\n");
        assert_eq!(rebound, Some(Err(Rejection::ForeignHost("evil.example:8080".to_owned()))));
        let lookalike = read(b"GET / HTTP/1.1\r\nHost: 127.0.0.1.evil.example\r\n\r\n");
        assert!(matches!(lookalike, Some(Err(Rejection::ForeignHost(_)))));
        // An HTTP/1.0 client without a Host header is local by construction of the listener.
        let old = read(b"HEAD / HTTP/1.0\r\n\r\n").expect("a request").expect("answered");
        assert!(old.head_only);
    }

    #[test]
    fn malformed_requests_are_refused_with_their_status() {
        assert_eq!(read(b""), None);
        assert_eq!(read(b"\r\n\r\n"), Some(Err(Rejection::Malformed)));
        assert_eq!(read(b"POST / HTTP/1.1\r\n\r\n"), Some(Err(Rejection::Method)));
        let mut huge = b"GET / HTTP/1.1\r\n".to_vec();
        for _ in 0..1000 {
            huge.extend_from_slice(b"X-Padding: aaaaaaaaaaaaaaaaaaaa\r\n");
        }
        assert_eq!(read(&huge), Some(Err(Rejection::TooLarge)));
        let binary = read(b"GET /\xff\xfe HTTP/1.1\r\n\r\n").expect("a request").expect("ok");
        assert!(binary.target.path.starts_with('/'));
        assert_eq!(Rejection::ForeignHost("x".into()).status(), 403);
    }
}
