//! Building blocks for an application's primitive behaviors (paper Table 4) that know nothing
//! of the application: command senders that keep a primitive from flooding actuation with
//! repeats of the same command, and the primitives every humanoid needs whatever its task
//! (stand still, get up).
//!
//! Goal-specific primitives (track the ball, go to a waypoint) stay in the application; they
//! use the senders so that every primitive re-sends on the same terms.

use crate::command::{
    BodyCommand, BodyMotion, HeadCommand, HeadMotion, ResourceGroup, WholeBodyCommand,
};
use crate::control::reactive::{PrimitiveBehavior, ReactiveInput, Stability};
use crate::control::scores::{Goal, PrimitiveId};
use crate::geometry::Velocity;
use crate::platform::{FallDirection, HeadAngles, SpecialMotion};
use strata_runtime::Time;

/// Names of the shared primitives, for an application's ids of them
/// ([`StandPrimitive`], [`StandUpPrimitive`]): reports and logs show the same names whichever
/// application runs.
pub mod names {
    pub const STAND: &str = "stand";
    pub const STAND_UP: &str = "stand-up";
}

/// The primitive ids of a body goal type that [`Stand`] can pursue: which of them is [`Stand`].
pub trait StandPrimitive: PrimitiveId {
    const STAND: Self;
}

/// The primitive ids of a head+body goal type that [`StandUp`] can pursue: which of them is
/// [`StandUp`].
pub trait StandUpPrimitive: PrimitiveId {
    const STAND_UP: Self;
}

/// Sends a walk only when it differs from the last one or half its duration has passed: fewer
/// commands for actuation to queue, the same motion. A walk command expires after `duration`,
/// so a primitive that goes silent stops the robot instead of leaving it walking.
#[derive(Debug, Default, Clone)]
pub struct WalkSender {
    last: Option<(Velocity, Time)>,
}

impl WalkSender {
    /// Velocity changes below these are walking-engine noise, not new commands.
    const SAME_LINEAR: f64 = 0.02;
    const SAME_TURN: f64 = 0.05;

    pub fn send(&mut self, now: Time, velocity: Velocity, duration: f64) -> Option<BodyCommand> {
        let repeat = self.last.is_some_and(|(v, t)| {
            (v.vx - velocity.vx).abs() < Self::SAME_LINEAR
                && (v.vy - velocity.vy).abs() < Self::SAME_LINEAR
                && (v.omega - velocity.omega).abs() < Self::SAME_TURN
                && (now - t).as_secs_f64() < duration * 0.5
        });
        if repeat {
            return None;
        }
        self.last = Some((velocity, now));
        Some(BodyCommand::NonQueue(BodyMotion::Walk { velocity, duration }))
    }

    /// Forgets the last walk: the next one is sent whatever it is (on activation).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// Sends a head target only when it moved by more than the head's settling tolerance.
#[derive(Debug, Default, Clone)]
pub struct HeadSender {
    last: Option<HeadAngles>,
}

impl HeadSender {
    const SAME_ANGLE: f64 = 0.03;

    pub fn send(&mut self, target: HeadAngles, max_speed: f64) -> Option<HeadCommand> {
        if self.last.is_some_and(|l| {
            (l.yaw - target.yaw).abs() < Self::SAME_ANGLE
                && (l.pitch - target.pitch).abs() < Self::SAME_ANGLE
        }) {
            return None;
        }
        self.last = Some(target);
        Some(HeadCommand::NonQueue(HeadMotion { target, max_speed }))
    }

    /// Forgets the last target: the next one is sent whatever it is (on activation).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// Stand still: one Stand order per activation, for any body goal that wants the robot still.
#[derive(Debug, Default)]
pub struct Stand {
    sent: bool,
}

impl<G: Goal<Primitive: StandPrimitive>, W> PrimitiveBehavior<G, BodyCommand, W> for Stand {
    fn id(&self) -> G::Primitive {
        G::Primitive::STAND
    }

    fn activate(&mut self, _: &G, _: &ReactiveInput<'_, W>) {
        self.sent = false;
    }

    fn step(&mut self, _: &G, _: &ReactiveInput<'_, W>) -> Option<BodyCommand> {
        (!std::mem::replace(&mut self.sent, true))
            .then_some(BodyCommand::NonQueue(BodyMotion::Stand))
    }
}

/// Stand-up: the platform's sequence for the side the robot lies on — sequence 1 from the
/// back, 0 from the front or a side (the order of the platforms' stand-up catalogues) — once
/// the fall is over and nothing else holds head and body.
#[derive(Debug, Default)]
pub struct StandUp;

impl StandUp {
    pub fn sequence_for(direction: FallDirection) -> u8 {
        match direction {
            FallDirection::Back => 1,
            FallDirection::Front | FallDirection::Left | FallDirection::Right => 0,
        }
    }
}

impl<G: Goal<Primitive: StandUpPrimitive>, W> PrimitiveBehavior<G, WholeBodyCommand, W>
    for StandUp
{
    fn id(&self) -> G::Primitive {
        G::Primitive::STAND_UP
    }

    fn step(&mut self, _: &G, input: &ReactiveInput<'_, W>) -> Option<WholeBodyCommand> {
        let Stability::Fallen(direction) = input.stability else { return None };
        if input.actuation.is_busy(ResourceGroup::HeadAndBody) {
            return None;
        }
        Some(WholeBodyCommand::Special {
            motion: SpecialMotion::stand_up(StandUp::sequence_for(direction)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_walk_is_resent_only_when_it_changes_or_half_its_duration_passed() {
        let mut sender = WalkSender::default();
        let at = Time::from_secs_f64;
        let v = Velocity::new(0.2, 0.0, 0.1);
        assert!(sender.send(at(0.0), v, 0.4).is_some());
        assert!(sender.send(at(0.1), Velocity::new(0.21, 0.0, 0.1), 0.4).is_none());
        assert!(sender.send(at(0.1), Velocity::new(0.25, 0.0, 0.1), 0.4).is_some());
        assert!(sender.send(at(0.35), Velocity::new(0.25, 0.0, 0.1), 0.4).is_some());
        sender.reset();
        assert!(sender.send(at(0.36), Velocity::new(0.25, 0.0, 0.1), 0.4).is_some());
    }

    #[test]
    fn a_head_target_is_resent_only_when_it_moved() {
        let mut sender = HeadSender::default();
        let target = |yaw| HeadAngles { yaw, pitch: 0.0 };
        assert!(sender.send(target(0.5), 3.0).is_some());
        assert!(sender.send(target(0.52), 3.0).is_none());
        assert!(sender.send(target(0.6), 3.0).is_some());
    }
}
