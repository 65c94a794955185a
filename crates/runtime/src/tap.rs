//! Taps see the packages a host delivers: the hook loggers and viewers attach to.

use crate::message::ErasedPackage;
use crate::package::ModuleId;
use crate::time::Time;

/// One package as it becomes visible to its readers.
#[derive(Clone, Copy)]
pub struct TapRecord<'a> {
    /// When the package became visible (host time).
    pub time: Time,
    /// A number unique to the host in this process: with `module` and `port` it names the
    /// output without comparing names, for a tap that sees several hosts.
    pub host: u64,
    pub module: ModuleId,
    pub module_name: &'a str,
    /// The output's place among its module's outputs.
    pub port: u16,
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

/// An output as a tap is asked about it, before any package: see [`Tap::wants`].
#[derive(Clone, Copy, Debug)]
pub struct TapOutput<'a> {
    pub module: ModuleId,
    pub module_name: &'a str,
    pub output: &'a str,
    pub type_name: &'static str,
}

/// Receives the packages sent on the outputs it wants (by default, every output). Called on
/// the sending module's thread, inside its cycle: an implementation must not block (hand the
/// record to a bounded background writer and count what it drops).
pub trait Tap: Send + Sync {
    fn package(&self, record: &TapRecord<'_>);

    /// Whether this tap wants the packages of `output`. A host asks once per output when the
    /// tap is set (before its first package) and then does not even build the records of the
    /// outputs nobody wants: a match sends about a million packages per simulated minute,
    /// and a tap that watches one output should not cost a call for each. The answer must
    /// not change afterwards.
    ///
    /// This tells the host what a tap can do without; it does not promise that the tap sees
    /// only what it asked for: [`Taps`] passes every record it gets to all its taps, so a tap
    /// that shares one with a tap wanting everything (a logger) gets everything. `package`
    /// must still ignore what it has no use for.
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        let _ = output;
        true
    }
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

    /// Every output one of the taps wants.
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        self.0.iter().any(|tap| tap.wants(output))
    }
}
