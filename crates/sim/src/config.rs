//! The simulator's configuration: one TOML file, every number a parameter.
//!
//! Times are seconds, distances metres, angles radians. Unknown keys are errors, and every error
//! names the file and the key. `crates/sim/config/default.toml` lists every key with its default.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use strata_spl::gamecontroller::TeamColour;

use crate::noise::{NoiseConfig, NoiseParams};

/// Why a configuration could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{source_name}: {message}")]
    Parse { source_name: String, message: String },
    #[error("{source_name}: `{field}` must be {requirement}, got {value}")]
    Invalid { source_name: String, field: String, requirement: String, value: String },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{source_name}: field `{field}`: {message}")]
    Global { source_name: String, field: String, message: String },
}

/// Everything the simulator needs to build a world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Seeds every random draw of the simulation.
    pub seed: u64,
    /// A field preset of the `spl` crate (`spl`, `paper2010`) or a path to a field TOML file.
    pub field: String,
    pub timing: TimingConfig,
    pub robot: RobotConfig,
    pub ball: BallConfig,
    pub noise: NoiseConfig,
    pub referee: RefereeConfig,
    pub broadcast: BroadcastConfig,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            seed: 1,
            field: "spl".to_owned(),
            timing: TimingConfig::default(),
            robot: RobotConfig::default(),
            ball: BallConfig::default(),
            noise: NoiseConfig::default(),
            referee: RefereeConfig::default(),
            broadcast: BroadcastConfig::default(),
        }
    }
}

/// Rates of the simulation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TimingConfig {
    /// Inertial sensors, joint encoders and foot contact (NAO v6: 12 ms, 83 Hz). The
    /// simulator module steps the world at this period.
    pub sensor_period: f64,
    /// Camera images (30 Hz); an image is attached to the first sensor frame at or after its
    /// due time.
    pub camera_period: f64,
    /// The longest physics step; longer steps are split.
    pub max_substep: f64,
    /// How often the simulator module publishes ground truth on its output.
    pub ground_truth_period: f64,
}

impl Default for TimingConfig {
    fn default() -> Self {
        TimingConfig {
            sensor_period: 0.012,
            camera_period: 1.0 / 30.0,
            max_substep: 0.012,
            ground_truth_period: 0.1,
        }
    }
}

/// Walking speed limits, robot frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SpeedLimits {
    pub forward: f64,
    pub backward: f64,
    pub sideways: f64,
    pub turn: f64,
}

impl Default for SpeedLimits {
    fn default() -> Self {
        SpeedLimits { forward: 0.25, backward: 0.15, sideways: 0.15, turn: 1.2 }
    }
}

/// Acceleration limits of the walking engine.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AccelerationLimits {
    /// m/s^2, forward and sideways.
    pub linear: f64,
    /// rad/s^2.
    pub turn: f64,
}

impl Default for AccelerationLimits {
    fn default() -> Self {
        AccelerationLimits { linear: 0.5, turn: 3.0 }
    }
}

/// The walk as a cyclic motion (paper 3.5.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WalkConfig {
    /// Initialization stage (shifting weight before the first step), s.
    pub init_duration: f64,
    /// End stage after the robot has come to a stop (closing the feet), s.
    pub end_duration: f64,
    /// One full gait cycle (two steps), s.
    pub step_period: f64,
    /// Torso sway while walking, rad (roll amplitude) ...
    pub sway_roll: f64,
    /// ... and pitch amplitude.
    pub sway_pitch: f64,
}

impl Default for WalkConfig {
    fn default() -> Self {
        WalkConfig {
            init_duration: 0.3,
            end_duration: 0.3,
            step_period: 0.5,
            sway_roll: 0.035,
            sway_pitch: 0.015,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HeadConfig {
    pub yaw_limits: [f64; 2],
    pub pitch_limits: [f64; 2],
    /// rad/s per joint.
    pub max_speed: f64,
}

impl Default for HeadConfig {
    fn default() -> Self {
        // NAO v6 HeadYaw +-119.5 deg, HeadPitch -38.5 .. 29.5 deg (down positive).
        HeadConfig { yaw_limits: [-2.0857, 2.0857], pitch_limits: [-0.672, 0.515], max_speed: 4.0 }
    }
}

/// The camera: what the robot can see. Top and bottom cameras of a NAO are modelled as one
/// camera whose vertical coverage is the union of both.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Horizontal field of view, rad (NAO: 61 degrees).
    pub fov: f64,
    /// Maximum detection range, m.
    pub range: f64,
    /// Height of the camera above the ground, m.
    pub height: f64,
    /// Vertical coverage at head pitch 0, as depression angles below the horizon (rad): a
    /// ground point is visible when its depression lies in [min, max] + head pitch. Tall
    /// objects (posts, beacons, robots) ignore the lower bound of the far side.
    pub min_depression: f64,
    pub max_depression: f64,
    /// Shorter visible pieces of a field line are not reported, m.
    pub min_line_length: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            fov: 61f64.to_radians(),
            range: 6.0,
            height: 0.5,
            min_depression: -0.40,
            max_depression: 1.11,
            min_line_length: 0.15,
        }
    }
}

