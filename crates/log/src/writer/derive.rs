//! Records a log derives from its packages on the writer thread ([`Derive`]).

use serde::Serialize;
use strata_runtime::{Encoding, ErasedPackage, Time};

use super::{EncodedRecord, RecordSchema};

/// Records a log derives from its packages on the writer thread: what it holds besides the
/// packages (a robot's active behavior path, the game state), worked out where it costs the
/// sending modules' cycles nothing. The records of a package are written just ahead of it, as
/// if its sender had recorded them.
pub trait Derive: Send {
    /// Whether the packages of `topic` go through [`Derive::package`]. Asked once per package
    /// topic, when it is created; `id` is the number `package` calls it by (dense from 0,
    /// shared with the record topics). The writer thread needs these packages whole: their
    /// senders clone them instead of encoding them.
    fn wants(&mut self, id: u32, topic: &str, type_name: &str) -> bool;

    /// A package of a topic this wants, visible at `time`, before it is written.
    fn package(
        &mut self,
        topic: u32,
        time: Time,
        package: &dyn ErasedPackage,
        records: &mut DerivedRecords,
    );

    /// The log goes on in a new file (its size cap,
    /// [`McapTapOptions::max_file_size`](crate::McapTapOptions::max_file_size)): records
    /// written only when something changes should be written again, so that each file holds
    /// them. Nothing by default.
    fn next_file(&mut self) {}
}

/// Where a [`Derive`] puts the records it makes of a package.
#[derive(Debug)]
pub struct DerivedRecords {
    /// The log's encoding of packages.
    pub(super) encoding: Encoding,
    /// The self-describing encoding: the log's own when it is one, otherwise for the values
    /// CDR cannot write.
    pub(super) fallback: Encoding,
    pub(super) records: Vec<DerivedRecord>,
    pub(super) unencodable: u64,
}

#[derive(Debug)]
pub(super) struct DerivedRecord {
    pub(super) topic: String,
    pub(super) type_name: &'static str,
    pub(super) time: Time,
    pub(super) value: EncodedRecord,
}

impl DerivedRecords {
    pub(super) fn new(encoding: Encoding, fallback: Encoding) -> DerivedRecords {
        DerivedRecords { encoding, fallback, records: Vec::new(), unencodable: 0 }
    }

    /// Records `value` on `topic` at `time`, in the log's encoding like a package of its type
    /// (CDR with an IDL schema by default, so that generic tools read it), or in a
    /// self-describing one when CDR cannot write it.
    pub fn record_value<T>(&mut self, topic: &str, time: Time, value: &T)
    where
        T: Serialize + serde::de::DeserializeOwned + 'static,
    {
        let Some(value) = EncodedRecord::of(value, self.encoding, self.fallback) else {
            self.unencodable += 1;
            return;
        };
        let type_name = std::any::type_name::<T>();
        self.records.push(DerivedRecord { topic: topic.to_owned(), type_name, time, value });
    }

    /// Records `value` on `topic` at `time` in JSON (message encoding `json`), on a channel
    /// whose schema is `schema` (encoding `jsonschema`) whatever the log's encoding: for
    /// messages of another project's definitions, such as Foxglove's `foxglove.SceneUpdate`,
    /// which its tools recognize by the schema's name. The value's JSON must follow the schema.
    pub fn record_json<T: Serialize + ?Sized>(
        &mut self,
        topic: &str,
        time: Time,
        schema: RecordSchema,
        value: &T,
    ) {
        let Some(value) = EncodedRecord::json_with_schema(value, schema) else {
            self.unencodable += 1;
            return;
        };
        self.records.push(DerivedRecord {
            topic: topic.to_owned(),
            type_name: schema.name,
            time,
            value,
        });
    }
}
