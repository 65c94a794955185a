//! What each 20 ms server cycle costs the robot, in CPU time: the whole process (every module
//! of every layer, perception, the platform's connection thread and its walking policy,
//! whatever else the process runs) and, of that, the connection thread and the policy.
//!
//! The server cycle is the robot's natural unit of work: every perception wakes the platform's
//! thread, whose answer wakes perception, world modeling and the layers in turn. The process's
//! CPU clock read at each perception's arrival therefore splits the robot's compute into one
//! share per cycle, without instrumenting any module, and counts what per-module wall times
//! miss (threads of the host, allocations, taps) and what they count wrongly (time a module's
//! thread waited for a core on a loaded machine is wall time, not compute). A module cycle
//! that straddles two arrivals (a long deliberative cycle) is split between the two. Linux
//! brings a thread's CPU time up to date when it stops running and at each scheduler tick, so a
//! thread running on another core at the moment of a reading can have up to one tick (1-4 ms)
//! attributed to the next cycle instead; totals are exact.

use std::time::Duration;

use nix::time::{ClockId, clock_gettime};
use serde::{Deserialize, Serialize};
use strata_runtime::{DurationRecorder, Summary};

use crate::controller::CYCLE;

/// CPU time this process has used, on all its threads; `None` where the clock is unavailable.
pub fn process_cpu_time() -> Option<Duration> {
    clock_gettime(ClockId::CLOCK_PROCESS_CPUTIME_ID).ok().map(Duration::from)
}

/// CPU time the calling thread has used.
pub fn thread_cpu_time() -> Option<Duration> {
    clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).ok().map(Duration::from)
}

/// Measures the compute of each server cycle (see the module's documentation).
#[derive(Debug, Clone, Default)]
pub struct ComputeMeter {
    process: DurationRecorder,
    connection: DurationRecorder,
    policy: DurationRecorder,
    /// The process's and the connection thread's CPU clocks at the last arrival.
    last: Option<(Duration, Duration)>,
}

impl ComputeMeter {
    /// A perception arrived (called on the connection thread): the CPU time since the previous
    /// arrival was the previous cycle's.
    pub fn arrival(&mut self) {
        let (Some(process), Some(thread)) = (process_cpu_time(), thread_cpu_time()) else {
            return;
        };
        if let Some((last_process, last_thread)) = self.last {
            self.process.record(process.saturating_sub(last_process));
            self.connection.record(thread.saturating_sub(last_thread));
        }
        self.last = Some((process, thread));
    }

    /// One step of the walking policy (with the rest of the body's control) took `cpu`.
    pub fn policy_step(&mut self, cpu: Duration) {
        self.policy.record(cpu);
    }

    /// Forgets what was measured (the robot's set-up is not a cycle's work); the next arrival
    /// starts the first cycle.
    pub fn restart(&mut self) {
        *self = ComputeMeter::default();
    }

    pub fn report(&self) -> ComputeReport {
        let process = self.process.summary();
        let share = |us: f64| us / (CYCLE * 1e6);
        ComputeReport {
            cycle_ms: CYCLE * 1e3,
            cycles: self.process.count(),
            share_of_cycle: CycleShare {
                p50: share(process.p50_us),
                p99: share(process.p99_us),
                max: share(process.max_us),
            },
            process,
            connection: self.connection.summary(),
            policy: self.policy.summary(),
        }
    }
}

/// The compute per server cycle, CPU time in microseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ComputeReport {
    /// The server cycle, ms.
    pub cycle_ms: f64,
    /// Server cycles measured.
    pub cycles: u64,
    /// The whole robot process per cycle: every thread.
    pub process: Summary,
    /// `process` as a share of the cycle (1.0: one core busy for the whole cycle; the robot's
    /// threads can use more than one core).
    pub share_of_cycle: CycleShare,
    /// The platform's connection thread per cycle: decoding the perception, the camera model,
    /// the body's control with the walking policy, the answer.
    pub connection: Summary,
    /// The body's control with the walking policy per cycle (part of `connection`).
    pub policy: Summary,
}

/// Percentiles of a per-cycle figure divided by the cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CycleShare {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_arrival_closes_the_previous_cycle() {
        let mut meter = ComputeMeter::default();
        meter.arrival();
        assert_eq!(meter.report().cycles, 0, "the first arrival opens the first cycle");
        // Some work on this thread, which is part of the process.
        let mut x = 0u64;
        for i in 0..2_000_000u64 {
            x = x.wrapping_mul(31).wrapping_add(std::hint::black_box(i));
        }
        std::hint::black_box(x);
        meter.arrival();
        meter.policy_step(Duration::from_micros(30));
        let report = meter.report();
        assert_eq!(report.cycles, 1);
        assert!(report.process.max_us > 0.0 && report.connection.max_us > 0.0, "{report:?}");
        assert!(report.process.max_us >= 0.99 * report.connection.max_us, "{report:?}");
        assert_eq!(report.policy.count, 1);
        assert_eq!(report.cycle_ms, 20.0);
        meter.restart();
        assert_eq!(meter.report().cycles, 0);
    }
}
