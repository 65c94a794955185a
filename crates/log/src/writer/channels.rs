//! The MCAP channels and schemas the writer thread creates: one channel per topic and
//! encoding, one per shared value type.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::sync::Arc;

use strata_runtime::Encoding;
use strata_runtime::cdr::{Format, idl_schema};
use strata_runtime::shared::NewRecord;

use crate::mcap_file::McapFile;
use crate::schema::infer_json_schema;
use crate::{FORMAT_KEY, PUBLISH_TIME_KEY, SHARED_KEY, WRAP_FIELD, WRAPPED_KEY};

use super::{CdrSchema, RecordSchema, Topic, WriterThread, is_map};

/// A topic's channel in one encoding, and whether its messages are wrapped.
#[derive(Clone, Copy, Debug)]
pub(super) struct ChannelState {
    pub(super) id: u16,
    pub(super) wrapped: bool,
}

/// Creates the channel of a shared value type: `shared/{type}` (the type's last path segment;
/// `_2`, `_3`… when another type has that name), its record's schema, metadata
/// `strata.shared`.
pub(super) fn shared_channel(
    writer: &mut McapFile<BufWriter<File>>,
    record: &NewRecord,
    taken: &[String],
) -> (u16, String) {
    let short = record.type_name.split('<').next().unwrap_or(record.type_name);
    let short = short.rsplit("::").next().unwrap_or(short);
    let mut topic = format!("shared/{short}");
    let mut k = 2;
    while taken.contains(&topic) {
        topic = format!("shared/{short}_{k}");
        k += 1;
    }
    let mut metadata = BTreeMap::from([
        ("type_name".to_owned(), format!("strata_runtime::shared::Record<{}>", record.type_name)),
        (SHARED_KEY.to_owned(), "true".to_owned()),
    ]);
    let idl = record.format.as_ref().and_then(|format| {
        let json = serde_json::to_string(format).ok()?;
        Some((idl_schema(format, "SharedRecord").ok()?, json))
    });
    let schema_id = match (idl, record.encoding) {
        (Some((idl, json)), Encoding::Cdr) => {
            metadata.insert(FORMAT_KEY.to_owned(), json);
            writer.add_schema(&idl.name, "omgidl", idl.text.as_bytes())
        }
        _ => {
            let sample = record.encoding.decode(&record.bytes).unwrap_or(serde_json::Value::Null);
            let schema = infer_json_schema(record.type_name, &sample);
            let data = serde_json::to_vec(&schema).unwrap_or_default();
            writer.add_schema(record.type_name, "jsonschema", &data)
        }
    };
    let id = writer.add_channel(schema_id, &topic, record.encoding.mcap_name(), &metadata);
    (id, topic)
}

impl WriterThread {
    /// Creates the JSON channel of a topic whose records have a schema of their own (see
    /// [`RecordSchema`]), unless it exists in this file.
    pub(super) fn named_channel(&mut self, topic: &Topic, named: RecordSchema) {
        if self.topic(topic.id).channel(Encoding::Json).is_some() {
            return;
        }
        let Some(writer) = self.writer.as_mut() else { return };
        let key = (named.name.to_owned(), Encoding::Json, false);
        let schema_id = match self.schemas.get(&key) {
            Some(&id) => id,
            None => {
                let id = writer.add_schema(named.name, "jsonschema", named.json_schema.as_bytes());
                self.schemas.insert(key, id);
                id
            }
        };
        let metadata = BTreeMap::from([("type_name".to_owned(), named.name.to_owned())]);
        let id = writer.add_channel(schema_id, &topic.name, Encoding::Json.mcap_name(), &metadata);
        let state = self.topic(topic.id);
        *state.channel(Encoding::Json) = Some(ChannelState { id, wrapped: false });
        state.logged = true;
    }

    /// The CDR schema of a topic's type (a package's or a record's), worked out from `format`
    /// on its first value.
    pub(super) fn cdr_schema(
        &mut self,
        topic: &Topic,
        format: impl FnOnce() -> Option<Format>,
    ) -> Option<Arc<CdrSchema>> {
        if let Some(known) = self.cdr_schemas.get(&topic.type_name) {
            return known.clone();
        }
        let schema = format().and_then(|format| CdrSchema::of(&format, &topic.type_name));
        self.cdr_schemas.insert(topic.type_name.clone(), schema.clone());
        schema
    }

    /// The channel of a topic in an encoding, created on its first message. A CDR channel
    /// has the type's IDL schema and its format (metadata `strata.format`, for Strata's own
    /// readers). Generic tools take self-describing messages that are objects (maps): a topic
    /// whose first value is not one (a number, a tuple, a unit enum variant) has every value
    /// wrapped as `{"value": ...}`, which the channel's metadata records and readers undo.
    pub(super) fn channel(
        &mut self,
        topic: &Topic,
        encoding: Encoding,
        cdr: Option<&CdrSchema>,
        sample: &[u8],
    ) -> ChannelState {
        if let Some(channel) = *self.topic(topic.id).channel(encoding) {
            return channel;
        }
        let Some(writer) = self.writer.as_mut() else {
            return ChannelState { id: 0, wrapped: false };
        };
        let mut metadata = BTreeMap::from([
            ("type_name".to_owned(), topic.type_name.clone()),
            (PUBLISH_TIME_KEY.to_owned(), "stamp".to_owned()),
        ]);
        let (schema_id, wrapped) = match (encoding, cdr) {
            (Encoding::Cdr, Some(cdr)) => {
                metadata.insert(FORMAT_KEY.to_owned(), cdr.format_json.clone());
                let key = (topic.type_name.clone(), encoding, false);
                let id = match self.schemas.get(&key) {
                    Some(&id) => id,
                    None => {
                        let id =
                            writer.add_schema(&cdr.idl.name, "omgidl", cdr.idl.text.as_bytes());
                        self.schemas.insert(key, id);
                        id
                    }
                };
                (id, false)
            }
            _ => {
                let wrapped = !is_map(encoding, sample);
                let key = (topic.type_name.clone(), encoding, wrapped);
                let id = match self.schemas.get(&key) {
                    Some(&id) => id,
                    None => {
                        let sample = encoding.decode(sample).unwrap_or(serde_json::Value::Null);
                        let sample = if wrapped {
                            serde_json::json!({ WRAP_FIELD: sample })
                        } else {
                            sample
                        };
                        let schema = infer_json_schema(&topic.type_name, &sample);
                        let data = serde_json::to_vec(&schema).unwrap_or_default();
                        let id = writer.add_schema(&topic.type_name, "jsonschema", &data);
                        self.schemas.insert(key, id);
                        id
                    }
                };
                if wrapped {
                    metadata.insert(WRAPPED_KEY.to_owned(), WRAP_FIELD.to_owned());
                }
                (id, wrapped)
            }
        };
        let id = writer.add_channel(schema_id, &topic.name, encoding.mcap_name(), &metadata);
        let channel = ChannelState { id, wrapped };
        let state = self.topic(topic.id);
        *state.channel(encoding) = Some(channel);
        state.logged = true;
        channel
    }
}
