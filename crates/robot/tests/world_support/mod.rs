//! A small generator of simulated sequences with known noise for the world-model tests: a robot
//! walking on a 9 m x 6 m field with symmetric landmarks, a head sweeping, a rolling ball, noisy
//! odometry and a noisy camera drawn from exactly the models the filters assume.

#![allow(dead_code)]

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use strata_robot::geometry::{Global, Odometry, Point, Pose, normalize_angle};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::platform::ObjectClass;
use strata_robot::world::{
    CameraNoise, ExpectedObservation, FieldLinesConfig, ObjectId, ObjectKind, ObjectOfInterest,
    OdometryNoise, PoseConfig, PosePrior, Region, SensingCandidate, WorldModelConfig, WorldState,
};
use strata_runtime::Time;

pub const BALL: ObjectClass = ObjectClass(1);
pub const POST: ObjectClass = ObjectClass(10);
pub const L_CROSSING: ObjectClass = ObjectClass(11);
pub const CIRCLE: ObjectClass = ObjectClass(14);
pub const PENALTY_MARK: ObjectClass = ObjectClass(15);
pub const LINE: ObjectClass = ObjectClass(3);
/// Standard deviation of a seen line's direction, rad.
pub const LINE_DIRECTION_SIGMA: f64 = 0.05;

pub const FRICTION: f64 = 0.4;
pub const BALL_ACCELERATION_NOISE: f64 = 0.15;
pub const BALL_MAX_SPEED: f64 = 3.0;
pub const DT: f64 = 1.0 / 30.0;

pub fn bounds() -> Region {
    Region { min_x: -5.2, max_x: 5.2, min_y: -3.7, max_y: 3.7 }
}

pub fn own_half() -> Region {
    Region { min_x: -5.2, max_x: 0.0, min_y: -3.7, max_y: 3.7 }
}

/// The landmarks of the test field: (class, map positions).
pub fn landmarks() -> Vec<(&'static str, ObjectClass, Vec<Point<Global>>)> {
    let p = |x: f64, y: f64| Point::new(x, y);
    vec![
        ("goal_post", POST, vec![p(4.5, 0.8), p(4.5, -0.8), p(-4.5, 0.8), p(-4.5, -0.8)]),
        ("penalty_mark", PENALTY_MARK, vec![p(3.2, 0.0), p(-3.2, 0.0)]),
        ("centre_circle", CIRCLE, vec![p(0.0, 0.0)]),
        ("corner", L_CROSSING, vec![p(4.5, 3.0), p(4.5, -3.0), p(-4.5, 3.0), p(-4.5, -3.0)]),
    ]
}

/// The painted lines of the test field: the outer lines, the halfway line, the goal areas.
pub fn field_lines() -> Vec<[Point<Global>; 2]> {
    let p = |x: f64, y: f64| Point::new(x, y);
    let mut lines = vec![
        [p(-4.5, -3.0), p(4.5, -3.0)],
        [p(-4.5, 3.0), p(4.5, 3.0)],
        [p(-4.5, -3.0), p(-4.5, 3.0)],
        [p(4.5, -3.0), p(4.5, 3.0)],
        [p(0.0, -3.0), p(0.0, 3.0)],
    ];
    for side in [-1.0, 1.0] {
        let (goal, front) = (4.5 * side, 3.9 * side);
        lines.push([p(front, -1.1), p(front, 1.1)]);
        lines.push([p(goal, -1.1), p(front, -1.1)]);
        lines.push([p(goal, 1.1), p(front, 1.1)]);
    }
    lines
}

/// [`config`] with the field lines as observations of the pose.
pub fn config_with_lines(initial: Option<PosePrior>) -> WorldModelConfig {
    WorldModelConfig {
        lines: FieldLinesConfig {
            class: Some(LINE),
            segments: field_lines(),
            direction_sigma: LINE_DIRECTION_SIGMA,
            end_margin: 0.1,
            max_range: 4.0,
            min_length: 0.15,
        },
        ..config(initial)
    }
}

/// The world-model configuration an application would give for this field.
pub fn config(initial: Option<PosePrior>) -> WorldModelConfig {
    let mut objects: Vec<ObjectOfInterest> = landmarks()
        .into_iter()
        .map(|(name, class, positions)| ObjectOfInterest {
            name: name.to_owned(),
            class,
            variant: None,
            kind: ObjectKind::Landmark { positions, position_noise: 0.0 },
            confidence: None,
        })
        .collect();
    objects.insert(
        0,
        ObjectOfInterest {
            name: "ball".to_owned(),
            class: BALL,
            variant: None,
            kind: ObjectKind::Mobile {
                friction: FRICTION,
                acceleration_noise: BALL_ACCELERATION_NOISE,
                max_speed: BALL_MAX_SPEED,
            },
            confidence: None,
        },
    );
    WorldModelConfig {
        objects,
        pose: PoseConfig { initial, bounds: Some(bounds()), ..PoseConfig::default() },
        ..WorldModelConfig::default()
    }
}

