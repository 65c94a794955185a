//! A small kinematic simulation of the building, the patrol's own [`Platform`] (paper 3.7: the
//! robot's code runs over an abstract hardware layer; simulation swaps the platform).
//!
//! A flat floor with the plan's walls. Each robot walks omnidirectionally with acceleration
//! limits and an initialization and end stage around its gait; its true motion differs from
//! what its odometry reports by a systematic scale error and random noise; it bumps into walls;
//! its head turns at a limited speed; its camera reports markers, corners, points of interest
//! and people inside its field of view and range, not hidden by walls, with noisy range and
//! bearing relative to the optical axis. Robots can slip and fall; a protective fall and a
//! stand-up are sequences that take their time. Team radio and the operator console are
//! in-process links. Everything random comes from one seed: a run is the same run every time.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use strata_robot::geometry::{Global, Odometry, Point, Pose, Velocity, normalize_angle};
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CameraFrame, CycleStage, Detection, ExternalLink,
    FallDirection, FootContact, HeadAngles, InertialData, LinkError, MotionFeedback, MotionName,
    MotionSpec, Platform, PlatformError, PlatformInfo, ReceivedPacket, SensorFrame, SharedPlatform,
    SpecialMotion, TeamLink,
};
use strata_runtime::{Context, GraphBuilder, Module, ModuleError, ModuleId, Time, Trigger};

use crate::building::FloorPlan;
use crate::console::{Alarm, AlarmPacket, PoiReport, StatusPacket};
use crate::world_config::{CORNER, MARKER, PERSON, POINT_OF_INTEREST};

/// Physics and noise of the building and its robots.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BuildingConfig {
    /// Sensor (and simulation) period, s.
    pub sensor_period: f64,
    /// A camera image every this many sensor frames.
    pub camera_every: u32,
    pub camera_fov: f64,
    pub camera_range: f64,
    pub detection_probability: f64,
    pub range_sigma: f64,
    pub range_sigma_per_metre: f64,
    pub bearing_sigma: f64,
    pub max_velocity: Velocity,
    /// m/s^2 and rad/s^2.
    pub acceleration: f64,
    pub angular_acceleration: f64,
    pub max_head_speed: f64,
    /// Standard deviation of each robot's systematic odometry scale error (per axis).
    pub odometry_scale_sigma: f64,
    /// Random odometry error: sigma per square root of metre (and of radian).
    pub odometry_noise: f64,
    /// Robots keep this far from walls (they bump otherwise), m.
    pub body_radius: f64,
    /// Team radio delay, s, and loss probability.
    pub radio_delay: f64,
    pub radio_loss: f64,
    /// The console broadcasts its state this often, s.
    pub console_period: f64,
}

impl Default for BuildingConfig {
    fn default() -> Self {
        BuildingConfig {
            sensor_period: 0.02,
            camera_every: 2,
            camera_fov: 1.06,
            camera_range: 6.0,
            detection_probability: 0.9,
            range_sigma: 0.03,
            range_sigma_per_metre: 0.04,
            bearing_sigma: 0.02,
            max_velocity: Velocity::new(0.35, 0.2, 1.2),
            acceleration: 0.8,
            angular_acceleration: 3.0,
            max_head_speed: 4.0,
            odometry_scale_sigma: 0.04,
            odometry_noise: 0.02,
            body_radius: 0.15,
            radio_delay: 0.03,
            radio_loss: 0.0,
            console_period: 0.5,
        }
    }
}

/// An alarm the operator raises at `at` seconds: someone is at `intruder`; the robots are sent
/// to `point`. The console clears it `hold` seconds after a robot reports from there that it
/// sees the intruder.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlarmEvent {
    pub at: f64,
    pub id: u16,
    pub point: Point<Global>,
    pub intruder: Point<Global>,
    pub hold: f64,
}

/// A robot (index) slips at `at` seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Slip {
    pub robot: usize,
    pub at: f64,
}

/// What happens in the building.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scenario {
    pub seed: u64,
    /// Where each robot starts (player `i + 1`).
    pub robots: Vec<Pose>,
    /// Where the points of interest really are (the plan may be wrong).
    pub points_of_interest: Vec<Point<Global>>,
    pub alarms: Vec<AlarmEvent>,
    pub slips: Vec<Slip>,
}

/// Why the building refused a request.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BuildingError {
    #[error("no robot {0} in the building")]
    NoRobot(usize),
    #[error("the scenario lists {found} points of interest, the plan {expected}")]
    PointsOfInterest { expected: usize, found: usize },
}

