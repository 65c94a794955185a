//! The world: robots, ball, referee and communications, stepped in simulated time.
//!
//! `step` is deterministic: the same configuration (seed included) and the same calls in the
//! same order give the same world, bit for bit. Every random draw comes from a stream seeded
//! by the configuration's seed (`random::Stream`); nothing reads the wall clock or depends on
//! hashing order.

mod controls;
mod io;
mod placement;
mod signals;

use std::time::Duration;

use strata_robot::platform::{
    CameraFrame, FallDirection, HeadAngles, MotionSpec, PlatformInfo, ReceivedPacket, SensorFrame,
    SpecialMotion,
};
use strata_robot::{Global as FieldFrame, Point, Pose, Vector, Velocity};
use strata_runtime::Time;
use strata_spl::Field;
use strata_spl::gamecontroller::{GameControlData, GameState, Penalty, ReturnData, RobotInfo};

use crate::body::{Body, FallCause, FallRecord, dive, kick, push_direction};
use crate::camera::{Camera, RobotMark, RobotMarks, Scene, Scratch, Viewer, ground_band};
use crate::comms::Broadcast;
use crate::config::{ConfigError, DiveSide, SimConfig};
use crate::noise::NoiseParams;
use crate::physics::{Ball, Contact, Discs, Obstacles, resolve_robots};
use crate::random::Stream;
use crate::referee::{Decision, Referee, RefereeView};
use crate::sensors;
use crate::truth::{CommsStats, Event, EventKind, RobotId};

/// Why the simulation refused a request.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("field `{name}`: {source}")]
    Field {
        name: String,
        #[source]
        source: strata_spl::FieldError,
    },
    #[error("no robot {robot} in this game (teams 0 and 1, players 1 to {players})")]
    UnknownRobot { robot: RobotId, players: u8 },
    #[error("no team with number {0} in this game")]
    UnknownTeam(u8),
    #[error("{0}")]
    Invalid(String),
}

/// What a robot's platform has not read yet.
#[derive(Clone, Debug, Default)]
struct Outbox {
    sensors: Option<SensorFrame>,
    camera: Option<CameraFrame>,
    /// A camera frame's detections, kept to reuse its allocation.
    spare_detections: Vec<strata_robot::platform::Detection>,
    team: Vec<ReceivedPacket>,
    control: Vec<ReceivedPacket>,
    /// The confidence of a whistle heard since the last sensor frame.
    whistle: Option<f64>,
}

#[derive(Clone, Debug)]
struct RobotSlot {
    id: RobotId,
    present: bool,
    body: Body,
    /// Walking, falls, kicks.
    motion_rng: Stream,
    /// Inertial unit, encoders, feet.
    imu_rng: Stream,
    camera_rng: Stream,
    /// The referee's signals, seen and heard: streams of their own, so that the signals, on
    /// or off, leave every other draw as it was.
    gesture_rng: Stream,
    whistle_rng: Stream,
    outbox: Outbox,
    encoders: HeadAngles,
    penalty: Penalty,
    penalty_remaining: Option<f64>,
    last_fall: Option<FallRecord>,
    last_return: Option<ReturnData>,
    jersey: u16,
    /// The camera's ground band and the head pitch it was computed for.
    band: (f64, (f64, f64)),
}

impl RobotSlot {
    /// On the field and taking part in physics.
    fn active(&self) -> bool {
        self.present && self.penalty == Penalty::None
    }
}

/// The simulated world.
pub struct Simulation {
    config: SimConfig,
    noise: NoiseParams,
    field: Field,
    obstacles: Obstacles,
    scene: Scene,
    info: PlatformInfo,
    time: Time,
    robots: Vec<RobotSlot>,
    ball: Ball,
    last_toucher: Option<usize>,
    referee: Referee,
    broadcast: Broadcast,
    broadcast_loss: f64,
    comms: CommsStats,
    events: Vec<Event>,
    sensor_period: Duration,
    /// `timing.max_substep` in nanoseconds.
    max_substep: u64,
    camera_period: Duration,
    packet_period: Duration,
    next_sensor: Time,
    next_camera: Time,
    next_packet: Time,
    comms_rng: Stream,
    signals: signals::Signals,
    previous_contacts: Vec<(usize, usize)>,
    /// Taken out while a step uses it (a pointer's move, not the buffers').
    scratch: Option<Box<Buffers>>,
}