/// How an unprotected fall develops.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FallConfig {
    /// From the onset to lying on the ground, s.
    pub duration: f64,
    /// Body angle when lying, rad.
    pub lying_tilt: f64,
    /// Extra acceleration at the impact, m/s^2.
    pub impact_accel: f64,
    /// An external push faster than this (m/s) always makes the robot fall.
    pub push_fall_speed: f64,
    /// Time constant with which a push's velocity decays, s.
    pub push_decay: f64,
}

impl Default for FallConfig {
    fn default() -> Self {
        FallConfig {
            duration: 0.7,
            lying_tilt: 1.45,
            impact_accel: 25.0,
            push_fall_speed: 0.35,
            push_decay: 0.2,
        }
    }
}

/// A kick of the motion catalogue (`Kick(n)` is the n-th).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KickSpec {
    pub name: String,
    pub duration: f64,
    /// When the foot meets the ball, s after the start.
    pub contact_time: f64,
    /// Ball speed given, m/s.
    pub speed: f64,
    /// Ball direction relative to the robot's heading, rad.
    pub direction: f64,
    /// The ball is hit if its centre lies in this box, robot frame: x in [min, max] ...
    pub reach_x: [f64; 2],
    /// ... and y in [min, max].
    pub reach_y: [f64; 2],
}

/// A stand-up sequence (`StandUp(n)`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StandUpSpec {
    pub name: String,
    pub duration: f64,
}

/// A protective fall (`Fall(n)`): finishes a fall with the joints relaxed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProtectiveFallSpec {
    pub name: String,
    pub duration: f64,
}

/// Which way a dive goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DiveSide {
    Left,
    Right,
    /// A wide sit-down that blocks both sides and ends standing.
    Both,
}

/// A goalkeeper dive (`Dive(n)`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiveSpec {
    pub name: String,
    pub duration: f64,
    pub side: DiveSide,
    /// From this time on, the body blocks the ball up to `reach` m to the side.
    pub block_time: f64,
    pub reach: f64,
}

/// A NAO-like robot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    pub name: String,
    /// Radius of the footprint (collisions, occlusion), m.
    pub radius: f64,
    /// Mass, kg (foot pressure).
    pub mass: f64,
    pub max_speed: SpeedLimits,
    pub acceleration: AccelerationLimits,
    pub walk: WalkConfig,
    pub head: HeadConfig,
    pub camera: CameraConfig,
    pub fall: FallConfig,
    pub kicks: Vec<KickSpec>,
    pub stand_ups: Vec<StandUpSpec>,
    pub protective_falls: Vec<ProtectiveFallSpec>,
    pub dives: Vec<DiveSpec>,
    /// Battery charge is 1 at the start and falls linearly to 0 after this many seconds.
    pub battery_life: f64,
}

impl Default for RobotConfig {
    fn default() -> Self {
        let kick = |name: &str, duration, contact_time, speed, direction| KickSpec {
            name: name.to_owned(),
            duration,
            contact_time,
            speed,
            direction,
            reach_x: [0.05, 0.28],
            reach_y: [-0.15, 0.15],
        };
        RobotConfig {
            name: "simulated NAO".to_owned(),
            radius: 0.13,
            mass: 5.3,
            max_speed: SpeedLimits::default(),
            acceleration: AccelerationLimits::default(),
            walk: WalkConfig::default(),
            head: HeadConfig::default(),
            camera: CameraConfig::default(),
            fall: FallConfig::default(),
            kicks: vec![
                kick("forward", 1.2, 0.6, 3.0, 0.0),
                kick("pass", 1.0, 0.5, 1.5, 0.0),
                kick("side left", 1.2, 0.6, 1.5, std::f64::consts::FRAC_PI_2),
                kick("side right", 1.2, 0.6, 1.5, -std::f64::consts::FRAC_PI_2),
            ],
            stand_ups: vec![
                StandUpSpec { name: "from front".to_owned(), duration: 3.6 },
                StandUpSpec { name: "from back".to_owned(), duration: 4.5 },
            ],
            protective_falls: vec![ProtectiveFallSpec {
                name: "protective".to_owned(),
                duration: 0.6,
            }],
            dives: vec![
                DiveSpec {
                    name: "left".to_owned(),
                    duration: 1.8,
                    side: DiveSide::Left,
                    block_time: 0.35,
                    reach: 0.55,
                },
                DiveSpec {
                    name: "right".to_owned(),
                    duration: 1.8,
                    side: DiveSide::Right,
                    block_time: 0.35,
                    reach: 0.55,
                },
                DiveSpec {
                    name: "block".to_owned(),
                    duration: 3.0,
                    side: DiveSide::Both,
                    block_time: 0.3,
                    reach: 0.35,
                },
            ],
            battery_life: 5400.0,
        }
    }
}

