//! Durations in configuration files and reports are seconds, as a float (`0.012`), which is what
//! people write; `std::time::Duration`'s own serde form (`{secs, nanos}`) is not.

use std::time::Duration;

use serde::{Deserialize, Deserializer, Serializer};

pub fn serialize<S: Serializer>(duration: &Duration, serializer: S) -> Result<S::Ok, S::Error> {
    serializer.serialize_f64(duration.as_secs_f64())
}

pub fn deserialize<'de, D: Deserializer<'de>>(deserializer: D) -> Result<Duration, D::Error> {
    let secs = f64::deserialize(deserializer)?;
    Duration::try_from_secs_f64(secs).map_err(|_| {
        serde::de::Error::custom(format!(
            "{secs} is not a valid duration in seconds (must be finite and >= 0)"
        ))
    })
}
