//! A trivial robot controller for tests and the `strata robot` process until the hybrid control
//! drives robots: it walks towards the ball when it sees it, looks around otherwise, kicks when
//! close, stands up after a fall, and stands still outside Playing or while penalized.
//!
//! It reads only what a robot has: its platform (sensor frames, detections, motion state) and
//! the GameController's packets. Never ground truth.

use std::time::Duration;

use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, ExternalLink, FallDirection, HeadAngles, HeadOrder,
    Platform, PlatformError, PlatformInfo, SharedPlatform, SpecialMotion, lock_platform,
};
use strata_robot::{Velocity, normalize_angle};
use strata_runtime::{Context, GraphBuilder, Module, ModuleError, ModuleId, Time, Trigger};
use strata_spl::ObjectKind;
use strata_spl::gamecontroller::{GameControlData, GameState, Penalty};

use crate::body::kick;

/// Tuning of the test controller.
#[derive(Clone, Debug, PartialEq)]
pub struct TestControllerConfig {
    /// Forward speed when walking to the ball, m/s.
    pub walk_speed: f64,
    /// Turning gain on the ball's bearing, 1/s.
    pub turn_gain: f64,
    /// The ball is kickable closer than this (m) and within `kick_bearing` (rad).
    pub kick_range: f64,
    pub kick_bearing: f64,
    /// A sighting older than this is forgotten, s.
    pub ball_memory: f64,
    /// Head scan amplitude (rad) and speed (rad/s).
    pub scan_yaw: f64,
    pub scan_speed: f64,
}

