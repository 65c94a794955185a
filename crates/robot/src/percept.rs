//! Percepts: what the perception module makes of a sensor frame, for the reactive layer
//! (Latest) and world modeling (Queue).

use serde::{Deserialize, Serialize};
use strata_runtime::Time;

use crate::geometry::{Point, Robot};
use crate::platform::{Buttons, FootContact, HeadAngles, InertialData, ObjectClass};

/// A signal perceived in one sensor frame — the referee's whistle heard, a gesture seen: an
/// event, not an object to track. Perception sends signals to the planning layer, whose
/// external device (the GameController) weighs them against its packets.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Signal {
    /// When it was perceived (the image's or the frame's time).
    pub stamp: Time,
    pub kind: SignalKind,
    /// The detector's confidence in [0, 1] (1 for a camera detection).
    pub confidence: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SignalKind {
    /// The platform's whistle detector fired.
    Whistle,
    /// The camera saw an object of a signal class ([`crate::perception::PerceptionConfig::
    /// signal_classes`]): the referee, its variant the gesture.
    Sight {
        class: ObjectClass,
        variant: Option<u16>,
        /// Ground distance, m, and direction relative to the body's heading, rad.
        range: f64,
        bearing: f64,
    },
}

/// One object seen, relative to the robot's body, with the noise perception expects on it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    pub class: ObjectClass,
    pub variant: Option<u16>,
    /// Ground distance, m.
    pub range: f64,
    /// Direction relative to the body's heading, rad.
    pub bearing: f64,
    /// The feature's orientation relative to the body's heading, when it has one.
    pub orientation: Option<f64>,
    /// Standard deviations of the measurement, as perception models them.
    pub range_sigma: f64,
    pub bearing_sigma: f64,
}

impl Observation {
    pub fn position(&self) -> Point<Robot> {
        Point::from_polar(self.range, self.bearing)
    }
}

/// The region the camera looked at when an image was taken: lets world modeling lower its
/// confidence in objects that should have been seen and were not.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewCone {
    /// Direction of the optical axis relative to the body, rad.
    pub direction: f64,
    /// Horizontal field of view, rad.
    pub fov: f64,
    /// Detection range, m: the detector's, or less where the image's upper edge meets the
    /// ground sooner.
    pub range: f64,
    /// Nearest ground distance the image showed, m (0 for a camera that sees the feet).
    #[serde(default)]
    pub near: f64,
}

impl ViewCone {
    /// Whether a point lies inside the cone, shrunk by `margin` rad on each side (objects at the
    /// border are often missed without being absent).
    pub fn contains(&self, point: Point<Robot>, margin: f64) -> bool {
        self.contains_polar(point.range(), point.bearing(), margin)
    }

    /// [`ViewCone::contains`] for a point given by its range and bearing, for callers that have
    /// them at hand (world modeling computes them for every filter anyway).
    pub fn contains_polar(&self, range: f64, bearing: f64, margin: f64) -> bool {
        let angle = crate::geometry::normalize_angle(bearing - self.direction);
        range >= self.near
            && range <= self.range
            && angle.abs() <= (self.fov / 2.0 - margin).max(0.0)
    }
}

/// The observations from one camera image.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraPercepts {
    pub stamp: Time,
    pub view: ViewCone,
    pub observations: Vec<Observation>,
}

/// Everything perception produced from one sensor frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Percepts {
    pub stamp: Time,
    pub inertial: InertialData,
    pub head: HeadAngles,
    pub foot_contact: FootContact,
    pub buttons: Buttons,
    /// Present when the frame carried a new camera image.
    pub camera: Option<CameraPercepts>,
    /// The platform saw the robot put somewhere since the previous frame
    /// ([`crate::platform::SensorFrame::placed`]).
    #[serde(default)]
    pub placed: bool,
}

impl Percepts {
    pub fn observations(&self) -> &[Observation] {
        self.camera.as_ref().map_or(&[], |c| c.observations.as_slice())
    }
}
