//! Active vision (paper 3.6): choosing where to look by what the look is worth to the current
//! deliberative behavior.
//!
//! The steps of the paper, as Strata runs them:
//! (a) the reactive layer executes the acting primitive; (b) world modeling predicts the belief;
//! (c) the deliberative layer evaluates, for each candidate sensing primitive (look along a
//! direction: at one object, or at a point from which several are seen together), the
//! behavior's value function under the belief that observation would produce — computed with
//! world modeling's [`WorldState::expected_update`], which simulates the correction without
//! performing it — and sends the results as deliberative scores to the head multiplexer;
//! (d) the multiplexer combines them with reactive scores and executes the sensing primitive;
//! (e) world modeling corrects with the new observation.
//!
//! Two optimality criteria, after Guerrero and Ruiz-del-Solar (the paper's [30]):
//! - **minimum expected value variance**: choose the look that minimises Var[V] under the
//!   posterior. Linearized, Var[V] = J P J^T, with J the gradient of V at the estimate and P the
//!   posterior covariance (block-diagonal: the pose and each object are separate filters).
//! - **maximum expected action task value**: choose the look that maximises E[V] after the next
//!   acting primitive, which acts on the posterior mean. To second order,
//!   E[V] = V(x') + tr(H' P') / 2, with x' and P' the belief after the look *and* the primitive's
//!   predicted motion ([`PredictedMotion`]: the pose moved by it, its covariance propagated as
//!   the pose filter's prediction does, the objects carried into the moved robot frame) and H'
//!   the Hessian of V there: uncertainty costs value where V is curved, even where its gradient
//!   is flat (near the optimum of a covering position, say), and a heading error costs more
//!   the farther the robot is about to walk.
//!
//! The two disagree when a look reduces uncertainty along a direction where V is steep but
//! flat-bottomed, versus one where V is level but curved; both are available and the
//! behavior chooses. V is the application's: a function of the robot's pose and the positions
//! of the objects it names, derived numerically (central differences).

use serde::{Deserialize, Serialize};

use crate::geometry::{Global, Odometry, Point, Pose, Robot, normalize_angle};
use crate::percept::ViewCone;
use crate::platform::Footprint;
use crate::world::{ExpectedBelief, ObjectId, ObservationPrior, SensingCandidate, WorldState};
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

/// How a sensing candidate is judged.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Criterion {
    #[default]
    MinExpectedValueVariance,
    MaxExpectedTaskValue,
}

/// The state a value function is evaluated on: the robot's pose and the positions of objects
/// (robot frame), possibly perturbed from the world state's estimates.
#[derive(Clone, Debug)]
pub struct ValueState<'a> {
    pub world: &'a WorldState,
    pub pose: Pose,
    objects: Vec<(ObjectId, Point<Robot>)>,
}

impl<'a> ValueState<'a> {
    /// The world state's own estimates.
    pub fn of(world: &'a WorldState) -> ValueState<'a> {
        ValueState { world, pose: world.pose.pose, objects: Vec::new() }
    }

    /// An object's position relative to the robot.
    pub fn object(&self, id: ObjectId) -> Option<Point<Robot>> {
        self.objects
            .iter()
            .find(|(o, _)| *o == id)
            .map(|(_, p)| *p)
            .or_else(|| self.world.get(id).map(|o| o.position))
    }

    /// An object's field position, through the (possibly perturbed) pose.
    pub fn object_field(&self, id: ObjectId) -> Option<Point<Global>> {
        self.object(id).map(|p| self.pose.to_global(p))
    }

    fn set_object(&mut self, id: ObjectId, position: Point<Robot>) {
        match self.objects.iter_mut().find(|(o, _)| *o == id) {
            Some(entry) => entry.1 = position,
            None => self.objects.push((id, position)),
        }
    }
}

/// The motion the next acting primitive is expected to make before the deliberative layer
/// decides again: the task-value criterion judges a look by the value expected *after* it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PredictedMotion {
    /// The displacement, in the robot frame it starts from.
    pub odometry: Odometry,
    /// Covariance of its error (e.g. [`crate::world::OdometryNoise::covariance`]).
    pub noise: Matrix3<f64>,
}

