//! The three connection policies of paper 3.7, as pure data structures.
//!
//! A connection holds the packages a writer has sent and its reader has not yet taken. When a
//! package arrives and others are pending, the policy decides:
//!
//! | policy   | pending packages after a send                                  | counted as   |
//! |----------|----------------------------------------------------------------|--------------|
//! | `Latest` | only the newest (the older pending one is overwritten)         | `overwritten`|
//! | `Queue`  | all, in order, up to `capacity`; past it the oldest is dropped | `dropped`    |
//! | `Merge`  | one, whose value is `combine(pending, new)`                    | `merged`     |
//!
//! A send never blocks the writer, whatever the policy: a real-time layer must not wait on a
//! slower reader. Both hosts use these structures, so the semantics are the same live and in
//! simulation; `tests/policies.rs` tabulates them.

use std::collections::VecDeque;
use std::fmt;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::package::Package;

/// A user-given combine function for [`Policy::Merge`]: folds a newer value into the pending one.
pub type CombineFn<T> = Arc<dyn Fn(&mut T, T) + Send + Sync>;

/// How a connection treats packages its reader has not taken yet. Chosen per input.
pub enum Policy<T> {
    /// Overwrite: the reader always sees the newest package (perception to behaviors).
    Latest,
    /// Every package arrives, in order (observations to a filter). Bounded: when `capacity`
    /// packages are pending, the oldest is dropped and counted.
    Queue { capacity: usize },
    /// Re-package: pending packages are combined into one (odometry increments summed).
    Merge(CombineFn<T>),
}

impl<T> Policy<T> {
    pub fn queue(capacity: usize) -> Policy<T> {
        Policy::Queue { capacity: capacity.max(1) }
    }

    pub fn merge(combine: impl Fn(&mut T, T) + Send + Sync + 'static) -> Policy<T> {
        Policy::Merge(Arc::new(combine))
    }

    pub fn kind(&self) -> PolicyKind {
        match self {
            Policy::Latest => PolicyKind::Latest,
            Policy::Queue { capacity } => PolicyKind::Queue { capacity: *capacity },
            Policy::Merge(_) => PolicyKind::Merge,
        }
    }
}

impl<T> Clone for Policy<T> {
    fn clone(&self) -> Self {
        match self {
            Policy::Latest => Policy::Latest,
            Policy::Queue { capacity } => Policy::Queue { capacity: *capacity },
            Policy::Merge(f) => Policy::Merge(Arc::clone(f)),
        }
    }
}

impl<T> fmt::Debug for Policy<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.kind().fmt(f)
    }
}

/// A policy without its combine function: what statistics and logs report.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "policy", rename_all = "snake_case")]
pub enum PolicyKind {
    Latest,
    Queue { capacity: usize },
    Merge,
}

impl fmt::Display for PolicyKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PolicyKind::Latest => write!(f, "latest"),
            PolicyKind::Queue { capacity } => write!(f, "queue({capacity})"),
            PolicyKind::Merge => write!(f, "merge"),
        }
    }
}

/// What happened to a package on arrival.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arrival {
    /// Nothing was pending: the reader has new data it did not have before.
    First,
    /// Stored behind other pending packages (`Queue`).
    Queued,
    /// Replaced the pending package (`Latest`).
    Overwrote,
    /// The queue was full: the oldest pending package was dropped to make room.
    DroppedOldest,
    /// Combined into the pending package (`Merge`).
    Merged,
}

/// Counters of one connection; all monotonically increasing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConnectionCounters {
    /// Packages sent into the connection.
    pub received: u64,
    /// Packages the reader took (a merged package counts once).
    pub delivered: u64,
    /// Pending packages replaced by a newer one (`Latest`).
    pub overwritten: u64,
    /// Packages dropped because the queue was full (`Queue` overflow).
    pub dropped: u64,
    /// Packages folded into a pending one (`Merge`).
    pub merged: u64,
}

/// The pending packages of one connection and its policy.
pub struct Connection<T> {
    policy: Policy<T>,
    pending: VecDeque<Package<T>>,
    counters: ConnectionCounters,
}

impl<T> fmt::Debug for Connection<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Connection")
            .field("policy", &self.policy)
            .field("pending", &self.pending.len())
            .field("counters", &self.counters)
            .finish()
    }
}

impl<T> Connection<T> {
    pub fn new(policy: Policy<T>) -> Connection<T> {
        Connection { policy, pending: VecDeque::new(), counters: ConnectionCounters::default() }
    }

    pub fn policy(&self) -> PolicyKind {
        self.policy.kind()
    }

    /// Accepts a package according to the policy; never blocks and never fails.
    pub fn push(&mut self, package: Package<T>) -> Arrival {
        self.counters.received += 1;
        if self.pending.is_empty() {
            self.pending.push_back(package);
            return Arrival::First;
        }
        match &self.policy {
            Policy::Latest => {
                self.pending.clear();
                self.pending.push_back(package);
                self.counters.overwritten += 1;
                Arrival::Overwrote
            }
            Policy::Queue { capacity } => {
                let mut arrival = Arrival::Queued;
                while self.pending.len() >= *capacity {
                    self.pending.pop_front();
                    self.counters.dropped += 1;
                    arrival = Arrival::DroppedOldest;
                }
                self.pending.push_back(package);
                arrival
            }
            Policy::Merge(combine) => {
                // The merged package carries the newest stamp and sequence number: its data
                // now covers everything up to the newest measurement.
                let Package { value, stamp, seq, producer } = package;
                if let Some(current) = self.pending.back_mut() {
                    combine(&mut current.value, value);
                    current.stamp = stamp;
                    current.seq = seq;
                    current.producer = producer;
                }
                self.counters.merged += 1;
                Arrival::Merged
            }
        }
    }

    /// Takes the oldest pending package.
    pub fn take(&mut self) -> Option<Package<T>> {
        let package = self.pending.pop_front();
        if package.is_some() {
            self.counters.delivered += 1;
        }
        package
    }

    /// Takes every pending package, oldest first.
    pub fn drain(&mut self) -> Vec<Package<T>> {
        self.counters.delivered += self.pending.len() as u64;
        self.pending.drain(..).collect()
    }

    /// Takes the newest pending package; older ones are consumed with it.
    pub fn take_newest(&mut self) -> Option<Package<T>> {
        let newest = self.pending.pop_back();
        if newest.is_some() {
            self.counters.delivered += 1 + self.pending.len() as u64;
            self.pending.clear();
        }
        newest
    }

    pub fn peek_newest(&self) -> Option<&Package<T>> {
        self.pending.back()
    }

    pub fn len(&self) -> usize {
        self.pending.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }

    pub fn counters(&self) -> ConnectionCounters {
        self.counters
    }
}
