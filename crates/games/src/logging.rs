//! `--log FILE.mcap` for simulated matches (docs/architecture.md, Principles, 8): every package
//! of the chosen robots, the simulator's ground truth, the game state and each layer's active
//! behavior path, with the run's effective configuration and graph, so that `strata replay` can
//! rebuild a module and `strata view` can show the match (`docs/logging.md`, `docs/viewer.md`).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use anyhow::{Context as _, Result, bail};
use serde::{Deserialize, Serialize};
use strata_log::{
    ConfigFormat, Derive, DerivedRecords, LogCompression, LogSummary, McapTap, McapTapOptions,
    RunInfo, WhenFull,
};
use strata_robot::command::ResourceGroup;
use strata_robot::control::reactive::{MuxReport, ReactiveReport};
use strata_robot::platform::PlatformInfo;
use strata_robot::world::WorldModelConfig;
use strata_runtime::{
    Encoding, ErasedPackage, GraphDescription, ModuleId, Tap, TapOutput, TapRecord, Time,
};
use strata_sim::{GameTruth, SimConfig};
use strata_soccer::field::TeamField;
use strata_soccer::team::{TeamConfig, team_world_config};
use strata_spl::field::FieldDimensions;

use crate::matches::{Match, robot_name};
use crate::outputs::{DECISION, GROUND_TRUTH, REPORT, SCORES, WORLD_STATE};
use crate::scene::feed::{SceneFeed, SceneSource};
use crate::scene::foxglove::{frame_transforms_schema, log_schema, scene_update_schema};
use crate::scene::plot::{PLOT_TOPIC, layer_plot_schema};
use crate::scene::{
    EVENTS_TOPIC, FIELD_TOPIC, OBJECTS_TOPIC, SceneConfig, SceneOutput, TRANSFORMS_TOPIC,
};

/// Topic of the game-state records (written when the game state changes).
pub const GAME_STATE_TOPIC: &str = "game/state";
/// Topic suffix of the behavior-path records: `home/3/behavior_path`.
pub const BEHAVIOR_PATH_TOPIC: &str = "behavior_path";

/// The effective configuration of a match, as stored in its log (`config.json`): what the
/// replay registry rebuilds modules from and what `--set` overrides.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub players: u8,
    pub seed: u64,
    pub half_duration: f64,
    pub packet_loss: f64,
    pub realtime: bool,
    /// The teams' configurations, defaults filled in.
    pub home: TeamConfig,
    pub away: TeamConfig,
    /// The world-model configuration each team's robots were built with (it derives from the
    /// field and the side the team attacked at kick-off).
    pub world: TeamWorldConfigs,
    /// The simulator's configuration (field name, noise, timing, referee...).
    pub sim: SimConfig,
    /// The field the match was played on.
    pub field: FieldDimensions,
    /// What the robots' platform reported (camera field of view and range, head limits).
    pub platform: PlatformInfo,
    /// GameController team numbers, by team index.
    pub team_numbers: [u8; 2],
    /// +1 when the team attacked +x at kick-off, by team index.
    pub attack_sign: [f64; 2],
}

/// The configuration a robot's own log (`strata robot --log`) holds: what its replayable
/// modules are rebuilt from (`strata replay FILE --robot t10/3`), as [`RunConfig`] is for a
/// match's log.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotRunConfig {
    /// The robot's module prefix, `t<team number>/<player>`.
    pub robot: String,
    /// The team configuration, defaults filled in.
    pub team: TeamConfig,
    /// The world model's configuration, as the robot built it from its field.
    pub world: WorldModelConfig,
    pub field: FieldDimensions,
    /// +1 when the robot's team attacked +x (from the GameController, `--attack-sign` or the
    /// default).
    pub attack_sign: f64,
    /// What the robot's platform reported (camera field of view and range, head limits).
    pub platform: PlatformInfo,
}

impl RobotRunConfig {
    /// What the scene channels of the robot's log are drawn with (its team attacks as it
    /// did; the other team the other way).
    pub fn scene(&self) -> SceneConfig {
        SceneConfig {
            field: self.field.clone(),
            camera_fov: self.platform.camera_fov,
            camera_range: self.platform.camera_range,
            attack_sign: [self.attack_sign, -self.attack_sign],
            period: SceneConfig::DEFAULT_PERIOD,
        }
    }
}

/// One world-model configuration per team.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeamWorldConfigs {
    pub home: WorldModelConfig,
    pub away: WorldModelConfig,
}

