//! A gate that holds the writer thread, for tests that fill the queue.

use std::sync::{Condvar, Mutex, PoisonError};

/// Holds the writer thread before it handles each record, so a test can fill the queue.
#[derive(Default)]
pub(super) struct Gate {
    closed: Mutex<bool>,
    changed: Condvar,
}

impl Gate {
    pub(super) fn set_closed(&self, closed: bool) {
        *self.closed.lock().unwrap_or_else(PoisonError::into_inner) = closed;
        self.changed.notify_all();
    }

    pub(super) fn wait_open(&self) {
        let guard = self.closed.lock().unwrap_or_else(PoisonError::into_inner);
        let _guard = self
            .changed
            .wait_while(guard, |closed| *closed)
            .unwrap_or_else(PoisonError::into_inner);
    }
}
