//! The simulator: bodies walking in a [`World`], stepped at the sensor period. Each step the
//! application's [`Script`] acts first (an object appears, a robot slips), then each body in
//! turn moves — its true motion differs from what its odometry reports by a systematic scale
//! error and random noise, and a wall stops it — and its sensors and camera measure the result.
//! Everything random comes from one seeded stream, drawn in a fixed order: a run is the same
//! run every time.

use std::time::Duration;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use strata_robot::geometry::{Odometry, Pose};
use strata_robot::platform::{
    ActuatorOrders, CameraFrame, Detection, MotionFeedback, MotionSpec, PlatformError,
    PlatformInfo, SensorFrame, SpecialMotion,
};
use strata_runtime::Time;

use crate::body::{Body, Landing};
use crate::camera;
use crate::config::{ConfigError, WorldSimConfig};
use crate::truth::Truth;
use crate::world::World;

/// Why the simulator refused a request.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WorldSimError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("no robot {0} in the world")]
    NoRobot(usize),
}

/// What happened to a body (by robot index) in a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodyEvent {
    /// It landed on the floor, from a slip or a protective fall.
    Landed(usize),
    /// It completed a stand-up.
    StoodUp(usize),
    /// It walked into a wall.
    Bumped(usize),
}

/// The application's part of each step. Both calls see the simulator with its clock already at
/// the step's time.
pub trait Script: Send {
    /// Before the bodies move: move markers, make robots slip.
    fn before_step(&mut self, sim: &mut WorldSim) {
        let _ = sim;
    }

    /// After the bodies moved and measured: what happened to them.
    fn after_step(&mut self, sim: &mut WorldSim, events: &[BodyEvent]) {
        let _ = (sim, events);
    }
}

/// No script: the world only does what its robots do.
impl Script for () {}

/// The world, its bodies and their sensors.
#[derive(Debug)]
pub struct WorldSim {
    config: WorldSimConfig,
    world: World,
    bodies: Vec<Body>,
    /// Each robot's newest frame, until its platform takes it.
    frames: Vec<Option<SensorFrame>>,
    rng: ChaCha8Rng,
    period: Duration,
    time: Time,
    steps: u64,
    truth: Truth,
    truth_period: Duration,
    next_sample: Time,
}

impl WorldSim {
    /// A world with a robot standing at each of `starts` (robot `i` at `starts[i]`), every draw
    /// from `seed`.
    pub fn new(
        config: WorldSimConfig,
        world: World,
        starts: &[Pose],
        seed: u64,
    ) -> Result<WorldSim, WorldSimError> {
        config.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let body = &config.body;
        let bodies: Vec<Body> = starts
            .iter()
            .map(|pose| {
                let mut scale = [0.0; 3];
                for s in &mut scale {
                    let n: f64 = StandardNormal.sample(&mut rng);
                    *s = 1.0 + body.odometry_scale_sigma * n;
                }
                Body::new(*pose, scale, body.max_head_speed)
            })
            .collect();
        let truth = Truth { trajectories: vec![Vec::new(); bodies.len()], ..Truth::default() };
        Ok(WorldSim {
            period: Duration::from_secs_f64(config.sensor_period),
            truth_period: Duration::from_secs_f64(config.truth_period),
            frames: vec![None; bodies.len()],
            config,
            world,
            bodies,
            rng,
            time: Time::ZERO,
            steps: 0,
            truth,
            next_sample: Time::ZERO,
        })
    }