/// What really happened, for tests and summaries (never for robots).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// Per robot: (time, true pose) every 0.1 s.
    pub trajectories: Vec<Vec<(f64, Pose)>>,
    /// (robot, time) of each landing on the floor.
    pub falls: Vec<(usize, f64)>,
    /// (robot, time) of each completed stand-up.
    pub stand_ups: Vec<(usize, f64)>,
    pub alarms: Vec<AlarmRecord>,
    /// Every point-of-interest report the console received.
    pub reports: Vec<ReportRecord>,
    pub points_of_interest: Vec<Point<Global>>,
    /// Steps in which a robot walked into a wall.
    pub bumps: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlarmRecord {
    pub id: u16,
    pub point: Point<Global>,
    pub raised: f64,
    /// The first robot (player) that reported from the spot, and when.
    pub on_site: Option<(u8, f64)>,
    pub cleared: Option<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReportRecord {
    pub time: f64,
    pub player: u8,
    pub report: PoiReport,
}

impl GroundTruth {
    /// A robot's true pose at time `t` (the nearest sample).
    pub fn pose_at(&self, robot: usize, t: f64) -> Option<Pose> {
        let samples = self.trajectories.get(robot)?;
        let i = samples.partition_point(|(s, _)| *s < t);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|i| samples.get(i))
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .map(|(_, p)| *p)
    }
}

const LYING_TILT: f64 = 1.45;
const FALL_TIME: f64 = 0.7;
const FALL_TILT0: f64 = 0.05;
const PROTECTIVE_FALL: f64 = 0.8;
const STAND_UP_TIME: f64 = 3.0;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Activity {
    Standing,
    Walking {
        stage: CycleStage,
        elapsed: f64,
    },
    /// Slipping, unprotected.
    Falling {
        elapsed: f64,
    },
    Special {
        motion: SpecialMotion,
        elapsed: f64,
        duration: f64,
        start_tilt: f64,
    },
    Fallen,
}

#[derive(Debug)]
struct SimRobot {
    pose: Pose,
    velocity: Velocity,
    target: Velocity,
    activity: Activity,
    head: HeadAngles,
    head_target: HeadAngles,
    head_speed: f64,
    tilt: f64,
    tilt_rate: f64,
    direction: FallDirection,
    /// What the walking engine believes it moved since the last `read_motion`.
    odometry: Odometry,
    /// True motion = scale * believed motion (+ noise), per axis.
    scale: [f64; 3],
    frame: Option<SensorFrame>,
    radio_inbox: Vec<ReceivedPacket>,
    console_inbox: Vec<ReceivedPacket>,
}

impl SimRobot {
    fn holds_head(&self) -> bool {
        match self.activity {
            Activity::Falling { .. } | Activity::Fallen => true,
            Activity::Special { motion, .. } => motion.head,
            _ => false,
        }
    }

    fn motion_state(&self) -> BodyMotionState {
        match self.activity {
            // The walking engine does not know the robot slips: only the IMU shows it.
            Activity::Standing | Activity::Falling { .. } => BodyMotionState::Standing,
            Activity::Walking { stage, .. } => {
                BodyMotionState::Walking { stage, velocity: self.velocity }
            }
            Activity::Special { motion, elapsed, duration, .. } => {
                BodyMotionState::Special { motion, elapsed, duration }
            }
            Activity::Fallen => BodyMotionState::Fallen { direction: self.direction },
        }
    }
}

#[derive(Debug)]
struct LiveAlarm {
    event: AlarmEvent,
    record: usize,
    on_site_since: Option<Time>,
}

/// The building: floor, robots, intruder, radio and console.
#[derive(Debug)]
pub struct Building {
    plan: Arc<FloorPlan>,
    config: BuildingConfig,
    scenario: Scenario,
    rng: ChaCha8Rng,
    time: Time,
    steps: u64,
    robots: Vec<SimRobot>,
    intruder: Option<Point<Global>>,
    radio: Vec<(Time, u64, usize, Vec<u8>)>,
    radio_seq: u64,
    alarm: Option<LiveAlarm>,
    next_alarm: usize,
    next_broadcast: Time,
    broadcast_seq: u8,
    truth: GroundTruth,
    next_sample: Time,
}

fn approach(value: f64, target: f64, step: f64) -> f64 {
    value + (target - value).clamp(-step, step)
}

