//! [`Shared`]: a part of a package that rarely changes (a world model's layout of objects, a
//! score vector's goals), written into a log once and referred to by every later package that
//! holds it, as ROS keeps static transforms on a latched topic.
//!
//! A match sends the same layout of forty objects with each of its world states, thirty times
//! a second per robot: logged in full every time, it would be most of the log, for no
//! information. So a `Shared` value serializes in one of two ways:
//!
//! - **inline**, the value itself, wherever nothing records shared values (JSON for a
//!   viewer, a test): the bytes stand alone;
//! - **by reference**, its id, on a thread where a [`Recorder`] is installed (a log's writer):
//!   the recorder hands the value's record (id and value) to the log the first time it sees
//!   it, and the log holds that record before the first package that refers to it.
//!
//! Reading a reference looks the id up in this process's [registry](register), which a log
//! reader fills with the log's records when it opens the file. The id is a hash of the
//! record's bytes: the same value gets the same id whoever writes it.

use std::any::{Any, TypeId};
use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex, PoisonError};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::cdr;
use crate::encoding::Encoding;

/// A rarely changing value shared by many packages; see the module documentation. Reads as
/// the value (`Deref`); two are equal when their values are.
pub struct Shared<T>(Arc<T>);

impl<T> Shared<T> {
    pub fn new(value: T) -> Shared<T> {
        Shared(Arc::new(value))
    }

    pub fn from_arc(value: Arc<T>) -> Shared<T> {
        Shared(value)
    }

    pub fn arc(&self) -> &Arc<T> {
        &self.0
    }

    /// Whether both hold the very same value (not only an equal one).
    pub fn ptr_eq(&self, other: &Shared<T>) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl<T> Clone for Shared<T> {
    fn clone(&self) -> Self {
        Shared(Arc::clone(&self.0))
    }
}

impl<T> std::ops::Deref for Shared<T> {
    type Target = T;

    fn deref(&self) -> &T {
        &self.0
    }
}

impl<T: PartialEq> PartialEq for Shared<T> {
    fn eq(&self, other: &Shared<T>) -> bool {
        Arc::ptr_eq(&self.0, &other.0) || *self.0 == *other.0
    }
}

impl<T: std::fmt::Debug> std::fmt::Debug for Shared<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

impl<T: Default> Default for Shared<T> {
    fn default() -> Self {
        Shared::new(T::default())
    }
}

/// How a [`Shared`] value is written: the value, or the id of its record.
#[derive(Serialize, Deserialize)]
#[serde(rename = "Shared", rename_all = "snake_case")]
enum Form<T> {
    Inline(T),
    Reference(u64),
}

/// Whether values of `format` may hold a [`Shared`] value (whose serialization depends on the
/// thread's [`Recorder`]).
pub fn appears_in(format: &cdr::Format) -> bool {
    use cdr::{Format, Variant};
    match format {
        Format::Enum { name, variants } => {
            (name == "Shared"
                && variants.len() == 2
                && variants[0].name == "inline"
                && variants[1].name == "reference")
                || variants.iter().any(|v| match &v.value {
                    Variant::Unit => false,
                    Variant::Newtype(f) => appears_in(f),
                    Variant::Tuple(fs) => fs.iter().any(appears_in),
                    Variant::Struct(fs) => fs.iter().any(|f| appears_in(&f.value)),
                })
        }
        Format::Option(inner) | Format::Seq(inner) | Format::Newtype { inner, .. } => {
            appears_in(inner)
        }
        Format::Array { element, .. } => appears_in(element),
        Format::Map { key, value } => appears_in(key) || appears_in(value),
        Format::Tuple(elements) | Format::TupleStruct { elements, .. } => {
            elements.iter().any(appears_in)
        }
        Format::Struct { fields, .. } => fields.iter().any(|f| appears_in(&f.value)),
        _ => false,
    }
}

/// What a log stores once per shared value: the value with its id, so that a reader of the
/// log alone (a generic tool) can match references to values.
#[derive(Debug, Serialize, Deserialize)]
#[serde(rename = "SharedRecord")]
pub struct Record<T> {
    pub id: u64,
    pub value: T,
}

impl<T> Serialize for Shared<T>
where
    T: Serialize + DeserializeOwned + Send + Sync + 'static,
{
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match Recorder::reference(&self.0) {
            Some(id) => Form::<&T>::Reference(id).serialize(serializer),
            None => Form::Inline(&*self.0).serialize(serializer),
        }
    }
}

