//! Packages: the unit of data passed between modules (paper 3.7).

use serde::{Deserialize, Serialize};

use crate::time::Time;

/// Identifies a module within one graph (its index, in the order modules were added).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ModuleId(pub u32);

impl ModuleId {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// A group of data transmitted as a whole from one module to another.
///
/// `stamp` is when the data was *measured* (a sensor frame's time, carried along by every
/// package derived from it), not when the package was sent: filters need the former.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Package<T> {
    pub value: T,
    pub stamp: Time,
    /// Per output, starting at 0; a gap seen by a reader means packages were overwritten or
    /// dropped on the way.
    pub seq: u64,
    pub producer: ModuleId,
}

impl<T> Package<T> {
    pub fn new(value: T, stamp: Time, seq: u64, producer: ModuleId) -> Package<T> {
        Package { value, stamp, seq, producer }
    }

    pub fn map<U>(self, f: impl FnOnce(T) -> U) -> Package<U> {
        Package { value: f(self.value), stamp: self.stamp, seq: self.seq, producer: self.producer }
    }
}