impl Building {
    pub fn new(
        plan: Arc<FloorPlan>,
        config: BuildingConfig,
        scenario: Scenario,
    ) -> Result<Building, BuildingError> {
        if scenario.points_of_interest.len() != plan.points_of_interest.len() {
            return Err(BuildingError::PointsOfInterest {
                expected: plan.points_of_interest.len(),
                found: scenario.points_of_interest.len(),
            });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
        let mut normal = || rng.sample::<f64, _>(StandardNormal);
        let robots = scenario
            .robots
            .iter()
            .map(|pose| {
                let mut scale = [0.0; 3];
                for s in &mut scale {
                    *s = 1.0 + config.odometry_scale_sigma * normal();
                }
                SimRobot {
                    pose: *pose,
                    velocity: Velocity::ZERO,
                    target: Velocity::ZERO,
                    activity: Activity::Standing,
                    head: HeadAngles::default(),
                    head_target: HeadAngles::default(),
                    head_speed: config.max_head_speed,
                    tilt: 0.0,
                    tilt_rate: 0.0,
                    direction: FallDirection::Front,
                    odometry: Odometry::ZERO,
                    scale,
                    frame: None,
                    radio_inbox: Vec::new(),
                    console_inbox: Vec::new(),
                }
            })
            .collect::<Vec<_>>();
        let truth = GroundTruth {
            trajectories: vec![Vec::new(); robots.len()],
            points_of_interest: scenario.points_of_interest.clone(),
            ..GroundTruth::default()
        };
        Ok(Building {
            plan,
            config,
            scenario,
            rng,
            time: Time::ZERO,
            steps: 0,
            robots,
            intruder: None,
            radio: Vec::new(),
            radio_seq: 0,
            alarm: None,
            next_alarm: 0,
            next_broadcast: Time::ZERO,
            broadcast_seq: 0,
            truth,
            next_sample: Time::ZERO,
        })
    }

    pub fn time(&self) -> Time {
        self.time
    }

    pub fn truth(&self) -> &GroundTruth {
        &self.truth
    }

    fn period(&self) -> Duration {
        Duration::from_secs_f64(self.config.sensor_period)
    }

    fn robot_mut(&mut self, robot: usize) -> Result<&mut SimRobot, BuildingError> {
        self.robots.get_mut(robot).ok_or(BuildingError::NoRobot(robot))
    }

    pub fn platform_info(&self) -> PlatformInfo {
        let spec = |motion, name: &str, seconds: f64| MotionSpec {
            motion,
            name: name.to_owned(),
            duration: Duration::from_secs_f64(seconds),
        };
        PlatformInfo {
            name: "patrol building".into(),
            sensor_period: self.period(),
            camera_fov: self.config.camera_fov,
            camera_range: self.config.camera_range,
            head_yaw_limits: (-2.0, 2.0),
            head_pitch_limits: (-0.6, 0.5),
            max_head_speed: self.config.max_head_speed,
            max_velocity: self.config.max_velocity,
            motions: vec![
                spec(SpecialMotion::fall(0), "protective fall", PROTECTIVE_FALL),
                spec(SpecialMotion::stand_up(0), "stand up from the front", STAND_UP_TIME),
                spec(SpecialMotion::stand_up(1), "stand up from the back", STAND_UP_TIME),
            ],
            can_walk: true,
        }
    }

    /// Steps the building up to `now`, one sensor period at a time.
    pub fn advance_to(&mut self, now: Time) {
        let period = self.period();
        while self.time + period <= now {
            self.step(period);
        }
    }

    fn normal(&mut self) -> f64 {
        self.rng.sample(StandardNormal)
    }

    fn step(&mut self, period: Duration) {
        self.time += period;
        self.steps += 1;
        let dt = period.as_secs_f64();
        let now = self.time.as_secs_f64();
        self.run_console();
        for i in 0..self.scenario.slips.len() {
            let slip = self.scenario.slips[i];
            if (now - dt..now).contains(&slip.at)
                && let Some(robot) = self.robots.get_mut(slip.robot)
                && matches!(robot.activity, Activity::Standing | Activity::Walking { .. })
            {
                robot.activity = Activity::Falling { elapsed: 0.0 };
                robot.direction = FallDirection::Front;
                robot.target = Velocity::ZERO;
            }
        }
        let camera = self.steps.is_multiple_of(u64::from(self.config.camera_every.max(1)));
        for i in 0..self.robots.len() {
            self.step_body(i, dt);
            self.step_motion(i, dt);
            let frame = self.sensor_frame(i, camera);
            let robot = &mut self.robots[i];
            // An unread camera image survives a newer frame without one: the perception module
            // may skip a period on a loaded host.
            let unread_camera = robot.frame.take().and_then(|f| f.camera);
            robot.frame =
                Some(SensorFrame { camera: frame.camera.clone().or(unread_camera), ..frame });
        }
        self.deliver_radio();
        if self.time >= self.next_sample {
            self.next_sample += Duration::from_millis(100);
            for (i, robot) in self.robots.iter().enumerate() {
                self.truth.trajectories[i].push((now, robot.pose));
            }
        }
    }

    fn step_body(&mut self, i: usize, dt: f64) {
        let config = self.config.clone();
        let previous_tilt = self.robots[i].tilt;
        let mut landed = false;
        let mut stood_up = false;
        let robot = &mut self.robots[i];
        robot.activity = match robot.activity {
            Activity::Standing => Activity::Standing,
            Activity::Walking { stage, elapsed } => {
                let elapsed = elapsed + dt;
                match stage {
                    CycleStage::Initialization if elapsed >= 0.1 => {
                        Activity::Walking { stage: CycleStage::Execution, elapsed: 0.0 }
                    }
                    CycleStage::End if elapsed >= 0.15 => {
                        robot.velocity = Velocity::ZERO;
                        Activity::Standing
                    }
                    _ => Activity::Walking { stage, elapsed },
                }
            }
            Activity::Falling { elapsed } => {
                let elapsed = elapsed + dt;
                let tau = FALL_TIME / (LYING_TILT / FALL_TILT0).acosh();
                robot.tilt = (FALL_TILT0 * (elapsed / tau).cosh()).min(LYING_TILT);
                if elapsed >= FALL_TIME {
                    landed = true;
                    Activity::Fallen
                } else {
                    Activity::Falling { elapsed }
                }
            }
            Activity::Special { motion, elapsed, duration, start_tilt } => {
                let elapsed = elapsed + dt;
                let progress = (elapsed / duration).min(1.0);
                match motion.kind {
                    MotionName::STAND_UP => {
                        robot.tilt = start_tilt * (1.0 - progress);
                        if progress >= 1.0 {
                            stood_up = true;
                            Activity::Standing
                        } else {
                            Activity::Special { motion, elapsed, duration, start_tilt }
                        }
                    }
                    _ => {
                        // A protective fall lowers the body on purpose, faster and softer.
                        robot.tilt = start_tilt + (LYING_TILT - start_tilt) * progress * progress;
                        if progress >= 1.0 {
                            landed = true;
                            Activity::Fallen
                        } else {
                            Activity::Special { motion, elapsed, duration, start_tilt }
                        }
                    }
                }
            }
            Activity::Fallen => {
                robot.tilt = LYING_TILT;
                Activity::Fallen
            }
        };
        let walking =
            matches!(robot.activity, Activity::Walking { stage: CycleStage::Execution, .. });
        let target = if walking { robot.target } else { Velocity::ZERO };
        let (lin, rot) = (config.acceleration * dt, config.angular_acceleration * dt);
        robot.velocity = Velocity::new(
            approach(robot.velocity.vx, target.vx, lin),
            approach(robot.velocity.vy, target.vy, lin),
            approach(robot.velocity.omega, target.omega, rot),
        );
        if !matches!(robot.activity, Activity::Walking { .. }) {
            robot.velocity = Velocity::ZERO;
        }
        robot.tilt_rate = (robot.tilt - previous_tilt) / dt;
        if !robot.holds_head() {
            let step = robot.head_speed * dt;
            robot.head = HeadAngles {
                yaw: approach(robot.head.yaw, robot.head_target.yaw, step),
                pitch: approach(robot.head.pitch, robot.head_target.pitch, step),
            };
        }
        let now = self.time.as_secs_f64();
        if landed {
            // Landing shoves the body a little: no odometry reports it.
            let (dx, dy, dtheta) =
                (0.08 * self.normal(), 0.08 * self.normal(), 0.1 * self.normal());
            let robot = &mut self.robots[i];
            let moved = robot.pose.moved(Odometry { dx, dy, dtheta });
            if self.plan.wall_distance(moved.position()) > config.body_radius {
                self.robots[i].pose = moved;
            }
            self.truth.falls.push((i, now));
        }
        if stood_up {
            self.truth.stand_ups.push((i, now));
        }
    }

    fn step_motion(&mut self, i: usize, dt: f64) {
        let v = self.robots[i].velocity;
        if v.is_zero() {
            return;
        }
        let believed = Odometry { dx: v.vx * dt, dy: v.vy * dt, dtheta: v.omega * dt };
        let k = self.config.odometry_noise;
        let distance = believed.dx.hypot(believed.dy);
        let noise = [
            k * distance.sqrt() * self.normal(),
            k * distance.sqrt() * self.normal(),
            k * believed.dtheta.abs().sqrt() * self.normal(),
        ];
        let robot = &mut self.robots[i];
        robot.odometry = robot.odometry.then(believed);
        let real = Odometry {
            dx: believed.dx * robot.scale[0] + noise[0],
            dy: believed.dy * robot.scale[1] + noise[1],
            dtheta: believed.dtheta * robot.scale[2] + noise[2],
        };
        let moved = robot.pose.moved(real);
        if self.plan.wall_distance(moved.position()) > self.config.body_radius {
            robot.pose = moved;
        } else {
            // Against a wall the feet slip: the robot turns but goes nowhere.
            robot.pose = Pose::new(robot.pose.x, robot.pose.y, moved.theta);
            self.truth.bumps += 1;
        }
    }

    fn sensor_frame(&mut self, i: usize, camera: bool) -> SensorFrame {
        let robot = &self.robots[i];
        let (pitch, roll) = match robot.direction {
            FallDirection::Front => (robot.tilt, 0.0),
            FallDirection::Back => (-robot.tilt, 0.0),
            FallDirection::Left => (0.0, -robot.tilt),
            FallDirection::Right => (0.0, robot.tilt),
        };
        let (pitch_rate, roll_rate) = match robot.direction {
            FallDirection::Front => (robot.tilt_rate, 0.0),
            FallDirection::Back => (-robot.tilt_rate, 0.0),
            FallDirection::Left => (0.0, -robot.tilt_rate),
            FallDirection::Right => (0.0, robot.tilt_rate),
        };
        let g = 9.81;
        let upright = robot.tilt < 0.5;
        let head = robot.head;
        let sees = camera
            && robot.tilt < 0.2
            && matches!(robot.activity, Activity::Standing | Activity::Walking { .. });
        let mut frame = SensorFrame {
            stamp: self.time,
            inertial: InertialData {
                accelerometer: [g * pitch.sin(), -g * roll.sin(), g * robot.tilt.cos()],
                gyroscope: [roll_rate, pitch_rate, robot.velocity.omega],
                body_angles: [roll, pitch],
            },
            head,
            foot_contact: if upright {
                FootContact { left: 2.5, right: 2.5 }
            } else {
                FootContact::default()
            },
            battery: Some(1.0),
            ..SensorFrame::default()
        };
        if sees {
            let detections = self.detections(i);
            frame.camera =
                Some(CameraFrame { stamp: self.time, head, detections, footprint: None });
        }
        frame
    }

    fn detections(&mut self, i: usize) -> Vec<Detection> {
        let pose = self.robots[i].pose;
        let yaw = self.robots[i].head.yaw;
        let plan = Arc::clone(&self.plan);
        let mut targets: Vec<(Point<Global>, strata_robot::platform::ObjectClass, Option<u16>)> =
            Vec::new();
        targets.extend(
            plan.markers.iter().enumerate().map(|(k, p)| (*p, MARKER, u16::try_from(k).ok())),
        );
        targets.extend(plan.corners.iter().map(|p| (*p, CORNER, None)));
        targets.extend(
            self.scenario
                .points_of_interest
                .iter()
                .enumerate()
                .map(|(k, p)| (*p, POINT_OF_INTEREST, u16::try_from(k).ok())),
        );
        targets.extend(self.intruder.map(|p| (p, PERSON, None)));
        let mut out = Vec::new();
        for (position, class, variant) in targets {
            let relative = pose.to_robot(position);
            let range = relative.range();
            let bearing = normalize_angle(relative.bearing() - yaw);
            if !(0.3..=self.config.camera_range).contains(&range)
                || bearing.abs() > self.config.camera_fov / 2.0
                || !plan.line_of_sight(pose.position(), position)
                || self.rng.random::<f64>() > self.config.detection_probability
            {
                continue;
            }
            let range_sigma = self.config.range_sigma + self.config.range_sigma_per_metre * range;
            let bearing_sigma = self.config.bearing_sigma;
            out.push(Detection {
                class,
                variant,
                range: (range + range_sigma * self.normal()).max(0.05),
                bearing: bearing + bearing_sigma * self.normal(),
                orientation: None,
            });
        }
        out
    }

    fn deliver_radio(&mut self) {
        let now = self.time;
        let mut due: Vec<_> = Vec::new();
        self.radio.retain(|m| {
            if m.0 <= now {
                due.push(m.clone());
                false
            } else {
                true
            }
        });
        due.sort_by_key(|m| (m.0, m.1));
        for (at, _, to, bytes) in due {
            self.robots[to].radio_inbox.push(ReceivedPacket { received: at, bytes });
        }
    }

    fn send_radio(&mut self, from: usize, payload: &[u8]) -> Result<(), LinkError> {
        const LIMIT: usize = 128;
        if payload.len() > LIMIT {
            return Err(LinkError::TooLarge { size: payload.len(), limit: LIMIT });
        }
        let at = self.time + Duration::from_secs_f64(self.config.radio_delay);
        for to in (0..self.robots.len()).filter(|&to| to != from) {
            if self.rng.random::<f64>() < self.config.radio_loss {
                continue;
            }
            self.radio_seq += 1;
            self.radio.push((at, self.radio_seq, to, payload.to_vec()));
        }
        Ok(())
    }

    /// The operator console: raises and clears alarms, broadcasts its state.
    fn run_console(&mut self) {
        let now = self.time;
        let seconds = now.as_secs_f64();
        if self.alarm.is_none()
            && let Some(event) = self.scenario.alarms.get(self.next_alarm).copied()
            && seconds >= event.at
        {
            self.next_alarm += 1;
            self.intruder = Some(event.intruder);
            self.truth.alarms.push(AlarmRecord {
                id: event.id,
                point: event.point,
                raised: seconds,
                on_site: None,
                cleared: None,
            });
            let record = self.truth.alarms.len() - 1;
            self.alarm = Some(LiveAlarm { event, record, on_site_since: None });
            // Raising an alarm is broadcast at once, not at the next period.
            self.next_broadcast = now;
        }
        if let Some(live) = &self.alarm
            && live.on_site_since.is_some_and(|t| (now - t).as_secs_f64() >= live.event.hold)
        {
            self.truth.alarms[live.record].cleared = Some(seconds);
            self.alarm = None;
            self.intruder = None;
            self.next_broadcast = now;
        }
        if now >= self.next_broadcast {
            self.next_broadcast = now + Duration::from_secs_f64(self.config.console_period);
            self.broadcast_seq = self.broadcast_seq.wrapping_add(1);
            let alarm = self.alarm.as_ref().map(|l| Alarm { id: l.event.id, point: l.event.point });
            let bytes = AlarmPacket { alarm, seq: self.broadcast_seq }.encode();
            for robot in &mut self.robots {
                robot.console_inbox.push(ReceivedPacket { received: now, bytes: bytes.clone() });
            }
        }
    }

    fn receive_status(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        let status = StatusPacket::decode(bytes).map_err(|e| LinkError::Io(e.to_string()))?;
        let now = self.time;
        let seconds = now.as_secs_f64();
        for report in &status.reports {
            self.truth.reports.push(ReportRecord {
                time: seconds,
                player: status.player,
                report: *report,
            });
        }
        if let Some(live) = &mut self.alarm
            && live.on_site_since.is_none()
            && status.intruder_sighted
            && status.position.distance(live.event.point) < 1.5
        {
            live.on_site_since = Some(now);
            self.truth.alarms[live.record].on_site = Some((status.player, seconds));
        }
        Ok(())
    }

    fn apply_orders(&mut self, i: usize, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        let max = self.config.max_velocity;
        let max_head = self.config.max_head_speed;
        let robot = self.robot_mut(i).map_err(|e| PlatformError::Unsupported(e.to_string()))?;
        if let Some(head) = orders.head
            && !robot.holds_head()
        {
            robot.head_target = HeadAngles {
                yaw: head.target.yaw.clamp(-2.0, 2.0),
                pitch: head.target.pitch.clamp(-0.6, 0.5),
            };
            robot.head_speed =
                if head.max_speed > 0.0 { head.max_speed.min(max_head) } else { max_head };
        }
        match orders.body {
            None => {}
            Some(BodyOrder::Stand) => {
                robot.target = Velocity::ZERO;
                if let Activity::Walking {
                    stage: CycleStage::Initialization | CycleStage::Execution,
                    ..
                } = robot.activity
                {
                    robot.activity = Activity::Walking { stage: CycleStage::End, elapsed: 0.0 };
                }
            }
            Some(BodyOrder::Walk { velocity }) => {
                robot.target = Velocity::new(
                    velocity.vx.clamp(-max.vx, max.vx),
                    velocity.vy.clamp(-max.vy, max.vy),
                    velocity.omega.clamp(-max.omega, max.omega),
                );
                robot.activity = match robot.activity {
                    Activity::Standing => {
                        Activity::Walking { stage: CycleStage::Initialization, elapsed: 0.0 }
                    }
                    // A new walk during the end stage resumes the gait.
                    Activity::Walking { stage: CycleStage::End, .. } => {
                        Activity::Walking { stage: CycleStage::Execution, elapsed: 0.0 }
                    }
                    other => other,
                };
            }
            Some(BodyOrder::Special { motion }) => {
                robot.activity = match (motion.kind, robot.activity) {
                    (MotionName::FALL, Activity::Falling { elapsed }) => Activity::Special {
                        motion,
                        elapsed: 0.0,
                        duration: (FALL_TIME - elapsed).max(0.1),
                        start_tilt: robot.tilt,
                    },
                    (MotionName::FALL, Activity::Standing | Activity::Walking { .. }) => {
                        // Sitting down backwards is the safe way for a standing humanoid.
                        robot.direction = FallDirection::Back;
                        Activity::Special {
                            motion,
                            elapsed: 0.0,
                            duration: PROTECTIVE_FALL,
                            start_tilt: robot.tilt,
                        }
                    }
                    (MotionName::STAND_UP, Activity::Fallen) => Activity::Special {
                        motion,
                        elapsed: 0.0,
                        duration: STAND_UP_TIME,
                        start_tilt: robot.tilt,
                    },
                    // The building's robots stand up and fall, nothing else.
                    (kind, _) if kind != MotionName::FALL && kind != MotionName::STAND_UP => {
                        return Err(PlatformError::Unsupported(format!(
                            "{motion}: the patrol robot's catalogue has stand_up and fall"
                        )));
                    }
                    // A sequence that does not fit the body's state is ignored (a stand-up
                    // while standing); actuation sees no special state and releases it.
                    (_, other) => other,
                };
                robot.target = Velocity::ZERO;
            }
        }
        Ok(())
    }
}

/// A shared handle to the building. Clones refer to the same building.
#[derive(Clone)]
pub struct BuildingHandle(Arc<Mutex<Building>>);

impl std::fmt::Debug for BuildingHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never locks: printing a handle while the building is locked must not deadlock.
        f.debug_struct("BuildingHandle").finish_non_exhaustive()
    }
}

