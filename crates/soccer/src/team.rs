//! A team of soccer robots: its configuration (which behavior variants it plays with) and the
//! function that adds one of its robots to a module graph over any platform.

use std::f64::consts::FRAC_PI_2;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_robot::actuation::ActuationConfig;
use strata_robot::application::Application;
use strata_robot::assembly::{RobotModules, RobotParts, RobotTiming, add_robot};
use strata_robot::command::ResourceGroup;
use strata_robot::control::active_vision::ActiveVisionConfig;
use strata_robot::control::planning::{Planner, PlanningConfig};
use strata_robot::control::reactive::{
    FallDetectorConfig, Multiplexer, MultiplexerConfig, ReactiveLayer,
};
use strata_robot::control::scores::{GoalScore, ScoreVector};
use strata_robot::edge::{RobotLinks, RobotPlatform};
use strata_robot::perception::PerceptionConfig;
use strata_robot::platform::{ObjectClass, PlatformInfo};
use strata_robot::world::{
    CameraNoise, PoseFeed, PosePrior, SymmetryHint, WorldModelConfig, WorldState,
};
use strata_runtime::GraphBuilder;
use strata_spl::ObjectKind;

use crate::activation::{BodyActivation, HeadActivation, WholeBodyActivation};
use crate::behaviors::{BehaviorConfig, SoccerBehavior};
use crate::field::TeamField;
use crate::game::{GameControllerReferee, SignalConfig};
use crate::gaze_override::GazeOverride;
use crate::goals::{BodyGoal, HeadGoal, WholeBodyGoal};
use crate::planning::{SoccerCodec, SoccerPlanning, SoccerPlanningConfig};
use crate::primitives::{
    AvoidCollision, Dive, Dribbling, Fall, GoToBall, GoToPosition, KickBall, LookAtTarget,
    MotionModel, ObjectTracking, SearchObjectEllipse, Stand, StandUp,
};
use crate::world_config::{BALL, OBSTACLE, world_config};

/// Everything that makes one team play the way it does. Loaded from TOML; every field has a
/// default, so a file only states what differs from the full architecture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TeamConfig {
    pub name: String,
    /// Team coordination through the planning layer. Off: no team messages, every field
    /// player attacks as striker (the no-coordination baseline).
    pub coordination: bool,
    pub behavior: BehaviorConfig,
    pub multiplexer: MultiplexerConfig,
    pub fall_detector: FallDetectorConfig,
    pub perception: PerceptionConfig,
    /// The robots' camera model: the noise perception attaches to each observation and world
    /// modeling predicts for active vision.
    pub camera: CameraNoise,
    pub actuation: ActuationConfig,
    pub motion: MotionModel,
    pub planning: PlanningConfig,
    pub soccer_planning: SoccerPlanningConfig,
    /// Following the referee's whistle and Ready gesture ahead of the GameController.
    pub signals: SignalConfig,
    pub timing: RobotTiming,
    /// Extra computation per deliberative tick, s (the rates experiment's load).
    pub deliberative_load: f64,
    pub localization: LocalizationConfig,
}

/// What the robots localize with (docs/world-model.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizationConfig {
    /// What the pose filter is corrected with from the landmark filters.
    pub feed: PoseFeed,
    /// The painted field lines as observations of the pose.
    pub field_lines: bool,
}

impl Default for LocalizationConfig {
    fn default() -> Self {
        LocalizationConfig { feed: PoseFeed::Gained, field_lines: true }
    }
}

impl Default for TeamConfig {
    fn default() -> Self {
        TeamConfig {
            name: "strata".into(),
            coordination: true,
            behavior: BehaviorConfig::default(),
            multiplexer: MultiplexerConfig::default(),
            fall_detector: FallDetectorConfig::default(),
            perception: PerceptionConfig::default(),
            camera: CameraNoise::default(),
            actuation: ActuationConfig::default(),
            motion: MotionModel::default(),
            planning: PlanningConfig::default(),
            soccer_planning: SoccerPlanningConfig::default(),
            signals: SignalConfig::default(),
            timing: RobotTiming::default(),
            deliberative_load: 0.0,
            localization: LocalizationConfig::default(),
        }
    }
}

