//! Soccer's special motions: the kicks and the goalkeeper's dives, beside the stand-ups and
//! protective falls every biped has ([`SpecialMotion::stand_up`], [`SpecialMotion::fall`]).
//! The names are the league's ([`strata_spl::motions`]), which the simulators' catalogues use
//! too.

use strata_robot::platform::{MotionName, SpecialMotion};
use strata_spl::motions::{DIVE as DIVE_MOTION, KICK as KICK_MOTION};

pub const KICK: MotionName = MotionName::from_static(KICK_MOTION.name);
pub const DIVE: MotionName = MotionName::from_static(DIVE_MOTION.name);

/// Kick `sequence` of the platform's catalogue ([`crate::goals::Kick::sequence`]): the body
/// only, the head stays free.
pub const fn kick(sequence: u8) -> SpecialMotion {
    SpecialMotion::new(KICK, sequence, KICK_MOTION.head)
}

/// Dive `sequence` of the platform's catalogue (0 left, 1 right, 2 block): head and body.
pub const fn dive(sequence: u8) -> SpecialMotion {
    SpecialMotion::new(DIVE, sequence, DIVE_MOTION.head)
}
