//! Any bytes from a viewer client (crates/view/src/request.rs): the request reader
//! answers with a request, a refusal with its status, or nothing, never panics, and never reads
//! more than the request limit plus a line.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_view::request::read_request;

fuzz_target!(|bytes: &[u8]| {
    let mut reader = bytes;
    if let Ok(Some(Ok(request))) = read_request(&mut reader) {
        let _ = request.target.number("t");
        let _ = request.target.get("robot");
    }
});