impl<'de, T> Deserialize<'de> for Shared<T>
where
    T: Serialize + DeserializeOwned + Send + Sync + 'static,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        match Form::<T>::deserialize(deserializer)? {
            Form::Inline(value) => Ok(Shared::new(value)),
            // A trace reads placeholders, not a log: there is nothing to look up.
            Form::Reference(_) if cdr::is_tracing() => {
                cdr::placeholder::<T>().map(Shared::new).map_err(serde::de::Error::custom)
            }
            Form::Reference(id) => resolve::<T>(id).map(Shared).map_err(serde::de::Error::custom),
        }
    }
}

/// A shared value the recorder saw for the first time: what the log must store.
#[derive(Debug)]
pub struct NewRecord {
    pub id: u64,
    /// The value's Rust type.
    pub type_name: &'static str,
    /// The [`Record`]'s encoding: CDR when the type can be traced, MessagePack otherwise.
    pub encoding: Encoding,
    /// The record's format (CDR only).
    pub format: Option<cdr::Format>,
    /// The encoded [`Record`].
    pub bytes: Vec<u8>,
}

/// Hashes a number with one multiplication: the recorder's keys are addresses and content
/// hashes, already spread, and it is asked for every shared value a log writes.
#[derive(Clone, Copy, Default)]
struct NumberHasher(u64);

impl std::hash::Hasher for NumberHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for byte in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(*byte)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }

    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0 ^ n).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }

    fn write_usize(&mut self, n: usize) {
        self.write_u64(n as u64);
    }
}

type NumberMap<K, V> = HashMap<K, V, std::hash::BuildHasherDefault<NumberHasher>>;

/// Turns shared values into references on the thread it is installed on (a log's writer),
/// remembering which records the log already holds.
#[derive(Default)]
pub struct Recorder {
    /// Ids the log already holds (or a replay's log holds).
    known: HashSet<u64, std::hash::BuildHasherDefault<NumberHasher>>,
    /// Values seen lately, by address, with their id: a value kept alive here keeps its
    /// address, so an address names one value for as long as it is remembered.
    seen: NumberMap<usize, (Arc<dyn Any + Send + Sync>, u64)>,
    /// Records to store before the package being written.
    new: Vec<NewRecord>,
    /// Formats of the types seen, traced once each.
    formats: HashMap<TypeId, Option<cdr::Format>>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("known", &self.known.len())
            .field("remembered", &self.seen.len())
            .field("new", &self.new.len())
            .finish()
    }
}

/// How many values the recorder remembers by address before it forgets them all (shared
/// values are few: a layout per robot, a goal list per score vector).
const REMEMBERED: usize = 512;

thread_local! {
    static RECORDER: std::cell::RefCell<Option<Recorder>> = const { std::cell::RefCell::new(None) };
}

impl Recorder {
    /// A recorder for a log that already holds the records `known` (a replay comparing its
    /// packages with a log's: equal values become the same references).
    pub fn knowing(known: impl IntoIterator<Item = u64>) -> Recorder {
        Recorder { known: known.into_iter().collect(), ..Recorder::default() }
    }

    /// Installs this recorder on the current thread (replacing and returning the previous
    /// one): shared values serialized on this thread become references.
    pub fn install(self) -> Option<Recorder> {
        RECORDER.with(|r| r.borrow_mut().replace(self))
    }

    /// Removes the current thread's recorder.
    pub fn uninstall() -> Option<Recorder> {
        RECORDER.with(|r| r.borrow_mut().take())
    }

    /// The records the installed recorder saw for the first time since the last call: a log
    /// writes them before the package whose encoding produced them.
    pub fn take_new() -> Vec<NewRecord> {
        RECORDER
            .with(|r| r.borrow_mut().as_mut().map(|rec| std::mem::take(&mut rec.new)))
            .unwrap_or_default()
    }

