//! The simulator and the application's script, shared: the simulator's module steps them, and
//! the application's links (a radio, a console) reach them between steps.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use strata_runtime::Time;

use crate::sim::{Script, WorldSim};

/// A simulator with its application's script.
#[derive(Debug)]
pub struct Simulation<S> {
    pub sim: WorldSim,
    pub script: S,
}

impl<S: Script> Simulation<S> {
    pub fn new(sim: WorldSim, script: S) -> Simulation<S> {
        Simulation { sim, script }
    }

    /// Steps up to `now`, the script in every step.
    pub fn advance_to(&mut self, now: Time) {
        self.sim.advance_to(now, &mut self.script);
    }
}

/// A shared handle to a [`Simulation`]. Clones refer to the same simulation.
pub struct WorldHandle<S>(Arc<Mutex<Simulation<S>>>);

impl<S> Clone for WorldHandle<S> {
    fn clone(&self) -> Self {
        WorldHandle(Arc::clone(&self.0))
    }
}

impl<S> std::fmt::Debug for WorldHandle<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never locks: printing a handle while the simulation is locked must not deadlock.
        f.debug_struct("WorldHandle").finish_non_exhaustive()
    }
}

impl<S> WorldHandle<S> {
    pub fn new(simulation: Simulation<S>) -> WorldHandle<S> {
        WorldHandle(Arc::new(Mutex::new(simulation)))
    }

    /// Locks the simulation. Every step and every link call leaves it consistent, so a panic
    /// elsewhere while it was locked leaves it usable.
    pub fn lock(&self) -> MutexGuard<'_, Simulation<S>> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner)
    }
}