pub fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// A sample of N(0, cov) for a 3x3 covariance (zero where it is singular).
pub fn sample3(rng: &mut ChaCha8Rng, cov: &Matrix3<f64>) -> Vector3<f64> {
    let n = Vector3::new(gaussian(rng), gaussian(rng), gaussian(rng));
    match (cov + Matrix3::identity() * 1e-15).cholesky() {
        Some(c) => c.l() * n,
        None => Vector3::zeros(),
    }
}

/// The ground truth and the sensors.
pub struct Sim {
    pub rng: ChaCha8Rng,
    pub truth: Pose,
    pub ball: Vector2<f64>,
    pub ball_velocity: Vector2<f64>,
    pub time: f64,
    pub odometry_noise: OdometryNoise,
    pub camera: CameraNoise,
    pub fov: f64,
    pub view_range: f64,
    /// Head sweep amplitude (rad) and period (s).
    pub sweep: (f64, f64),
    /// Per-frame probability of a spurious observation of each class in `false_classes`.
    pub false_positive_rate: f64,
    pub false_classes: Vec<ObjectClass>,
    /// Relative bias of the reported forward odometry (reported = (1 + bias) * commanded).
    pub forward_bias: f64,
    pub detection_probability: f64,
    pub see_landmarks: bool,
    pub see_ball: bool,
    /// Report the painted lines (nearest point of the visible piece, direction).
    pub see_lines: bool,
    /// Consecutive frames, up to now, in which the real ball was detected.
    pub ball_streak: usize,
    landmarks: Vec<(ObjectClass, Point<Global>)>,
}

impl Sim {
    pub fn new(seed: u64, truth: Pose) -> Sim {
        let landmarks = landmarks()
            .into_iter()
            .flat_map(|(_, class, positions)| positions.into_iter().map(move |p| (class, p)))
            .collect();
        Sim {
            rng: ChaCha8Rng::seed_from_u64(seed),
            truth,
            ball: Vector2::new(1.0, 0.5),
            ball_velocity: Vector2::zeros(),
            time: 0.0,
            odometry_noise: OdometryNoise::default(),
            camera: CameraNoise::default(),
            fov: 1.0,
            view_range: 6.0,
            sweep: (1.2, 3.0),
            false_positive_rate: 0.0,
            false_classes: Vec::new(),
            forward_bias: 0.0,
            detection_probability: 1.0,
            see_landmarks: true,
            see_ball: true,
            see_lines: false,
            ball_streak: 0,
            landmarks,
        }
    }

    pub fn stamp(&self) -> Time {
        Time::from_secs_f64(self.time)
    }

    pub fn head_yaw(&self) -> f64 {
        let (amplitude, period) = self.sweep;
        amplitude * (2.0 * std::f64::consts::PI * self.time / period).sin()
    }

    pub fn ball_in_robot_frame(&self) -> Vector2<f64> {
        let p = self.truth.to_robot(Point::new(self.ball.x, self.ball.y));
        Vector2::new(p.x, p.y)
    }

    /// Moves the robot by `step` as odometry reports it; the true motion differs from it by
    /// noise drawn from the odometry model the filters assume (true = reported + noise).
    /// Returns the reported odometry.
    pub fn walk(&mut self, step: Odometry) -> Odometry {
        let q = self.odometry_noise.covariance(&step);
        let n = sample3(&mut self.rng, &q);
        self.truth = self.truth.moved(Odometry {
            dx: step.dx + n[0],
            dy: step.dy + n[1],
            dtheta: step.dtheta + n[2],
        });
        Odometry { dx: step.dx * (1.0 + self.forward_bias), dy: step.dy, dtheta: step.dtheta }
    }

    /// Advances the ball by `DT` with the filter's model: constant deceleration plus white
    /// acceleration noise.
    pub fn roll_ball(&mut self, dt: f64) {
        let v = self.ball_velocity;
        let s = v.norm();
        let a = FRICTION;
        let (dp, v_new) = if s > a * dt {
            (v * (dt - a * dt * dt / (2.0 * s)), v * (1.0 - a * dt / s))
        } else {
            (v * (s / (2.0 * a)), Vector2::zeros())
        };
        let q = BALL_ACCELERATION_NOISE.powi(2);
        let cov = Matrix2::new(q * dt.powi(3) / 3.0, q * dt * dt / 2.0, q * dt * dt / 2.0, q * dt);
        let l = cov.cholesky().map(|c| c.l()).unwrap_or_else(Matrix2::zeros);
        let nx = l * Vector2::new(gaussian(&mut self.rng), gaussian(&mut self.rng));
        let ny = l * Vector2::new(gaussian(&mut self.rng), gaussian(&mut self.rng));
        self.ball += dp + Vector2::new(nx[0], ny[0]);
        self.ball_velocity = v_new + Vector2::new(nx[1], ny[1]);
    }