/// A team configuration that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum TeamConfigError {
    #[error("cannot read team configuration {path}: {error}")]
    Read { path: String, error: std::io::Error },
    #[error("{source_name}: {error}")]
    Parse { source_name: String, error: String },
    #[error("{source_name}: `{field}` {problem}")]
    Invalid { source_name: String, field: String, problem: String },
    #[error(
        "no built-in team `{0}` (try: full, no-coordination, no-active-vision, always-ball, fixed-scan, entropy, task-value)"
    )]
    UnknownPreset(String),
}

const PRESETS: [(&str, &str); 7] = [
    ("full", include_str!("../teams/full.toml")),
    ("no-coordination", include_str!("../teams/no-coordination.toml")),
    ("no-active-vision", include_str!("../teams/no-active-vision.toml")),
    ("always-ball", include_str!("../teams/always-ball.toml")),
    ("fixed-scan", include_str!("../teams/fixed-scan.toml")),
    ("entropy", include_str!("../teams/entropy.toml")),
    ("task-value", include_str!("../teams/task-value.toml")),
];

impl TeamConfig {
    pub fn preset_names() -> impl Iterator<Item = &'static str> {
        PRESETS.iter().map(|(n, _)| *n)
    }

    pub fn preset(name: &str) -> Result<TeamConfig, TeamConfigError> {
        let (_, text) = PRESETS
            .iter()
            .find(|(n, _)| *n == name)
            .ok_or_else(|| TeamConfigError::UnknownPreset(name.to_owned()))?;
        TeamConfig::from_toml_str(text, &format!("built-in team `{name}`"))
    }

    /// A preset name or a path to a TOML file. What is neither a file nor a preset is read
    /// as a file when it looks like one (an extension or a directory in it), so a mistyped
    /// path is reported as a file that cannot be read, not as an unknown preset.
    pub fn resolve(name_or_path: &str) -> Result<TeamConfig, TeamConfigError> {
        let path = Path::new(name_or_path);
        let is_preset = PRESETS.iter().any(|(name, _)| *name == name_or_path);
        let looks_like_path = path.extension().is_some() || path.components().count() > 1;
        if path.exists() || (looks_like_path && !is_preset) {
            TeamConfig::load(name_or_path)
        } else {
            TeamConfig::preset(name_or_path)
        }
    }

    pub fn load(path: impl AsRef<Path>) -> Result<TeamConfig, TeamConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|error| TeamConfigError::Read { path: path.display().to_string(), error })?;
        TeamConfig::from_toml_str(&text, &path.display().to_string())
    }

    pub fn from_toml_str(text: &str, source_name: &str) -> Result<TeamConfig, TeamConfigError> {
        let config: TeamConfig = toml::from_str(text).map_err(|e| TeamConfigError::Parse {
            source_name: source_name.to_owned(),
            error: e.to_string(),
        })?;
        config.validate(source_name)?;
        Ok(config)
    }

    pub fn validate(&self, source_name: &str) -> Result<(), TeamConfigError> {
        let invalid = |field: &str, problem: String| TeamConfigError::Invalid {
            source_name: source_name.to_owned(),
            field: field.to_owned(),
            problem,
        };
        let positive = |field: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(field, format!("must be > 0, got {v}")))
            }
        };
        for (name, timing) in [
            ("timing.perception", &self.timing.perception),
            ("timing.deliberative", &self.timing.deliberative),
            ("timing.planning", &self.timing.planning),
        ] {
            if let Some(hz) = timing.rate_hz {
                positive(&format!("{name}.rate_hz"), hz)?;
            }
        }
        positive("motion.max_forward", self.motion.max_forward)?;
        positive("motion.approach_speed", self.motion.approach_speed)?;
        let gain = self.motion.approach_speed_gain;
        if !(gain.is_finite() && gain >= 0.0) {
            return Err(invalid("motion.approach_speed_gain", format!("must be >= 0, got {gain}")));
        }
        let behind = self.motion.dribble_behind;
        if !(behind.is_finite() && behind >= 0.0) {
            return Err(invalid(
                "motion.dribble_behind",
                format!("must be >= 0 (0: no line-up), got {behind}"),
            ));
        }
        let [period, glance] = self.motion.dribble_glance;
        if !(period.is_finite() && glance.is_finite() && glance >= 0.0 && glance <= period) {
            return Err(invalid(
                "motion.dribble_glance",
                format!(
                    "must be [period, glance] with 0 <= glance <= period, got [{period}, {glance}]"
                ),
            ));
        }
        let dodge = self.motion.dribble_dodge;
        if !(dodge.is_finite() && (0.0..FRAC_PI_2).contains(&dodge)) {
            return Err(invalid(
                "motion.dribble_dodge",
                format!("must be >= 0 and below pi/2 rad (0: no dodge), got {dodge}"),
            ));
        }
        let dribble = self.behavior.dribble_distance;
        if !(dribble.is_finite() && dribble >= 0.0) {
            return Err(invalid(
                "behavior.dribble_distance",
                format!("must be >= 0, got {dribble}"),
            ));
        }
        positive("camera.range_sigma", self.camera.range_sigma)?;
        positive("camera.bearing_sigma", self.camera.bearing_sigma)?;
        let per_metre = self.camera.range_sigma_per_metre;
        if !(per_metre.is_finite() && per_metre >= 0.0) {
            return Err(invalid(
                "camera.range_sigma_per_metre",
                format!("must be >= 0, got {per_metre}"),
            ));
        }
        positive("motion.head_speed", self.motion.head_speed)?;
        positive("motion.camera_height", self.motion.camera_height)?;
        let [up, down] = self.motion.head_pitch_limits;
        if !(up.is_finite() && down.is_finite() && up <= down) {
            return Err(invalid(
                "motion.head_pitch_limits",
                format!("must be [up, down] with up <= down, got [{up}, {down}]"),
            ));
        }
        positive("planning.message_interval", self.planning.message_interval)?;
        positive("behavior.fov", self.behavior.fov)?;
        let distance = self.behavior.set_play_distance;
        if !(distance.is_finite() && distance >= 0.0) {
            return Err(invalid(
                "behavior.set_play_distance",
                format!("must be >= 0 (0: no rule), got {distance}"),
            ));
        }
        let let_go = self.behavior.let_go_distance;
        if !(let_go.is_finite() && let_go >= 0.0) {
            return Err(invalid("behavior.let_go_distance", format!("must be >= 0, got {let_go}")));
        }
        let fov = self.motion.vertical_fov;
        if !(fov.is_finite() && (0.0..std::f64::consts::PI).contains(&fov)) {
            return Err(invalid(
                "motion.vertical_fov",
                format!("must be in [0, pi) rad (0: not modelled), got {fov}"),
            ));
        }
        if !(0.0..=1.0).contains(&self.multiplexer.hysteresis) {
            return Err(invalid(
                "multiplexer.hysteresis",
                format!("must be in [0, 1], got {}", self.multiplexer.hysteresis),
            ));
        }
        if !(self.deliberative_load.is_finite() && self.deliberative_load >= 0.0) {
            return Err(invalid(
                "deliberative_load",
                format!("must be >= 0, got {}", self.deliberative_load),
            ));
        }
        if let Some((field, problem)) = self.signals.invalid() {
            return Err(invalid(field, problem));
        }
        Ok(())
    }
}