impl PredictedMotion {
    /// The pose after the motion.
    fn pose(&self, pose: Pose) -> Pose {
        let moved = pose.to_global(Point::new(self.odometry.dx, self.odometry.dy));
        Pose::new(moved.x, moved.y, normalize_angle(pose.theta + self.odometry.dtheta))
    }

    /// A robot-frame position in the robot frame after the motion (the same field position).
    fn carry(&self, p: Point<Robot>) -> Point<Robot> {
        let (s, c) = self.odometry.dtheta.sin_cos();
        let (x, y) = (p.x - self.odometry.dx, p.y - self.odometry.dy);
        Point::new(c * x + s * y, -s * x + c * y)
    }

    /// The pose covariance after the motion, from `p` at heading `theta`: the pose filter's
    /// prediction (the heading's uncertainty turns into position uncertainty along the walk).
    fn pose_covariance(&self, theta: f64, p: &Matrix3<f64>) -> Matrix3<f64> {
        let (s, c) = theta.sin_cos();
        let (dx, dy) = (self.odometry.dx, self.odometry.dy);
        let f = Matrix3::new(1.0, 0.0, -s * dx - c * dy, 0.0, 1.0, c * dx - s * dy, 0.0, 0.0, 1.0);
        let g = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        f * p * f.transpose() + g * self.noise * g.transpose()
    }

    /// An object's robot-frame covariance after the motion: turned into the new frame, plus
    /// the motion's own error as it moves the object relative to the robot.
    fn object_covariance(&self, p: Point<Robot>, covariance: &Matrix2<f64>) -> Matrix2<f64> {
        let (s, c) = self.odometry.dtheta.sin_cos();
        let turn = Matrix2::new(c, s, -s, c);
        let (x, y) = (p.x - self.odometry.dx, p.y - self.odometry.dy);
        // d(carried)/d(dx, dy, dtheta).
        let j = nalgebra::Matrix2x3::new(-c, -s, -s * x + c * y, s, -c, -c * x - s * y);
        turn * covariance * turn.transpose() + j * self.noise * j.transpose()
    }
}

/// A behavior-dependent value function V(x) (paper 3.4): larger means a world state more
/// convenient for the behavior.
pub trait ValueFunction: Send + Sync {
    fn name(&self) -> &str;

    /// The objects V depends on (besides the robot's pose).
    fn objects(&self) -> Vec<ObjectId>;

    fn value(&self, state: &ValueState<'_>) -> f64;
}

/// A sensing primitive to evaluate: look along `direction` (body frame).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GazeCandidate {
    pub label: String,
    pub direction: f64,
    /// The stretch of ground this gaze would show, for a body whose camera cannot see near
    /// and far at once (a tall robot pitches its head down to look at something close, and
    /// then sees nothing far); `None`: everything out to the camera's range.
    #[serde(default)]
    pub footprint: Option<Footprint>,
}

impl GazeCandidate {
    /// Look at an object's estimated position.
    pub fn toward(
        world: &WorldState,
        id: ObjectId,
        label: impl Into<String>,
    ) -> Option<GazeCandidate> {
        let direction = Self::toward_direction(world, id)?;
        Some(GazeCandidate { label: label.into(), direction, footprint: None })
    }

    /// The direction [`GazeCandidate::toward`] would look along, without making a candidate.
    pub fn toward_direction(world: &WorldState, id: ObjectId) -> Option<f64> {
        Some(world.get(id)?.position.bearing())
    }

    /// Look at a point from which all `ids` are seen, when one exists (their bearings span
    /// less than the usable field of view).
    pub fn covering(
        world: &WorldState,
        ids: &[ObjectId],
        usable_fov: f64,
        label: impl Into<String>,
    ) -> Option<GazeCandidate> {
        let direction = Self::covering_direction(world, ids.iter().copied(), usable_fov)?;
        Some(GazeCandidate { label: label.into(), direction, footprint: None })
    }

