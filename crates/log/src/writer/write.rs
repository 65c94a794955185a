//! How the writer thread writes a message: a package (encoded here, with the records of the
//! shared values it holds ahead of it), a record encoded where it was made, or bytes a sender
//! encoded.

use std::sync::atomic::Ordering;
use std::sync::{Arc, PoisonError};
use std::time::{Duration, Instant};

use strata_runtime::shared::{NewRecord, Recorder};
use strata_runtime::{Encoding, ErasedPackage, Time};

use super::{
    AGE_CHECK_EVERY, CdrSchema, DerivedRecords, EncodedRecord, OpenChunk, Topic, WriterThread,
    shared_channel, wrap_frame,
};

impl WriterThread {
    /// Writes the records the log's [`Derive`](crate::Derive) makes of `package`, ahead of it.
    pub(super) fn derive(&mut self, topic: &Topic, log_time: u64, package: &dyn ErasedPackage) {
        let mut records = DerivedRecords::new(self.options.encoding, self.shared.record_encoding());
        if let Some(derive) =
            self.shared.derive.lock().unwrap_or_else(PoisonError::into_inner).as_mut()
        {
            derive.package(topic.id, Time::from_nanos(log_time), package, &mut records);
        }
        self.shared.serialize_errors.fetch_add(records.unencodable, Ordering::Relaxed);
        for record in records.records {
            let topic = self.shared.record_topic(&record.topic, record.type_name);
            let seq = topic.next_seq.fetch_add(1, Ordering::Relaxed);
            let time = record.time.as_nanos();
            self.write_record(&topic, time, time, seq, &record.value);
        }
    }

    /// Writes a record encoded where it was made, with its type's IDL schema when in CDR.
    pub(super) fn write_record(
        &mut self,
        topic: &Topic,
        log_time: u64,
        stamp: u64,
        seq: u64,
        record: &EncodedRecord,
    ) {
        if let Some(named) = record.named {
            self.named_channel(topic, named);
        }
        let schema = match record.encoding {
            Encoding::Cdr => self.cdr_schema(topic, record.format),
            _ => None,
        };
        if record.encoding == Encoding::Cdr && schema.is_none() {
            // `cdr_describes` found one: cannot happen.
            self.shared.unencodable();
            return;
        }
        self.write_message(topic, record.encoding, schema, log_time, stamp, seq, &record.bytes);
    }

    pub(super) fn write_package(
        &mut self,
        topic: &Topic,
        log_time: u64,
        stamp: u64,
        seq: u64,
        package: &dyn ErasedPackage,
    ) {
        let wanted = self.options.encoding;
        let (mut encoding, mut schema) = match self.topic(topic.id).encoding {
            Some(encoding) => (encoding, self.topic(topic.id).cdr.clone()),
            None => {
                let schema = if wanted == Encoding::Cdr {
                    self.cdr_schema(topic, || package.format().ok())
                } else {
                    None
                };
                let encoding = match (wanted, &schema) {
                    (Encoding::Cdr, None) => Encoding::MessagePack,
                    _ => wanted,
                };
                let state = self.topic(topic.id);
                (state.encoding, state.cdr) = (Some(encoding), schema.clone());
                (encoding, schema)
            }
        };
        let mut encoded = std::mem::take(&mut self.encoded);
        encoded.clear();
        let mut result = package.encode(encoding, &mut encoded);
        if result.is_err() && encoding == Encoding::Cdr {
            // A value CDR cannot write (a field left out when serializing): this topic goes on
            // in MessagePack, on a channel of its own.
            encoding = Encoding::MessagePack;
            schema = None;
            let state = self.topic(topic.id);
            (state.encoding, state.cdr) = (Some(encoding), None);
            encoded.clear();
            result = package.encode(encoding, &mut encoded);
        }
        // Records of shared values seen for the first time go before the package.
        self.write_shared_records(log_time);
        match result {
            Ok(()) => self.write_message(topic, encoding, schema, log_time, stamp, seq, &encoded),
            Err(_) => self.shared.unencodable(),
        }
        self.encoded = encoded;
    }

    /// Writes the records of shared values the last encoding saw for the first time, each on
    /// the channel of its type (`shared/{type}`, metadata `strata.shared`).
    pub(super) fn write_shared_records(&mut self, log_time: u64) {
        for record in Recorder::take_new() {
            if self.error.is_some() {
                return;
            }
            self.write_shared_record(&record, log_time);
        }
    }

    pub(super) fn write_shared_record(&mut self, record: &NewRecord, log_time: u64) {
        let Some(writer) = self.writer.as_mut() else { return };
        let (channel, seq) = match self.shared_channels.get(record.type_name) {
            Some(&known) => known,
            None => {
                let (id, topic) = shared_channel(writer, record, &self.shared_topics);
                self.shared_topics.push(topic);
                (id, 0)
            }
        };
        self.shared_channels.insert(record.type_name, (channel, seq + 1));
        writer.write_message(channel, seq as u32, log_time, log_time, &record.bytes);
        self.messages += 1;
    }

    #[allow(clippy::too_many_arguments)]
    pub(super) fn write_message(
        &mut self,
        topic: &Topic,
        encoding: Encoding,
        schema: Option<Arc<CdrSchema>>,
        log_time: u64,
        stamp: u64,
        seq: u64,
        value: &[u8],
    ) {
        if self.error.is_some() {
            self.shared.drop_record(topic);
            return;
        }
        let channel = self.channel(topic, encoding, schema.as_deref(), value);
        let payload = if channel.wrapped {
            let (prefix, suffix) = wrap_frame(encoding);
            self.scratch.clear();
            self.scratch.extend_from_slice(prefix);
            self.scratch.extend_from_slice(value);
            self.scratch.extend_from_slice(suffix);
            &self.scratch[..]
        } else {
            value
        };
        let Some(writer) = self.writer.as_mut() else { return };
        // MCAP sequences are 32 bits; readers unwrap them per channel.
        writer.write_message(channel.id, seq as u32, log_time, stamp, payload);
        self.messages += 1;
        let full = writer.chunk_full();
        let chunk = self.chunk.get_or_insert_with(|| OpenChunk {
            first_log_time: log_time,
            opened: Instant::now(),
            messages: 0,
        });
        chunk.messages += 1;
        let span = Duration::from_nanos(log_time.saturating_sub(chunk.first_log_time));
        if full
            || span >= self.options.max_chunk_span
            || (chunk.messages.is_multiple_of(AGE_CHECK_EVERY)
                && chunk.opened.elapsed() >= self.options.max_chunk_age)
        {
            self.close_chunk();
        }
    }
}