    /// The id to write for `value`, when a recorder is installed on this thread.
    fn reference<T>(value: &Arc<T>) -> Option<u64>
    where
        T: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        // Taken out while it works: a shared value inside this one is then written inline
        // into this one's record instead of finding the recorder borrowed.
        let mut recorder = RECORDER.with(|r| r.borrow_mut().take())?;
        let id = recorder.id_of(value);
        RECORDER.with(|r| *r.borrow_mut() = Some(recorder));
        id
    }

    fn id_of<T>(&mut self, value: &Arc<T>) -> Option<u64>
    where
        T: Serialize + DeserializeOwned + Send + Sync + 'static,
    {
        let address = Arc::as_ptr(value) as *const () as usize;
        if let Some((_, id)) = self.seen.get(&address) {
            return Some(*id);
        }
        let format = self
            .formats
            .entry(TypeId::of::<T>())
            .or_insert_with(|| cdr::trace::<Record<T>>().ok())
            .clone();
        let encoding = if format.is_some() { Encoding::Cdr } else { Encoding::MessagePack };
        // The id is the hash of the value's bytes: the record's own bytes depend on the id.
        let mut bytes = Vec::new();
        encoding.encode(&**value, &mut bytes).ok()?;
        let id = content_id(&bytes);
        if self.known.insert(id) {
            bytes.clear();
            encoding.encode(&Record { id, value: &**value }, &mut bytes).ok()?;
            self.new.push(NewRecord {
                id,
                type_name: std::any::type_name::<T>(),
                encoding,
                format,
                bytes,
            });
        }
        if self.seen.len() >= REMEMBERED {
            self.seen.clear();
        }
        let keep: Arc<dyn Any + Send + Sync> = value.clone();
        self.seen.insert(address, (keep, id));
        Some(id)
    }
}

/// FNV-1a over the bytes, 64 bits: stable across builds and platforms.
fn content_id(bytes: &[u8]) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in bytes {
        hash ^= u64::from(*byte);
        hash = hash.wrapping_mul(0x0100_0000_01b3);
    }
    hash
}

/// A record in the registry: its bytes, and the values decoded from them by type.
struct Registered {
    encoding: Encoding,
    bytes: Arc<[u8]>,
    decoded: Vec<(TypeId, Arc<dyn Any + Send + Sync>)>,
}

fn registry() -> &'static Mutex<HashMap<u64, Registered>> {
    static REGISTRY: std::sync::OnceLock<Mutex<HashMap<u64, Registered>>> =
        std::sync::OnceLock::new();
    REGISTRY.get_or_init(Default::default)
}

/// Makes the record `id` (an encoded [`Record`]) available to references read in this
/// process: log readers call it for every record of a log they open. A record registered
/// again replaces the earlier one.
pub fn register(id: u64, encoding: Encoding, bytes: &[u8]) {
    let mut registry = registry().lock().unwrap_or_else(PoisonError::into_inner);
    let same = registry.get(&id).is_some_and(|r| r.encoding == encoding && *r.bytes == *bytes);
    if !same {
        registry.insert(id, Registered { encoding, bytes: bytes.into(), decoded: Vec::new() });
    }
}

/// Whether a record with this id is registered.
pub fn is_registered(id: u64) -> bool {
    registry().lock().unwrap_or_else(PoisonError::into_inner).contains_key(&id)
}

/// The ids of every registered record.
pub fn registered_ids() -> Vec<u64> {
    registry().lock().unwrap_or_else(PoisonError::into_inner).keys().copied().collect()
}