impl BuildingHandle {
    pub fn new(building: Building) -> BuildingHandle {
        BuildingHandle(Arc::new(Mutex::new(building)))
    }

    /// Locks the building. Every step is self-contained, so a panic elsewhere leaves it usable.
    pub fn lock(&self) -> MutexGuard<'_, Building> {
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn check(&self, robot: usize) -> Result<(), BuildingError> {
        if robot < self.lock().robots.len() { Ok(()) } else { Err(BuildingError::NoRobot(robot)) }
    }

    /// The platform of robot `robot` (index), as its perception and actuation share it.
    pub fn platform(&self, robot: usize) -> Result<SharedPlatform, BuildingError> {
        self.check(robot)?;
        let info = self.lock().platform_info();
        Ok(Arc::new(Mutex::new(BuildingPlatform { building: self.clone(), robot, info })))
    }

    pub fn radio(&self, robot: usize) -> Result<RadioLink, BuildingError> {
        self.check(robot)?;
        Ok(RadioLink { building: self.clone(), robot })
    }

    pub fn console(&self, robot: usize) -> Result<ConsoleLink, BuildingError> {
        self.check(robot)?;
        Ok(ConsoleLink { building: self.clone(), robot })
    }
}

/// One robot's hardware in the building.
#[derive(Debug)]
pub struct BuildingPlatform {
    building: BuildingHandle,
    robot: usize,
    info: PlatformInfo,
}

