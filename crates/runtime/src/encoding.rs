//! How package values become bytes outside the process (logs, replay) and back.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// The byte encodings of package values. JSON and MessagePack are self-describing (field names
/// included): a reader needs nothing but the bytes. CDR is positional: the values alone, in
/// declaration order, described once per channel by a schema ([`crate::cdr`]). They differ in
/// cost: writing a world state as JSON spends most of its time escaping keys and printing
/// floats in decimal, MessagePack copies both but writes every field name with every value,
/// CDR copies the values alone — what lets a match log every package of every robot
/// (`docs/logging.md`, "Overhead").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// Text; what Foxglove and `jq` read directly.
    Json,
    /// MessagePack with structs as maps keyed by field name; floats keep their bits.
    #[serde(rename = "msgpack")]
    MessagePack,
    /// Plain CDR, little endian, as ROS 2 writes it; needs the value's format to be read
    /// without its Rust type. Floats keep their bits.
    #[default]
    Cdr,
}

impl std::str::FromStr for Encoding {
    type Err = String;

    fn from_str(text: &str) -> Result<Encoding, String> {
        Encoding::from_mcap_name(text)
            .ok_or_else(|| format!("unknown encoding `{text}` (cdr, msgpack or json)"))
    }
}

/// A value that could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum EncodingError {
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("MessagePack: {0}")]
    MessagePackEncode(#[from] rmp_serde::encode::Error),
    #[error("MessagePack: {0}")]
    MessagePackDecode(#[from] rmp_serde::decode::Error),
    #[error("CDR: {0}")]
    Cdr(#[from] crate::cdr::CdrError),
}

impl Encoding {
    /// The name MCAP's registry gives the encoding (a channel's `message_encoding`).
    pub fn mcap_name(self) -> &'static str {
        match self {
            Encoding::Json => "json",
            Encoding::MessagePack => "msgpack",
            Encoding::Cdr => "cdr",
        }
    }

    /// The encoding an MCAP channel names; `None` for the ones Strata does not read.
    pub fn from_mcap_name(name: &str) -> Option<Encoding> {
        match name {
            "json" => Some(Encoding::Json),
            "msgpack" => Some(Encoding::MessagePack),
            "cdr" => Some(Encoding::Cdr),
            _ => None,
        }
    }

    /// Appends `value` to `out`.
    pub fn encode<T: Serialize + ?Sized>(
        self,
        value: &T,
        out: &mut Vec<u8>,
    ) -> Result<(), EncodingError> {
        match self {
            Encoding::Json => serde_json::to_writer(out, value)?,
            Encoding::MessagePack => rmp_serde::encode::write_named(out, value)?,
            Encoding::Cdr => crate::cdr::encode(value, out)?,
        }
        Ok(())
    }

    /// Whether a value reads without its type or schema (JSON, MessagePack).
    pub fn is_self_describing(self) -> bool {
        !matches!(self, Encoding::Cdr)
    }

    /// Reads a value of type `T`. CDR values read only as their own type (or one of the same
    /// layout); see [`crate::cdr::to_json`] for reading them as JSON.
    pub fn decode<T: DeserializeOwned>(self, bytes: &[u8]) -> Result<T, EncodingError> {
        Ok(match self {
            Encoding::Json => serde_json::from_slice(bytes)?,
            Encoding::MessagePack => rmp_serde::from_slice(bytes)?,
            Encoding::Cdr => crate::cdr::decode(bytes)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    enum Kind {
        Ball,
        Landmark { id: u8 },
    }

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct Sample {
        name: String,
        kind: Kind,
        other: Kind,
        position: (f64, f64),
        covariance: [f64; 4],
        velocity: Option<f64>,
        tiny: f64,
    }

    fn sample() -> Sample {
        Sample {
            name: "ball".into(),
            kind: Kind::Ball,
            other: Kind::Landmark { id: 3 },
            position: (0.1 + 0.2, -4.5),
            covariance: [1e-300, -0.0, f64::MAX, 1.0 / 3.0],
            velocity: None,
            tiny: f64::MIN_POSITIVE,
        }
    }

    #[test]
    fn every_encoding_round_trips_every_bit() {
        for encoding in [Encoding::Json, Encoding::MessagePack, Encoding::Cdr] {
            let mut bytes = Vec::new();
            encoding.encode(&sample(), &mut bytes).expect("encode");
            let back: Sample = encoding.decode(&bytes).expect("decode");
            assert_eq!(back, sample(), "{encoding:?}");
            assert_eq!(back.covariance[1].to_bits(), (-0.0f64).to_bits());
        }
    }

    #[test]
    fn message_pack_reads_as_the_same_json_value() {
        let mut json = Vec::new();
        Encoding::Json.encode(&sample(), &mut json).expect("json");
        let mut packed = Vec::new();
        Encoding::MessagePack.encode(&sample(), &mut packed).expect("msgpack");
        let from_json: serde_json::Value = Encoding::Json.decode(&json).expect("json value");
        let from_packed: serde_json::Value =
            Encoding::MessagePack.decode(&packed).expect("msgpack value");
        assert_eq!(from_json, from_packed);
        assert!(packed.len() < json.len());
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        for encoding in [Encoding::Json, Encoding::MessagePack, Encoding::Cdr] {
            for bytes in [&b""[..], b"\xc1", b"{\"name\":", b"\x92\xa4ba"] {
                assert!(encoding.decode::<Sample>(bytes).is_err(), "{encoding:?} {bytes:?}");
            }
        }
        assert_eq!(Encoding::from_mcap_name("cbor"), None);
        assert_eq!(Encoding::from_mcap_name("cdr"), Some(Encoding::Cdr));
        assert_eq!(Encoding::from_mcap_name("msgpack"), Some(Encoding::MessagePack));
    }
}
