//! The building's devices and the robots' links to them: the team radio (a message reaches
//! every other robot after a delay, unless lost) and the operator's console (it raises and
//! clears alarms, broadcasts its state, and reads the robots' status packets).
//!
//! Links stamp by the world's clock at the host's time (`WorldSim::clock_at`), not by the
//! world's last step, and the console catches up with the step a link calls at: what a link
//! sends or receives at an instant does not depend on whether the building's module stepped
//! the world at that instant before or after it. No module priority orders them.

use std::time::Duration;

use rand::RngExt;
use strata_robot::platform::{ExternalLink, LinkError, ReceivedPacket, TeamLink};
use strata_runtime::Time;
use strata_worldsim::WorldSim;

use super::{AlarmRecord, Building, BuildingError, BuildingHandle, LiveAlarm, ReportRecord};
use crate::console::{Alarm, AlarmPacket, StatusPacket};

/// The radio's payload limit, as on a real team network.
const RADIO_LIMIT: usize = 128;
/// A status counts as "on site" this close to the alarm's point, m.
const ON_SITE: f64 = 1.5;

impl Building {
    /// Runs the console at every world step up to `until`.
    pub(super) fn advance_console(&mut self, until: Time, period: Duration) {
        while self.console_clock + period <= until {
            self.console_clock += period;
            self.run_console(self.console_clock);
        }
    }

    /// The operator console at one step: raises and clears alarms, broadcasts its state.
    fn run_console(&mut self, now: Time) {
        let seconds = now.as_secs_f64();
        if self.alarm.is_none()
            && let Some(event) = self.scenario.alarms.get(self.next_alarm).copied()
            && seconds >= event.at
        {
            self.next_alarm += 1;
            self.alarms.push(AlarmRecord {
                id: event.id,
                point: event.point,
                raised: seconds,
                on_site: None,
                cleared: None,
            });
            let record = self.alarms.len() - 1;
            self.alarm = Some(LiveAlarm { event, record, on_site_since: None });
            // Raising an alarm is broadcast at once, not at the next period.
            self.next_broadcast = now;
        }
        if let Some(live) = &self.alarm
            && live.on_site_since.is_some_and(|t| (now - t).as_secs_f64() >= live.event.hold)
        {
            self.alarms[live.record].cleared = Some(seconds);
            self.alarm = None;
            self.next_broadcast = now;
        }
        if now >= self.next_broadcast {
            self.next_broadcast = now + Duration::from_secs_f64(self.config.console_period);
            self.broadcast_seq = self.broadcast_seq.wrapping_add(1);
            let alarm = self.alarm.as_ref().map(|l| Alarm { id: l.event.id, point: l.event.point });
            let bytes = AlarmPacket { alarm, seq: self.broadcast_seq }.encode();
            for inbox in &mut self.console_inboxes {
                inbox.push(ReceivedPacket { received: now, bytes: bytes.clone() });
            }
        }
    }

    fn receive_status(&mut self, sim: &WorldSim, now: Time, bytes: &[u8]) -> Result<(), LinkError> {
        let status = StatusPacket::decode(bytes).map_err(|e| LinkError::Io(e.to_string()))?;
        let now = sim.clock_at(now);
        self.advance_console(now, sim.period());
        let seconds = now.as_secs_f64();
        for report in &status.reports {
            self.reports.push(ReportRecord {
                time: seconds,
                player: status.player,
                report: *report,
            });
        }
        if let Some(live) = &mut self.alarm
            && live.on_site_since.is_none()
            && status.intruder_sighted
            && status.position.distance(live.event.point) < ON_SITE
        {
            live.on_site_since = Some(now);
            self.alarms[live.record].on_site = Some((status.player, seconds));
        }
        Ok(())
    }

    fn take_console(&mut self, sim: &WorldSim, robot: usize, now: Time) -> Vec<ReceivedPacket> {
        self.advance_console(sim.clock_at(now), sim.period());
        self.console_inboxes.get_mut(robot).map(std::mem::take).unwrap_or_default()
    }

    fn send_radio(
        &mut self,
        sim: &mut WorldSim,
        from: usize,
        now: Time,
        payload: &[u8],
    ) -> Result<(), LinkError> {
        if payload.len() > RADIO_LIMIT {
            return Err(LinkError::TooLarge { size: payload.len(), limit: RADIO_LIMIT });
        }
        let at = sim.clock_at(now) + Duration::from_secs_f64(self.config.radio_delay);
        for to in (0..sim.robots()).filter(|&to| to != from) {
            // Drawn from the simulation's stream, loss or not: one seed decides the whole run.
            if sim.rng().random::<f64>() < self.config.radio_loss {
                continue;
            }
            self.radio_seq += 1;
            self.radio.push((at, self.radio_seq, to, payload.to_vec()));
        }
        Ok(())
    }

    /// The messages that reached `robot` by `now`, in the order they arrived.
    fn take_radio(&mut self, robot: usize, now: Time) -> Vec<ReceivedPacket> {
        let mut due = Vec::new();
        self.radio.retain(|message| {
            let arrived = message.2 == robot && message.0 <= now;
            if arrived {
                due.push((message.0, message.1, message.3.clone()));
            }
            !arrived
        });
        due.sort_by_key(|&(at, seq, _)| (at, seq));
        due.into_iter().map(|(received, _, bytes)| ReceivedPacket { received, bytes }).collect()
    }
}

fn check(building: &BuildingHandle, robot: usize) -> Result<(), BuildingError> {
    if robot < building.lock().sim.robots() { Ok(()) } else { Err(BuildingError::NoRobot(robot)) }
}