    /// The direction [`GazeCandidate::covering`] would look along, without making a
    /// candidate: the multiplexer asks every cycle whether objects still fit in one gaze.
    pub fn covering_direction(
        world: &WorldState,
        ids: impl IntoIterator<Item = ObjectId>,
        usable_fov: f64,
    ) -> Option<f64> {
        // The smallest arc holding every bearing: measured around the first one.
        let mut reference = None;
        let (mut lo, mut hi) = (0.0f64, 0.0f64);
        for id in ids {
            let bearing = world.get(id)?.position.bearing();
            let offset = normalize_angle(bearing - *reference.get_or_insert(bearing));
            lo = lo.min(offset);
            hi = hi.max(offset);
        }
        let reference = reference?;
        (hi - lo <= usable_fov).then(|| normalize_angle(reference + (lo + hi) / 2.0))
    }
}

/// The camera the candidates are evaluated with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ActiveVisionConfig {
    pub criterion: Criterion,
    /// Horizontal field of view, rad.
    pub fov: f64,
    /// Detection range, m.
    pub range: f64,
    /// Head yaw limits, rad: a direction beyond them is looked at from the limit.
    pub yaw_limits: (f64, f64),
    /// Objects less likely than this to be seen are not counted for a candidate.
    pub min_visibility: f64,
    /// Finite-difference steps: metres for positions, radians for the heading.
    pub position_step: f64,
    pub heading_step: f64,
    /// How long the chosen look holds, s (the deliberative period): an object of V the look
    /// does not observe is judged with the uncertainty its motion adds by then, `P + T² P_v`
    /// (constant velocity), one it observes with its posterior (kept by looking). 0: the belief
    /// right after the look.
    pub horizon: f64,
}

impl Default for ActiveVisionConfig {
    fn default() -> Self {
        ActiveVisionConfig {
            criterion: Criterion::MinExpectedValueVariance,
            fov: 1.06,
            range: 6.0,
            yaw_limits: (-2.0, 2.0),
            min_visibility: 0.05,
            position_step: 0.01,
            heading_step: 0.01,
            horizon: 0.0,
        }
    }
}

/// One candidate's evaluation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GazeEvaluation {
    pub label: String,
    pub direction: f64,
    /// Objects the look would probably observe (world-model names).
    pub observed: Vec<String>,
    /// Var[V] after the look.
    pub value_variance: f64,
    /// E[V] after the look (and the next acting primitive).
    pub expected_value: f64,
    /// How much better than not looking, by the criterion (>= 0).
    pub improvement: f64,
    /// The deliberative score S_d in [0, 1]: improvement relative to the best candidate's.
    pub score: f64,
}

/// The result of one active-vision evaluation.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ActiveVisionReport {
    pub value_function: String,
    pub criterion: Criterion,
    pub value: f64,
    /// Var[V] and E[V] under the current (prior) belief.
    pub prior_variance: f64,
    pub prior_expected_value: f64,
    pub candidates: Vec<GazeEvaluation>,
}

impl ActiveVisionReport {
    pub fn best(&self) -> Option<&GazeEvaluation> {
        self.candidates.iter().max_by(|a, b| a.score.total_cmp(&b.score))
    }

    pub fn score_of(&self, label: &str) -> Option<f64> {
        self.candidates.iter().find(|c| c.label == label).map(|c| c.score)
    }
}

/// Gradient and Hessian of V, per filter block.
struct Derivatives {
    value: f64,
    pose_gradient: Vector3<f64>,
    pose_hessian: Matrix3<f64>,
    objects: Vec<(ObjectId, Vector2<f64>, Matrix2<f64>)>,
}

/// Evaluates sensing candidates for a value function (step (c) of paper 3.6).
#[derive(Clone, Debug, Default)]
pub struct ActiveVision {
    pub config: ActiveVisionConfig,
    scratch: ExpectedBelief,
    /// The objects' view-independent predictions (and simulated corrections), made once per
    /// evaluation.
    priors: Vec<ObservationPrior>,
    sensing: SensingCandidate,
    /// The objects whose covariances the value function's moments read.
    wanted: Vec<ObjectId>,
}