impl RunConfig {
    /// The configuration `game` was built with.
    pub fn of(game: &Match) -> RunConfig {
        let sim = game.sim.lock();
        let field = sim.field().clone();
        let truth = sim.game();
        let world = |team: usize, config: &TeamConfig| {
            team_world_config(config, &TeamField::new(field.clone(), truth.attack_sign[team]))
        };
        RunConfig {
            players: game.config.players,
            seed: game.config.seed,
            half_duration: game.config.half_duration,
            packet_loss: game.config.packet_loss,
            realtime: game.config.realtime,
            home: game.config.home.clone(),
            away: game.config.away.clone(),
            world: TeamWorldConfigs {
                home: world(0, &game.config.home),
                away: world(1, &game.config.away),
            },
            sim: sim.config().clone(),
            field: field.dimensions().clone(),
            platform: sim.platform_info(),
            team_numbers: truth.team_numbers,
            attack_sign: truth.attack_sign,
        }
    }

    /// What the scene channels of the match's log are drawn with.
    pub fn scene(&self) -> SceneConfig {
        SceneConfig {
            field: self.field.clone(),
            camera_fov: self.platform.camera_fov,
            camera_range: self.platform.camera_range,
            attack_sign: self.attack_sign,
            period: SceneConfig::DEFAULT_PERIOD,
        }
    }

    /// `home` or `away`, from a robot name such as `home/3`.
    pub fn team_of(robot: &str) -> Option<&'static str> {
        match robot.split('/').next() {
            Some("home") => Some("home"),
            Some("away") => Some("away"),
            _ => None,
        }
    }
}

/// What to log.
#[derive(Clone, Debug, PartialEq)]
pub struct LogSettings {
    pub path: PathBuf,
    /// Robots to log (`home/1`, `away/2`); every robot when empty.
    pub robots: Vec<String>,
    /// World-state packages logged per second and robot; `None`: every package. The world state
    /// is the one large stream (`docs/logging.md`, "Overhead").
    pub world_state_hz: Option<f64>,
    pub compression: LogCompression,
    pub encoding: Encoding,
    /// Whether the log holds the scene channels Foxglove draws (`scene/...`,
    /// `docs/foxglove.md`).
    pub scene: bool,
}

impl LogSettings {
    /// Every package of every robot, nothing decimated, the default compression and encoding.
    pub fn full(path: impl Into<PathBuf>) -> LogSettings {
        let defaults = McapTapOptions::default();
        LogSettings {
            path: path.into(),
            robots: Vec::new(),
            world_state_hz: None,
            compression: defaults.compression,
            encoding: defaults.encoding,
            scene: true,
        }
    }
}

/// Parses `home/1,away/2` (also `home/1 away/2`); checks each name.
pub fn parse_robots(text: &str, players: u8) -> Result<Vec<String>> {
    let mut robots = Vec::new();
    for name in text.split([',', ' ']).map(str::trim).filter(|s| !s.is_empty()) {
        let (team, player) = name
            .split_once('/')
            .with_context(|| format!("robot `{name}`: expected TEAM/PLAYER, e.g. home/3"))?;
        if team != "home" && team != "away" {
            bail!("robot `{name}`: the team is `home` or `away`");
        }
        let player: u8 =
            player.parse().ok().filter(|p| (1..=players).contains(p)).with_context(|| {
                format!("robot `{name}`: the player is a number from 1 to {players}")
            })?;
        robots.push(format!("{team}/{player}"));
    }
    if robots.is_empty() {
        bail!("--log-robots names no robot (e.g. home/1,away/2)");
    }
    Ok(robots)
}

/// Creates a log and writes what a reader needs besides the packages: the run (seed, command
/// line, configuration) and the graph; the log derives the behavior paths of `robots` (module
/// prefixes: `home/3`, `t10/3`), where the simulator's ground truth is logged the game state,
/// and with a `scene` configuration the scene channels Foxglove draws
/// ([`crate::scene`]). What matches, robots and experiments share.
pub fn open_run_log(
    path: &Path,
    options: McapTapOptions,
    run: &RunInfo,
    graph: &GraphDescription,
    robots: impl IntoIterator<Item = String>,
    scene: Option<SceneConfig>,
) -> Result<Arc<McapTap>> {
    let tap = McapTap::create(path, options)
        .with_context(|| format!("creating the log {}", path.display()))?;
    tap.write_run_info(run)?;
    tap.write_graph("", graph)?;
    let robots: Vec<String> = robots.into_iter().collect();
    tap.set_derive(Box::new(RunRecords {
        robots: robots.iter().map(|robot| PathRecord::new(robot)).collect(),
        sources: Vec::new(),
        last_game: None,
        scene: scene.map(|config| SceneFeed::new(config, robots.iter().cloned())),
    }));
    Ok(Arc::new(tap))
}