/// The ball (SPL: 10 cm).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BallConfig {
    pub radius: f64,
    /// Rolling resistance: a constant deceleration, m/s^2.
    pub friction: f64,
    /// Velocity-proportional drag, 1/s.
    pub drag: f64,
    /// Fraction of the normal speed kept when bouncing off a goal post or net.
    pub restitution_posts: f64,
    /// ... off a robot.
    pub restitution_robots: f64,
    /// The fastest a ball can move, m/s.
    pub max_speed: f64,
}

impl Default for BallConfig {
    fn default() -> Self {
        BallConfig {
            radius: 0.05,
            friction: 0.5,
            drag: 0.25,
            restitution_posts: 0.5,
            restitution_robots: 0.3,
            max_speed: 8.0,
        }
    }
}

/// One team in the game.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TeamConfig {
    /// The team number, as in GameController packets.
    pub number: u8,
    pub field_player_colour: TeamColour,
    pub goalkeeper_colour: TeamColour,
    /// Player number of the goalkeeper (0: none).
    pub goalkeeper: u8,
}

/// The referee and the GameController it emulates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RefereeConfig {
    /// Runs the game by itself (states, halves, set plays, placements, penalties). When false,
    /// states change only through [`crate::Simulation::set_game_state`]; goals and outs are
    /// still detected and recorded, the score kept, but nothing is moved.
    pub auto: bool,
    pub players_per_team: u8,
    pub teams: [TeamConfig; 2],
    /// Index (0 or 1) of the team taking the first kick-off.
    pub kick_off_team: usize,
    pub half_duration: f64,
    pub initial_duration: f64,
    /// Seconds the automatic referee stays in Standby before signalling Ready (the gesture
    /// robots must see under the current SPL rules). 0: no Standby, Initial goes straight to
    /// Ready. GameController3 has Standby whenever `delay_after_ready` is not 0.
    pub standby_duration: f64,
    pub ready_duration: f64,
    pub set_duration: f64,
    pub half_time_break: f64,
    pub switch_sides_at_half_time: bool,
    /// Moves robots that are not in a legal kick-off position when Set begins (the
    /// referee's manual placement).
    pub auto_placement: bool,
    /// Kick-off formation per player number, in the team's frame (own goal at -x), as
    /// fractions of half the field length and half the field width.
    pub formation: Vec<[f64; 2]>,
    pub penalty_duration: f64,
    /// A set play (kick-in, goal kick, corner kick) ends after this, or when the ball moves.
    pub set_play_duration: f64,
    /// A robot whose centre is this far beyond the outer edge of the field lines has left the
    /// field (penalized while Playing), m.
    pub leaving_field_margin: f64,
    /// Team messages a team may send in a game.
    pub message_budget: u16,
    /// Control packets per second.
    pub packet_rate: f64,
    /// Probability that a robot misses a control packet.
    pub packet_loss: f64,
    /// GameController3 broadcasts a delayed copy of the game, because robots must see the
    /// referee's Ready gesture and hear the kick-off whistle themselves: for this many seconds
    /// after Standby -> Ready the control packets still say Standby. The world acts on the true
    /// state at once. GameController3's champions-cup value is 45 s (as long as the kick-off's
    /// Ready, so robots never receive Ready; [`RefereeConfig::game_controller3`]). 0 (the code's
    /// default): every state is sent at once, as GameController3's `--no-delay` does. Takes
    /// effect only when the game passes through Standby (`standby_duration`, or a state set by
    /// hand).
    pub delay_after_ready: f64,
    /// Seconds after Set -> Playing (the kick-off whistle) during which packets still say Set
    /// (GameController3: 15 s; code default 0, see `delay_after_ready`).
    pub delay_after_playing: f64,
    /// Seconds after a goal during which packets still say Playing with the old score
    /// (GameController3: 15 s; code default 0, see `delay_after_ready`).
    pub delay_after_goal: f64,
    /// The head referee's Ready gesture and whistle, as robots' cameras and microphones
    /// perceive them (`[referee.signals]`).
    pub signals: SignalConfig,
}