/// Reused per-step buffers (the steady state allocates nothing).
#[derive(Clone, Debug, Default)]
struct Buffers {
    positions: Vec<Option<Point<FieldFrame>>>,
    velocities: Vec<Vector<FieldFrame>>,
    /// Diving robots' blocking bodies, by slot.
    blocks: Vec<(usize, strata_robot::geometry::Segment<FieldFrame>)>,
    marks: RobotMarks,
    contacts: Vec<Contact>,
    decisions: Vec<Decision>,
    camera: Scratch,
    deliveries: Vec<(usize, Time, Vec<u8>)>,
}

impl std::fmt::Debug for Simulation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulation")
            .field("time", &self.time)
            .field("field", &self.field.dimensions().name)
            .field("robots", &self.robots.iter().filter(|r| r.present).count())
            .field("state", &self.referee.state)
            .finish_non_exhaustive()
    }
}

fn period(seconds: f64) -> Duration {
    Duration::from_nanos((seconds * 1e9).round().max(1.0) as u64)
}

impl Simulation {
    /// Builds the world: every robot present at its starting place on the side lines, the ball
    /// at the centre, the game in Initial.
    pub fn new(config: SimConfig) -> Result<Simulation, SimError> {
        config.validate("simulation config")?;
        let field = if strata_spl::field::PRESETS.contains(&config.field.as_str()) {
            Field::preset(&config.field)
        } else {
            Field::load(&config.field)
        }
        .map_err(|source| SimError::Field { name: config.field.clone(), source })?;
        let noise = config.noise_params();
        let obstacles = Obstacles::new(&field);
        let scene = Scene::new(&field, &config.robot.camera, obstacles.carpet);
        let info = platform_info(&config);
        let seed = config.seed;
        let referee = Referee::new(&config.referee);
        let players = config.referee.players_per_team;
        let mut robots = Vec::new();
        for team in 0..2 {
            for player in 1..=players {
                let id = RobotId::new(team, player);
                let name = |what: &str| format!("robot/{team}/{player}/{what}");
                let team_config = &config.referee.teams[team];
                let jersey = if player == team_config.goalkeeper {
                    team_config.goalkeeper_colour
                } else {
                    team_config.field_player_colour
                };
                robots.push(RobotSlot {
                    id,
                    present: true,
                    body: Body::new(Pose::default()),
                    motion_rng: Stream::new(seed, &name("motion")),
                    imu_rng: Stream::new(seed, &name("imu")),
                    camera_rng: Stream::new(seed, &name("camera")),
                    gesture_rng: Stream::new(seed, &name("gesture")),
                    whistle_rng: Stream::new(seed, &name("whistle")),
                    outbox: Outbox::default(),
                    encoders: HeadAngles::default(),
                    penalty: Penalty::None,
                    penalty_remaining: None,
                    last_fall: None,
                    last_return: None,
                    jersey: u16::from(u8::from(jersey)),
                    band: (f64::NAN, (0.0, 0.0)),
                });
            }
        }
        let sensor_period = period(config.timing.sensor_period);
        let camera_period = period(config.timing.camera_period);
        let packet_period = period(1.0 / config.referee.packet_rate);
        let broadcast_loss = config.broadcast.loss;
        let signals = signals::Signals::new(
            &config.referee.signals,
            field.half_width(),
            sensor_period,
            referee.state,
        );
        let mut sim = Simulation {
            noise,
            obstacles,
            scene,
            info,
            time: Time::ZERO,
            robots,
            ball: Ball {
                position: Point::new(0.0, 0.0),
                velocity: Vector::new(0.0, 0.0),
                script: None,
            },
            last_toucher: None,
            referee,
            broadcast: Broadcast::default(),
            broadcast_loss,
            comms: CommsStats::default(),
            events: Vec::new(),
            sensor_period,
            max_substep: period(config.timing.max_substep).as_nanos() as u64,
            camera_period,
            packet_period,
            next_sensor: Time::ZERO + sensor_period,
            next_camera: Time::ZERO + sensor_period,
            next_packet: Time::ZERO,
            comms_rng: Stream::new(seed, "comms"),
            signals,
            previous_contacts: Vec::new(),
            scratch: Some(Box::default()),
            field,
            config,
        };
        for slot in 0..sim.robots.len() {
            let pose = sim.start_pose(sim.robots[slot].id);
            sim.robots[slot].body = Body::new(pose);
        }
        Ok(sim)
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    pub fn field(&self) -> &Field {
        &self.field
    }

    pub fn noise(&self) -> &NoiseParams {
        &self.noise
    }

    /// The current simulated time.
    pub fn time(&self) -> Time {
        self.time
    }

    /// What every simulated robot is and can do.
    pub fn platform_info(&self) -> PlatformInfo {
        self.info.clone()
    }

    /// Every robot slot of the game, present or not.
    pub fn robot_ids(&self) -> impl Iterator<Item = RobotId> + '_ {
        self.robots.iter().map(|r| r.id)
    }