impl ActiveVision {
    pub fn new(config: ActiveVisionConfig) -> ActiveVision {
        ActiveVision { config, ..ActiveVision::default() }
    }

    /// V's value and derivatives at the world state's estimates, or where `motion` takes them.
    fn derivatives(
        &self,
        world: &WorldState,
        vf: &dyn ValueFunction,
        motion: Option<&PredictedMotion>,
    ) -> Derivatives {
        // One state, perturbed and restored in place: each perturbed state is the world
        // state's own (or the moved one) but for one block, as a fresh copy would be.
        let mut state = ValueState::of(world);
        let mut carried = Vec::new();
        if let Some(motion) = motion {
            state.pose = motion.pose(state.pose);
            for id in vf.objects() {
                if let Some(p) = world.get(id).map(|o| o.position) {
                    carried.push((id, motion.carry(p)));
                }
            }
            state.objects.clone_from(&carried);
        }
        let base = state.pose;
        let value = vf.value(&state);
        // Pose block: x, y, theta.
        let steps =
            [self.config.position_step, self.config.position_step, self.config.heading_step];
        let perturbed_pose = |s: &mut ValueState<'_>, deltas: [f64; 3]| {
            s.pose = Pose::new(base.x + deltas[0], base.y + deltas[1], base.theta + deltas[2]);
            vf.value(s)
        };
        let (pose_gradient, pose_hessian) =
            derivatives_of::<3, _>(value, &steps, &mut state, perturbed_pose);
        state.pose = base;
        let mut objects = Vec::new();
        for id in vf.objects() {
            let Some(position) = state.object(id) else { continue };
            let steps = [self.config.position_step; 2];
            let perturbed = |s: &mut ValueState<'_>, d: [f64; 2]| {
                s.set_object(id, Point::new(position.x + d[0], position.y + d[1]));
                vf.value(s)
            };
            let (g, h) = derivatives_of::<2, _>(value, &steps, &mut state, perturbed);
            state.objects.clone_from(&carried);
            objects.push((
                id,
                Vector2::new(g[0], g[1]),
                Matrix2::new(h[(0, 0)], h[(0, 1)], h[(1, 0)], h[(1, 1)]),
            ));
        }
        Derivatives {
            value,
            pose_gradient: Vector3::new(pose_gradient[0], pose_gradient[1], pose_gradient[2]),
            pose_hessian: Matrix3::from_fn(|r, c| pose_hessian[(r, c)]),
            objects,
        }
    }

    /// Var[V] and E[V] for a belief whose covariances `pose` and `object(id)` give.
    fn moments(
        d: &Derivatives,
        pose: &Matrix3<f64>,
        object: impl Fn(ObjectId) -> Option<Matrix2<f64>>,
    ) -> (f64, f64) {
        let mut variance = (d.pose_gradient.transpose() * pose * d.pose_gradient)[(0, 0)];
        let mut curvature = (d.pose_hessian * pose).trace();
        for (id, g, h) in &d.objects {
            if let Some(p) = object(*id) {
                variance += (g.transpose() * p * g)[(0, 0)];
                curvature += (h * p).trace();
            }
        }
        (variance.max(0.0), d.value + 0.5 * curvature)
    }

    /// Evaluates every candidate; scores are normalised so the best candidate gets 1.
    pub fn evaluate(
        &mut self,
        world: &WorldState,
        vf: &dyn ValueFunction,
        candidates: &[GazeCandidate],
    ) -> ActiveVisionReport {
        let mut report = ActiveVisionReport::default();
        self.evaluate_into(world, vf, candidates, &mut report);
        report
    }

    /// As [`ActiveVision::evaluate`], into `report`, reusing its storage (its candidates' labels
    /// and observed names): a deliberative layer evaluates at every tick.
    pub fn evaluate_into(
        &mut self,
        world: &WorldState,
        vf: &dyn ValueFunction,
        candidates: &[GazeCandidate],
        report: &mut ActiveVisionReport,
    ) {
        self.evaluate_after_into(world, vf, candidates, None, report);
    }

    /// As [`ActiveVision::evaluate_into`], with the task-value criterion judging each look by
    /// the value expected after `motion`, the next acting primitive's (the variance criterion
    /// judges the belief the look leaves now, and ignores it).
    pub fn evaluate_after_into(
        &mut self,
        world: &WorldState,
        vf: &dyn ValueFunction,
        candidates: &[GazeCandidate],
        motion: Option<&PredictedMotion>,
        report: &mut ActiveVisionReport,
    ) {
        let motion = motion.filter(|_| self.config.criterion == Criterion::MaxExpectedTaskValue);
        let d = self.derivatives(world, vf, motion);
        let heading = world.pose.pose.theta;
        // The belief a look leaves, carried through the motion when there is one.
        let moved_pose = |p: &Matrix3<f64>| match motion {
            Some(m) => m.pose_covariance(heading, p),
            None => *p,
        };
        let moved_object = |id: ObjectId, p: Matrix2<f64>| match (motion, world.get(id)) {
            (Some(m), Some(o)) => m.object_covariance(o.position, &p),
            _ => p,
        };
        // Unobserved for the horizon, an object's estimate spreads with its velocity's
        // uncertainty.
        let horizon = self.config.horizon.max(0.0);
        let prior_object = |id: ObjectId| {
            world.get(id).map(|o| match o.velocity_covariance {
                Some(v) if horizon > 0.0 => o.covariance + v * (horizon * horizon),
                _ => o.covariance,
            })
        };
        let (prior_variance, prior_expected_value) =
            Self::moments(&d, &moved_pose(&world.pose.covariance), |id| {
                prior_object(id).map(|p| moved_object(id, p))
            });
        let (lo, hi) = self.config.yaw_limits;
        let (range, min_visibility) = (self.config.range, self.config.min_visibility);
        // Objects no view of this range can observe are left out once for all candidates.
        world.observation_priors_reaching_into(range, min_visibility, &mut self.priors);
        // Only the pose's and these objects' posteriors are read (by `moments`).
        self.wanted.clear();
        self.wanted.extend(d.objects.iter().map(|(id, _, _)| *id));
        let evaluations = &mut report.candidates;
        evaluations.truncate(candidates.len());
        for (i, candidate) in candidates.iter().enumerate() {
            let direction = candidate.direction.clamp(lo.min(hi), hi.max(lo));
            if i == evaluations.len() {
                evaluations.push(GazeEvaluation {
                    label: String::new(),
                    direction,
                    observed: Vec::new(),
                    value_variance: 0.0,
                    expected_value: 0.0,
                    improvement: 0.0,
                    score: 0.0,
                });
            }
            let (done, rest) = evaluations.split_at_mut(i);
            let e = &mut rest[0];
            e.label.clone_from(&candidate.label);
            e.direction = direction;
            // Candidates beyond a yaw limit are all looked at from the limit: the same view,
            // simulated once.
            let same = done.iter().zip(candidates).find(|(d, c)| {
                d.direction.to_bits() == direction.to_bits() && c.footprint == candidate.footprint
            });
            if let Some((same, _)) = same {
                e.observed.clone_from(&same.observed);
                e.value_variance = same.value_variance;
                e.expected_value = same.expected_value;
                e.improvement = same.improvement;
                continue;
            }
            let view = ViewCone {
                direction,
                fov: self.config.fov,
                range: candidate.footprint.map_or(range, |f| f.far.min(range)),
                near: candidate.footprint.map_or(0.0, |f| f.near),
            };
            world.expected_view_update_of_into(
                &mut self.priors,
                &view,
                self.config.min_visibility,
                &self.wanted,
                &mut self.sensing,
                &mut self.scratch,
            );
            let scratch = &self.scratch;
            let posterior_object = |id: ObjectId| {
                scratch
                    .object(id)
                    .copied()
                    .or_else(|| prior_object(id))
                    .map(|p| moved_object(id, p))
            };
            let (variance, expected) =
                Self::moments(&d, &moved_pose(&scratch.pose), posterior_object);
            let names = self.sensing.observations.iter().filter_map(|o| world.get(o.object));
            overwrite(&mut e.observed, names.map(|o| o.name.as_str()));
            e.value_variance = variance;
            e.expected_value = expected;
            e.improvement = match self.config.criterion {
                Criterion::MinExpectedValueVariance => prior_variance - variance,
                Criterion::MaxExpectedTaskValue => expected - prior_expected_value,
            }
            .max(0.0);
        }
        let best = evaluations.iter().map(|e| e.improvement).fold(0.0, f64::max);
        for e in evaluations.iter_mut() {
            e.score = if best > 1e-15 { (e.improvement / best).clamp(0.0, 1.0) } else { 0.0 };
        }
        report.value_function.clear();
        report.value_function.push_str(vf.name());
        report.criterion = self.config.criterion;
        report.value = d.value;
        report.prior_variance = prior_variance;
        report.prior_expected_value = prior_expected_value;
    }
}