/// What a soccer robot needs from its surroundings.
pub struct SoccerRobotSpec {
    /// Prefix of the robot's module names.
    pub name: String,
    pub team_number: u8,
    pub player: u8,
    pub field: Arc<TeamField>,
    pub platform: RobotPlatform,
    /// The team link and the GameController's.
    pub links: RobotLinks,
    pub half_duration: f64,
    /// Where the robot knows it starts (a platform that places it), in the team frame; `None`:
    /// the pose is lost until landmarks fix it.
    pub initial_pose: Option<PosePrior>,
    /// Where the platform's referee may put the robot without telling it, in the team frame
    /// (rcssservermj's penalty spots); empty where the referee says so (a GameController).
    pub relocations: Vec<PosePrior>,
}

impl std::fmt::Debug for SoccerRobotSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SoccerRobotSpec")
            .field("name", &self.name)
            .field("player", &self.player)
            .finish_non_exhaustive()
    }
}

/// How far (m, m, rad) a robot whose landmarks disagree with its pose may be from it, on a
/// platform that reports every move it sees.
const DISAGREEMENT_PRIOR: [f64; 3] = [2.0, 2.0, 1.0];

/// A torso tilted beyond this has fallen (rad): a walking T1 leans by a few tenths at most.
const FALL_TILT: f64 = 1.0;

/// The world model of a team's robots: the field's, with the team's camera model.
pub fn team_world_config(team: &TeamConfig, field: &TeamField) -> WorldModelConfig {
    let mut config = WorldModelConfig { camera: team.camera, ..world_config(field) };
    config.pose.feed = team.localization.feed;
    if !team.localization.field_lines {
        config.lines.class = None;
    }
    config
}

