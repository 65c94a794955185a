//! What may travel between modules, and how the framework handles it without knowing its type.

use std::any::Any;
use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::connection::{Arrival, Connection, ConnectionCounters, Policy, PolicyKind};
use crate::encoding::{Encoding, EncodingError};
use crate::package::Package;
use crate::time::Time;

/// Data that can be sent between modules.
///
/// Every package can be logged and replayed (docs/architecture.md, Principles, 8), hence the
/// serde bounds.
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
    /// The format of the value's type, for a positional encoding's schema ([`crate::cdr`]).
    fn format(&self) -> Result<crate::cdr::Format, crate::cdr::TraceError>;
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

    fn format(&self) -> Result<crate::cdr::Format, crate::cdr::TraceError> {
        crate::cdr::format_of::<T>()
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
    connection: std::sync::Mutex<Connection<T>>,
    /// Whether packages are pending, readable without the lock: a module looks at some
    /// inputs every cycle that rarely have anything (a robot's team messages, its planning
    /// layer's world commands), and locking to find nothing cost more than the rest of such a
    /// look. Written only under the lock, after every change (see [`InputSlot::modify`]), so
    /// it is exact whenever nobody holds the lock. A reader that sees `false` while a writer
    /// is pushing on another thread acts as if it had taken the lock just before the writer;
    /// the writer's wake-up reaches it after the push, and it sees `true` then.
    pending: AtomicBool,
}

impl<T> InputSlot<T> {
    pub(crate) fn new(policy: Policy<T>) -> InputSlot<T> {
        InputSlot {
            connection: std::sync::Mutex::new(Connection::new(policy)),
            pending: AtomicBool::new(false),
        }
    }

    /// A module that panicked while holding the lock leaves the data intact (the connection's
    /// operations cannot panic half-way), so a poisoned lock is safe to keep using.
    fn lock(&self) -> std::sync::MutexGuard<'_, Connection<T>> {
        self.connection.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Runs `change` on the connection under its lock and publishes whether packages are
    /// still pending: every change to the pending packages goes through here.
    pub(crate) fn modify<R>(&self, change: impl FnOnce(&mut Connection<T>) -> R) -> R {
        let mut connection = self.lock();
        let result = change(&mut connection);
        self.pending.store(!connection.is_empty(), Ordering::Release);
        result
    }

    /// Whether packages are pending, without taking the lock.
    pub(crate) fn is_pending(&self) -> bool {
        self.pending.load(Ordering::Acquire)
    }
}

impl<T: Message> ErasedInput for InputSlot<T> {
    fn push_cloned(&self, package: &dyn Any) -> Option<Arrival> {
        let package = package.downcast_ref::<Package<T>>()?.clone();
        Some(self.modify(|connection| connection.push(package)))
    }

    fn push_owned(&self, package: Box<dyn Any + Send>) -> Option<Arrival> {
        let package = package.downcast::<Package<T>>().ok()?;
        Some(self.modify(|connection| connection.push(*package)))
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
        Ok(self.modify(|connection| connection.push(Package::new(value, stamp, seq, producer))))
    }

    fn has_pending(&self) -> bool {
        self.is_pending()
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

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use crate::package::ModuleId;

    fn package(value: u32) -> Package<u32> {
        Package::new(value, Time::from_nanos(u64::from(value)), u64::from(value), ModuleId(0))
    }

    proptest! {
        /// The lock-free look at an input answers what looking under the lock answers, after
        /// any mix of arrivals and takes, whatever the policy.
        #[test]
        fn the_pending_flag_follows_the_pending_packages(
            policy in 0u8..3,
            ops in proptest::collection::vec((0u8..6, any::<u32>()), 0..200),
        ) {
            let policy = match policy {
                0 => Policy::Latest,
                1 => Policy::queue(3),
                _ => Policy::merge(|a: &mut u32, b| *a = a.wrapping_add(b)),
            };
            let slot = InputSlot::new(policy);
            prop_assert!(!slot.is_pending());
            for (op, value) in ops {
                match op {
                    0 => {
                        slot.push_owned(Box::new(package(value)));
                    }
                    1 => {
                        slot.push_cloned(&package(value));
                    }
                    2 => {
                        slot.modify(Connection::take);
                    }
                    3 => {
                        slot.modify(Connection::take_newest);
                    }
                    4 => {
                        slot.modify(Connection::drain);
                    }
                    _ => {
                        slot.push_encoded(
                            Encoding::Json,
                            value.to_string().as_bytes(),
                            Time::ZERO,
                            0,
                            ModuleId(0),
                        )
                        .map_err(|e| TestCaseError::fail(e.to_string()))?;
                    }
                }
                let locked = !slot.lock().is_empty();
                prop_assert_eq!(slot.is_pending(), locked);
                prop_assert_eq!(slot.has_pending(), locked);
            }
        }
    }
}