/// A match's log: an [`McapTap`] and the tap in front of it.
pub struct MatchLog {
    tap: Arc<McapTap>,
    path: PathBuf,
}

impl std::fmt::Debug for MatchLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MatchLog").field("path", &self.path).finish_non_exhaustive()
    }
}

impl MatchLog {
    /// Creates the file, writes the run (seed, command line, effective configuration) and the
    /// graph, and adds the logging tap to `game`. Call before the match is played.
    pub fn attach(game: &mut Match, settings: &LogSettings) -> Result<MatchLog> {
        let graph = game
            .graph
            .as_ref()
            .context("the match's graph was already taken: attach the log before playing")?
            .describe();
        let mut modules: Vec<String> = settings.robots.iter().map(|r| format!("{r}/")).collect();
        if !modules.is_empty() {
            // Ground truth comes from the simulator module, and so do the chosen robots' sensor
            // frames and motion feedback (it is their platform).
            modules.push(format!("simulator/{GROUND_TRUTH}"));
            for (id, _) in &game.robots {
                if settings.robots.contains(&robot_name(*id)) {
                    modules.push(format!("simulator/{}/", strata_sim::robot_port_prefix(*id)));
                }
            }
        }
        let options = McapTapOptions {
            // The lockstep host runs in simulated time: waiting for the disk costs no deadline
            // and gives the complete log replay needs. A real-time host must never wait.
            when_full: if game.config.realtime { WhenFull::Drop } else { WhenFull::Wait },
            modules,
            compression: settings.compression,
            encoding: settings.encoding,
            ..McapTapOptions::default()
        };
        let run_config = RunConfig::of(game);
        let config = serde_json::to_string_pretty(&run_config)
            .context("serializing the match configuration")?;
        let run = RunInfo::current(game.config.seed).with_config(ConfigFormat::Json, config);
        let chosen =
            |name: &str| settings.robots.is_empty() || settings.robots.iter().any(|r| r == name);
        let robots = game.robots.iter().map(|(id, _)| robot_name(*id)).filter(|r| chosen(r));
        let scene = settings.scene.then(|| run_config.scene());
        let tap = open_run_log(&settings.path, options, &run, &graph, robots, scene)?;
        let world_period = settings
            .world_state_hz
            .filter(|hz| hz.is_finite() && *hz > 0.0)
            .map(|hz| Duration::from_secs_f64(1.0 / hz));
        match world_period {
            Some(period) => game.add_tap(Arc::new(WorldStateDecimation {
                tap: Arc::clone(&tap),
                period,
                last: Mutex::new(HashMap::new()),
            })),
            None => game.add_tap(Arc::clone(&tap) as Arc<dyn Tap>),
        }
        Ok(MatchLog { tap, path: settings.path.clone() })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The tap, for application records.
    pub fn tap(&self) -> &Arc<McapTap> {
        &self.tap
    }

    /// Writes what is queued, the statistics, summary and footer. Also run when the last handle
    /// is dropped; calling it again returns the same summary.
    pub fn finish(&self) -> Result<LogSummary> {
        self.tap.finish().with_context(|| format!("finishing the log {}", self.path.display()))
    }
}

/// The newest active behavior path of each layer of one robot.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BehaviorPath {
    /// `head+body: ... | head: observe ball > object tracking | body: ...`
    pub reactive: String,
    /// The deliberative layer's state and behavior-tree path.
    pub deliberative: String,
    /// Mission and role from the planning layer: `attacker/striker`.
    pub planning: String,
}

