//! Taps see every package a host delivers: the hook loggers and viewers attach to.

use crate::message::ErasedPackage;
use crate::package::ModuleId;
use crate::time::Time;

/// One package as it becomes visible to its readers.
#[derive(Clone, Copy)]
pub struct TapRecord<'a> {
    /// When the package became visible (host time).
    pub time: Time,
    pub module: ModuleId,
    pub module_name: &'a str,
    pub output: &'a str,
    pub type_name: &'static str,
    pub package: &'a dyn ErasedPackage,
}

impl std::fmt::Debug for TapRecord<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TapRecord")
            .field("time", &self.time)
            .field("module", &self.module_name)
            .field("output", &self.output)
            .field("seq", &self.package.seq())
            .finish()
    }
}

/// Receives every package sent on every output. Called on the sending module's thread, inside
/// its cycle: an implementation must not block (hand the record to a bounded background
/// writer and count what it drops).
pub trait Tap: Send + Sync {
    fn package(&self, record: &TapRecord<'_>);
}

/// Several taps on one host (a host holds one): each sees every record, in order.
#[derive(Clone, Default)]
pub struct Taps(pub Vec<std::sync::Arc<dyn Tap>>);

impl std::fmt::Debug for Taps {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Taps").field("count", &self.0.len()).finish()
    }
}

impl Tap for Taps {
    fn package(&self, record: &TapRecord<'_>) {
        for tap in &self.0 {
            tap.package(record);
        }
    }
}