    pub fn is_present(&self, robot: RobotId) -> bool {
        self.slot(robot).is_ok_and(|s| self.robots[s].present)
    }

    /// The team index of a team number.
    pub fn team_index(&self, team_number: u8) -> Result<usize, SimError> {
        self.config
            .referee
            .teams
            .iter()
            .position(|t| t.number == team_number)
            .ok_or(SimError::UnknownTeam(team_number))
    }

    pub fn team_number(&self, team: usize) -> u8 {
        self.config.referee.teams[team.min(1)].number
    }

    fn slot(&self, robot: RobotId) -> Result<usize, SimError> {
        let players = self.config.referee.players_per_team;
        if robot.team < 2 && robot.player >= 1 && robot.player <= players {
            Ok(robot.team * usize::from(players) + usize::from(robot.player) - 1)
        } else {
            Err(SimError::UnknownRobot { robot, players })
        }
    }

    fn event(&mut self, kind: EventKind) {
        self.events.push(Event { time: self.time, kind });
    }

    // ---------------------------------------------------------------------------------------
    // Stepping.

    /// Advances the world by `dt`: physics in sub-steps no longer than `timing.max_substep`,
    /// then the referee's packets, team messages due, and sensor frames and camera images due.
    pub fn step(&mut self, dt: Duration) {
        if dt.is_zero() {
            return;
        }
        let start = self.time;
        let total = dt.as_nanos() as u64;
        let max = self.max_substep;
        let steps = total.div_ceil(max).max(1);
        let mut done = 0u64;
        for k in 1..=steps {
            let until = total * k / steps;
            let h = (until - done) as f64 * 1e-9;
            done = until;
            self.time = start + Duration::from_nanos(until);
            self.physics(h);
        }
        self.deliver_team_messages();
        if self.time >= self.next_packet {
            self.publish_control_packet();
            self.next_packet += self.packet_period;
            if self.next_packet <= self.time {
                self.next_packet = self.time + self.packet_period;
            }
        }
        // Sensors first: an image records the head angles the encoders just measured.
        if self.time >= self.next_sensor {
            self.next_sensor += self.sensor_period;
            if self.next_sensor <= self.time {
                self.next_sensor = self.time + self.sensor_period;
            }
            self.sample_sensors();
        }
        if self.time >= self.next_camera {
            self.next_camera += self.camera_period;
            if self.next_camera <= self.time {
                self.next_camera = self.time + self.camera_period;
            }
            self.take_images();
        }
    }

    /// Steps until `time` (no-op if already there).
    pub fn advance_to(&mut self, time: Time) {
        let dt = time.saturating_since(self.time);
        self.step(dt);
    }

    /// Steps `duration` in steps of the sensor period.
    pub fn run_for(&mut self, duration: Duration) {
        let end = self.time + duration;
        while self.time < end {
            let next = (self.time + self.sensor_period).min(end);
            self.advance_to(next);
        }
    }