/// The world model's configuration for one robot of `team`: the team's, with where it starts
/// if known and where it may be put without being told.
pub fn robot_world_config(
    team: &TeamConfig,
    field: &TeamField,
    initial_pose: Option<PosePrior>,
    relocations: &[PosePrior],
) -> WorldModelConfig {
    let mut config = team_world_config(team, field);
    config.pose.initial = initial_pose;
    if !relocations.is_empty() {
        // The platform reports the moves it sees (`Percepts::placed`); a single landmark's
        // disagreement is not enough to declare one (`pose.kidnap_from_one_landmark` stays
        // off): with it, a T1 walking in midfield once declared itself kidnapped and stayed
        // lost for half a minute.
        config.pose.hints.push(SymmetryHint::Relocations { poses: relocations.to_vec() });
        // So landmarks that disagree mean the estimate went wrong, mostly through a fall: the
        // robot is within a few metres of it and faces within a radian or so. Without this a
        // fallen T1 could come up on its mirror image (two robot-halves of one game at 9.8 and
        // 16.9 m of mean error).
        config.pose.disagreement_prior = Some(DISAGREEMENT_PRIOR);
        // Better still, a fall is noticed as it happens: standing up, the pose and the tracks
        // grow uncertain and the next landmarks correct them. Without it a T1 keeper that fell
        // in its goal stood up 1-2 m from where it believed, its pose too sure to take the
        // landmarks that said so, and walked out of its goal for 20 s.
        config.pose.fall_tilt = Some(FALL_TILT);
        if initial_pose.is_some() {
            // A robot that starts from its pose needs no hint that it enters the field in its
            // own half, and in play the hint is wrong half the time: a T1 that fell in the
            // opponent half recovered the mirror image of its pose, in its own half, and its
            // team dribbled toward their own goal for two minutes.
            config.pose.hints.retain(|h| !matches!(h, SymmetryHint::Region { .. }));
        }
    }
    config
}

/// Soccer's reactive layer: the three multiplexers of Table 4 with their primitive behaviors,
/// the fall and stand-up reflexes, and the fall detector.
pub fn reactive_layer(
    config: &TeamConfig,
    info: &PlatformInfo,
    field: &Arc<TeamField>,
) -> SoccerReactiveLayer {
    let model = Arc::new(config.motion.clone());
    let mux = config.multiplexer.clone();
    let head = Multiplexer::with_shortcuts(
        ResourceGroup::Head,
        mux.clone(),
        Box::new(HeadActivation { fov: info.camera_fov }),
    )
    .with_primitive(Box::new(SearchObjectEllipse::new(Arc::clone(&model))))
    .with_primitive(Box::new(ObjectTracking::new(Arc::clone(&model))))
    .with_primitive(Box::new(LookAtTarget::new(Arc::clone(&model), Arc::clone(field))));
    let body = Multiplexer::with_shortcuts(
        ResourceGroup::Body,
        mux.clone(),
        Box::new(BodyActivation { model: Arc::clone(&model) }),
    )
    .with_primitive(Box::new(GoToPosition::new(Arc::clone(&model))))
    .with_primitive(Box::new(GoToBall::new(Arc::clone(&model))))
    .with_primitive(Box::new(KickBall))
    .with_primitive(Box::new(AvoidCollision::new(Arc::clone(&model))))
    .with_primitive(Box::new(Stand::default()));
    // The fall and stand-up reflexes are always offered: they must not wait for the slow
    // deliberative layer (the paper's 51 ms fall detection).
    let reflexes = ScoreVector::default()
        .with(GoalScore::new(WholeBodyGoal::Fall { sequence: 0 }, 1.0))
        .with(GoalScore::new(WholeBodyGoal::StandUp { sequence: 0 }, 1.0));
    let whole = Multiplexer::with_shortcuts(
        ResourceGroup::HeadAndBody,
        mux,
        Box::new(WholeBodyActivation {
            dive_horizon: 1.0,
            dive_reach: 0.8,
            field: Arc::clone(field),
        }),
    )
    .with_primitive(Box::new(Dribbling::new(Arc::clone(&model))))
    .with_primitive(Box::new(StandUp))
    .with_primitive(Box::new(Fall))
    .with_primitive(Box::new(Dive))
    .with_reflexes(reflexes);
    ReactiveLayer::new(head, body, whole, config.fall_detector.clone())
}

