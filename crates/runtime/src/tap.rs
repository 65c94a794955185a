//! Taps see the packages a host delivers: the hook loggers and viewers attach to.

use crate::graph::PortName;
use crate::message::{ErasedPackage, Message};
use crate::package::{ModuleId, Package};
use crate::time::Time;
use std::sync::Arc;

/// One package as it becomes visible to its readers.
#[derive(Clone, Copy)]
pub struct TapRecord<'a> {
    /// When the package became visible (host time).
    pub time: Time,
    /// The output it was sent on.
    pub sent_on: TapOutput<'a>,
    pub package: &'a dyn ErasedPackage,
}

impl<'a> TapRecord<'a> {
    /// The package, if it was sent on an output named `port` and has the port's type (a tap
    /// that shares a host sees every module's outputs: several may have that name).
    pub fn package<T: Message>(&self, port: PortName<T>) -> Option<&'a Package<T>> {
        if self.sent_on.output != port.name() {
            return None;
        }
        port.downcast(self.package)
    }

    /// The value of [`TapRecord::package`].
    pub fn value<T: Message>(&self, port: PortName<T>) -> Option<&'a T> {
        self.package(port).map(|p| &p.value)
    }

    /// [`TapRecord::package`], of the module named `module` only.
    pub fn package_from<T: Message>(
        &self,
        module: &str,
        port: PortName<T>,
    ) -> Option<&'a Package<T>> {
        if self.sent_on.module_name != module {
            return None;
        }
        self.package(port)
    }

    /// [`TapRecord::value`], of the module named `module` only.
    pub fn value_from<T: Message>(&self, module: &str, port: PortName<T>) -> Option<&'a T> {
        self.package_from(module, port).map(|p| &p.value)
    }
}

impl std::fmt::Debug for TapRecord<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TapRecord")
            .field("time", &self.time)
            .field("module", &self.sent_on.module_name)
            .field("output", &self.sent_on.output)
            .field("seq", &self.package.seq())
            .finish()
    }
}

/// An output as a tap is asked about it, before any package: see [`Tap::wants`].
#[derive(Clone, Copy, Debug)]
pub struct TapOutput<'a> {
    /// A number unique to the host in this process: with `module` and `port` it names the
    /// output without comparing names, for a tap that sees several hosts.
    pub host: u64,
    pub module: ModuleId,
    pub module_name: &'a str,
    /// The output's place among its module's outputs.
    pub port: u16,
    pub output: &'a str,
    pub type_name: &'static str,
}

impl<'a> TapOutput<'a> {
    /// Whether this output is named `port` and has its type, for [`Tap::wants`]. (The type is
    /// compared by its name, which Rust does not promise unique: [`TapRecord::package`] still
    /// checks the type itself.)
    pub fn is<T: Message>(&self, port: PortName<T>) -> bool {
        self.output == port.name() && self.type_name == std::any::type_name::<T>()
    }

    /// The record of `package`, sent on this output and visible at `time`.
    pub fn record(&self, time: Time, package: &'a dyn ErasedPackage) -> TapRecord<'a> {
        TapRecord { time, sent_on: *self, package }
    }
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
    /// only what it asked for (a host that was not asked, a `Taps` shared by several hosts
    /// passes what it does not know about to all): `package` must still ignore what it has no
    /// use for.
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        let _ = output;
        true
    }

    /// A package of an output no module reads, given to keep: the host would drop it next.
    /// A tap that keeps packages (a logger handing them to its writer thread) takes it instead
    /// of cloning it; the others let the default show it to [`Tap::package`]. Of the taps
    /// that want such an output, the host gives it to one and shows it to the others.
    ///
    /// A match sends a third of its packages on outputs nobody reads (the reactive layer's
    /// reports, the actuation's feedback): kept, a logger spares the sending module a clone
    /// and a drop of each.
    fn package_owned(&self, output: &TapOutput<'_>, time: Time, package: Box<dyn ErasedPackage>) {
        self.package(&output.record(time, package.as_ref()));
    }

    /// A sender of this tap's own for one host, which the host then calls instead of the tap:
    /// with `&mut`, from one thread at a time, so it can gather what it is shown and given
    /// without taking a lock for each package (a 7 vs 7 match sends about 6 600 packages per
    /// simulated second). The lockstep host asks for one when the tap is added, flushes it
    /// ([`TapSender::flush`]) before each of its run calls returns and when it stops, and
    /// drops it with itself. `None` (the default): the host calls the tap. A tap whose
    /// records must reach it during a run (a viewer's live feed) keeps the default.
    fn sender(&self) -> Option<Box<dyn TapSender>> {
        None
    }
}