    fn physics(&mut self, h: f64) {
        let radius = self.config.robot.radius;
        let mut scratch = self.scratch.take().unwrap_or_default();

        // Bodies, and each robot on the field as a position and a velocity.
        let n = self.robots.len();
        scratch.blocks.clear();
        scratch.positions.clear();
        scratch.velocities.clear();
        for slot in 0..n {
            let robot = &mut self.robots[slot];
            if !robot.active() {
                scratch.positions.push(None);
                scratch.velocities.push(Vector::new(0.0, 0.0));
                continue;
            }
            let events =
                robot.body.update(h, &self.config.robot, &self.noise, &mut robot.motion_rng);
            let id = robot.id;
            if let Some(index) = events.kick_contact {
                self.kick(slot, index);
            }
            if let Some((direction, cause)) = events.fall_started {
                self.record_fall(slot, direction, cause);
            }
            if let Some(since) = events.ordered_fall
                && let Some(direction) = events.landed
            {
                // A protective fall or a dive the robot chose: its onset is its start.
                let onset = Time::from_nanos(
                    self.time.as_nanos().saturating_sub((since * 1e9).round() as u64),
                );
                self.record_fall_at(slot, direction, FallCause::Ordered, onset);
            }
            if let Some(direction) = events.landed {
                self.event(EventKind::Landed { robot: id, direction });
            }
            if let Some(success) = events.stand_up {
                self.event(EventKind::StandUp { robot: id, success });
            }
            let body = &self.robots[slot].body;
            if let Some((side, reach)) = events.dive_block {
                let p = body.pose.position();
                let (lx, ly) = body.to_global(0.0, 1.0);
                let left = Vector::new(lx, ly);
                let block = match side {
                    DiveSide::Left => strata_robot::geometry::Segment::new(p, p + left * reach),
                    DiveSide::Right => strata_robot::geometry::Segment::new(p, p - left * reach),
                    DiveSide::Both => {
                        strata_robot::geometry::Segment::new(p - left * reach, p + left * reach)
                    }
                };
                scratch.blocks.push((slot, block));
            }
            scratch.positions.push(Some(body.pose.position()));
            scratch.velocities.push(global_velocity(body));
        }

        // Robots against robots, posts, nets and the carpet's edge.
        resolve_robots(
            &mut scratch.positions,
            &scratch.velocities,
            radius,
            &self.obstacles,
            &mut self.previous_contacts,
            &mut scratch.contacts,
        );
        for (slot, position) in scratch.positions.iter().enumerate() {
            if let Some(p) = position {
                let body = &mut self.robots[slot].body;
                if p.x != body.pose.x || p.y != body.pose.y {
                    body.set_position(p.x, p.y);
                }
            }
        }
        for contact in &scratch.contacts {
            self.collision_falls(contact, h);
        }

        // The ball.
        let discs = Discs {
            positions: &scratch.positions,
            velocities: &scratch.velocities,
            radius,
            blocks: &scratch.blocks,
        };
        if let Some(slot) = self.ball.step(h, &self.config.ball, &self.obstacles, &discs) {
            self.touch(slot);
        }

        // Penalty timers run in Ready and Playing, as the GameController's do.
        let mut unpenalized = false;
        if matches!(self.referee.state, GameState::Ready | GameState::Playing) {
            for slot in 0..n {
                if let Some(remaining) = self.robots[slot].penalty_remaining.as_mut() {
                    *remaining -= h;
                    if *remaining <= 0.0 {
                        self.unpenalize_slot(slot);
                        unpenalized = true;
                    }
                }
            }
        }

        // The referee sees the robots on the field where they are: where the collisions left
        // them, unless a robot just came back.
        if unpenalized {
            scratch.positions.clear();
            for robot in &self.robots {
                scratch.positions.push(robot.active().then(|| robot.body.pose.position()));
            }
        }
        let view = RefereeView {
            field: &self.field,
            ball: self.ball.position,
            ball_radius: self.config.ball.radius,
            robots: &scratch.positions,
        };
        scratch.decisions.clear();
        self.referee.update(h, &view, &mut scratch.decisions);
        let decisions = std::mem::take(&mut scratch.decisions);
        for decision in &decisions {
            self.carry_out(decision);
        }
        scratch.decisions = decisions;
        self.scratch = Some(scratch);
    }