/// One robot's radio: the building delivers its messages to every other robot.
#[derive(Debug)]
pub struct RadioLink {
    building: BuildingHandle,
    robot: usize,
}

impl RadioLink {
    pub fn new(building: &BuildingHandle, robot: usize) -> Result<RadioLink, BuildingError> {
        check(building, robot)?;
        Ok(RadioLink { building: building.clone(), robot })
    }
}

impl TeamLink for RadioLink {
    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError> {
        let mut simulation = self.building.lock();
        let simulation = &mut *simulation;
        simulation.script.send_radio(&mut simulation.sim, self.robot, now, payload)
    }

    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        Ok(self.building.lock().script.take_radio(self.robot, now))
    }
}

/// One robot's connection to the operator console.
#[derive(Debug)]
pub struct ConsoleLink {
    building: BuildingHandle,
    robot: usize,
}

impl ConsoleLink {
    pub fn new(building: &BuildingHandle, robot: usize) -> Result<ConsoleLink, BuildingError> {
        check(building, robot)?;
        Ok(ConsoleLink { building: building.clone(), robot })
    }
}

impl ExternalLink for ConsoleLink {
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let mut simulation = self.building.lock();
        let simulation = &mut *simulation;
        Ok(simulation.script.take_console(&simulation.sim, self.robot, now))
    }

    fn send(&mut self, now: Time, payload: &[u8]) -> Result<(), LinkError> {
        let mut simulation = self.building.lock();
        let simulation = &mut *simulation;
        simulation.script.receive_status(&simulation.sim, now, payload)
    }
}

#[cfg(test)]
mod tests {
    use strata_robot::geometry::Point;

    use super::super::test_building;
    use super::*;

    fn at(seconds: f64) -> Time {
        Time::from_secs_f64(seconds)
    }

    #[test]
    fn the_radio_delivers_to_the_other_robots_after_its_delay_and_refuses_long_messages() {
        let handle = BuildingHandle::new(test_building(Vec::new()));
        let (mut a, mut b) = (
            RadioLink::new(&handle, 0).expect("robot 0"),
            RadioLink::new(&handle, 1).expect("robot 1"),
        );
        assert!(RadioLink::new(&handle, 2).is_err());
        // Sent between two steps: it leaves with the world's clock at 0.10 s.
        a.send(at(0.102), b"hello").expect("sent");
        assert_eq!(b.receive(at(0.12)), Ok(Vec::new()), "not before the delay");
        let received = b.receive(at(0.14)).expect("receives");
        assert_eq!(received, vec![ReceivedPacket { received: at(0.13), bytes: b"hello".to_vec() }]);
        assert_eq!(a.receive(at(1.0)), Ok(Vec::new()), "not to itself");
        assert_eq!(
            a.send(at(0.2), &[0; 129]),
            Err(LinkError::TooLarge { size: 129, limit: RADIO_LIMIT })
        );
    }

    #[test]
    fn a_console_read_at_a_step_is_the_same_whether_the_world_stepped_first_or_not() {
        // The alarm is raised at 1.0 s: a read at 1.0 s gets its broadcast either way.
        let read = |world_first: bool| {
            let handle = BuildingHandle::new(test_building(Vec::new()));
            let mut console = ConsoleLink::new(&handle, 0).expect("robot 0");
            handle.lock().advance_to(at(0.98));
            let _ = console.receive(at(0.98));
            if world_first {
                handle.lock().advance_to(at(1.0));
            }
            let packets = console.receive(at(1.0)).expect("receives");
            handle.lock().advance_to(at(1.0));
            let simulation = handle.lock();
            (packets, simulation.script.truth(&simulation.sim).alarms)
        };
        let (packets, alarms) = read(true);
        assert_eq!((packets.clone(), alarms.clone()), read(false));
        let [packet] = packets.as_slice() else { panic!("one broadcast: {packets:?}") };
        assert_eq!(packet.received, at(1.0));
        let alarm = AlarmPacket::decode(&packet.bytes).expect("an alarm packet").alarm;
        assert_eq!(alarm.map(|a| a.id), Some(4));
        assert_eq!(alarms.len(), 1);
    }

    #[test]
    fn the_console_clears_an_alarm_its_hold_after_a_robot_reports_the_intruder_from_the_spot() {
        let handle = BuildingHandle::new(test_building(Vec::new()));
        let mut console = ConsoleLink::new(&handle, 0).expect("robot 0");
        let status = |x: f64, sighted: bool| StatusPacket {
            player: 1,
            stable: true,
            localized: true,
            intruder_sighted: sighted,
            position: Point::new(x, 2.4),
            reports: Vec::new(),
        };
        handle.lock().advance_to(at(1.5));
        console.send(at(1.502), &status(0.0, true).encode()).expect("far away");
        console.send(at(1.602), &status(-5.0, false).encode()).expect("sees nobody");
        console.send(at(1.702), &status(-5.2, true).encode()).expect("on site");
        assert!(console.send(at(1.8), b"garbage").is_err());
        handle.lock().advance_to(at(4.0));
        let simulation = handle.lock();
        let alarms = simulation.script.truth(&simulation.sim).alarms;
        // On site at the world's step before the report; cleared 2 s (the hold) after that.
        let centis = |t: f64| (t * 100.0).round();
        assert_eq!(alarms[0].on_site.map(|(player, t)| (player, centis(t))), Some((1, 170.0)));
        assert_eq!(alarms[0].cleared.map(centis), Some(370.0));
    }
}