/// The value a reference names.
fn resolve<T>(id: u64) -> Result<Arc<T>, String>
where
    T: Serialize + DeserializeOwned + Send + Sync + 'static,
{
    let (encoding, bytes) = {
        let registry = registry().lock().unwrap_or_else(PoisonError::into_inner);
        let Some(record) = registry.get(&id) else {
            return Err(format!(
                "shared value {id:016x} ({}) is not in the log: its record is missing",
                std::any::type_name::<T>()
            ));
        };
        if let Some((_, value)) = record.decoded.iter().find(|(t, _)| *t == TypeId::of::<T>())
            && let Ok(value) = Arc::clone(value).downcast::<T>()
        {
            return Ok(value);
        }
        (record.encoding, Arc::clone(&record.bytes))
    };
    // Decoded without the lock: the value may hold references itself.
    let record: Record<T> = encoding
        .decode(&bytes)
        .map_err(|e| format!("shared value {id:016x} ({}): {e}", std::any::type_name::<T>()))?;
    if record.id != id {
        return Err(format!("shared value {id:016x} is stored under id {:016x}", record.id));
    }
    let value = Arc::new(record.value);
    let mut registry = registry().lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(entry) = registry.get_mut(&id) {
        let any: Arc<dyn Any + Send + Sync> = value.clone();
        entry.decoded.push((TypeId::of::<T>(), any));
    }
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct Layout {
        names: Vec<String>,
    }

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct State {
        stamp: u64,
        layout: Shared<Layout>,
    }

    fn state(stamp: u64, layout: &Shared<Layout>) -> State {
        State { stamp, layout: layout.clone() }
    }

    #[test]
    fn without_a_recorder_the_value_is_written_inline() {
        let layout = Shared::new(Layout { names: vec!["ball".into()] });
        let json = serde_json::to_value(state(1, &layout)).expect("json");
        assert_eq!(json["layout"], serde_json::json!({ "inline": { "names": ["ball"] } }));
        let back: State = serde_json::from_value(json).expect("back");
        assert_eq!(back, state(1, &layout));
    }

    #[test]
    fn a_recorder_stores_each_value_once_and_references_it() {
        let layout = Shared::new(Layout { names: vec!["ball".into(), "goal".into()] });
        let equal = Shared::new((*layout).clone());
        let other = Shared::new(Layout { names: vec!["robot".into()] });
        let previous = Recorder::default().install();
        let mut encoded = Vec::new();
        let mut records = Vec::new();
        for (i, l) in [&layout, &layout, &equal, &other, &layout].into_iter().enumerate() {
            let mut bytes = Vec::new();
            Encoding::Cdr.encode(&state(i as u64, l), &mut bytes).expect("encode");
            encoded.push(bytes);
            records.extend(Recorder::take_new());
        }
        Recorder::uninstall();
        if let Some(previous) = previous {
            previous.install();
        }
        // One record per distinct value, equal values included.
        assert_eq!(records.len(), 2);
        assert!(records.iter().all(|r| r.encoding == Encoding::Cdr && r.format.is_some()));
        assert_ne!(records[0].id, records[1].id);
        // Packages are small: the layout is not in them.
        assert!(encoded.iter().all(|b| b.len() < 32), "{:?}", encoded);
        assert_eq!(encoded[0][8..], encoded[2][8..], "equal values, same reference");
        for record in &records {
            register(record.id, record.encoding, &record.bytes);
        }
        for (i, (bytes, l)) in
            encoded.iter().zip([&layout, &layout, &equal, &other, &layout]).enumerate()
        {
            let back: State = Encoding::Cdr.decode(bytes).expect("decode");
            assert_eq!(back, state(i as u64, l));
        }
    }

    #[test]
    fn a_type_holding_a_shared_value_traces_and_says_so() {
        let state = cdr::trace::<State>().expect("traced, references and all");
        assert!(appears_in(&state));
        assert!(!appears_in(&cdr::trace::<Layout>().expect("traced")));
        assert!(appears_in(&cdr::trace::<Vec<Option<State>>>().expect("traced")));
    }

    #[test]
    fn an_unknown_reference_is_an_error_that_says_so() {
        let bytes = {
            let mut bytes = Vec::new();
            Encoding::Cdr
                .encode(&(5u64, Form::<Layout>::Reference(0x1234_5678_9abc_def0)), &mut bytes)
                .expect("encode");
            bytes
        };
        let error = Encoding::Cdr.decode::<(u64, Shared<Layout>)>(&bytes).expect_err("unknown");
        assert!(error.to_string().contains("123456789abcdef0"), "{error}");
        assert!(error.to_string().contains("not in the log"), "{error}");
    }

    #[test]
    fn a_replay_recorder_references_what_the_log_holds() {
        let layout = Shared::new(Layout { names: vec!["post".into()] });
        let mut bytes = Vec::new();
        Encoding::Cdr.encode(&*layout, &mut bytes).expect("encode");
        let id = content_id(&bytes);
        Recorder::knowing([id]).install();
        let mut package = Vec::new();
        Encoding::Cdr.encode(&state(3, &layout), &mut package).expect("encode");
        assert!(Recorder::take_new().is_empty(), "the log already holds it");
        Recorder::uninstall();
        assert!(package.len() < 32);
    }
}