/// The reactive layer type of a soccer robot.
pub type SoccerReactiveLayer = ReactiveLayer<HeadGoal, BodyGoal, WholeBodyGoal, WorldState>;

/// The perception of a soccer robot: the team's, with the referee as a signal (its gesture),
/// not an object world modeling tracks.
pub fn perception_config(config: &TeamConfig) -> PerceptionConfig {
    let mut perception = config.perception.clone();
    let referee_class = ObjectClass(ObjectKind::Referee.code());
    if !perception.signal_classes.contains(&referee_class) {
        perception.signal_classes.push(referee_class);
    }
    perception
}

/// The deliberative behaviors of player `player`, with active vision fitted to the platform's
/// camera.
pub fn deliberative_behavior(
    config: &TeamConfig,
    info: &PlatformInfo,
    field: &Arc<TeamField>,
    player: u8,
) -> Result<SoccerBehavior, String> {
    let vision = ActiveVisionConfig {
        fov: info.camera_fov,
        range: info.camera_range,
        yaw_limits: info.head_yaw_limits,
        ..ActiveVisionConfig::default()
    };
    SoccerBehavior::new(
        player,
        Arc::clone(field),
        config.behavior.clone(),
        vision,
        Arc::new(config.motion.clone()),
    )
    // A load the configuration check would refuse (a config read back from a log is not
    // checked again) is no load.
    .map(|b| b.with_load(Duration::try_from_secs_f64(config.deliberative_load).unwrap_or_default()))
}

/// The planner and the GameController's side of player `player` of team `team_number`.
pub fn planning_parts(
    config: &TeamConfig,
    field: &TeamField,
    player: u8,
    team_number: u8,
    half_duration: f64,
) -> (Planner<SoccerPlanning>, GameControllerReferee) {
    let planner = Planner::new(
        SoccerPlanning::new(field.clone(), config.soccer_planning.clone()),
        config.planning.clone(),
    );
    let referee = GameControllerReferee::new(
        team_number,
        player,
        field.clone(),
        half_duration,
        config.signals.clone(),
    );
    (planner, referee)
}

/// The world-model objects a soccer robot shares with its teammates, most important first.
pub fn shared_objects() -> Vec<String> {
    vec![BALL.to_owned(), OBSTACLE.to_owned()]
}

/// Robot soccer as an application of the architecture: Tables 1-4 of the paper.
#[derive(Clone, Copy, Debug)]
pub struct Soccer;

impl Application for Soccer {
    type Planning = SoccerPlanning;
    type Device = GameControllerReferee;
    type Codec = SoccerCodec;
    type Deliberative = SoccerBehavior;
}

/// Adds one soccer robot (all four modules, all three layers) to `graph`.
pub fn add_soccer_robot(
    graph: &mut GraphBuilder,
    spec: SoccerRobotSpec,
    config: &TeamConfig,
) -> Result<RobotModules, String> {
    add_soccer_robot_with_gaze(graph, spec, config, None)
}