impl Default for TestControllerConfig {
    fn default() -> Self {
        TestControllerConfig {
            walk_speed: 0.22,
            turn_gain: 1.5,
            kick_range: 0.22,
            kick_bearing: 0.25,
            ball_memory: 1.5,
            scan_yaw: 1.2,
            scan_speed: 1.5,
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Sighting {
    /// Relative to the body, at the time of the image.
    range: f64,
    bearing: f64,
    time: Time,
}

/// What the controller knows of the game from the GameController.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GameView {
    pub state: Option<GameState>,
    pub penalized: bool,
    pub score: [u8; 2],
    pub packets: u64,
}

/// The controller's state. Pure: [`TestController::step`] reads and writes a platform.
#[derive(Debug)]
pub struct TestController {
    config: TestControllerConfig,
    info: PlatformInfo,
    team_number: u8,
    player: u8,
    ball: Option<Sighting>,
    scan_direction: f64,
    game: GameView,
    frames: u64,
    detections: u64,
}

impl TestController {
    pub fn new(info: PlatformInfo, team_number: u8, player: u8) -> TestController {
        TestController::with_config(info, team_number, player, TestControllerConfig::default())
    }

    pub fn with_config(
        info: PlatformInfo,
        team_number: u8,
        player: u8,
        config: TestControllerConfig,
    ) -> TestController {
        TestController {
            config,
            info,
            team_number,
            player,
            ball: None,
            scan_direction: 1.0,
            game: GameView::default(),
            frames: 0,
            detections: 0,
        }
    }

    pub fn game(&self) -> GameView {
        self.game
    }

    /// Sensor frames and detections seen so far.
    pub fn counts(&self) -> (u64, u64) {
        (self.frames, self.detections)
    }

    /// Whether the ball was seen within the ball memory.
    pub fn sees_ball(&self, now: Time) -> bool {
        self.ball.is_some_and(|b| (now - b.time).as_secs_f64() <= self.config.ball_memory)
    }

    /// Reads GameController packets; malformed ones are ignored, as a robot must.
    pub fn read_game_controller(&mut self, link: &mut dyn ExternalLink, now: Time) {
        let Ok(packets) = link.receive(now) else { return };
        for packet in packets {
            let Ok(data) = GameControlData::decode(&packet.bytes) else { continue };
            self.game.packets += 1;
            self.game.state = Some(data.state);
            self.game.score = [data.teams[0].score, data.teams[1].score];
            self.game.penalized = data
                .team(self.team_number)
                .and_then(|team| team.player(self.player))
                .is_some_and(|p| p.penalty != Penalty::None);
        }
    }

    /// One control cycle: read the platform, decide, write orders.
    pub fn step(&mut self, platform: &mut dyn Platform, now: Time) -> Result<(), PlatformError> {
        if let Some(frame) = platform.read_sensors(now)? {
            self.frames += 1;
            if let Some(camera) = &frame.camera {
                self.detections += camera.detections.len() as u64;
                let ball = camera
                    .detections
                    .iter()
                    .filter(|d| d.class.0 == ObjectKind::Ball.code())
                    .min_by(|a, b| a.range.total_cmp(&b.range));
                if let Some(ball) = ball {
                    self.ball = Some(Sighting {
                        range: ball.range,
                        bearing: normalize_angle(ball.bearing + camera.head.yaw),
                        time: camera.stamp,
                    });
                }
            }
        }
        let motion = platform.read_motion(now)?;
        let orders = self.decide(now, motion.body, motion.head);
        match platform.write(now, &orders) {
            // The body refused a sequence it cannot start now (a kick while it is already
            // falling): the next cycle decides again.
            Err(PlatformError::Unsupported(_)) => Ok(()),
            other => other,
        }
    }

    fn decide(&mut self, now: Time, body: BodyMotionState, head: HeadAngles) -> ActuatorOrders {
        let playing = self.game.state.is_none_or(|s| s == GameState::Playing);
        let ball = self.ball.filter(|_| self.sees_ball(now));
        let head_order = match ball {
            Some(ball) => HeadOrder {
                target: HeadAngles {
                    yaw: ball.bearing,
                    // Look down at a near ball, ahead at a far one.
                    pitch: (0.45 - 0.1 * ball.range).clamp(0.0, 0.45),
                },
                max_speed: self.info.max_head_speed.min(3.0),
            },
            None => {
                let limit = self.config.scan_yaw;
                if head.yaw * self.scan_direction >= limit - 0.05 {
                    self.scan_direction = -self.scan_direction;
                }
                HeadOrder {
                    target: HeadAngles { yaw: self.scan_direction * limit, pitch: 0.2 },
                    max_speed: self.config.scan_speed,
                }
            }
        };
        let body_order = match body {
            BodyMotionState::Fallen { direction } => {
                let sequence = if direction == FallDirection::Back { 1 } else { 0 };
                Some(BodyOrder::Special { motion: SpecialMotion::stand_up(sequence) })
            }
            // Let a running sequence finish.
            BodyMotionState::Special { .. } | BodyMotionState::Limp => None,
            _ if !playing || self.game.penalized => Some(BodyOrder::Stand),
            _ => Some(match ball {
                Some(ball)
                    if ball.range < self.config.kick_range
                        && ball.bearing.abs() < self.config.kick_bearing
                        && self.info.motion(kick(0)).is_some() =>
                {
                    BodyOrder::Special { motion: kick(0) }
                }
                Some(ball) => {
                    let aligned = (1.0 - ball.bearing.abs() / 0.8).clamp(0.0, 1.0);
                    // Slow down close to the ball so it is not pushed away.
                    let speed = self.config.walk_speed * aligned * (ball.range / 0.6).min(1.0);
                    BodyOrder::Walk {
                        velocity: Velocity::new(
                            speed.max(0.03 * aligned),
                            0.0,
                            (self.config.turn_gain * ball.bearing).clamp(-1.0, 1.0),
                        ),
                    }
                }
                None => BodyOrder::Walk { velocity: Velocity::new(0.0, 0.0, 0.5) },
            }),
        };
        ActuatorOrders { head: Some(head_order), body: body_order }
    }
}

/// The test controller as a module of one robot: reads its platform (and GameController
/// link) every period.
pub struct TestControllerModule {
    controller: TestController,
    platform: SharedPlatform,
    game_controller: Option<Box<dyn ExternalLink>>,
}

impl std::fmt::Debug for TestControllerModule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TestControllerModule").field("controller", &self.controller).finish()
    }
}

impl Module for TestControllerModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        if let Some(link) = self.game_controller.as_deref_mut() {
            self.controller.read_game_controller(link, now);
        }
        let mut platform = lock_platform(&self.platform);
        self.controller.step(&mut *platform, now)?;
        Ok(())
    }
}

/// Adds a robot driven by the test controller, running every `period`.
pub fn add_test_controller(
    graph: &mut GraphBuilder,
    name: &str,
    controller: TestController,
    platform: SharedPlatform,
    game_controller: Option<Box<dyn ExternalLink>>,
    period: Duration,
) -> ModuleId {
    graph.add(name, |p| {
        p.trigger(Trigger::every(period));
        let id = p.id();
        (TestControllerModule { controller, platform, game_controller }, id)
    })
}
