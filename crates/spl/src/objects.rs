//! What a camera can detect on an SPL field, with stable numeric codes.
//!
//! The simulator produces observations and the soccer application consumes them; both import
//! this crate, so these codes are the one vocabulary they share (in logs and over TCP too).
//! Codes never change meaning: add new kinds with new codes.

use std::fmt;

use serde::{Deserialize, Serialize};

/// A kind of fixed landmark of the field.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LandmarkKind {
    GoalPost,
    LCrossing,
    TCrossing,
    XCrossing,
    CenterCircle,
    PenaltyMark,
    Beacon,
}

impl LandmarkKind {
    /// Every landmark kind, in code order.
    pub const ALL: [LandmarkKind; 7] = [
        LandmarkKind::GoalPost,
        LandmarkKind::LCrossing,
        LandmarkKind::TCrossing,
        LandmarkKind::XCrossing,
        LandmarkKind::CenterCircle,
        LandmarkKind::PenaltyMark,
        LandmarkKind::Beacon,
    ];

    /// The same kind as an [`ObjectKind`].
    pub const fn object_kind(self) -> ObjectKind {
        match self {
            LandmarkKind::GoalPost => ObjectKind::GoalPost,
            LandmarkKind::LCrossing => ObjectKind::LCrossing,
            LandmarkKind::TCrossing => ObjectKind::TCrossing,
            LandmarkKind::XCrossing => ObjectKind::XCrossing,
            LandmarkKind::CenterCircle => ObjectKind::CenterCircle,
            LandmarkKind::PenaltyMark => ObjectKind::PenaltyMark,
            LandmarkKind::Beacon => ObjectKind::Beacon,
        }
    }

    /// The snake_case name, as in serialized data.
    pub const fn name(self) -> &'static str {
        self.object_kind().name()
    }
}

impl fmt::Display for LandmarkKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Everything a camera can detect on an SPL field.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u16)]
pub enum ObjectKind {
    Ball = 1,
    Robot = 2,
    /// A straight piece of painted line (not a landmark: it fixes only a distance and a direction).
    FieldLine = 3,
    /// The head referee, beside the field; the variant is the gesture it shows
    /// ([`Gesture`]).
    Referee = 4,
    GoalPost = 10,
    LCrossing = 11,
    TCrossing = 12,
    XCrossing = 13,
    CenterCircle = 14,
    PenaltyMark = 15,
    Beacon = 16,
}

impl ObjectKind {
    /// Every object kind, in code order.
    pub const ALL: [ObjectKind; 11] = [
        ObjectKind::Ball,
        ObjectKind::Robot,
        ObjectKind::FieldLine,
        ObjectKind::Referee,
        ObjectKind::GoalPost,
        ObjectKind::LCrossing,
        ObjectKind::TCrossing,
        ObjectKind::XCrossing,
        ObjectKind::CenterCircle,
        ObjectKind::PenaltyMark,
        ObjectKind::Beacon,
    ];

    /// The stable numeric code.
    pub const fn code(self) -> u16 {
        self as u16
    }

    /// The kind with this code, if any.
    pub fn from_code(code: u16) -> Option<ObjectKind> {
        ObjectKind::ALL.into_iter().find(|kind| kind.code() == code)
    }