/// What a multiplexer's part of the active path is made of: selected goal, primitive behavior,
/// inhibiting multiplexer.
type MuxPathKey = (Option<Arc<str>>, Option<std::borrow::Cow<'static, str>>, Option<ResourceGroup>);

/// The whole body's, the head's and the body's parts: compared every reactive cycle, cheaply,
/// instead of formatting the path text each time.
type PathKey = [MuxPathKey; 3];

fn mux_path_key(r: &MuxReport) -> MuxPathKey {
    (r.selected_goal.clone(), r.primitive.clone(), r.inhibited_by)
}

fn path_key(report: &ReactiveReport) -> PathKey {
    [mux_path_key(&report.whole_body), mux_path_key(&report.head), mux_path_key(&report.body)]
}

fn same_path(key: &PathKey, report: &ReactiveReport) -> bool {
    // The labels are shared with the multiplexers: the same text is usually the same pointer.
    fn same_text(a: Option<&str>, b: Option<&str>) -> bool {
        match (a, b) {
            (Some(a), Some(b)) => std::ptr::eq(a, b) || a == b,
            (a, b) => a.is_none() && b.is_none(),
        }
    }
    let same = |k: &MuxPathKey, r: &MuxReport| {
        same_text(k.0.as_deref(), r.selected_goal.as_deref())
            && same_text(k.1.as_deref(), r.primitive.as_deref())
            && k.2 == r.inhibited_by
    };
    same(&key[0], &report.whole_body) && same(&key[1], &report.head) && same(&key[2], &report.body)
}

/// The layer a behavior path comes from.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Layer {
    Deliberative,
    Planning,
    Reactive,
}

struct PathRecord {
    /// Where the robot's path records go: `home/3/behavior_path`.
    topic: String,
    /// The topics of the robot's deliberative scores, planning decisions and reactive reports.
    sources: [(String, Layer); 3],
    /// The newest path of each layer, and the last one written.
    path: BehaviorPath,
    written: BehaviorPath,
    /// `path` may differ from `written`.
    changed: bool,
    /// What the reactive path was made of when it was last formatted.
    reactive_key: Option<PathKey>,
}

impl PathRecord {
    fn new(robot: &str) -> PathRecord {
        PathRecord {
            topic: format!("{robot}/{BEHAVIOR_PATH_TOPIC}"),
            sources: [
                (format!("{robot}/deliberative/{SCORES}"), Layer::Deliberative),
                (format!("{robot}/planning/{DECISION}"), Layer::Planning),
                (format!("{robot}/reactive/{REPORT}"), Layer::Reactive),
            ],
            path: BehaviorPath::default(),
            written: BehaviorPath::default(),
            changed: false,
            reactive_key: None,
        }
    }

    /// Takes in a package of the robot's `layer`; writes the path when any layer's changed,
    /// checked at every reactive report (which carries the path of every cycle): a path holds
    /// until the next record.
    fn update(
        &mut self,
        layer: Layer,
        time: Time,
        package: &dyn ErasedPackage,
        records: &mut DerivedRecords,
    ) {
        match layer {
            Layer::Deliberative => {
                if let Some(p) = SCORES.downcast(package) {
                    self.path.deliberative.clone_from(&p.value.behavior_path);
                    self.changed = true;
                }
            }
            Layer::Planning => {
                if let Some(p) = DECISION.downcast(package) {
                    let a = &p.value.assignment;
                    self.path.planning = format!("{}/{}", a.mission.name(), a.role.name());
                    self.changed = true;
                }
            }
            Layer::Reactive => {
                let Some(p) = REPORT.downcast(package) else { return };
                let reactive_changed =
                    self.reactive_key.as_ref().is_none_or(|key| !same_path(key, &p.value));
                if reactive_changed {
                    self.reactive_key = Some(path_key(&p.value));
                    self.path.reactive = p.value.active_path();
                    self.changed = true;
                }
                if self.changed && self.written != self.path {
                    records.record_value(&self.topic, time, &self.path);
                    self.written.clone_from(&self.path);
                }
                self.changed = false;
            }
        }
    }
}

/// What a logged topic's packages are derived into.
#[derive(Clone, Copy, Default)]
struct Sources {
    /// The simulator's ground truth: the game state.
    game_state: bool,
    /// A layer's output of the robot with this index: its behavior path.
    path: Option<(usize, Layer)>,
    /// What it is to the scene, when the log has one.
    scene: Option<SceneSource>,
}

/// The records of a log that are not packages, derived on the log's writer thread (see
/// [`strata_log::Derive`]): the game state when it changes (from the simulator's ground
/// truth), each logged robot's behavior path, checked every reactive cycle and written
/// when it changes, and the scene channels.
struct RunRecords {
    robots: Vec<PathRecord>,
    /// By topic id.
    sources: Vec<Sources>,
    last_game: Option<GameTruth>,
    /// The scene channels' state, when the log has them.
    scene: Option<SceneFeed>,
}