    fn observe(
        &mut self,
        class: ObjectClass,
        p: Point<strata_robot::geometry::Robot>,
    ) -> Observation {
        let r = p.range();
        let (sr, sb) = self.camera.sigmas(r);
        let range = (r + sr * gaussian(&mut self.rng)).max(0.0);
        let bearing = normalize_angle(p.bearing() + sb * gaussian(&mut self.rng));
        Observation {
            class,
            variant: None,
            range,
            bearing,
            orientation: None,
            range_sigma: sr,
            bearing_sigma: sb,
        }
    }

    /// A line as the simulator's camera reports it: the point of its piece inside the view
    /// nearest the robot, and its direction modulo a half turn, both with noise.
    fn observe_line(&mut self, [a, b]: [Point<Global>; 2], view: &ViewCone) -> Option<Observation> {
        const STEPS: usize = 400;
        let (a, b) = (self.truth.to_robot(a), self.truth.to_robot(b));
        let at = |t: f64| Point::new(a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
        // The view is convex: the visible piece is one interval of the segment.
        let visible: Vec<f64> = (0..=STEPS)
            .map(|k| k as f64 / STEPS as f64)
            .filter(|&t| view.contains(at(t), 0.0) && at(t).range() > 0.2)
            .collect();
        let (&t0, &t1) = (visible.first()?, visible.last()?);
        if (t1 - t0) * a.distance(b) < 0.3 {
            return None;
        }
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let foot = -(a.x * dx + a.y * dy) / (dx * dx + dy * dy);
        let nearest = at(foot.clamp(t0, t1));
        if rand::RngExt::random::<f64>(&mut self.rng) >= self.detection_probability {
            return None;
        }
        let mut observation = self.observe(LINE, nearest);
        let direction = dy.atan2(dx) + LINE_DIRECTION_SIGMA * gaussian(&mut self.rng);
        let half_turn = normalize_angle(2.0 * direction) / 2.0;
        observation.orientation = Some(half_turn);
        Some(observation)
    }

    /// One camera frame at the current time.
    pub fn camera_frame(&mut self) -> Percepts {
        let view = ViewCone {
            direction: self.head_yaw(),
            fov: self.fov,
            range: self.view_range,
            near: 0.0,
        };
        let mut observations = Vec::new();
        if self.see_landmarks {
            for k in 0..self.landmarks.len() {
                let (class, m) = self.landmarks[k];
                let p = self.truth.to_robot(m);
                if view.contains(p, 0.0)
                    && p.range() > 0.2
                    && rand::RngExt::random::<f64>(&mut self.rng) < self.detection_probability
                {
                    observations.push(self.observe(class, p));
                }
            }
        }
        if self.see_lines {
            for segment in field_lines() {
                if let Some(observation) = self.observe_line(segment, &view) {
                    observations.push(observation);
                }
            }
        }
        let mut ball_seen = false;
        if self.see_ball {
            let b = self.ball_in_robot_frame();
            let p = Point::new(b.x, b.y);
            if view.contains(p, 0.0)
                && p.range() > 0.2
                && rand::RngExt::random::<f64>(&mut self.rng) < self.detection_probability
            {
                observations.push(self.observe(BALL, p));
                ball_seen = true;
            }
        }
        self.ball_streak = if ball_seen { self.ball_streak + 1 } else { 0 };
        for k in 0..self.false_classes.len() {
            if rand::RngExt::random::<f64>(&mut self.rng) < self.false_positive_rate {
                let class = self.false_classes[k];
                let range = rand::RngExt::random_range(&mut self.rng, 0.5..5.0);
                let bearing = view.direction
                    + rand::RngExt::random_range(&mut self.rng, -view.fov / 2.0..view.fov / 2.0);
                let p = Point::from_polar(range, bearing);
                observations.push(self.observe(class, p));
            }
        }
        Percepts {
            stamp: self.stamp(),
            camera: Some(CameraPercepts { stamp: self.stamp(), view, observations }),
            ..Percepts::default()
        }
    }

    /// One frame: walk `step`, roll the ball, take an image. Returns the reported odometry and
    /// the percepts.
    pub fn frame(&mut self, step: Odometry) -> (Odometry, Percepts) {
        self.time += DT;
        let odometry = self.walk(step);
        self.roll_ball(DT);
        (odometry, self.camera_frame())
    }
}

/// A gentle walk that covers the field: forward at 0.2 m/s, turning back and forth, and
/// turning towards the centre when near the border.
pub fn patrol_step(sim: &Sim) -> Odometry {
    let t = sim.time;
    let mut omega = 0.25 * (0.4 * t).sin();
    let pos = sim.truth.position();
    if pos.x.abs() > 3.5 || pos.y.abs() > 2.3 {
        let to_centre = (-pos.y).atan2(-pos.x);
        omega = 0.6 * normalize_angle(to_centre - sim.truth.theta).signum();
    }
    Odometry { dx: 0.2 * DT, dy: 0.0, dtheta: omega * DT }
}

/// Pose error as (x, y, theta) with the heading wrapped.
pub fn pose_error(estimate: &Pose, truth: &Pose) -> Vector3<f64> {
    Vector3::new(
        estimate.x - truth.x,
        estimate.y - truth.y,
        normalize_angle(estimate.theta - truth.theta),
    )
}

pub fn nees3(e: &Vector3<f64>, p: &Matrix3<f64>) -> f64 {
    p.try_inverse().map_or(f64::INFINITY, |inv| (e.transpose() * inv * e)[(0, 0)])
}

pub fn nees2(e: &Vector2<f64>, p: &Matrix2<f64>) -> f64 {
    p.try_inverse().map_or(f64::INFINITY, |inv| (e.transpose() * inv * e)[(0, 0)])
}

/// Chi-square quantile (Wilson-Hilferty; accurate for the tens of degrees of freedom used).
pub fn chi2_quantile(dof: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + z * a.sqrt()).powi(3)
}