    fn record_fall(&mut self, slot: usize, direction: FallDirection, cause: FallCause) {
        self.record_fall_at(slot, direction, cause, self.time);
    }

    fn record_fall_at(
        &mut self,
        slot: usize,
        direction: FallDirection,
        cause: FallCause,
        onset: Time,
    ) {
        let robot = &mut self.robots[slot];
        robot.last_fall = Some(FallRecord { onset, direction, cause });
        let id = robot.id;
        self.event(EventKind::Fall { robot: id, onset, direction, cause });
    }

    fn collision_falls(&mut self, contact: &Contact, h: f64) {
        let falls = self.noise.falls.clone();
        let (a, b) = (contact.a, contact.b);
        if contact.onset && contact.approach_speed > 0.05 {
            let (ida, idb) = (self.robots[a].id, self.robots[b].id);
            self.event(EventKind::Collision { a: ida, b: idb, speed: contact.approach_speed });
        }
        let onset_p = if contact.onset {
            (falls.collision_fall_per_mps * contact.approach_speed).min(1.0)
        } else {
            0.0
        };
        let pushing = contact.a_pushing || contact.b_pushing;
        let contact_p = if pushing { falls.contact_fall_per_second * h } else { 0.0 };
        let p = 1.0 - (1.0 - onset_p) * (1.0 - contact_p);
        for (slot, away) in [(a, -contact.normal), (b, contact.normal)] {
            let robot = &mut self.robots[slot];
            if robot.body.is_down() || !robot.motion_rng.chance(p) {
                continue;
            }
            let direction = push_direction(&robot.body.pose, away);
            if robot.body.start_fall(direction) {
                self.record_fall(slot, direction, FallCause::Collision);
            }
        }
    }

    fn touch(&mut self, slot: usize) {
        self.last_toucher = Some(slot);
        self.referee.last_touch = Some(self.robots[slot].id.team);
    }

    fn kick(&mut self, slot: usize, index: usize) {
        let Some(spec) = self.config.robot.kicks.get(index) else { return };
        let robot = &mut self.robots[slot];
        let local = robot.body.pose.to_robot(self.ball.position);
        let hit = (spec.reach_x[0]..=spec.reach_x[1]).contains(&local.x)
            && (spec.reach_y[0]..=spec.reach_y[1]).contains(&local.y)
            && self.ball.script.is_none();
        if hit {
            let noise = &self.noise.actuation;
            let speed = (spec.speed * (1.0 + robot.motion_rng.gauss(noise.kick_speed_sigma)))
                .clamp(0.0, self.config.ball.max_speed);
            let direction = robot.body.pose.theta
                + spec.direction
                + robot.motion_rng.gauss(noise.kick_direction_sigma);
            self.ball.velocity = Vector::from_polar(speed, direction);
        }
        let id = robot.id;
        let motion = kick(u8::try_from(index).unwrap_or(u8::MAX));
        if hit {
            self.touch(slot);
        }
        self.event(EventKind::Kick { robot: id, motion, hit });
    }

    fn carry_out(&mut self, decision: &Decision) {
        match decision {
            Decision::State(state) => {
                let first_half = self.referee.first_half;
                self.event(EventKind::GameState { state: *state, first_half });
                self.signal_state(*state);
            }
            Decision::Goal { team } => {
                let scorer = self.last_toucher.map(|s| self.robots[s].id);
                let score = self.referee.score;
                self.event(EventKind::Goal { team: *team, score, scorer });
                self.whistle();
            }
            Decision::Out { status, set_play, team, place } => {
                let at = self.ball.position;
                if let Some(place) = place {
                    self.put_ball(*place);
                }
                self.event(EventKind::BallOut {
                    status: *status,
                    set_play: *set_play,
                    team: *team,
                    at,
                    placed: *place,
                });
            }
            Decision::PlaceBall(p) => {
                self.put_ball(*p);
                self.event(EventKind::BallPlaced { position: *p });
            }
            Decision::PlaceForKickOff => self.place_for_kick_off(),
            Decision::PlaceForHalf => {
                for slot in 0..self.robots.len() {
                    if self.robots[slot].penalty != Penalty::None {
                        self.robots[slot].penalty = Penalty::None;
                        self.robots[slot].penalty_remaining = None;
                    }
                    let pose = self.start_pose(self.robots[slot].id);
                    self.robots[slot].body.place(pose);
                }
            }
            Decision::LeftField { slot } => {
                let duration = self.config.referee.penalty_duration;
                self.penalize_slot(*slot, Penalty::LeavingTheField, Some(duration));
            }
            Decision::SetPlayOver => self.event(EventKind::SetPlayOver),
        }
    }

