//! The module interface, and the context a module's cycle runs in.

use std::fmt;

use rand_chacha::ChaCha8Rng;

use crate::connection::Connection;
use crate::graph::{Input, InputDecl, Output};
use crate::message::{ErasedPackage, InputSlot, Message};
use crate::package::{ModuleId, Package};
use crate::time::Time;

/// Anything a module's cycle can fail with; the host stops and reports it with the module name.
pub type ModuleError = Box<dyn std::error::Error + Send + Sync>;

/// A part of the software with an encapsulated functionality and an explicit interface
/// (paper 3.7). A module only sees the world through its [`Context`]: its inputs, its
/// outputs, the host's clock and its own seeded RNG. That is what lets the same module run on
/// the threaded host, the lockstep host and in a replay.
pub trait Module: Send + 'static {
    /// One cycle: read inputs, compute, send outputs.
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError>;

    /// Called once when the host stops (release hardware, flush files).
    fn stop(&mut self) {}
}

/// What started a cycle. A cycle may have several reasons when events coincide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wake {
    /// The module's period elapsed.
    Tick,
    /// A package arrived on this input port.
    Input(u16),
    /// The readers of this output port took what it last sent.
    ReceiversReady(u16),
}

/// Where a cycle's sends and takes go; each host provides its own.
pub(crate) trait Backend {
    fn publish(&mut self, port: u16, package: Box<dyn ErasedPackage>);
    /// The pending packages of an input whose writer wants to be woken were all taken.
    fn input_emptied(&mut self, port: u16);
    fn receivers_ready(&self, port: u16) -> bool;
}

/// The module's window on the world during one cycle.
pub struct Context<'a> {
    pub(crate) module: ModuleId,
    pub(crate) name: &'a str,
    pub(crate) now: Time,
    pub(crate) rng: &'a mut ChaCha8Rng,
    pub(crate) inputs: &'a [InputDecl],
    pub(crate) output_seq: &'a mut [u64],
    pub(crate) backend: &'a mut dyn Backend,
    pub(crate) woken_by: &'a [Wake],
    pub(crate) sent: usize,
}

impl fmt::Debug for Context<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Context").field("module", &self.name).field("now", &self.now).finish()
    }
}

impl Context<'_> {
    /// The host's time at the start of this cycle.
    pub fn now(&self) -> Time {
        self.now
    }

    pub fn module_id(&self) -> ModuleId {
        self.module
    }

    pub fn module_name(&self) -> &str {
        self.name
    }

    /// This module's own RNG, seeded from the host seed and the module name: the only source of
    /// randomness a module may use, so runs and replays are reproducible.
    pub fn rng(&mut self) -> &mut ChaCha8Rng {
        self.rng
    }

    pub fn woken_by(&self) -> &[Wake] {
        self.woken_by
    }

    /// How many packages this cycle has sent so far.
    pub fn sent_count(&self) -> usize {
        self.sent
    }

    fn slot<T: Message>(&self, input: Input<T>) -> &InputSlot<T> {
        assert_eq!(
            input.module, self.module,
            "module `{}` used an input handle of another module ({input:?})",
            self.name
        );
        self.inputs
            .get(usize::from(input.port))
            .and_then(|decl| decl.slot.as_any().downcast_ref::<InputSlot<T>>())
            .unwrap_or_else(|| panic!("module `{}`: {input:?} does not match its ports", self.name))
    }

    fn after_take<T: Message>(&mut self, input: Input<T>, now_empty: bool) {
        if now_empty && self.inputs[usize::from(input.port)].wakes_writer {
            self.backend.input_emptied(input.port);
        }
    }

    /// Takes the oldest pending package of `input` (for `Queue` inputs, one at a time).
    pub fn take<T: Message>(&mut self, input: Input<T>) -> Option<Package<T>> {
        let slot = self.slot(input);
        if !slot.is_pending() {
            return None;
        }
        let (package, now_empty) = slot.modify(|connection| {
            let package = connection.take();
            (package, connection.is_empty())
        });
        if package.is_some() {
            self.after_take(input, now_empty);
        }
        package
    }

    /// Takes the newest pending package of `input`; older pending ones are consumed with it.
    pub fn latest<T: Message>(&mut self, input: Input<T>) -> Option<Package<T>> {
        let slot = self.slot(input);
        if !slot.is_pending() {
            return None;
        }
        let package = slot.modify(Connection::take_newest);
        if package.is_some() {
            self.after_take(input, true);
        }
        package
    }

    /// Takes every pending package of `input`, oldest first.
    pub fn drain<T: Message>(&mut self, input: Input<T>) -> Vec<Package<T>> {
        let slot = self.slot(input);
        if !slot.is_pending() {
            return Vec::new();
        }
        let packages = slot.modify(Connection::drain);
        if !packages.is_empty() {
            self.after_take(input, true);
        }
        packages
    }

    pub fn has_pending<T: Message>(&self, input: Input<T>) -> bool {
        self.slot(input).is_pending()
    }

    /// Sends `value` stamped with the cycle's start time.
    pub fn send<T: Message>(&mut self, output: Output<T>, value: T) {
        let stamp = self.now;
        self.send_stamped(output, value, stamp);
    }

    /// Sends `value` stamped with the time its data was measured (usually the stamp of the
    /// input it was computed from).
    pub fn send_stamped<T: Message>(&mut self, output: Output<T>, value: T, stamp: Time) {
        assert_eq!(
            output.module, self.module,
            "module `{}` used an output handle of another module ({output:?})",
            self.name
        );
        let port = usize::from(output.port);
        let Some(seq) = self.output_seq.get_mut(port) else {
            panic!("module `{}`: {output:?} does not match its ports", self.name);
        };
        let package = Package::new(value, stamp, *seq, self.module);
        *seq += 1;
        self.sent += 1;
        self.backend.publish(output.port, Box::new(package));
    }

    /// Whether every reader of `output` has taken what it last sent.
    pub fn receivers_ready<T: Message>(&self, output: Output<T>) -> bool {
        self.backend.receivers_ready(output.port)
    }
}