/// The two-sided 95% band of the average of `runs` NEES values with `dof` degrees of freedom.
pub fn anees_band(dof: f64, runs: usize) -> (f64, f64) {
    let k = dof * runs as f64;
    (chi2_quantile(k, -1.959_964) / runs as f64, chi2_quantile(k, 1.959_964) / runs as f64)
}

/// The plain path to a view's sensing candidate, the reference for the shortcuts: every
/// object's prediction, filtered by visibility.
pub fn plain_sensing_candidate(
    world: &WorldState,
    view: &ViewCone,
    min_visibility: f64,
) -> SensingCandidate {
    let observations = (0..world.objects.len())
        .filter_map(|i| u16::try_from(i).ok())
        .filter_map(|i| world.predicted_observation(ObjectId(i), view))
        .filter(|p| p.visibility >= min_visibility && p.visibility > 0.0)
        .map(|p| ExpectedObservation {
            object: p.object,
            range_sigma: p.range_sigma,
            bearing_sigma: p.bearing_sigma,
            detection_probability: p.visibility * world.detection_probability,
        })
        .collect();
    let mut lines = Vec::new();
    world.expected_lines_into(view, &mut lines);
    SensingCandidate { observations, lines }
}

/// [`config`] with obstacle tracks too (never observed by [`Sim`]: untracked objects without a
/// map position).
pub fn config_with_obstacles(initial: Option<PosePrior>) -> WorldModelConfig {
    let mut config = config(initial);
    config.objects.push(ObjectOfInterest {
        name: "obstacle".to_owned(),
        class: ObjectClass(30),
        variant: None,
        kind: ObjectKind::Obstacle {
            max_tracks: 3,
            acceleration_noise: 0.5,
            velocity_decay: 1.0,
            max_speed: 0.6,
        },
        confidence: None,
    });
    config
}

/// Debug prints every float with its sign and shortest round-trip digits: equal texts are
/// equal states, bit for bit (NaNs aside).
pub fn state_text(state: &WorldState) -> String {
    format!("{state:?}")
}

/// A patrol with a rolling ball, a kidnap half way and an extra odometry prediction now and
/// then (every path of the publication), on [`config_with_obstacles`]: `visit` sees the model
/// after each of the `frames` frames.
pub fn kidnapped_patrol(
    initial: Option<PosePrior>,
    seed: u64,
    frames: usize,
    mut visit: impl FnMut(usize, &mut strata_robot::world::WorldModel),
) {
    let mut world =
        strata_robot::world::WorldModel::new(config_with_obstacles(initial)).expect("valid config");
    let mut sim = Sim::new(seed, Pose::new(-1.0, 0.5, 0.3));
    sim.ball_velocity = Vector2::new(0.4, -0.2);
    for frame in 0..frames {
        let (odometry, percepts) = sim.frame(patrol_step(&sim));
        world.process(odometry, &percepts);
        if frame == frames / 2 {
            world.command(strata_robot::world::WorldCommand::Kidnapped).expect("accepted");
        }
        if frame % 37 == 5 {
            world.predict(Odometry { dx: 0.01, dy: 0.0, dtheta: -0.03 });
        }
        visit(frame, &mut world);
    }
}
