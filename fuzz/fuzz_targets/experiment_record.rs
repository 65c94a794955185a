//! Any bytes: an experiment's job record (`strata_experiments::records`, read from a records
//! directory a sweep shares) decodes to an error or a record, never a panic, for every
//! experiment that has records.
#![no_main]

use libfuzzer_sys::fuzz_target;
use strata_experiments::RECORDABLE;
use strata_experiments::records::decode_for;

fuzz_target!(|bytes: &[u8]| {
    for name in RECORDABLE {
        let _ = decode_for(name, bytes);
    }
});