    fn put_ball(&mut self, p: Point<FieldFrame>) {
        self.ball.position = p;
        self.ball.velocity = Vector::new(0.0, 0.0);
        self.ball.script = None;
        self.last_toucher = None;
    }

    // ---------------------------------------------------------------------------------------
    // Sensors.

    #[inline(never)] // once per step; kept apart so profiles show it
    fn sample_sensors(&mut self) {
        let now = self.time;
        let battery = Some((1.0 - now.as_secs_f64() / self.config.robot.battery_life).max(0.0));
        for robot in &mut self.robots {
            if !robot.present {
                continue;
            }
            let lifted = robot.penalty != Penalty::None;
            let imu = &self.noise.imu;
            let (inertial, head, foot_contact) = sensors::sample(
                &mut robot.body,
                lifted,
                &self.config.robot,
                imu,
                &mut robot.imu_rng,
            );
            robot.encoders = head;
            let whistle = signals::whistle_report(&self.signals, robot, now, &mut self.events);
            robot.outbox.sensors = Some(SensorFrame {
                stamp: now,
                inertial,
                head,
                foot_contact,
                buttons: Default::default(),
                battery,
                camera: None,
                // A robot the referee carries off is lifted: its feet tell.
                placed: false,
                whistle,
            });
        }
    }

    #[inline(never)] // once per step; kept apart so profiles show it
    fn take_images(&mut self) {
        let now = self.time;
        let mut scratch = self.scratch.take().unwrap_or_default();
        scratch.marks.clear();
        for (slot, robot) in self.robots.iter().enumerate() {
            if robot.active() {
                let position = robot.body.pose.position();
                scratch.marks.push(slot, RobotMark { position, variant: robot.jersey });
            }
        }
        let camera = Camera::new(
            &self.config.robot.camera,
            &self.noise.camera,
            self.config.robot.radius,
            &self.scene,
        );
        let gesture = self.signals.gesture(now);
        for (index, robot) in self.robots.iter_mut().enumerate() {
            if !robot.present {
                continue;
            }
            let body = &robot.body;
            if robot.band.0 != body.head.pitch {
                let band = ground_band(&self.config.robot.camera, body.head.pitch);
                robot.band = (body.head.pitch, band);
            }
            let viewer = Viewer {
                pose: body.pose,
                axis: {
                    // The camera's direction: the heading turned by the head yaw.
                    let (s, c) = body.heading();
                    let (sy, cy) = (body.head_yaw.sin, body.head_yaw.cos);
                    (s * cy + c * sy, c * cy - s * sy)
                },
                head: body.head,
                head_rate: body.head_rate,
                index: Some(index),
                blind: body.is_down() || robot.penalty != Penalty::None,
                band: robot.band.1,
            };
            // Reuse the allocation of an image nobody read.
            let mut detections = match robot.outbox.camera.take() {
                Some(unread) => unread.detections,
                None => std::mem::take(&mut robot.outbox.spare_detections),
            };
            detections.clear();
            camera.capture(
                &self.scene,
                &viewer,
                &scratch.marks,
                Some(self.ball.position),
                &mut robot.camera_rng,
                &mut scratch.camera,
                &mut detections,
            );
            if let Some(referee) = &gesture {
                let rng = &mut robot.gesture_rng;
                camera.capture_gesture(&viewer, &scratch.marks, referee, rng, &mut detections);
            }
            robot.outbox.camera =
                Some(CameraFrame { stamp: now, head: robot.encoders, detections, footprint: None });
        }
        self.scratch = Some(scratch);
    }

