//! Value functions of the patrol's deliberative behaviors (paper 3.4): V(x) grows with how
//! convenient the world state is for the behavior. Active vision differentiates them
//! numerically, so they are smooth.

use strata_robot::control::active_vision::{ValueFunction, ValueState};
use strata_robot::geometry::{Global, Point};
use strata_robot::world::ObjectId;

/// V of an inspection: how well the point of interest is placed on the floor plan.
///
/// `V = -|p̂ - m|² / s²`, with p̂ the point's field position (the robot's pose applied to the
/// point's robot-frame estimate) and m its position on the plan. Its curvature is what matters:
/// under the maximum expected action task value criterion, `E[V] = V + tr(H P) / 2` falls by the
/// expected squared error of p̂ — the point's own uncertainty plus the robot's pose uncertainty,
/// the heading's weighted by the squared distance to the point. Looking at the point sharpens
/// the first, looking at a landmark the second: the gaze goes to whichever the inspection
/// needs more ("how well the point is localized and how well the robot knows its own pose").
#[derive(Debug, Clone)]
pub struct InspectionQuality {
    pub poi: ObjectId,
    pub nominal: Point<Global>,
    /// Length scale, m.
    pub scale: f64,
}

impl ValueFunction for InspectionQuality {
    fn name(&self) -> &str {
        "inspection quality"
    }

    fn objects(&self) -> Vec<ObjectId> {
        vec![self.poi]
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        let Some(point) = state.object_field(self.poi) else { return 0.0 };
        let d = point - self.nominal;
        -d.dot(d) / (self.scale * self.scale)
    }
}

/// V of walking a route: closeness to the next stop, which only localization improves (judged
/// by the minimum expected value variance criterion: the landmark that best pins the pose
/// along the way wins the head).
#[derive(Debug, Clone)]
pub struct RouteValue {
    pub target: Point<Global>,
}

impl ValueFunction for RouteValue {
    fn name(&self) -> &str {
        "route progress"
    }

    fn objects(&self) -> Vec<ObjectId> {
        Vec::new()
    }

    fn value(&self, state: &ValueState<'_>) -> f64 {
        (-0.5 * state.pose.position().distance(self.target)).exp()
    }
}