impl Platform for BuildingPlatform {
    fn info(&self) -> PlatformInfo {
        self.info.clone()
    }

    fn read_sensors(&mut self, _now: Time) -> Result<Option<SensorFrame>, PlatformError> {
        let mut building = self.building.lock();
        Ok(building.robots.get_mut(self.robot).and_then(|r| r.frame.take()))
    }

    fn read_motion(&mut self, _now: Time) -> Result<MotionFeedback, PlatformError> {
        let mut building = self.building.lock();
        let stamp = building.time;
        let robot = building
            .robots
            .get_mut(self.robot)
            .ok_or_else(|| PlatformError::Disconnected(format!("robot {}", self.robot)))?;
        Ok(MotionFeedback {
            stamp,
            body: robot.motion_state(),
            head: robot.head,
            head_settled: robot.head == robot.head_target,
            odometry: std::mem::take(&mut robot.odometry),
        })
    }

    fn write(&mut self, _now: Time, orders: &ActuatorOrders) -> Result<(), PlatformError> {
        self.building.lock().apply_orders(self.robot, orders)
    }
}

/// One robot's radio: the building delivers its messages to every other robot.
#[derive(Debug)]
pub struct RadioLink {
    building: BuildingHandle,
    robot: usize,
}

impl TeamLink for RadioLink {
    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        self.building.lock().send_radio(self.robot, payload)
    }

    fn receive(&mut self, _now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let mut building = self.building.lock();
        Ok(building
            .robots
            .get_mut(self.robot)
            .map(|r| std::mem::take(&mut r.radio_inbox))
            .unwrap_or_default())
    }
}