/// Makes `target` the list of `texts`, reusing its strings' storage.
fn overwrite<'a>(target: &mut Vec<String>, texts: impl Iterator<Item = &'a str>) {
    let mut n = 0;
    for text in texts {
        match target.get_mut(n) {
            Some(kept) => {
                kept.clear();
                kept.push_str(text);
            }
            None => target.push(text.to_owned()),
        }
        n += 1;
    }
    target.truncate(n);
}

/// Central-difference gradient and Hessian of `f` around 0 with the given steps.
/// `f` is evaluated on `state` (which it may change).
fn derivatives_of<const N: usize, S>(
    f0: f64,
    steps: &[f64; N],
    state: &mut S,
    f: impl Fn(&mut S, [f64; N]) -> f64,
) -> ([f64; N], nalgebra::SMatrix<f64, N, N>) {
    let mut gradient = [0.0; N];
    let mut hessian = nalgebra::SMatrix::<f64, N, N>::zeros();
    let mut shifted = |i: usize, a: f64, j: usize, b: f64| {
        let mut d = [0.0; N];
        d[i] += a;
        d[j] += b;
        f(state, d)
    };
    for i in 0..N {
        let h = steps[i];
        let plus = shifted(i, h, i, 0.0);
        let minus = shifted(i, -h, i, 0.0);
        gradient[i] = (plus - minus) / (2.0 * h);
        hessian[(i, i)] = (plus - 2.0 * f0 + minus) / (h * h);
        for j in (i + 1)..N {
            let k = steps[j];
            let pp = shifted(i, h, j, k);
            let pm = shifted(i, h, j, -k);
            let mp = shifted(i, -h, j, k);
            let mm = shifted(i, -h, j, -k);
            let mixed = (pp - pm - mp + mm) / (4.0 * h * k);
            hessian[(i, j)] = mixed;
            hessian[(j, i)] = mixed;
        }
    }
    (gradient, hessian)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finite_differences_recover_a_quadratic() {
        // f(x, y) = 3x - 2y + x^2 + 4xy - 5y^2 at the origin.
        let f = |d: [f64; 2]| {
            3.0 * d[0] - 2.0 * d[1] + d[0] * d[0] + 4.0 * d[0] * d[1] - 5.0 * d[1] * d[1]
        };
        let (g, h) = derivatives_of::<2, _>(f([0.0, 0.0]), &[0.01, 0.01], &mut (), |_, d| f(d));
        assert!((g[0] - 3.0).abs() < 1e-9 && (g[1] + 2.0).abs() < 1e-9);
        assert!((h[(0, 0)] - 2.0).abs() < 1e-6);
        assert!((h[(0, 1)] - 4.0).abs() < 1e-6 && (h[(1, 0)] - 4.0).abs() < 1e-6);
        assert!((h[(1, 1)] + 10.0).abs() < 1e-6);
    }
}
