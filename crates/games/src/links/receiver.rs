//! The thread that drains a link's socket.
//!
//! A robot reads its links once per planning cycle. Reading the socket itself then would let
//! a flood decide what the robot hears: between two cycles the socket's buffer fills with
//! whatever arrives fastest, and the kernel drops what comes after, real packets with the
//! garbage. So each UDP link has a thread that reads its socket as fast as datagrams come,
//! judges each at once (garbage and other games' packets go, counted) and keeps only the
//! packets meant for the robot, in a bounded queue the planning cycle empties. A flood then
//! costs the thread's time, not the real packets; only a flood of packets the link cannot tell
//! from real ones can overflow the queue, which drops its oldest (counted) and keeps the newest.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use super::LinkCounters;

/// How long one read of the socket waits, and so how long dropping a link waits for its thread.
pub(super) const READ_WAIT: Duration = Duration::from_millis(50);

/// A socket that keeps failing is read again after this pause rather than in a tight loop.
const RETRY_PAUSE: Duration = Duration::from_millis(20);

/// One read of the socket, judged.
pub(super) enum Read<T> {
    /// A packet for the robot.
    Packet(T),
    /// Nothing arrived within the read's wait.
    Nothing,
    /// Not what the port carries.
    Rejected,
    /// Valid, but not for this robot.
    Ignored,
    /// The socket failed.
    Failed(String),
}

struct Shared<T> {
    queue: Mutex<Queue<T>>,
    capacity: AtomicUsize,
    stop: AtomicBool,
}

struct Queue<T> {
    packets: VecDeque<T>,
    /// The socket's newest failure since the robot last collected.
    failure: Option<String>,
}

impl<T> Shared<T> {
    fn queue(&self) -> MutexGuard<'_, Queue<T>> {
        // A panic while holding the lock cannot leave the queue half-changed.
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// The draining thread of one socket and the queue it fills; dropping it stops the thread.
pub(super) struct Receiver<T> {
    shared: Arc<Shared<T>>,
    thread: Option<JoinHandle<()>>,
}

impl<T> std::fmt::Debug for Receiver<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Receiver")
            .field("capacity", &self.shared.capacity.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

impl<T: Send + 'static> Receiver<T> {
    /// Starts a thread named `name` calling `read` (which must wait at most [`READ_WAIT`] when
    /// nothing arrives) until the receiver is dropped.
    pub(super) fn spawn(
        name: String,
        capacity: usize,
        counters: Arc<LinkCounters>,
        mut read: impl FnMut() -> Read<T> + Send + 'static,
    ) -> std::io::Result<Receiver<T>> {
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue { packets: VecDeque::new(), failure: None }),
            capacity: AtomicUsize::new(capacity.max(1)),
            stop: AtomicBool::new(false),
        });
        let inner = Arc::clone(&shared);
        let thread = std::thread::Builder::new().name(name).spawn(move || {
            while !inner.stop.load(Ordering::Relaxed) {
                match read() {
                    Read::Packet(packet) => {
                        let capacity = inner.capacity.load(Ordering::Relaxed);
                        let mut queue = inner.queue();
                        queue.packets.push_back(packet);
                        while queue.packets.len() > capacity {
                            queue.packets.pop_front();
                            counters.dropped();
                        }
                    }
                    Read::Nothing => {}
                    Read::Rejected => counters.rejected(),
                    Read::Ignored => counters.ignored(),
                    Read::Failed(error) => {
                        counters.error();
                        inner.queue().failure = Some(error);
                        std::thread::sleep(RETRY_PAUSE);
                    }
                }
            }
        })?;
        Ok(Receiver { shared, thread: Some(thread) })
    }

    /// Everything queued, oldest first. A socket failure since the last call is the result
    /// only when nothing arrived (what did arrive is handed over; a failure that persists
    /// shows again).
    pub(super) fn take(&self) -> Result<Vec<T>, String> {
        let mut queue = self.shared.queue();
        let failure = queue.failure.take();
        let packets: Vec<T> = queue.packets.drain(..).collect();
        match failure {
            Some(error) if packets.is_empty() => Err(error),
            _ => Ok(packets),
        }
    }

    pub(super) fn capacity(&self) -> usize {
        self.shared.capacity.load(Ordering::Relaxed)
    }

    /// Sets how many packets wait at most (at least one); the oldest go beyond it.
    pub(super) fn set_capacity(&self, capacity: usize) {
        self.shared.capacity.store(capacity.max(1), Ordering::Relaxed);
    }
}

impl<T> Drop for Receiver<T> {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            // Bounded by one read's wait; a panic in the thread has already been printed.
            let _ = thread.join();
        }
    }
}