/// One robot's connection to the operator console.
#[derive(Debug)]
pub struct ConsoleLink {
    building: BuildingHandle,
    robot: usize,
}

impl ExternalLink for ConsoleLink {
    fn receive(&mut self, _now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let mut building = self.building.lock();
        Ok(building
            .robots
            .get_mut(self.robot)
            .map(|r| std::mem::take(&mut r.console_inbox))
            .unwrap_or_default())
    }

    fn send(&mut self, _now: Time, payload: &[u8]) -> Result<(), LinkError> {
        self.building.lock().receive_status(payload)
    }
}

/// Lower priorities run first at one instant on the lockstep host: the building moves before
/// any robot reads it.
pub const BUILDING_PRIORITY: i32 = -100;

/// Steps the building at its sensor period.
#[derive(Debug)]
struct BuildingModule {
    building: BuildingHandle,
}

impl Module for BuildingModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        self.building.lock().advance_to(ctx.now());
        Ok(())
    }
}

/// Adds the module (named `building`) that steps the building.
pub fn add_building(graph: &mut GraphBuilder, building: BuildingHandle) -> ModuleId {
    let period = building.lock().period();
    let mut id = ModuleId(0);
    graph.add("building", |p| {
        id = p.id();
        p.trigger(Trigger::every(period));
        p.priority(BUILDING_PRIORITY);
        (BuildingModule { building }, ())
    });
    id
}