/// The signals robots must perceive themselves under the current SPL rules (see
/// [`RefereeConfig::delay_after_ready`]): the head referee's Ready gesture, reported by cameras
/// as an `ObjectKind::Referee` detection with the variant `Gesture::Ready`, and the whistle at
/// the kick-off and at a goal, reported in sensor frames (`SensorFrame::whistle`). The referee
/// stands on the halfway line, `behind_line` outside the side line at negative y of the field
/// frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SignalConfig {
    /// Emulates the signals at all. Off in code (`SimConfig::default()`, GameController3's
    /// `--no-delay`), so that worlds built without a configuration file draw exactly what they
    /// draw without signals; [`RefereeConfig::game_controller3`] and `config/default.toml`
    /// turn them on.
    pub enabled: bool,
    /// How far outside the side line the referee stands, m.
    pub behind_line: f64,
    /// How long the Ready gesture is shown from the moment the true game goes Standby -> Ready
    /// (it ends early when the game leaves Ready), s.
    pub gesture_duration: f64,
    /// How far a camera sees the gesture, m. A person is larger than the ball: the camera's
    /// `range` does not limit it.
    pub gesture_range: f64,
    /// Probability that an image whose view holds the gesturing referee (within the
    /// horizontal field of view and `gesture_range`, not behind a robot, the camera not blind)
    /// reports it.
    pub gesture_detection: f64,
    /// Robots farther than this from the referee do not hear the whistle, m.
    pub whistle_range: f64,
    /// Probability that a robot within `whistle_range` misses a whistle.
    pub whistle_miss: f64,
    /// False whistle detections per robot and minute, at any time (per sensor frame with
    /// probability `whistle_false_rate / 60 * timing.sensor_period`).
    pub whistle_false_rate: f64,
}

impl Default for SignalConfig {
    fn default() -> Self {
        SignalConfig {
            enabled: false,
            behind_line: 0.6,
            gesture_duration: 5.0,
            gesture_range: 10.0,
            gesture_detection: 0.85,
            whistle_range: 12.0,
            whistle_miss: 0.05,
            whistle_false_rate: 0.05,
        }
    }
}

impl Default for RefereeConfig {
    fn default() -> Self {
        RefereeConfig {
            auto: true,
            players_per_team: 7,
            teams: [
                TeamConfig {
                    number: 10,
                    field_player_colour: TeamColour::Blue,
                    goalkeeper_colour: TeamColour::Yellow,
                    goalkeeper: 1,
                },
                TeamConfig {
                    number: 20,
                    field_player_colour: TeamColour::Red,
                    goalkeeper_colour: TeamColour::Black,
                    goalkeeper: 1,
                },
            ],
            kick_off_team: 0,
            half_duration: 600.0,
            initial_duration: 2.0,
            standby_duration: 0.0,
            ready_duration: 45.0,
            set_duration: 5.0,
            half_time_break: 10.0,
            switch_sides_at_half_time: true,
            auto_placement: true,
            formation: vec![
                [-0.95, 0.0],
                [-0.6, 0.3],
                [-0.6, -0.3],
                [-0.35, 0.6],
                [-0.35, -0.6],
                [-0.22, 0.0],
                [-0.2, 0.4],
            ],
            penalty_duration: 45.0,
            set_play_duration: 30.0,
            leaving_field_margin: 0.3,
            message_budget: 1200,
            packet_rate: 2.0,
            packet_loss: 0.0,
            delay_after_ready: 0.0,
            delay_after_playing: 0.0,
            delay_after_goal: 0.0,
            signals: SignalConfig::default(),
        }
    }
}

