//! CDR: the compact binary encoding of package values in logs, as ROS 2 and DDS write it
//! (plain CDR, little endian, "XCDR1"), described by an OMG IDL schema that generic tools —
//! Foxglove among them — read.
//!
//! Why CDR: a match logs every package of fourteen robots, about ten thousand values per
//! simulated second at a hundred times real time. A self-describing encoding (JSON,
//! MessagePack with field names) writes every field name with every value and costs the log
//! writer several times the match's own work; CDR writes the values alone, in declaration
//! order, aligned to their size, and costs little more than copying them. What the bytes mean
//! comes from the schema, written once per channel.
//!
//! The mapping from serde's data model (what every package type already implements):
//!
//! | serde | CDR | IDL |
//! |---|---|---|
//! | bool, integers, floats | the value, aligned to its size (at most 8) | `boolean`, `int8` … `unsigned long long`, `float`, `double` |
//! | char | its code point as a `u32` | `unsigned long` |
//! | string | `u32` length including a terminating NUL, the bytes, NUL | `string` |
//! | bytes | `u32` length, the bytes | `sequence<octet>` |
//! | `Option<T>` | `u32` count (0 or 1), the value | `sequence<T, 1>` |
//! | sequence, map | `u32` count, the elements (a map's: key, value) | `sequence<T>`, `sequence<Entry>` |
//! | tuple | the elements | `T name[n]` when all alike, else a struct `_0`, `_1` … |
//! | struct | the fields in order | `struct` |
//! | newtype struct | the inner value | the inner type |
//! | unit, unit struct | nothing | `Empty` (a struct without members) |
//! | enum | the variant's index as a `u32`, then its fields | `enum` when no variant has fields, else a `union` switched by an `enum` |
//!
//! Positional encodings need every field every time: a type that skips fields when it
//! serializes (`skip_serializing_if`) cannot be written ([`CdrError::SkippedField`]), and one
//! that reads itself through `deserialize_any` (internally tagged or untagged enums, flattened
//! fields) cannot be described ([`trace`] fails). Loggers fall back to a self-describing
//! encoding for those.

mod de;
mod format;
mod idl;
mod json;
mod ser;

pub use format::{Format, Named, TraceError, Variant, format_of, is_tracing, placeholder, trace};
pub use idl::{IdlError, Schema, idl_schema};
pub use json::to_json;

use serde::Serialize;
use serde::de::DeserializeOwned;

/// The encapsulation header in front of every value: plain CDR, little endian, no options.
pub const HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// What went wrong writing or reading CDR.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    #[error("{0}")]
    Custom(String),
    #[error(
        "field `{0}` is left out when it is serialized; a positional encoding needs every field"
    )]
    SkippedField(&'static str),
    #[error("{0} cannot be written in CDR")]
    Unsupported(&'static str),
    #[error("CDR is not self-describing: {0} needs the value's type")]
    NotSelfDescribing(&'static str),
    #[error("a length of {0} does not fit CDR's 32 bits")]
    TooLong(usize),
    #[error("the data ends at byte {offset} where {needed} more bytes were expected")]
    Truncated { offset: usize, needed: usize },
    #[error("not a little-endian plain CDR value (header {0:02x?})")]
    Header(Vec<u8>),
    #[error("byte {offset}: {what}")]
    Invalid { offset: usize, what: String },
    #[error("{0} bytes left over after the value")]
    TrailingBytes(usize),
}

impl serde::ser::Error for CdrError {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        CdrError::Custom(msg.to_string())
    }
}

impl serde::de::Error for CdrError {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        CdrError::Custom(msg.to_string())
    }
}