#[cfg(test)]
mod tests {
    use super::*;

    fn building() -> Building {
        let plan = Arc::new(FloorPlan::office());
        let scenario = Scenario {
            seed: 3,
            robots: vec![Pose::new(-5.0, 2.0, 0.0)],
            points_of_interest: plan.points_of_interest.iter().map(|p| p.nominal).collect(),
            alarms: Vec::new(),
            slips: vec![Slip { robot: 0, at: 1.0 }],
        };
        Building::new(plan, BuildingConfig::default(), scenario).expect("building")
    }

    #[test]
    fn a_walking_robot_moves_and_its_odometry_roughly_agrees() {
        let mut b = building();
        b.apply_orders(
            0,
            &ActuatorOrders {
                head: None,
                body: Some(BodyOrder::Walk { velocity: Velocity::new(0.3, 0.0, 0.0) }),
            },
        )
        .expect("walk");
        b.scenario.slips.clear();
        b.advance_to(Time::from_secs_f64(3.0));
        let moved = b.robots[0].pose.x + 5.0;
        let reported = b.robots[0].odometry.dx;
        assert!(moved > 0.6 && (moved - reported).abs() < 0.15 * reported, "{moved} {reported}");
    }

    #[test]
    fn the_camera_sees_what_faces_it_and_not_through_walls() {
        let mut b = building();
        b.config.detection_probability = 1.0;
        // Facing north from (-5, 2): marker 0 at (-5.5, 3.98) is ahead.
        b.robots[0].pose = Pose::new(-5.0, 2.0, std::f64::consts::FRAC_PI_2);
        let seen = b.detections(0);
        assert!(seen.iter().any(|d| d.class == MARKER && d.variant == Some(0)));
        // Facing south: the dividing wall hides the south wing's markers, its own stay.
        b.robots[0].pose = Pose::new(-5.0, 2.0, -std::f64::consts::FRAC_PI_2);
        let seen = b.detections(0);
        assert!(seen.iter().any(|d| d.class == MARKER && d.variant == Some(4)));
        assert!(!seen.iter().any(|d| d.class == MARKER && d.variant == Some(14)));
    }