/// A tap's sender for one host: see [`Tap::sender`]. It sees what the tap would see, in the
/// same order.
pub trait TapSender: Send {
    /// As [`Tap::package`].
    fn package(&mut self, record: &TapRecord<'_>);

    /// As [`Tap::package_owned`].
    fn package_owned(
        &mut self,
        output: &TapOutput<'_>,
        time: Time,
        package: Box<dyn ErasedPackage>,
    );

    /// Hands on everything gathered so far: the host is between runs, or stopping.
    fn flush(&mut self);
}

/// Several taps as one: each sees every record, in order. A host shows each of its own taps
/// ([`crate::LockstepHost::add_tap`]) only the outputs that tap wants; `Taps` is for a place
/// that takes a single tap.
#[derive(Clone, Default)]
pub struct Taps(pub Vec<Arc<dyn Tap>>);

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

    /// Shown to every tap but the last, given to the last.
    fn package_owned(&self, output: &TapOutput<'_>, time: Time, package: Box<dyn ErasedPackage>) {
        if let Some((last, others)) = self.0.split_last() {
            let record = output.record(time, package.as_ref());
            for tap in others {
                tap.package(&record);
            }
            last.package_owned(output, time, package);
        }
    }
}

/// A host's taps, and the dispatch of a record to those that want its output.
#[derive(Default)]
pub(crate) struct HostTaps(Vec<Arc<dyn Tap>>);

/// By tap of a [`HostTaps`], the sender the host calls instead of it ([`Tap::sender`]), if
/// any: only a host that calls its taps from one thread (the lockstep host) has them.
#[derive(Default)]
pub(crate) struct TapSenders(Vec<Option<Box<dyn TapSender>>>);

impl TapSenders {
    /// Has every sender hand on what it gathered.
    pub(crate) fn flush(&mut self) {
        for sender in self.0.iter_mut().flatten() {
            sender.flush();
        }
    }
}

impl HostTaps {
    pub(crate) fn push(&mut self, tap: Arc<dyn Tap>) {
        self.0.push(tap);
    }

    /// Adds `tap`, and its sender to `senders` (which then has one place per tap).
    pub(crate) fn push_with_sender(&mut self, tap: Arc<dyn Tap>, senders: &mut TapSenders) {
        senders.0.resize_with(self.0.len(), || None);
        senders.0.push(tap.sender());
        self.0.push(tap);
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The taps that want `output`, one bit each (the 64th and later share the last bit).
    pub(crate) fn wanting(&self, output: &TapOutput<'_>) -> u64 {
        self.0
            .iter()
            .enumerate()
            .filter(|(_, tap)| tap.wants(output))
            .fold(0, |mask, (i, _)| mask | 1 << i.min(63))
    }

    /// Offers `package`, sent on `output` and visible at `time`, to the taps of `mask`: when a
    /// module reads the output, they are shown it and the host gets it back to deliver; when
    /// nobody does, the last tap of `mask` is given it ([`Tap::package_owned`]) and the others
    /// are shown it. Taps with a sender in `senders` are reached through it; a host shared by
    /// several threads has none and calls every tap itself.
    pub(crate) fn offer(
        &self,
        senders: Option<&mut TapSenders>,
        mask: u64,
        output: &TapOutput<'_>,
        time: Time,
        package: Box<dyn ErasedPackage>,
        read: bool,
    ) -> Option<Box<dyn ErasedPackage>> {
        let senders = match senders {
            Some(senders) => &mut senders.0[..],
            None => &mut [],
        };
        let mut dispatch = Dispatch { taps: &self.0, senders };
        let last = 63usize.saturating_sub(mask.leading_zeros() as usize);
        // Beyond 63 taps each decides for itself which records it takes: show them all.
        if read || mask == 0 || last >= 63 {
            dispatch.package(mask, &output.record(time, package.as_ref()));
            return read.then_some(package);
        }
        dispatch.package(mask & !(1 << last), &output.record(time, package.as_ref()));
        match dispatch.senders.get_mut(last).and_then(Option::as_mut) {
            Some(sender) => sender.package_owned(output, time, package),
            None => self.0[last].package_owned(output, time, package),
        }
        None
    }
}

/// The taps of a host and their senders, as one dispatch sees them.
struct Dispatch<'a> {
    taps: &'a [Arc<dyn Tap>],
    senders: &'a mut [Option<Box<dyn TapSender>>],
}

impl Dispatch<'_> {
    /// Shows `record` to the taps of `mask` (see [`HostTaps::wanting`]).
    fn package(&mut self, mask: u64, record: &TapRecord<'_>) {
        let mut bits = mask;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            if i < 63 {
                self.show(i, record);
            } else {
                // Beyond 63 taps: each of the rest decides for itself.
                for i in 63..self.taps.len() {
                    self.show(i, record);
                }
            }
        }
    }

    fn show(&mut self, tap: usize, record: &TapRecord<'_>) {
        match self.senders.get_mut(tap).and_then(Option::as_mut) {
            Some(sender) => sender.package(record),
            None => self.taps[tap].package(record),
        }
    }
}