/// Serialization of `$ty` in two forms: one for text (JSON, TOML: `is_human_readable`), which
/// people read and write — an internally tagged enum such as `{ kind = "stand_up", sequence =
/// 2 }` in a motion file, or flattened fields —, and serde's default, externally tagged form
/// for binary encodings (logs), since positional CDR can neither hold a tag read before the
/// fields it selects nor fields found by name. `$text` and `$binary` are remote definitions
/// of `$ty` (`#[serde(remote = "...")]`) with those attributes; the crate using this needs
/// `serde` among its dependencies.
#[macro_export]
macro_rules! text_and_binary_forms {
    ($ty:ident, $text:ident, $binary:ident) => {
        impl ::serde::Serialize for $ty {
            fn serialize<S: ::serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                if serializer.is_human_readable() {
                    $text::serialize(self, serializer)
                } else {
                    $binary::serialize(self, serializer)
                }
            }
        }

        impl<'de> ::serde::Deserialize<'de> for $ty {
            fn deserialize<D>(deserializer: D) -> Result<$ty, D::Error>
            where
                D: ::serde::Deserializer<'de>,
            {
                if deserializer.is_human_readable() {
                    $text::deserialize(deserializer)
                } else {
                    $binary::deserialize(deserializer)
                }
            }
        }
    };
}

/// An enum with the two forms of [`text_and_binary_forms!`], written once: the enum as
/// declared, its text form with the serde attributes after `text:` (e.g. `tag = "event"`) and
/// its binary form with those after `binary:` (usually only the renaming).
///
/// ```
/// strata_runtime::text_and_binary_enum! {
///     #[derive(Clone, Debug, PartialEq)]
///     pub enum Hint {
///         Region { x: f64 },
///         Lost,
///     }
///     text: #[serde(tag = "type", rename_all = "snake_case")]
///     binary: #[serde(rename_all = "snake_case")]
/// }
/// let text = serde_json::to_string(&Hint::Region { x: 1.0 }).unwrap();
/// assert_eq!(text, r#"{"type":"region","x":1.0}"#);
/// let format = strata_runtime::cdr::trace::<Hint>().expect("CDR describes the binary form");
/// # let _ = format;
/// ```
#[macro_export]
macro_rules! text_and_binary_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident { $($body:tt)* }
        text: #[serde($($text:tt)*)]
        binary: #[serde($($binary:tt)*)]
    ) => {
        $(#[$meta])*
        $vis enum $name { $($body)* }

        const _: () = {
            // serde names the remote type by a path in a string: an alias gives it one.
            type Remote = $name;

            #[derive(::serde::Serialize, ::serde::Deserialize)]
            #[serde(remote = "Remote", $($text)*)]
            enum Text { $($body)* }

            #[derive(::serde::Serialize, ::serde::Deserialize)]
            #[serde(remote = "Remote", $($binary)*)]
            enum Binary { $($body)* }

            $crate::text_and_binary_forms!($name, Text, Binary);
        };
    };
}

/// Appends `value` to `out`: the header, then the value.
pub fn encode<T: Serialize + ?Sized>(value: &T, out: &mut Vec<u8>) -> Result<(), CdrError> {
    let start = out.len();
    out.extend_from_slice(&HEADER);
    let mut writer = ser::Writer::new(out, start + HEADER.len());
    let result = value.serialize(&mut writer);
    if result.is_err() {
        out.truncate(start);
    }
    result
}

/// Reads a value of type `T` written by [`encode`] (header included).
pub fn decode<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
    let data = payload(bytes)?;
    let mut reader = de::Reader::new(data);
    let value = T::deserialize(&mut reader)?;
    reader.finish()?;
    Ok(value)
}

/// The bytes after the encapsulation header, once it is checked.
fn payload(bytes: &[u8]) -> Result<&[u8], CdrError> {
    match bytes.get(..HEADER.len()) {
        Some(header) if header[..2] == HEADER[..2] => Ok(&bytes[HEADER.len()..]),
        Some(header) => Err(CdrError::Header(header.to_vec())),
        None => Err(CdrError::Header(bytes.to_vec())),
    }
}

#[cfg(test)]
mod tests;