    #[test]
    fn a_slip_ends_on_the_floor_and_a_stand_up_gets_the_robot_back() {
        let mut b = building();
        b.advance_to(Time::from_secs_f64(1.78));
        b.robots[0].frame = None;
        b.advance_to(Time::from_secs_f64(1.8));
        assert_eq!(b.robots[0].activity, Activity::Fallen);
        assert_eq!(b.truth.falls.len(), 1);
        let frame = b.robots[0].frame.clone().expect("frame");
        assert!(frame.inertial.body_angles[1] > 1.0 && frame.camera.is_none());
        // A motion the building's robots lack is refused by name, not ignored.
        let kick = SpecialMotion::new(MotionName::from_static("kick"), 0, false);
        let orders = ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion: kick }) };
        let refused = b.apply_orders(0, &orders).expect_err("no kick");
        assert!(refused.to_string().contains("kick 0"), "{refused}");
        b.apply_orders(
            0,
            &ActuatorOrders {
                head: None,
                body: Some(BodyOrder::Special { motion: SpecialMotion::stand_up(0) }),
            },
        )
        .expect("stand up");
        b.advance_to(Time::from_secs_f64(5.0));
        assert_eq!(b.robots[0].activity, Activity::Standing);
        assert_eq!(b.truth.stand_ups.len(), 1);
    }
}
