//! The NAO v6's 25 joints in LoLA's order, their names and their mechanical limits.
//!
//! LoLA has one hip yaw-pitch value (`LHipYawPitch`): the two hips share one motor, so there is
//! no `RHipYawPitch` on the wire.

use std::fmt;

use serde::{Deserialize, Serialize};

/// Number of joints in every LoLA joint array (`Position`, `Stiffness`, `Temperature`, ...).
pub const JOINT_COUNT: usize = 25;

/// One value per joint, indexed in LoLA's order.
pub type JointArray<T> = [T; JOINT_COUNT];

/// A joint, numbered as LoLA numbers it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[repr(u8)]
pub enum Joint {
    HeadYaw,
    HeadPitch,
    LShoulderPitch,
    LShoulderRoll,
    LElbowYaw,
    LElbowRoll,
    LWristYaw,
    LHipYawPitch,
    LHipRoll,
    LHipPitch,
    LKneePitch,
    LAnklePitch,
    LAnkleRoll,
    RHipRoll,
    RHipPitch,
    RKneePitch,
    RAnklePitch,
    RAnkleRoll,
    RShoulderPitch,
    RShoulderRoll,
    RElbowYaw,
    RElbowRoll,
    RWristYaw,
    LHand,
    RHand,
}

/// Mechanical range of a joint, rad (hands: 0 closed .. 1 open).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    pub min: f64,
    pub max: f64,
}

impl JointLimits {
    pub fn clamp(&self, value: f64) -> f64 {
        value.clamp(self.min, self.max)
    }

    pub fn contains(&self, value: f64, margin: f64) -> bool {
        value >= self.min - margin && value <= self.max + margin
    }
}

const fn limits(min: f64, max: f64) -> JointLimits {
    JointLimits { min, max }
}

impl Joint {
    /// Every joint, in LoLA's order.
    pub const ALL: [Joint; JOINT_COUNT] = [
        Joint::HeadYaw,
        Joint::HeadPitch,
        Joint::LShoulderPitch,
        Joint::LShoulderRoll,
        Joint::LElbowYaw,
        Joint::LElbowRoll,
        Joint::LWristYaw,
        Joint::LHipYawPitch,
        Joint::LHipRoll,
        Joint::LHipPitch,
        Joint::LKneePitch,
        Joint::LAnklePitch,
        Joint::LAnkleRoll,
        Joint::RHipRoll,
        Joint::RHipPitch,
        Joint::RKneePitch,
        Joint::RAnklePitch,
        Joint::RAnkleRoll,
        Joint::RShoulderPitch,
        Joint::RShoulderRoll,
        Joint::RElbowYaw,
        Joint::RElbowRoll,
        Joint::RWristYaw,
        Joint::LHand,
        Joint::RHand,
    ];

