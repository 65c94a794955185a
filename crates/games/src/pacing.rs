//! Pacing a lockstep match to a multiple of real time, so that it can be watched live (the
//! lockstep host otherwise runs as fast as it can): what the web viewer's and the Foxglove
//! server's taps share.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;

use strata_runtime::Time;

/// Holds the match thread back until its simulated time is due on the wall clock.
#[derive(Debug)]
pub struct Pacer {
    /// Simulated seconds per wall second.
    speed: f64,
    /// Wall time and simulated time of the first call.
    origin: Mutex<Option<(Instant, Time)>>,
    /// Stops pacing (Ctrl-C: the match must end promptly).
    interrupted: Option<Arc<AtomicBool>>,
}

impl Pacer {
    /// `speed` simulated seconds per wall second; `None` for a speed that is not a positive
    /// number (unpaced).
    pub fn new(speed: f64) -> Option<Pacer> {
        (speed.is_finite() && speed > 0.0).then(|| Pacer {
            speed,
            origin: Mutex::new(None),
            interrupted: strata_runtime::signal::interrupt_flag().ok(),
        })
    }

    /// Sleeps until `now` is due. Called with the simulator's ground truth, which every
    /// lockstep match sends at a steady rate.
    pub fn pace(&self, now: Time) {
        if self.interrupted.as_ref().is_some_and(|f| f.load(Ordering::Relaxed)) {
            return;
        }
        let (wall, sim) = *self
            .origin
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get_or_insert((Instant::now(), now));
        let due = wall + (now - sim).div_f64(self.speed);
        let wait = due.saturating_duration_since(Instant::now());
        if !wait.is_zero() {
            std::thread::sleep(wait);
        }
    }
}