    pub fn config(&self) -> &WorldSimConfig {
        &self.config
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    /// The world, for the application to move its markers.
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// The time of the last step.
    pub fn time(&self) -> Time {
        self.time
    }

    /// The step (and sensor) period.
    pub fn period(&self) -> Duration {
        self.period
    }

    /// The world's clock at host time `now`: the world moves in steps, so for it whatever
    /// happens between two steps happens at the earlier one. It does not depend on whether the
    /// step due at `now` has run yet, so a link that stamps by it needs no order against the
    /// simulator's module.
    pub fn clock_at(&self, now: Time) -> Time {
        let period = u64::try_from(self.period.as_nanos()).unwrap_or(u64::MAX).max(1);
        Time::from_nanos(now.as_nanos() / period * period)
    }

    pub fn robots(&self) -> usize {
        self.bodies.len()
    }

    pub fn body(&self, robot: usize) -> Option<&Body> {
        self.bodies.get(robot)
    }

    fn body_mut(&mut self, robot: usize) -> Result<&mut Body, WorldSimError> {
        self.bodies.get_mut(robot).ok_or(WorldSimError::NoRobot(robot))
    }

    /// The simulation's random stream, for the application's own draws (a lossy radio): one
    /// seed then decides the whole run.
    pub fn rng(&mut self) -> &mut ChaCha8Rng {
        &mut self.rng
    }

    /// What really happened so far.
    pub fn truth(&self) -> &Truth {
        &self.truth
    }

    /// Puts a robot somewhere (its odometry does not notice).
    pub fn set_pose(&mut self, robot: usize, pose: Pose) -> Result<(), WorldSimError> {
        self.body_mut(robot)?.set_pose(pose);
        Ok(())
    }

    /// Makes a robot on its feet slip into an unprotected forward fall; false if it was not on
    /// its feet.
    pub fn slip(&mut self, robot: usize) -> Result<bool, WorldSimError> {
        Ok(self.body_mut(robot)?.slip())
    }

    /// Gives a robot's orders to its body; they act from the next step.
    pub fn apply_orders(
        &mut self,
        robot: usize,
        orders: &ActuatorOrders,
    ) -> Result<(), PlatformError> {
        let body = self.bodies.get_mut(robot).ok_or_else(|| {
            PlatformError::Disconnected(WorldSimError::NoRobot(robot).to_string())
        })?;
        body.apply(orders, &self.config.body)
    }

    /// The robots' platform: the same for every robot of the world.
    pub fn platform_info(&self) -> PlatformInfo {
        let body = &self.config.body;
        let spec = |motion, name: &str, seconds: f64| MotionSpec {
            motion,
            name: name.to_owned(),
            duration: Duration::from_secs_f64(seconds),
        };
        PlatformInfo {
            name: self.config.name.clone(),
            sensor_period: self.period,
            camera_fov: self.config.camera.fov,
            camera_range: self.config.camera.range,
            head_yaw_limits: body.head_yaw_limits,
            head_pitch_limits: body.head_pitch_limits,
            max_head_speed: body.max_head_speed,
            max_velocity: body.max_velocity,
            motions: vec![
                spec(SpecialMotion::fall(0), "protective fall", body.protective_fall_time),
                spec(SpecialMotion::stand_up(0), "stand up from the front", body.stand_up_time),
                spec(SpecialMotion::stand_up(1), "stand up from the back", body.stand_up_time),
            ],
            can_walk: true,
        }
    }

    /// Steps up to `now`, one period at a time.
    pub fn advance_to(&mut self, now: Time, script: &mut dyn Script) {
        while self.time + self.period <= now {
            self.step(script);
        }
    }

    /// One step: the script, then each body, then the ground truth.
    pub fn step(&mut self, script: &mut dyn Script) {
        self.time += self.period;
        self.steps += 1;
        let dt = self.period.as_secs_f64();
        script.before_step(self);
        let camera = self.steps.is_multiple_of(u64::from(self.config.camera.every));
        let mut events = Vec::new();
        for i in 0..self.bodies.len() {
            self.move_body(i, dt, &mut events);
            let mut frame = self.sensor_frame(i, camera);
            // An unread camera image survives a newer frame without one: a late cycle on the
            // threaded host steps several times and hands over the newest frame only.
            let unread_camera = self.frames[i].take().and_then(|f| f.camera);
            frame.camera = frame.camera.or(unread_camera);
            self.frames[i] = Some(frame);
        }
        if self.time >= self.next_sample {
            self.next_sample += self.truth_period;
            let now = self.time.as_secs_f64();
            for (samples, body) in self.truth.trajectories.iter_mut().zip(&self.bodies) {
                samples.push((now, body.pose()));
            }
        }
        script.after_step(self, &events);
    }

    fn normal(&mut self) -> f64 {
        StandardNormal.sample(&mut self.rng)
    }

    /// The body's own motion, then where its steps really take it.
    fn move_body(&mut self, i: usize, dt: f64, events: &mut Vec<BodyEvent>) {
        let config = &self.config.body;
        let radius = config.radius;
        let now = self.time.as_secs_f64();
        match self.bodies[i].advance(dt, config) {
            Some(Landing::OnTheFloor) => {
                // Landing shoves the body a little: no odometry reports it.
                let [sx, sy, sh] = config.landing_shove;
                let (dx, dy, dtheta) = (sx * self.normal(), sy * self.normal(), sh * self.normal());
                let moved = self.bodies[i].pose().moved(Odometry { dx, dy, dtheta });
                if self.world.wall_distance(moved.position()) > radius {
                    self.bodies[i].set_pose(moved);
                }
                self.truth.falls.push((i, now));
                events.push(BodyEvent::Landed(i));
            }
            Some(Landing::OnItsFeet) => {
                self.truth.stand_ups.push((i, now));
                events.push(BodyEvent::StoodUp(i));
            }
            None => {}
        }
        let Some(believed) = self.bodies[i].believed_step(dt) else { return };
        let k = self.config.body.odometry_noise;
        let distance = believed.dx.hypot(believed.dy);
        let noise = [
            k * distance.sqrt() * self.normal(),
            k * distance.sqrt() * self.normal(),
            k * believed.dtheta.abs().sqrt() * self.normal(),
        ];
        let body = &mut self.bodies[i];
        let scale = body.odometry_scale();
        let real = Odometry {
            dx: believed.dx * scale[0] + noise[0],
            dy: believed.dy * scale[1] + noise[1],
            dtheta: believed.dtheta * scale[2] + noise[2],
        };
        let pose = body.pose();
        let moved = pose.moved(real);
        if self.world.wall_distance(moved.position()) > radius {
            body.set_pose(moved);
        } else {
            // Against a wall the feet slip: the robot turns but goes nowhere.
            body.set_pose(Pose::new(pose.x, pose.y, moved.theta));
            self.truth.bumps += 1;
            events.push(BodyEvent::Bumped(i));
        }
    }

    fn sensor_frame(&mut self, i: usize, camera: bool) -> SensorFrame {
        let mut frame = self.bodies[i].sensor_frame(self.time);
        if camera && self.bodies[i].can_see(self.config.camera.max_tilt) {
            let detections = self.look(i);
            frame.camera = Some(CameraFrame {
                stamp: self.time,
                head: frame.head,
                detections,
                footprint: None,
            });
        }
        frame
    }

    /// What robot `robot`'s camera reports now, wherever its body and head are (it draws its
    /// noise from the simulation's stream); nothing for a robot that is not there.
    pub fn look(&mut self, robot: usize) -> Vec<Detection> {
        let Some(body) = self.bodies.get(robot) else { return Vec::new() };
        camera::detections(
            &self.config.camera,
            body.pose(),
            body.head().yaw,
            &self.world,
            &mut self.rng,
        )
    }

    /// Robot `robot`'s newest sensor frame since the last call.
    pub fn take_frame(&mut self, robot: usize) -> Result<Option<SensorFrame>, WorldSimError> {
        let frame = self.frames.get_mut(robot).ok_or(WorldSimError::NoRobot(robot))?;
        Ok(frame.take())
    }

    /// Robot `robot`'s motion state, and the odometry its walking engine accumulated since the
    /// last call.
    pub fn take_feedback(&mut self, robot: usize) -> Result<MotionFeedback, WorldSimError> {
        let stamp = self.time;
        Ok(self.body_mut(robot)?.take_feedback(stamp))
    }
}