    /// Position in LoLA's joint arrays.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The name LoLA's documentation (and Aldebaran's) uses.
    pub const fn name(self) -> &'static str {
        match self {
            Joint::HeadYaw => "HeadYaw",
            Joint::HeadPitch => "HeadPitch",
            Joint::LShoulderPitch => "LShoulderPitch",
            Joint::LShoulderRoll => "LShoulderRoll",
            Joint::LElbowYaw => "LElbowYaw",
            Joint::LElbowRoll => "LElbowRoll",
            Joint::LWristYaw => "LWristYaw",
            Joint::LHipYawPitch => "LHipYawPitch",
            Joint::LHipRoll => "LHipRoll",
            Joint::LHipPitch => "LHipPitch",
            Joint::LKneePitch => "LKneePitch",
            Joint::LAnklePitch => "LAnklePitch",
            Joint::LAnkleRoll => "LAnkleRoll",
            Joint::RHipRoll => "RHipRoll",
            Joint::RHipPitch => "RHipPitch",
            Joint::RKneePitch => "RKneePitch",
            Joint::RAnklePitch => "RAnklePitch",
            Joint::RAnkleRoll => "RAnkleRoll",
            Joint::RShoulderPitch => "RShoulderPitch",
            Joint::RShoulderRoll => "RShoulderRoll",
            Joint::RElbowYaw => "RElbowYaw",
            Joint::RElbowRoll => "RElbowRoll",
            Joint::RWristYaw => "RWristYaw",
            Joint::LHand => "LHand",
            Joint::RHand => "RHand",
        }
    }

    /// Looks a joint up by name. `HipYawPitch` and `RHipYawPitch` name the shared hip motor.
    pub fn from_name(name: &str) -> Option<Joint> {
        match name {
            "HipYawPitch" | "RHipYawPitch" => Some(Joint::LHipYawPitch),
            _ => Joint::ALL.into_iter().find(|j| j.name() == name),
        }
    }

    pub const fn is_head(self) -> bool {
        matches!(self, Joint::HeadYaw | Joint::HeadPitch)
    }

    /// Hands are not angles: 0 is closed, 1 open.
    pub const fn is_hand(self) -> bool {
        matches!(self, Joint::LHand | Joint::RHand)
    }

    /// The NAO v6's mechanical joint limits (Aldebaran's joint documentation). Key-frame files
    /// are checked against them when loaded and every target is clamped to them before it is
    /// sent, so a mistyped value cannot drive a joint into its end stop.
    pub const fn limits(self) -> JointLimits {
        match self {
            Joint::HeadYaw => limits(-2.0857, 2.0857),
            Joint::HeadPitch => limits(-0.6720, 0.5149),
            Joint::LShoulderPitch | Joint::RShoulderPitch => limits(-2.0857, 2.0857),
            Joint::LShoulderRoll => limits(-0.3142, 1.3265),
            Joint::RShoulderRoll => limits(-1.3265, 0.3142),
            Joint::LElbowYaw | Joint::RElbowYaw => limits(-2.0857, 2.0857),
            Joint::LElbowRoll => limits(-1.5446, -0.0349),
            Joint::RElbowRoll => limits(0.0349, 1.5446),
            Joint::LWristYaw | Joint::RWristYaw => limits(-1.8238, 1.8238),
            Joint::LHipYawPitch => limits(-1.145303, 0.740810),
            Joint::LHipRoll => limits(-0.379472, 0.790477),
            Joint::RHipRoll => limits(-0.790477, 0.379472),
            Joint::LHipPitch | Joint::RHipPitch => limits(-1.535889, 0.484090),
            Joint::LKneePitch => limits(-0.092346, 2.112528),
            Joint::RKneePitch => limits(-0.103083, 2.120198),
            Joint::LAnklePitch => limits(-1.189516, 0.922747),
            Joint::RAnklePitch => limits(-1.186448, 0.932056),
            Joint::LAnkleRoll => limits(-0.397880, 0.769001),
            Joint::RAnkleRoll => limits(-0.768992, 0.397935),
            Joint::LHand | Joint::RHand => limits(0.0, 1.0),
        }
    }
}

impl fmt::Display for Joint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Head pitch range as a function of head yaw, so the head does not hit the shoulders when it
/// looks to the side: (|yaw| rad, min pitch rad, max pitch rad), linearly interpolated.
/// Conservative values after Aldebaran's head-limit table; the outermost row is kept for larger
/// yaw angles.
const HEAD_PITCH_BY_YAW: [(f64, f64, f64); 6] = [
    (0.0, -0.6720, 0.5149),
    (0.4861, -0.6720, 0.4220),
    (0.7561, -0.5480, 0.3700),
    (0.9030, -0.4800, 0.3299),
    (1.0900, -0.4300, 0.3000),
    (1.5270, -0.3300, 0.2000),
];

/// The head pitch range allowed at a head yaw.
pub fn head_pitch_limits(yaw: f64) -> JointLimits {
    let yaw = yaw.abs();
    let mut previous = HEAD_PITCH_BY_YAW[0];
    for row in HEAD_PITCH_BY_YAW {
        if yaw <= row.0 {
            let span = row.0 - previous.0;
            let t = if span > 0.0 { (yaw - previous.0) / span } else { 1.0 };
            return limits(
                previous.1 + (row.1 - previous.1) * t,
                previous.2 + (row.2 - previous.2) * t,
            );
        }
        previous = row;
    }
    limits(previous.1, previous.2)
}

#[cfg(test)]
// A panic is how a test reports failure.
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn order_matches_lola() {
        for (index, joint) in Joint::ALL.iter().enumerate() {
            assert_eq!(joint.index(), index);
            assert_eq!(Joint::from_name(joint.name()), Some(*joint));
        }
        assert_eq!(Joint::LHipYawPitch.index(), 7);
        assert_eq!(Joint::RHipRoll.index(), 13);
        assert_eq!(Joint::RShoulderPitch.index(), 18);
        assert_eq!(Joint::RHand.index(), 24);
        assert_eq!(Joint::from_name("RHipYawPitch"), Some(Joint::LHipYawPitch));
        assert_eq!(Joint::from_name("Elbow"), None);
    }

    #[test]
    fn limits_are_ordered() {
        for joint in Joint::ALL {
            let l = joint.limits();
            assert!(l.min < l.max, "{joint}");
        }
    }

    #[test]
    fn head_pitch_range_narrows_to_the_side() {
        let centre = head_pitch_limits(0.0);
        let side = head_pitch_limits(-1.5);
        let far = head_pitch_limits(2.0);
        assert_eq!(centre, Joint::HeadPitch.limits());
        assert!(side.min > centre.min && side.max < centre.max);
        assert_eq!(far, head_pitch_limits(1.527));
        assert_eq!(head_pitch_limits(0.3), head_pitch_limits(-0.3));
    }
}
