//! What may travel between modules, and how the framework handles it without knowing its type.

use std::any::Any;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::connection::{Arrival, Connection, ConnectionCounters, Policy, PolicyKind};
use crate::encoding::{Encoding, EncodingError};
use crate::package::Package;
use crate::time::Time;

/// Data that can be sent between modules.
///
/// Every package can be logged and replayed (DESIGN principle 8), hence the serde bounds.
pub trait Message: Clone + Send + Serialize + DeserializeOwned + 'static {}

impl<T> Message for T where T: Clone + Send + Serialize + DeserializeOwned + 'static {}

/// A package whose value type the framework does not know: what taps (loggers) see.
pub trait ErasedPackage: Send {
    fn stamp(&self) -> Time;
    fn seq(&self) -> u64;
    /// Appends the value, encoded.
    fn encode(&self, encoding: Encoding, out: &mut Vec<u8>) -> Result<(), EncodingError>;
    /// The value as JSON.
    fn write_json(&self, out: &mut Vec<u8>) -> Result<(), serde_json::Error>;
    /// A copy of the package, for a tap that encodes it on another thread: cloning costs the
    /// sending module far less than encoding.
    fn clone_boxed(&self) -> Box<dyn ErasedPackage>;
    fn as_any(&self) -> &dyn Any;
    fn into_any(self: Box<Self>) -> Box<dyn Any + Send>;
}

impl<T: Message> ErasedPackage for Package<T> {
    fn stamp(&self) -> Time {
        self.stamp
    }

    fn seq(&self) -> u64 {
        self.seq
    }

    fn encode(&self, encoding: Encoding, out: &mut Vec<u8>) -> Result<(), EncodingError> {
        encoding.encode(&self.value, out)
    }

    fn write_json(&self, out: &mut Vec<u8>) -> Result<(), serde_json::Error> {
        serde_json::to_writer(out, &self.value)
    }

    fn clone_boxed(&self) -> Box<dyn ErasedPackage> {
        Box::new(self.clone())
    }

    fn as_any(&self) -> &dyn Any {
        self
    }

    fn into_any(self: Box<Self>) -> Box<dyn Any + Send> {
        self
    }
}

/// The receiving end of a connection, shared between the writer's and the reader's threads.
pub(crate) trait ErasedInput: Send + Sync {
    /// Stores a clone of `package` (a `&Package<T>`); used for all readers but the last.
    fn push_cloned(&self, package: &dyn Any) -> Option<Arrival>;
    /// Stores `package` (a `Box<Package<T>>`) without cloning.
    fn push_owned(&self, package: Box<dyn Any + Send>) -> Option<Arrival>;
    /// Decodes a logged value and stores it (replay).
    fn push_encoded(
        &self,
        encoding: Encoding,
        bytes: &[u8],
        stamp: Time,
        seq: u64,
        producer: crate::ModuleId,
    ) -> Result<Arrival, EncodingError>;
    fn has_pending(&self) -> bool;
    fn counters(&self) -> ConnectionCounters;
    fn policy(&self) -> PolicyKind;
    fn as_any(&self) -> &dyn Any;
}

pub(crate) struct InputSlot<T> {
    pub(crate) connection: std::sync::Mutex<Connection<T>>,
}

impl<T> InputSlot<T> {
    pub(crate) fn new(policy: Policy<T>) -> InputSlot<T> {
        InputSlot { connection: std::sync::Mutex::new(Connection::new(policy)) }
    }

    /// A module that panicked while holding the lock leaves the data intact (the connection's
    /// operations cannot panic half-way), so a poisoned lock is safe to keep using.
    pub(crate) fn lock(&self) -> std::sync::MutexGuard<'_, Connection<T>> {
        self.connection.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl<T: Message> ErasedInput for InputSlot<T> {
    fn push_cloned(&self, package: &dyn Any) -> Option<Arrival> {
        let package = package.downcast_ref::<Package<T>>()?;
        Some(self.lock().push(package.clone()))
    }

    fn push_owned(&self, package: Box<dyn Any + Send>) -> Option<Arrival> {
        let package = package.downcast::<Package<T>>().ok()?;
        Some(self.lock().push(*package))
    }

    fn push_encoded(
        &self,
        encoding: Encoding,
        bytes: &[u8],
        stamp: Time,
        seq: u64,
        producer: crate::ModuleId,
    ) -> Result<Arrival, EncodingError> {
        let value: T = encoding.decode(bytes)?;
        Ok(self.lock().push(Package::new(value, stamp, seq, producer)))
    }

    fn has_pending(&self) -> bool {
        !self.lock().is_empty()
    }

    fn counters(&self) -> ConnectionCounters {
        self.lock().counters()
    }

    fn policy(&self) -> PolicyKind {
        self.lock().policy()
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
}