    /// The snake_case name, as in serialized data.
    pub const fn name(self) -> &'static str {
        match self {
            ObjectKind::Ball => "ball",
            ObjectKind::Robot => "robot",
            ObjectKind::FieldLine => "field_line",
            ObjectKind::Referee => "referee",
            ObjectKind::GoalPost => "goal_post",
            ObjectKind::LCrossing => "l_crossing",
            ObjectKind::TCrossing => "t_crossing",
            ObjectKind::XCrossing => "x_crossing",
            ObjectKind::CenterCircle => "center_circle",
            ObjectKind::PenaltyMark => "penalty_mark",
            ObjectKind::Beacon => "beacon",
        }
    }

    /// The kind with this name, if any.
    pub fn from_name(name: &str) -> Option<ObjectKind> {
        ObjectKind::ALL.into_iter().find(|kind| kind.name() == name)
    }

    /// The landmark kind, for fixed objects.
    pub const fn landmark_kind(self) -> Option<LandmarkKind> {
        match self {
            ObjectKind::Ball | ObjectKind::Robot | ObjectKind::FieldLine | ObjectKind::Referee => {
                None
            }
            ObjectKind::GoalPost => Some(LandmarkKind::GoalPost),
            ObjectKind::LCrossing => Some(LandmarkKind::LCrossing),
            ObjectKind::TCrossing => Some(LandmarkKind::TCrossing),
            ObjectKind::XCrossing => Some(LandmarkKind::XCrossing),
            ObjectKind::CenterCircle => Some(LandmarkKind::CenterCircle),
            ObjectKind::PenaltyMark => Some(LandmarkKind::PenaltyMark),
            ObjectKind::Beacon => Some(LandmarkKind::Beacon),
        }
    }
}

/// The referee's gestures a camera reports, as the variant of an [`ObjectKind::Referee`]
/// detection. Under the SPL rules robots must see the Ready gesture themselves: GameController3
/// keeps sending Standby for a while after it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u16)]
pub enum Gesture {
    /// Standing, arms down.
    None = 0,
    /// Both arms raised: the game goes from Standby to Ready.
    Ready = 1,
}

impl Gesture {
    /// The stable numeric code (the detection's variant).
    pub const fn code(self) -> u16 {
        self as u16
    }

    /// The gesture with this code, if any.
    pub fn from_code(code: u16) -> Option<Gesture> {
        [Gesture::None, Gesture::Ready].into_iter().find(|g| g.code() == code)
    }
}

impl From<LandmarkKind> for ObjectKind {
    fn from(kind: LandmarkKind) -> ObjectKind {
        kind.object_kind()
    }
}

impl fmt::Display for ObjectKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_stable_and_round_trip() {
        // These numbers are part of logs and the simulator protocol: changing one is a break.
        let expected = [
            (ObjectKind::Ball, 1, "ball"),
            (ObjectKind::Robot, 2, "robot"),
            (ObjectKind::FieldLine, 3, "field_line"),
            (ObjectKind::Referee, 4, "referee"),
            (ObjectKind::GoalPost, 10, "goal_post"),
            (ObjectKind::LCrossing, 11, "l_crossing"),
            (ObjectKind::TCrossing, 12, "t_crossing"),
            (ObjectKind::XCrossing, 13, "x_crossing"),
            (ObjectKind::CenterCircle, 14, "center_circle"),
            (ObjectKind::PenaltyMark, 15, "penalty_mark"),
            (ObjectKind::Beacon, 16, "beacon"),
        ];
        assert_eq!(expected.len(), ObjectKind::ALL.len());
        for (kind, code, name) in expected {
            assert_eq!(kind.code(), code);
            assert_eq!(kind.name(), name);
            assert_eq!(ObjectKind::from_code(code), Some(kind));
            assert_eq!(ObjectKind::from_name(name), Some(kind));
        }
        assert_eq!(ObjectKind::from_code(0), None);
        assert_eq!(ObjectKind::from_code(5), None);
        assert_eq!(Gesture::from_code(1), Some(Gesture::Ready));
        assert_eq!(Gesture::from_code(0), Some(Gesture::None));
        assert_eq!(Gesture::from_code(2), None);
        assert_eq!(ObjectKind::from_name("goal"), None);
    }

    #[test]
    fn every_landmark_kind_is_an_object_kind() {
        for kind in LandmarkKind::ALL {
            assert_eq!(kind.object_kind().landmark_kind(), Some(kind));
            assert_eq!(kind.name(), kind.object_kind().name());
        }
        assert_eq!(ObjectKind::Ball.landmark_kind(), None);
    }

    #[test]
    fn serde_names_match_name() {
        for kind in ObjectKind::ALL {
            let text = toml::Value::try_from(kind).map(|v| v.to_string());
            assert_eq!(text.ok(), Some(format!("\"{}\"", kind.name())));
        }
    }
}
