//! Team broadcast emulation (paper 4.1): a robot's team message goes to the simulator, which
//! forwards it to each teammate after a delay, with jitter, or loses it. The simulator also
//! delivers the referee's control packets to every robot.

use strata_runtime::Time;

use crate::config::BroadcastConfig;
use crate::random::Stream;

/// A message on its way to one robot.
#[derive(Clone, Debug)]
struct InFlight {
    deliver_at: Time,
    seq: u64,
    to: usize,
    bytes: Vec<u8>,
}

/// Messages in flight, delivered in order of arrival time (then of sending).
#[derive(Clone, Debug, Default)]
pub(crate) struct Broadcast {
    in_flight: Vec<InFlight>,
    seq: u64,
}

impl Broadcast {
    /// Queues copies of `bytes` for `recipients`; returns how many copies were lost.
    pub fn send(
        &mut self,
        now: Time,
        bytes: &[u8],
        recipients: impl Iterator<Item = usize>,
        config: &BroadcastConfig,
        loss: f64,
        rng: &mut Stream,
    ) -> (u64, u64) {
        let (mut queued, mut lost) = (0, 0);
        for to in recipients {
            if rng.chance(loss) {
                lost += 1;
                continue;
            }
            let delay = config.delay + rng.uniform(0.0, config.jitter);
            self.seq += 1;
            self.in_flight.push(InFlight {
                deliver_at: now + std::time::Duration::from_secs_f64(delay.max(0.0)),
                seq: self.seq,
                to,
                bytes: bytes.to_vec(),
            });
            queued += 1;
        }
        (queued, lost)
    }

    /// Takes every message due at `now`, in delivery order: (recipient, sent bytes).
    pub fn due(&mut self, now: Time, out: &mut Vec<(usize, Time, Vec<u8>)>) {
        if self.in_flight.iter().all(|m| m.deliver_at > now) {
            return;
        }
        let mut due: Vec<InFlight> = Vec::new();
        let mut index = 0;
        while index < self.in_flight.len() {
            if self.in_flight[index].deliver_at <= now {
                due.push(self.in_flight.swap_remove(index));
            } else {
                index += 1;
            }
        }
        due.sort_by_key(|m| (m.deliver_at, m.seq));
        out.extend(due.into_iter().map(|m| (m.to, m.deliver_at, m.bytes)));
    }

    /// Drops messages addressed to a robot that left the world.
    pub fn forget(&mut self, robot: usize) {
        self.in_flight.retain(|m| m.to != robot);
    }

    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }
}
