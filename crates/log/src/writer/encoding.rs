//! How values are encoded for the log: wrapping of values that are not maps, records encoded
//! where they are made, and the CDR schemas of types.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use serde::Serialize;
use strata_runtime::Encoding;
use strata_runtime::cdr::{Format, Schema, idl_schema};
use strata_runtime::shared;

/// How a wrapped message is framed in each encoding (see `WriterThread::channel`): the bytes of a
/// one-entry map with the key [`WRAP_FIELD`](crate::WRAP_FIELD) in front of the value, and what
/// closes it. CDR values are never wrapped: their schema declares the wrapping struct, whose bytes
/// are the value's own.
pub(crate) fn wrap_frame(encoding: Encoding) -> (&'static [u8], &'static [u8]) {
    match encoding {
        Encoding::Json => (b"{\"value\":", b"}"),
        // fixmap of one entry, then fixstr "value".
        Encoding::MessagePack => (b"\x81\xa5value", b""),
        Encoding::Cdr => (b"", b""),
    }
}

/// Whether an encoded value is a map (an object), as generic tools expect messages to be.
pub(super) fn is_map(encoding: Encoding, bytes: &[u8]) -> bool {
    match (encoding, bytes.first()) {
        (Encoding::Json, Some(first)) => *first == b'{',
        // fixmap, map 16, map 32.
        (Encoding::MessagePack, Some(first)) => matches!(first, 0x80..=0x8f | 0xde | 0xdf),
        (Encoding::Cdr, _) => true,
        (_, None) => false,
    }
}

/// A record's value, encoded where it was made.
#[derive(Debug)]
pub(super) struct EncodedRecord {
    pub(super) encoding: Encoding,
    /// The type's format, for a CDR record's channel schema (traced once per type).
    pub(super) format: fn() -> Option<Format>,
    /// The schema the record's channel is given instead of one worked out from its type: a
    /// message of another project's schema (`foxglove.SceneUpdate`), which generic tools
    /// recognize by its name.
    pub(super) named: Option<RecordSchema>,
    pub(super) bytes: Vec<u8>,
}

/// A schema given by name and text rather than traced from a Rust type: for records of
/// another project's message definitions, which tools recognize by their schema's name
/// (Foxglove draws `foxglove.SceneUpdate` in its 3D panel). See
/// [`DerivedRecords::record_json`](crate::DerivedRecords::record_json).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordSchema {
    /// The schema's name (MCAP schema `name`), e.g. `foxglove.SceneUpdate`.
    pub name: &'static str,
    /// The schema in JSON Schema (MCAP schema encoding `jsonschema`).
    pub json_schema: &'static str,
}

impl EncodedRecord {
    /// `value` in `encoding` when that is CDR and CDR describes `T` (an IDL schema for generic
    /// tools), otherwise in the self-describing `fallback`; `None` when it cannot be encoded.
    pub(super) fn of<T>(value: &T, encoding: Encoding, fallback: Encoding) -> Option<EncodedRecord>
    where
        T: Serialize + serde::de::DeserializeOwned + 'static,
    {
        let format: fn() -> Option<Format> = || strata_runtime::cdr::format_of::<T>().ok();
        let mut bytes = Vec::with_capacity(256);
        let in_cdr = encoding == Encoding::Cdr
            && cdr_describes::<T>()
            && Encoding::Cdr.encode(value, &mut bytes).is_ok();
        let encoding = if in_cdr { Encoding::Cdr } else { fallback };
        if !in_cdr {
            bytes.clear();
            encoding.encode(value, &mut bytes).ok()?;
        }
        Some(EncodedRecord { encoding, format, named: None, bytes })
    }

    /// `value` in JSON, for a channel with the given schema.
    pub(super) fn json_with_schema<T: Serialize + ?Sized>(
        value: &T,
        schema: RecordSchema,
    ) -> Option<EncodedRecord> {
        let mut bytes = Vec::with_capacity(1024);
        serde_json::to_writer(&mut bytes, value).ok()?;
        Some(EncodedRecord {
            encoding: Encoding::Json,
            format: || None,
            named: Some(schema),
            bytes,
        })
    }

    /// A value without a type to trace (a `serde_json::Value`), in a self-describing encoding.
    pub(super) fn untyped<T: Serialize + ?Sized>(
        value: &T,
        encoding: Encoding,
    ) -> Option<EncodedRecord> {
        let mut bytes = Vec::with_capacity(256);
        encoding.encode(value, &mut bytes).ok()?;
        Some(EncodedRecord { encoding, format: || None, named: None, bytes })
    }
}

/// Whether a record of type `T` (application or derived) can go in CDR: its format traces to
/// an IDL schema, and it holds no shared value (which would be written as a reference to a
/// record of its own; records keep them inline, in the self-describing encoding). Worked out
/// once per type.
pub(super) fn cdr_describes<T: serde::de::DeserializeOwned + 'static>() -> bool {
    type Known = Mutex<HashMap<std::any::TypeId, bool>>;
    static KNOWN: OnceLock<Known> = OnceLock::new();
    let known = KNOWN.get_or_init(Default::default);
    let id = std::any::TypeId::of::<T>();
    if let Some(&describes) = known.lock().unwrap_or_else(PoisonError::into_inner).get(&id) {
        return describes;
    }
    let describes = strata_runtime::cdr::format_of::<T>().is_ok_and(|format| {
        !shared::appears_in(&format) && idl_schema(&format, std::any::type_name::<T>()).is_ok()
    });
    known.lock().unwrap_or_else(PoisonError::into_inner).insert(id, describes);
    describes
}

/// How a package type is logged in CDR: its schema, and its format for the channel metadata.
#[derive(Debug)]
pub(super) struct CdrSchema {
    pub(super) idl: Schema,
    pub(super) format_json: String,
}

impl CdrSchema {
    pub(super) fn of(format: &Format, type_name: &str) -> Option<Arc<CdrSchema>> {
        let idl = idl_schema(format, type_name).ok()?;
        let format_json = serde_json::to_string(format).ok()?;
        Some(Arc::new(CdrSchema { idl, format_json }))
    }
}