/// Writes what the scene says to write, at `time` (the package's log time).
fn write_scene(out: SceneOutput, time: Time, records: &mut DerivedRecords) {
    if let Some(field) = &out.field {
        records.record_json(FIELD_TOPIC, time, scene_update_schema(), field);
    }
    if let Some(objects) = &out.objects {
        records.record_json(OBJECTS_TOPIC, time, scene_update_schema(), objects);
    }
    if let Some(transforms) = &out.transforms {
        records.record_json(TRANSFORMS_TOPIC, time, frame_transforms_schema(), transforms);
    }
    if let Some(plot) = &out.plot {
        records.record_json(PLOT_TOPIC, time, layer_plot_schema(), plot);
    }
    for line in &out.logs {
        records.record_json(EVENTS_TOPIC, time, log_schema(), line);
    }
}

impl RunRecords {
    fn game_state(
        &mut self,
        time: Time,
        package: &dyn ErasedPackage,
        records: &mut DerivedRecords,
    ) {
        let Some(truth) = GROUND_TRUTH.downcast(package) else { return };
        let game = &truth.value.game;
        // The clock runs down and the message budgets shrink all the time: a change of the
        // game state is a change of anything else.
        let changed = self.last_game.as_ref().is_none_or(|g| {
            let mut g = g.clone();
            g.secs_remaining = game.secs_remaining;
            g.message_budget = game.message_budget;
            g != *game
        });
        if changed {
            records.record_value(GAME_STATE_TOPIC, time, game);
            self.last_game = Some(game.clone());
        }
    }
}

impl Derive for RunRecords {
    fn wants(&mut self, id: u32, topic: &str, _type_name: &str) -> bool {
        let game_state =
            topic.rsplit_once('/').is_some_and(|(_, output)| output == GROUND_TRUTH.name());
        let path = self.robots.iter().enumerate().find_map(|(robot, record)| {
            let (_, layer) = record.sources.iter().find(|(name, _)| name == topic)?;
            Some((robot, *layer))
        });
        let scene = self.scene.as_ref().and_then(|scene| scene.source(topic));
        let index = id as usize;
        if self.sources.len() <= index {
            self.sources.resize(index + 1, Sources::default());
        }
        self.sources[index] = Sources { game_state, path, scene };
        game_state || path.is_some() || scene.is_some()
    }

    fn package(
        &mut self,
        topic: u32,
        time: Time,
        package: &dyn ErasedPackage,
        records: &mut DerivedRecords,
    ) {
        let Some(sources) = self.sources.get(topic as usize).copied() else { return };
        if let (Some(source), Some(scene)) = (sources.scene, self.scene.as_mut()) {
            write_scene(scene.package(source, time, package), time, records);
        }
        if sources.game_state {
            self.game_state(time, package, records);
        }
        if let Some((robot, layer)) = sources.path
            && let Some(record) = self.robots.get_mut(robot)
        {
            record.update(layer, time, package, records);
        }
    }

    /// A new file of the log (its size cap) starts with the game state and each robot's path
    /// again, at their next packages: written only when they change, they would otherwise be
    /// missing from it until then.
    fn next_file(&mut self) {
        self.last_game = None;
        if let Some(scene) = self.scene.as_mut() {
            scene.restart();
        }
        for robot in &mut self.robots {
            robot.written = BehaviorPath::default();
            robot.changed = true;
        }
    }
}

/// Passes packages to the log, the world state of each robot at most once per `period`.
struct WorldStateDecimation {
    tap: Arc<McapTap>,
    period: Duration,
    last: Mutex<HashMap<ModuleId, Time>>,
}

impl WorldStateDecimation {
    fn keep(&self, output: &TapOutput<'_>, time: Time) -> bool {
        if !output.is(WORLD_STATE) {
            return true;
        }
        let mut last = self.last.lock().unwrap_or_else(PoisonError::into_inner);
        match last.get(&output.module) {
            Some(t) if time < *t + self.period => false,
            _ => {
                last.insert(output.module, time);
                true
            }
        }
    }
}

impl Tap for WorldStateDecimation {
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        self.tap.wants(output)
    }

    fn package(&self, record: &TapRecord<'_>) {
        if self.keep(&record.sent_on, record.time) {
            self.tap.package(record);
        }
    }

    fn package_owned(&self, output: &TapOutput<'_>, time: Time, package: Box<dyn ErasedPackage>) {
        if self.keep(output, time) {
            self.tap.package_owned(output, time, package);
        }
    }
}