impl RefereeConfig {
    /// GameController3's default timing (v5.0.0, champions cup): Standby before Ready, packets
    /// held 45 s after the Ready gesture, 15 s after the kick-off whistle and after a goal, and
    /// the referee's signals emulated so that robots can act on them. What `strata match`
    /// plays and `config/default.toml` ships; the code's default is GameController3's
    /// `--no-delay` (every state sent at once, no signals).
    pub fn game_controller3(self) -> RefereeConfig {
        RefereeConfig {
            standby_duration: GC3_STANDBY,
            delay_after_ready: 45.0,
            delay_after_playing: 15.0,
            delay_after_goal: 15.0,
            signals: SignalConfig { enabled: true, ..self.signals },
            ..self
        }
    }

    /// GameController3's `--no-delay`: no Standby, every state sent at once, no signals (the
    /// robots follow the packets alone).
    pub fn no_delay(self) -> RefereeConfig {
        let defaults = RefereeConfig::default();
        RefereeConfig {
            standby_duration: defaults.standby_duration,
            delay_after_ready: defaults.delay_after_ready,
            delay_after_playing: defaults.delay_after_playing,
            delay_after_goal: defaults.delay_after_goal,
            signals: SignalConfig { enabled: false, ..self.signals },
            ..self
        }
    }
}

/// How long the simulated referee waits in Standby before its Ready gesture, s: robots enter,
/// stand and localize first (GameController3's Standby has no timer; the referee decides).
const GC3_STANDBY: f64 = 10.0;

/// Team broadcast emulation: the simulator forwards a robot's team messages to its teammates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BroadcastConfig {
    /// Probability that a message does not reach one teammate (drawn per recipient).
    pub loss: f64,
    /// Delivery delay, s ...
    pub delay: f64,
    /// ... plus a uniform jitter in [0, jitter], s.
    pub jitter: f64,
    /// Larger messages are rejected and counted (SPL: 128 bytes).
    pub max_message_size: usize,
    /// Drops messages of a team whose budget is spent (the GameController only counts them).
    pub enforce_budget: bool,
}

impl Default for BroadcastConfig {
    fn default() -> Self {
        BroadcastConfig {
            loss: 0.0,
            delay: 0.01,
            jitter: 0.01,
            max_message_size: strata_spl::MAX_TEAM_MESSAGE_SIZE,
            enforce_budget: false,
        }
    }
}

impl SimConfig {
    /// The embedded `config/default.toml`.
    pub const DEFAULT_TOML: &'static str = include_str!("../config/default.toml");

    /// Parses TOML; `source_name` (usually the path) prefixes every error.
    pub fn from_toml_str(text: &str, source_name: &str) -> Result<SimConfig, ConfigError> {
        let config: SimConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            source_name: source_name.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        config.validate(source_name)?;
        Ok(config)
    }