    // ---------------------------------------------------------------------------------------
    // Communication.

    #[inline(never)] // once per step; kept apart so profiles show it
    fn deliver_team_messages(&mut self) {
        let mut scratch = self.scratch.take().unwrap_or_default();
        let mut deliveries = std::mem::take(&mut scratch.deliveries);
        deliveries.clear();
        self.broadcast.due(self.time, &mut deliveries);
        for (to, at, bytes) in deliveries.drain(..) {
            if let Some(robot) = self.robots.get_mut(to)
                && robot.present
            {
                robot.outbox.team.push(ReceivedPacket { received: at, bytes });
                self.comms.delivered += 1;
            }
        }
        scratch.deliveries = deliveries;
        self.scratch = Some(scratch);
    }

    /// The control packet the referee would send now (without sending it).
    pub fn control_data(&mut self) -> GameControlData {
        let robots = &self.robots;
        let players = self.config.referee.players_per_team;
        self.referee.control_data(&self.config.referee.teams, players, |team, player| {
            let slot = team * usize::from(players) + usize::from(player) - 1;
            robots.get(slot).map_or(RobotInfo::default(), |r| RobotInfo {
                penalty: r.penalty,
                secs_till_unpenalised: r
                    .penalty_remaining
                    .map_or(0, |s| s.ceil().clamp(0.0, 255.0) as u8),
            })
        })
    }

    fn publish_control_packet(&mut self) {
        let bytes = self.control_data().encode();
        self.comms.control_packets += 1;
        let loss = self.config.referee.packet_loss;
        for robot in &mut self.robots {
            if !robot.present {
                continue;
            }
            if self.comms_rng.chance(loss) {
                self.comms.control_packets_lost += 1;
                continue;
            }
            robot
                .outbox
                .control
                .push(ReceivedPacket { received: self.time, bytes: bytes.to_vec() });
        }
    }
}

/// A robot's walking and pushed velocity in the field frame.
fn global_velocity(body: &Body) -> Vector<FieldFrame> {
    let (x, y) = body.to_global(body.velocity.vx, body.velocity.vy);
    Vector::new(x + body.push.x, y + body.push.y)
}

/// The platform description every simulated robot reports.
pub(crate) fn platform_info(config: &SimConfig) -> PlatformInfo {
    let r = &config.robot;
    let mut motions = Vec::new();
    let spec = |motion, name: String, duration: f64| MotionSpec {
        motion,
        name,
        duration: Duration::from_secs_f64(duration),
    };
    let number = |i: usize| u8::try_from(i).unwrap_or(u8::MAX);
    for (i, k) in r.kicks.iter().enumerate() {
        motions.push(spec(kick(number(i)), format!("kick {}", k.name), k.duration));
    }
    for (i, s) in r.stand_ups.iter().enumerate() {
        let name = format!("stand up {}", s.name);
        motions.push(spec(SpecialMotion::stand_up(number(i)), name, s.duration));
    }
    for (i, s) in r.protective_falls.iter().enumerate() {
        let name = format!("fall {}", s.name);
        motions.push(spec(SpecialMotion::fall(number(i)), name, s.duration));
    }
    for (i, d) in r.dives.iter().enumerate() {
        motions.push(spec(dive(number(i)), format!("dive {}", d.name), d.duration));
    }
    PlatformInfo {
        name: r.name.clone(),
        sensor_period: period(config.timing.sensor_period),
        camera_fov: r.camera.fov,
        camera_range: r.camera.range,
        head_yaw_limits: (r.head.yaw_limits[0], r.head.yaw_limits[1]),
        head_pitch_limits: (r.head.pitch_limits[0], r.head.pitch_limits[1]),
        max_head_speed: r.head.max_speed,
        max_velocity: Velocity::new(r.max_speed.forward, r.max_speed.sideways, r.max_speed.turn),
        motions,
        can_walk: true,
    }
}