/// [`add_soccer_robot`], the head's goal chosen through `gaze` when given (a learning
/// environment's actions; `crate::gaze_override`).
pub fn add_soccer_robot_with_gaze(
    graph: &mut GraphBuilder,
    spec: SoccerRobotSpec,
    config: &TeamConfig,
    gaze: Option<Arc<GazeOverride>>,
) -> Result<RobotModules, String> {
    let info = spec.platform.info();
    let field = Arc::clone(&spec.field);
    let reactive = reactive_layer(config, &info, &field);
    let mut deliberative = deliberative_behavior(config, &info, &field, spec.player)?;
    if let Some(gaze) = gaze {
        deliberative = deliberative.with_gaze_override(gaze);
    }
    let (planner, referee) =
        planning_parts(config, &field, spec.player, spec.team_number, spec.half_duration);
    let parts = RobotParts::<Soccer> {
        name: spec.name,
        member: spec.player,
        platform: spec.platform,
        perception: perception_config(config),
        world: robot_world_config(config, &field, spec.initial_pose, &spec.relocations),
        reactive,
        deliberative,
        planner,
        codec: SoccerCodec,
        device: referee,
        links: if config.coordination { spec.links } else { spec.links.without_team() },
        shared_objects: shared_objects(),
        actuation: config.actuation.clone(),
        timing: config.timing.clone(),
    };
    add_robot(graph, parts).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_placed_by_a_platform_that_reports_moves_drops_the_own_half_hint() {
        use strata_robot::geometry::Pose;
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let team = TeamConfig::default();
        let region = |c: &WorldModelConfig| {
            c.pose.hints.iter().any(|h| matches!(h, SymmetryHint::Region { .. }))
        };
        let start = PosePrior { pose: Pose::new(-2.0, 0.0, 0.0), sigma: [0.1, 0.1, 0.05] };
        let spot = PosePrior { pose: Pose::new(-1.0, -3.5, FRAC_PI_2), sigma: [0.3, 0.3, 0.4] };
        // The built-in simulator's robots: entering in their own half breaks the symmetry.
        let sim = robot_world_config(&team, &field, Some(start), &[]);
        assert!(region(&sim) && sim.pose.disagreement_prior.is_none());
        // A T1 in rcssservermj: beamed to its pose, its moves reported or at known spots.
        let t1 = robot_world_config(&team, &field, Some(start), &[spot]);
        assert!(!region(&t1) && t1.pose.disagreement_prior.is_some());
        assert!(t1.pose.hints.iter().any(|h| matches!(h, SymmetryHint::Relocations { .. })));
        // Not told where it starts: it still enters in its own half.
        assert!(region(&robot_world_config(&team, &field, None, &[spot])));
    }

    /// Every primitive an activation policy can name is registered with its multiplexer, on
    /// every preset: one left out would make the goals only it pursues inapplicable, silently.
    #[test]
    fn the_reactive_layer_registers_every_primitive() {
        let field =
            Arc::new(TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0));
        let info = PlatformInfo {
            name: "test".into(),
            sensor_period: Duration::from_millis(12),
            camera_fov: 1.06,
            camera_range: 6.0,
            head_yaw_limits: (-2.0, 2.0),
            head_pitch_limits: (-0.6, 0.5),
            max_head_speed: 4.0,
            max_velocity: strata_robot::geometry::Velocity::new(0.25, 0.15, 1.2),
            motions: Vec::new(),
            can_walk: true,
        };
        for name in TeamConfig::preset_names() {
            let config = TeamConfig::preset(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            let layer = reactive_layer(&config, &info, &field);
            assert_eq!(layer.unregistered(), [], "{name}");
        }
    }

    #[test]
    fn every_preset_loads() {
        for name in TeamConfig::preset_names() {
            TeamConfig::preset(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        }
        assert!(!TeamConfig::preset("no-coordination").expect("preset").coordination);
    }

    #[test]
    fn a_missing_team_file_is_reported_as_a_file_and_a_mistyped_preset_as_a_preset() {
        let missing = TeamConfig::resolve("teams/missing-team.toml").expect_err("no such file");
        assert!(
            matches!(&missing, TeamConfigError::Read { path, .. } if path == "teams/missing-team.toml"),
            "{missing}"
        );
        let nested = TeamConfig::resolve("teams/missing-team").expect_err("no such file");
        assert!(matches!(nested, TeamConfigError::Read { .. }), "{nested}");
        let typo = TeamConfig::resolve("no-coordinaton").expect_err("no such preset");
        assert!(matches!(typo, TeamConfigError::UnknownPreset(_)), "{typo}");
        assert!(TeamConfig::resolve("entropy").is_ok());
    }

    #[test]
    fn bad_values_name_the_file_and_the_field() {
        let e =
            TeamConfig::from_toml_str("[timing.deliberative]\nrate_hz = -1.0\n", "teams/bad.toml")
                .expect_err("invalid");
        assert_eq!(
            e.to_string(),
            "teams/bad.toml: `timing.deliberative.rate_hz` must be > 0, got -1"
        );
        let e = TeamConfig::from_toml_str("[camera]\nbearing_sigma = 0.0\n", "teams/bad.toml")
            .expect_err("invalid");
        assert_eq!(e.to_string(), "teams/bad.toml: `camera.bearing_sigma` must be > 0, got 0");
        // The camera model moved out of `[perception]`: the old keys are named as unknown.
        let e = TeamConfig::from_toml_str("[perception]\nrange_sigma = 0.1\n", "teams/old.toml")
            .expect_err("unknown key");
        assert!(e.to_string().contains("range_sigma"), "{e}");
        let e = TeamConfig::from_toml_str("coordinaton = true\n", "teams/typo.toml")
            .expect_err("unknown key");
        assert!(
            e.to_string().starts_with("teams/typo.toml:") && e.to_string().contains("coordinaton"),
            "{e}"
        );
    }
}