    /// Reads, parses and validates a TOML file.
    pub fn load(path: impl AsRef<Path>) -> Result<SimConfig, ConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|source| ConfigError::Io { path: path.to_owned(), source })?;
        let mut config = SimConfig::from_toml_str(&text, &path.display().to_string())?;
        // A field file named relative to the config file is found next to it.
        let field = Path::new(&config.field);
        if !strata_spl::field::PRESETS.contains(&config.field.as_str())
            && field.is_relative()
            && let Some(dir) = path.parent()
        {
            config.field = dir.join(field).display().to_string();
        }
        Ok(config)
    }

    /// The resolved noise levels.
    pub fn noise_params(&self) -> NoiseParams {
        self.noise.resolve()
    }

    /// This config without any noise or random error (tests).
    pub fn without_noise(mut self) -> SimConfig {
        self.noise = NoiseConfig::level(crate::noise::NoiseLevel::None);
        self.broadcast.loss = 0.0;
        self.broadcast.jitter = 0.0;
        self.referee.packet_loss = 0.0;
        self
    }

    /// Checks every value; the error names the key.
    pub fn validate(&self, source_name: &str) -> Result<(), ConfigError> {
        let v = Validator { source_name };
        self.validate_timing(&v)?;
        self.validate_robot(&v)?;
        self.validate_ball(&v)?;
        self.validate_noise(&v)?;
        self.validate_referee(&v)?;
        self.validate_broadcast(&v)?;
        Ok(())
    }

    /// The periods of the simulation loop.
    fn validate_timing(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        let t = &self.timing;
        v.positive("timing.sensor_period", t.sensor_period)?;
        v.positive("timing.camera_period", t.camera_period)?;
        v.positive("timing.max_substep", t.max_substep)?;
        v.positive("timing.ground_truth_period", t.ground_truth_period)?;
        Ok(())
    }

    /// The robot's body, camera and motion catalogue.
    fn validate_robot(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        let r = &self.robot;
        v.positive("robot.radius", r.radius)?;
        v.positive("robot.mass", r.mass)?;
        v.positive("robot.battery_life", r.battery_life)?;
        for (name, value) in [
            ("robot.max_speed.forward", r.max_speed.forward),
            ("robot.max_speed.backward", r.max_speed.backward),
            ("robot.max_speed.sideways", r.max_speed.sideways),
            ("robot.max_speed.turn", r.max_speed.turn),
            ("robot.walk.init_duration", r.walk.init_duration),
            ("robot.walk.end_duration", r.walk.end_duration),
            ("robot.walk.sway_roll", r.walk.sway_roll),
            ("robot.walk.sway_pitch", r.walk.sway_pitch),
            ("robot.fall.impact_accel", r.fall.impact_accel),
        ] {
            v.non_negative(name, value)?;
        }
        v.positive("robot.acceleration.linear", r.acceleration.linear)?;
        v.positive("robot.acceleration.turn", r.acceleration.turn)?;
        v.positive("robot.walk.step_period", r.walk.step_period)?;
        v.positive("robot.head.max_speed", r.head.max_speed)?;
        v.interval("robot.head.yaw_limits", r.head.yaw_limits)?;
        v.interval("robot.head.pitch_limits", r.head.pitch_limits)?;
        let c = &r.camera;
        v.range("robot.camera.fov", c.fov, 1e-3, 3.0)?;
        v.positive("robot.camera.range", c.range)?;
        v.positive("robot.camera.height", c.height)?;
        v.interval(
            "robot.camera.[min_depression, max_depression]",
            [c.min_depression, c.max_depression],
        )?;
        v.non_negative("robot.camera.min_line_length", c.min_line_length)?;
        v.positive("robot.fall.duration", r.fall.duration)?;
        v.range("robot.fall.lying_tilt", r.fall.lying_tilt, 0.5, std::f64::consts::FRAC_PI_2)?;
        v.positive("robot.fall.push_fall_speed", r.fall.push_fall_speed)?;
        v.positive("robot.fall.push_decay", r.fall.push_decay)?;
        for (i, kick) in r.kicks.iter().enumerate() {
            let at = |name: &str| format!("robot.kicks[{i}].{name}");
            v.positive(&at("duration"), kick.duration)?;
            v.range(&at("contact_time"), kick.contact_time, 0.0, kick.duration)?;
            v.non_negative(&at("speed"), kick.speed)?;
            v.finite(&at("direction"), kick.direction)?;
            v.interval(&at("reach_x"), kick.reach_x)?;
            v.interval(&at("reach_y"), kick.reach_y)?;
        }
        for (i, s) in r.stand_ups.iter().enumerate() {
            v.positive(&format!("robot.stand_ups[{i}].duration"), s.duration)?;
        }
        for (i, s) in r.protective_falls.iter().enumerate() {
            v.positive(&format!("robot.protective_falls[{i}].duration"), s.duration)?;
        }
        for (i, d) in r.dives.iter().enumerate() {
            v.positive(&format!("robot.dives[{i}].duration"), d.duration)?;
            v.range(&format!("robot.dives[{i}].block_time"), d.block_time, 0.0, d.duration)?;
            v.non_negative(&format!("robot.dives[{i}].reach"), d.reach)?;
        }
        let catalogue_len = [r.kicks.len(), r.stand_ups.len(), r.protective_falls.len()];
        if catalogue_len.iter().chain([&r.dives.len()]).any(|&n| n > 256) {
            return Err(v.invalid("robot motions", "at most 256 of each kind", "more"));
        }
        Ok(())
    }

    /// The ball's physics.
    fn validate_ball(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        let b = &self.ball;
        v.positive("ball.radius", b.radius)?;
        v.non_negative("ball.friction", b.friction)?;
        v.non_negative("ball.drag", b.drag)?;
        v.range("ball.restitution_posts", b.restitution_posts, 0.0, 1.0)?;
        v.range("ball.restitution_robots", b.restitution_robots, 0.0, 1.0)?;
        v.positive("ball.max_speed", b.max_speed)?;
        Ok(())
    }

    /// The noise parameters, as resolved.
    fn validate_noise(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        let noise = self.noise.resolve();
        for (name, value) in noise.values() {
            let key = format!("noise.{name}");
            if name.starts_with("odometry.scale") {
                v.range(&key, value, -0.9, 10.0)?;
            } else if name.starts_with("camera.detection")
                || name == "camera.landmark_factor"
                || name == "camera.false_positive_rate"
                || name.ends_with("probability")
                || name == "falls.stand_up_failure"
            {
                v.range(&key, value, 0.0, 1.0)?;
            } else {
                v.non_negative(&key, value)?;
            }
        }
        Ok(())
    }

    /// The referee: teams, players, durations, formation, packets.
    fn validate_referee(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        let f = &self.referee;
        if f.players_per_team == 0
            || usize::from(f.players_per_team) > strata_spl::gamecontroller::MAX_NUM_PLAYERS
        {
            return Err(v.invalid(
                "referee.players_per_team",
                "between 1 and 20",
                &f.players_per_team.to_string(),
            ));
        }
        if f.teams[0].number == f.teams[1].number {
            return Err(v.invalid(
                "referee.teams",
                "two different team numbers",
                &f.teams[0].number.to_string(),
            ));
        }
        for (i, team) in f.teams.iter().enumerate() {
            if team.number == strata_spl::gamecontroller::KICKING_TEAM_NONE {
                return Err(v.invalid(
                    &format!("referee.teams[{i}].number"),
                    "below 255",
                    &team.number.to_string(),
                ));
            }
            if team.goalkeeper > f.players_per_team {
                return Err(v.invalid(
                    &format!("referee.teams[{i}].goalkeeper"),
                    "0 or a player number of the team",
                    &team.goalkeeper.to_string(),
                ));
            }
        }
        if f.kick_off_team > 1 {
            return Err(v.invalid("referee.kick_off_team", "0 or 1", &f.kick_off_team.to_string()));
        }
        v.positive("referee.half_duration", f.half_duration)?;
        for (name, value) in [
            ("referee.initial_duration", f.initial_duration),
            ("referee.standby_duration", f.standby_duration),
            ("referee.ready_duration", f.ready_duration),
            ("referee.set_duration", f.set_duration),
            ("referee.half_time_break", f.half_time_break),
            ("referee.penalty_duration", f.penalty_duration),
            ("referee.set_play_duration", f.set_play_duration),
            ("referee.leaving_field_margin", f.leaving_field_margin),
            ("referee.delay_after_ready", f.delay_after_ready),
            ("referee.delay_after_playing", f.delay_after_playing),
            ("referee.delay_after_goal", f.delay_after_goal),
        ] {
            v.non_negative(name, value)?;
        }
        if f.half_duration > f64::from(i16::MAX) {
            return Err(v.invalid(
                "referee.half_duration",
                "at most 32767 s (the packet's clock is an i16)",
                &f.half_duration.to_string(),
            ));
        }
        for (i, [x, y]) in f.formation.iter().enumerate() {
            v.range(&format!("referee.formation[{i}][0]"), *x, -1.0, 0.0)?;
            v.range(&format!("referee.formation[{i}][1]"), *y, -1.0, 1.0)?;
        }
        v.positive("referee.packet_rate", f.packet_rate)?;
        v.range("referee.packet_loss", f.packet_loss, 0.0, 1.0)?;
        let s = &f.signals;
        for (name, value) in [
            ("referee.signals.behind_line", s.behind_line),
            ("referee.signals.gesture_duration", s.gesture_duration),
            ("referee.signals.gesture_range", s.gesture_range),
            ("referee.signals.whistle_range", s.whistle_range),
            ("referee.signals.whistle_false_rate", s.whistle_false_rate),
        ] {
            v.non_negative(name, value)?;
        }
        v.range("referee.signals.gesture_detection", s.gesture_detection, 0.0, 1.0)?;
        v.range("referee.signals.whistle_miss", s.whistle_miss, 0.0, 1.0)?;
        Ok(())
    }

    /// The team-message broadcast.
    fn validate_broadcast(&self, v: &Validator<'_>) -> Result<(), ConfigError> {
        let c = &self.broadcast;
        v.range("broadcast.loss", c.loss, 0.0, 1.0)?;
        v.non_negative("broadcast.delay", c.delay)?;
        v.non_negative("broadcast.jitter", c.jitter)?;
        if c.max_message_size == 0 {
            return Err(v.invalid("broadcast.max_message_size", "positive", "0"));
        }
        Ok(())
    }
}

struct Validator<'a> {
    source_name: &'a str,
}

impl Validator<'_> {
    fn invalid(&self, field: &str, requirement: &str, value: &str) -> ConfigError {
        ConfigError::Invalid {
            source_name: self.source_name.to_owned(),
            field: field.to_owned(),
            requirement: requirement.to_owned(),
            value: value.to_owned(),
        }
    }

    fn finite(&self, field: &str, value: f64) -> Result<(), ConfigError> {
        if value.is_finite() {
            Ok(())
        } else {
            Err(self.invalid(field, "a finite number", &value.to_string()))
        }
    }

    fn positive(&self, field: &str, value: f64) -> Result<(), ConfigError> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(self.invalid(field, "a positive number", &value.to_string()))
        }
    }

    fn non_negative(&self, field: &str, value: f64) -> Result<(), ConfigError> {
        if value.is_finite() && value >= 0.0 {
            Ok(())
        } else {
            Err(self.invalid(field, "zero or positive", &value.to_string()))
        }
    }

    fn range(&self, field: &str, value: f64, min: f64, max: f64) -> Result<(), ConfigError> {
        if value.is_finite() && (min..=max).contains(&value) {
            Ok(())
        } else {
            Err(self.invalid(field, &format!("between {min} and {max}"), &value.to_string()))
        }
    }

    fn interval(&self, field: &str, [min, max]: [f64; 2]) -> Result<(), ConfigError> {
        if min.is_finite() && max.is_finite() && min <= max {
            Ok(())
        } else {
            Err(self.invalid(field, "[min, max] with min <= max", &format!("[{min}, {max}]")))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_default_file_is_the_default_config() {
        let parsed = SimConfig::from_toml_str(SimConfig::DEFAULT_TOML, "config/default.toml")
            .expect("the default config parses");
        // The one difference: the file has GameController3's timing and the referee's signals,
        // the code GameController3's `--no-delay`.
        let mut expected = SimConfig::default();
        expected.referee = expected.referee.game_controller3();
        assert_eq!(parsed, expected);
    }

    #[test]
    fn bad_signal_values_name_their_key() {
        for (key, value) in [
            ("behind_line", "-0.1"),
            ("gesture_duration", "nan"),
            ("gesture_range", "-1.0"),
            ("gesture_detection", "1.5"),
            ("whistle_range", "inf"),
            ("whistle_miss", "-0.01"),
            ("whistle_false_rate", "-1.0"),
        ] {
            let text = format!("[referee.signals]\n{key} = {value}\n");
            let error = SimConfig::from_toml_str(&text, "x.toml").expect_err(&text);
            assert!(error.to_string().contains(&format!("`referee.signals.{key}`")), "{error}");
        }
        let error = SimConfig::from_toml_str("[referee.signals]\nwhistle = 1.0\n", "x.toml")
            .expect_err("unknown key");
        assert!(error.to_string().contains("whistle"), "{error}");
        let config = SimConfig::from_toml_str("[referee.signals]\nenabled = true\n", "x.toml")
            .expect("valid");
        assert!(config.referee.signals.enabled);
        assert_eq!(config.referee.signals.whistle_range, 12.0);
    }

    #[test]
    fn a_config_file_may_name_a_field_file_next_to_it() {
        let dir = std::env::temp_dir().join(format!("strata-sim-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a temporary directory");
        let path = dir.join("game.toml");
        std::fs::write(&path, "seed = 7\nfield = \"my-field.toml\"\n[referee]\nauto = false\n")
            .expect("writable");
        let config = SimConfig::load(&path).expect("valid");
        assert_eq!(config.seed, 7);
        assert!(!config.referee.auto);
        assert_eq!(Path::new(&config.field), dir.join("my-field.toml"));
        let _ = std::fs::remove_dir_all(&dir);
        let missing = SimConfig::load(dir.join("absent.toml")).expect_err("no such file");
        assert!(missing.to_string().contains("absent.toml"), "{missing}");
    }

    #[test]
    fn errors_name_the_file_and_the_field() {
        let error = SimConfig::from_toml_str("[robot]\nradiuss = 1.0\n", "my.toml")
            .expect_err("unknown key");
        let text = error.to_string();
        assert!(text.starts_with("my.toml"), "{text}");
        assert!(text.contains("radiuss"), "{text}");
        let error = SimConfig::from_toml_str("[ball]\nfriction = -1.0\n", "my.toml")
            .expect_err("negative friction");
        assert!(error.to_string().contains("ball.friction"), "{error}");
        let error = SimConfig::from_toml_str("[noise.camera]\ndetection_far = 2.0\n", "x.toml")
            .expect_err("probability above 1");
        assert!(error.to_string().contains("noise.camera.detection_far"), "{error}");
    }
}
