//! `strata experiment fall --engine rcssservermj` (paper 4.3, Fig. 6, on Booster T1s in
//! rcssservermj): falls caused in physics, how long the reactive layer takes to order the
//! protective Fall, how long the robot takes to stand again, and how often it orders a Fall
//! with no fall while walking.
//!
//! Each robot is a `strata robot --platform rcssservermj` process under the full
//! architecture. Its platform measures every fall against the server's ground truth
//! ([`strata_rcssmj::falls`]): the onset (the torso's tilt past 20 degrees), the protective-fall
//! order, standing again, and the orders no fall followed; the experiment reads them from the
//! robot's final report. The experiment is the trainer: through the server's monitor port it
//! kicks off, places the ball the robots walk after, and pushes — the ball shot at the torso,
//! a real push through MuJoCo's contacts (or, with `method = "tilt"`, the robot placed tilted,
//! as a fallback that always falls). Robots chasing one ball also collide: those falls are
//! measured the same way.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use indicatif::ProgressBar;
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use strata_rcssmj::falls::{FALL_ONSET_TILT, FallRecord, UPRIGHT_HOLD};
use strata_rcssmj::protocol::FieldSide;
use strata_rcssmj::protocol::monitor::{
    MonitorCommand, MonitorState, RobotOrientation, RobotTruth, TeamRef,
};
use strata_rcssmj::server::{ServerOptions, ServerProcess};

use crate::fall as fall2d;
use crate::stats::{Distribution, Estimate, mean, percentile};
use crate::{Check, Ctx, HostKind, Options, ScenarioError, Validate, load_average, parse_scenario};
use strata_games::physics::Engine;
use strata_games::physics::robot::{T1Launch, T1Process, strata_exe};

mod report;

pub const NAME: &str = fall2d::NAME;
pub const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/rcssservermj/fall.toml");

/// The robots' team number and name in the server (the first team to connect is the left one).
const TEAM: u8 = 1;
const TEAM_NAME: &str = "Strata1";

/// A torso's origin lower than this, m, is not standing (it stands at 0.64 m).
const STANDING_HEIGHT: f64 = 0.5;

/// No new simulation time for this long, wall clock, means the server or a robot hangs.
const STALL: Duration = Duration::from_secs(60);

// ---------------------------------------------------------------------------------------------
// The scenario.

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    /// The robots' team: a built-in team or a team file (relative to the scenario's directory).
    pub team: String,
    pub pushes: Pushes,
    pub walking: Walking,
    pub targets: Targets,
    pub sim2d: Sim2d,
    #[serde(skip)]
    team_arg: String,
}

/// How a push is made.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PushMethod {
    /// The ball shot at the torso.
    Ball,
    /// The robot placed tilted towards the push's side (every joint reset to zero).
    Tilt,
}

/// The side a robot is pushed to, relative to its heading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Direction {
    Front,
    Back,
    Left,
    Right,
}

impl Direction {
    fn name(self) -> &'static str {
        match self {
            Direction::Front => "front",
            Direction::Back => "back",
            Direction::Left => "left",
            Direction::Right => "right",
        }
    }

    /// The push's unit vector in the world for a robot heading `heading` rad.
    fn unit(self, heading: f64) -> [f64; 2] {
        let angle = heading
            + match self {
                Direction::Front => 0.0,
                Direction::Left => std::f64::consts::FRAC_PI_2,
                Direction::Back => std::f64::consts::PI,
                Direction::Right => -std::f64::consts::FRAC_PI_2,
            };
        [angle.cos(), angle.sin()]
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Pushes {
    pub runs: usize,
    pub pushes_per_run: usize,
    pub player: u8,
    /// Team frame, metres and degrees.
    pub beam: [f64; 3],
    /// Seconds of the game's Ready (the robot walks to its kick-off position) before kick-off.
    pub ready: f64,
    pub method: PushMethod,
    pub ball_speed: f64,
    pub ball_height: f64,
    pub ball_distance: f64,
    pub tilt_degrees: f64,
    pub directions: Vec<Direction>,
    pub chase_distance: f64,
    pub settle: [f64; 2],
    pub fall_window: f64,
    pub recovery_timeout: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Walking {
    pub runs: usize,
    pub robots: u8,
    pub duration: f64,
    pub ready: f64,
    pub ball_every: f64,
    /// `[[x min, x max], [y min, y max]]`, world frame.
    pub ball_area: [[f64; 2]; 2],
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Targets {
    pub onset_to_command_ms: f64,
    pub percept_to_command_ms: f64,
    pub walking_minutes: f64,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Sim2d {
    /// Run the 2D simulator's fall experiment (lockstep host) in the same command.
    pub run: bool,
    pub documented_onset_to_command_ms: f64,
    pub documented_percepts_to_command_ms: f64,
    pub documented_standing_s: f64,
    pub documented_source: String,
}

fn check_interval(check: &Check<'_>, field: &str, [lo, hi]: [f64; 2]) -> Result<(), ScenarioError> {
    if lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi {
        Ok(())
    } else {
        Err(check.fail(field, format!("must be [min, max] with 0 <= min <= max, got [{lo}, {hi}]")))
    }
}

fn check_area(check: &Check<'_>, field: &str, area: [[f64; 2]; 2]) -> Result<(), ScenarioError> {
    if area.iter().all(|[lo, hi]| lo.is_finite() && hi.is_finite() && lo <= hi) {
        Ok(())
    } else {
        Err(check.fail(field, format!("must be [[x min, x max], [y min, y max]], got {area:?}")))
    }
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        check.team("team", &self.team, dir)?;
        self.team_arg = match dir {
            Some(dir) if self.team.ends_with(".toml") => dir.join(&self.team).display().to_string(),
            _ => self.team.clone(),
        };
        let p = &self.pushes;
        check.at_least("pushes.pushes_per_run", p.pushes_per_run, 1)?;
        if !(2..=11).contains(&p.player) {
            return Err(check.fail("pushes.player", "must be a field player, 2 to 11"));
        }
        if !p.beam.iter().all(|v| v.is_finite()) {
            return Err(check.fail("pushes.beam", format!("must be finite, got {:?}", p.beam)));
        }
        check.non_negative("pushes.ready", p.ready)?;
        check.positive("pushes.ball_speed", p.ball_speed)?;
        check.positive("pushes.ball_height", p.ball_height)?;
        // The ball (radius 0.11 m) must start clear of the torso.
        if !(p.ball_distance.is_finite() && p.ball_distance >= 0.3) {
            return Err(check.fail(
                "pushes.ball_distance",
                format!("must be at least 0.3 m (clear of the torso), got {}", p.ball_distance),
            ));
        }
        if !(p.tilt_degrees.is_finite() && (0.0..90.0).contains(&p.tilt_degrees)) {
            return Err(check.fail(
                "pushes.tilt_degrees",
                format!("must be in [0, 90), got {}", p.tilt_degrees),
            ));
        }
        check.not_empty("pushes.directions", &p.directions)?;
        check.positive("pushes.chase_distance", p.chase_distance)?;
        check_interval(check, "pushes.settle", p.settle)?;
        check.positive("pushes.fall_window", p.fall_window)?;
        if !(p.recovery_timeout.is_finite() && p.recovery_timeout > p.fall_window) {
            return Err(check.fail(
                "pushes.recovery_timeout",
                format!("must be longer than pushes.fall_window, got {}", p.recovery_timeout),
            ));
        }
        let w = &self.walking;
        if w.runs > 0 && !(1..=10).contains(&w.robots) {
            return Err(check.fail("walking.robots", "must be 1 to 10 (players 2 to 11)"));
        }
        check.positive("walking.duration", w.duration)?;
        check.non_negative("walking.ready", w.ready)?;
        check.positive("walking.ball_every", w.ball_every)?;
        check_area(check, "walking.ball_area", w.ball_area)?;
        check.positive("targets.onset_to_command_ms", self.targets.onset_to_command_ms)?;
        check.positive("targets.percept_to_command_ms", self.targets.percept_to_command_ms)?;
        check.positive("targets.walking_minutes", self.targets.walking_minutes)?;
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Ground truth.

/// The angle between the torso's z axis and the world's vertical, rad.
pub fn tilt_of([_, x, y, _]: [f64; 4]) -> f64 {
    (1.0 - 2.0 * (x * x + y * y)).clamp(-1.0, 1.0).acos()
}

/// The torso's heading about the world's z axis, rad.
pub fn heading_of([w, x, y, z]: [f64; 4]) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// A unit quaternion `[w, x, y, z]`: heading `heading`, then tilted by `tilt` rad towards the
/// world direction `towards` (a unit vector on the ground).
pub fn tilted_towards(heading: f64, tilt: f64, towards: [f64; 2]) -> [f64; 4] {
    // The rotation axis is horizontal, perpendicular to the direction of the tilt: z x towards.
    let axis = [-towards[1], towards[0]];
    let (s, c) = ((tilt / 2.0).sin(), (tilt / 2.0).cos());
    let q_tilt = [c, axis[0] * s, axis[1] * s, 0.0];
    let (sh, ch) = ((heading / 2.0).sin(), (heading / 2.0).cos());
    let q_heading = [ch, 0.0, 0.0, sh];
    multiply(q_tilt, q_heading)
}

fn multiply(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Standing, by the ground truth: the torso up and nearly vertical (half the onset tilt).
fn standing(robot: &RobotTruth) -> bool {
    robot.position[2] > STANDING_HEIGHT && tilt_of(robot.orientation) < FALL_ONSET_TILT / 2.0
}

fn robot_of(state: &MonitorState, player: u8) -> Option<&RobotTruth> {
    state.robots.iter().find(|r| r.team == TEAM_NAME && r.player == u32::from(player))
}

/// The server and the robots of one run, followed on the simulation's clock.
struct Session {
    server: ServerProcess,
    robots: Vec<T1Process>,
    /// The newest simulation time seen, s.
    now: f64,
    /// When the simulation time last moved (wall clock).
    moved: Instant,
    bar: ProgressBar,
    /// The simulation time already counted on the progress bar.
    shown: f64,
}

impl Session {
    fn start(launches: &[T1Launch], bar: ProgressBar) -> Result<Session> {
        strata_games::physics::check_interrupt()?;
        let server = ServerProcess::start(&ServerOptions::default())
            .context("starting rcssservermj for the fall experiment")?;
        let mut robots = Vec::new();
        for launch in launches {
            let launch = T1Launch { server: server.agent_address(), ..launch.clone() };
            robots.push(T1Process::spawn(&launch)?);
        }
        Ok(Session { server, robots, now: 0.0, moved: Instant::now(), bar, shown: f64::NAN })
    }

    /// Waits for the next monitor state with a newer simulation time; fails if a robot ended
    /// or the simulation stalled.
    fn next(&mut self) -> Result<MonitorState> {
        loop {
            strata_games::physics::check_interrupt()?;
            for robot in &mut self.robots {
                if let Some(status) = robot.exited() {
                    bail!(
                        "robot {}/{} ended early ({status}): {}",
                        robot.team,
                        robot.player,
                        robot.stderr_tail(5)
                    );
                }
            }
            let state = self.server.truth();
            if let Some(t) = state.sim_time
                && t > self.now
            {
                self.now = t;
                self.moved = Instant::now();
                if self.shown.is_nan() {
                    self.shown = t;
                }
                if t - self.shown >= 1.0 {
                    self.bar.inc((t - self.shown).floor() as u64);
                    self.shown += (t - self.shown).floor();
                }
                return Ok(state);
            }
            if self.moved.elapsed() > STALL {
                bail!("the simulation has not moved for {STALL:?} (at {:.2} s)", self.now);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits until every robot is in the simulation; returns the simulation time then.
    fn wait_for_robots(&mut self, players: &[u8]) -> Result<f64> {
        let started = Instant::now();
        loop {
            let state = self.next_or_idle()?;
            if players.iter().all(|p| robot_of(&state, *p).is_some())
                && let Some(t) = state.sim_time
            {
                return Ok(t);
            }
            if started.elapsed() > Duration::from_secs(120) {
                bail!("the robots {players:?} were not in the simulation after 2 minutes");
            }
        }
    }

    /// Like [`Session::next`], but before the robots join the server does not step: the state
    /// as it is.
    fn next_or_idle(&mut self) -> Result<MonitorState> {
        strata_games::physics::check_interrupt()?;
        for robot in &mut self.robots {
            if let Some(status) = robot.exited() {
                bail!(
                    "robot {}/{} ended early ({status}): {}",
                    robot.team,
                    robot.player,
                    robot.stderr_tail(5)
                );
            }
        }
        std::thread::sleep(Duration::from_millis(20));
        Ok(self.server.truth())
    }

    /// Follows the simulation until time `until`.
    fn until(&mut self, until: f64) -> Result<MonitorState> {
        loop {
            let state = self.next()?;
            if self.now >= until {
                return Ok(state);
            }
        }
    }

    /// Stops every robot as Ctrl-C does and returns their final reports.
    fn finish(mut self) -> Result<Vec<RobotReport>> {
        for robot in &mut self.robots {
            robot.interrupt();
        }
        let mut reports = Vec::new();
        for robot in &mut self.robots {
            let (report, status) = robot.finish(Duration::from_secs(30));
            let mut missions: Vec<String> = Vec::new();
            for line in robot.json_of("status") {
                let seen = format!("{} {}", line["game_state"], line["mission"]);
                if missions.last() != Some(&seen) {
                    missions.push(seen);
                }
            }
            tracing::info!(
                player = robot.player,
                missions = %missions.join(" -> "),
                "game states and missions"
            );
            let report = report.with_context(|| {
                format!(
                    "robot {}/{} printed no report ({status:?}): {}",
                    robot.team,
                    robot.player,
                    robot.stderr_tail(5)
                )
            })?;
            reports.push(RobotReport::read(robot.player, &report)?);
        }
        Ok(reports)
    }
}

/// What the experiment reads from a robot's final report.
#[derive(Clone, Debug)]
struct RobotReport {
    player: u8,
    falls: Vec<FallRecord>,
    false_falls: Vec<f64>,
    reactive_hz: f64,
}

impl RobotReport {
    fn read(player: u8, report: &serde_json::Value) -> Result<RobotReport> {
        let falls = match report.get("falls") {
            Some(falls) => serde_json::from_value(falls.clone())
                .with_context(|| format!("robot {player}'s report: `falls`"))?,
            None => Vec::new(),
        };
        let false_falls = match report.get("false_falls") {
            Some(times) => serde_json::from_value(times.clone())
                .with_context(|| format!("robot {player}'s report: `false_falls`"))?,
            None => Vec::new(),
        };
        let reactive_hz = report
            .get("layers")
            .and_then(|layers| layers.as_array())
            .and_then(|layers| layers.iter().find(|l| l["layer"] == "reactive"))
            .and_then(|l| l["mean_hz"].as_f64())
            .unwrap_or(f64::NAN);
        Ok(RobotReport { player, falls, false_falls, reactive_hz })
    }
}

// ---------------------------------------------------------------------------------------------
// Runs.

/// One push of the trainer.
#[derive(Clone, Debug, Serialize)]
pub struct Push {
    pub run: usize,
    /// Simulation time of the push command, s.
    pub at: f64,
    pub direction: &'static str,
    /// The ground truth's tilt passed the onset angle within the fall window.
    pub fell: bool,
    /// The robot was not standing by the recovery timeout: the trainer put it upright.
    pub helped_up: bool,
}

/// One fall as measured, from the robot's report.
#[derive(Clone, Debug, Serialize)]
pub struct Fall {
    pub kind: &'static str,
    pub run: usize,
    pub player: u8,
    /// What caused it: `push front`, ..., or `walking` (a collision or a stumble).
    pub cause: String,
    pub onset: f64,
    pub crossing: Option<f64>,
    pub ordered: Option<f64>,
    /// Interpolated ground-truth onset to the Fall order, s.
    pub onset_to_command: Option<f64>,
    /// Arrival of the first percept past the onset tilt to the Fall order, s.
    pub percept_to_command: Option<f64>,
    /// Arrival of the newest percept to the Fall order, s: the architecture's reaction.
    pub reaction: Option<f64>,
    /// Onset to standing again, s.
    pub onset_to_standing: Option<f64>,
    pub helped_up: bool,
}

#[derive(Clone, Debug, Serialize)]
struct RunResult {
    kind: &'static str,
    run: usize,
    seed: u64,
    robots: usize,
    /// Simulation seconds from kick-off to the end.
    played_s: f64,
    /// Robot-seconds upright and walking (the ground truth moved), from kick-off.
    walking_s: f64,
    upright_s: f64,
    falls: usize,
    false_falls: Vec<f64>,
    reactive_hz: f64,
    machine_load: Option<f64>,
}

fn launch(
    scenario: &Scenario,
    ctx: &Ctx<'_>,
    player: u8,
    beam: [f64; 3],
    seed: u64,
) -> Result<T1Launch> {
    Ok(T1Launch {
        exe: strata_exe(ctx.options.strata_exe.as_deref())?,
        server: String::new(),
        team: TEAM,
        team_name: TEAM_NAME.to_owned(),
        player,
        beam,
        team_config: scenario.team_arg.clone(),
        seed,
        // Without team messages every robot is a striker and walks after the ball.
        team_port: None,
        log: None,
        status_interval: 1.0,
        duration: None,
        extra: Vec::new(),
    })
}

fn ball_at(x: f64, y: f64) -> MonitorCommand {
    MonitorCommand::PlaceBall { position: [x, y, 0.11], velocity: Some([0.0; 3]) }
}

/// The ball `distance` m ahead of the robot, turned `turn` rad from its heading.
fn ball_ahead(robot: &RobotTruth, distance: f64, turn: f64) -> MonitorCommand {
    let heading = heading_of(robot.orientation) + turn;
    ball_at(
        robot.position[0] + distance * heading.cos(),
        robot.position[1] + distance * heading.sin(),
    )
}

fn push_command(p: &Pushes, robot: &RobotTruth, direction: Direction) -> MonitorCommand {
    let heading = heading_of(robot.orientation);
    let u = direction.unit(heading);
    match p.method {
        PushMethod::Ball => MonitorCommand::PlaceBall {
            position: [
                robot.position[0] - p.ball_distance * u[0],
                robot.position[1] - p.ball_distance * u[1],
                p.ball_height,
            ],
            velocity: Some([p.ball_speed * u[0], p.ball_speed * u[1], 0.0]),
        },
        PushMethod::Tilt => MonitorCommand::PlaceRobot {
            team: TeamRef::Name(TEAM_NAME.to_owned()),
            player: p.player,
            position: [robot.position[0], robot.position[1], 0.72],
            orientation: RobotOrientation::Quaternion(tilted_towards(
                heading,
                p.tilt_degrees.to_radians(),
                u,
            )),
        },
    }
}

/// Times the trainer puts a robot upright that does not stand by itself before it gives up on
/// it (a robot that falls again each time it is put up): without a bound, the experiment would
/// wait for it forever.
const MAX_HELP_UPS: u32 = 3;

/// What the trainer does about a robot that is not standing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum HelpStep {
    Wait,
    PutUpright,
    GiveUp,
}

/// The trainer's help for a robot that is not standing: put upright each time it has not stood
/// for the recovery timeout, up to [`MAX_HELP_UPS`] times.
#[derive(Clone, Copy, Debug)]
struct Help {
    since: f64,
    given: u32,
}

impl Help {
    fn new(now: f64) -> Help {
        Help { since: now, given: 0 }
    }

    fn step(&mut self, now: f64, timeout: f64) -> HelpStep {
        if now - self.since <= timeout {
            return HelpStep::Wait;
        }
        if self.given >= MAX_HELP_UPS {
            return HelpStep::GiveUp;
        }
        self.given += 1;
        self.since = now;
        HelpStep::PutUpright
    }
}

fn help_up(player: u8, robot: &RobotTruth) -> MonitorCommand {
    MonitorCommand::PlaceRobot {
        team: TeamRef::Name(TEAM_NAME.to_owned()),
        player,
        position: [robot.position[0], robot.position[1], 0.72],
        orientation: RobotOrientation::Yaw(heading_of(robot.orientation).to_degrees()),
    }
}

fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    if hi > lo { rng.random_range(lo..hi) } else { lo }
}

/// Upright and walking time of the robots, from the ground truth sampled every half second.
#[derive(Default)]
struct Motion {
    last: Vec<Option<(f64, [f64; 2])>>,
    upright_s: f64,
    walking_s: f64,
}

impl Motion {
    /// Half a second; moving 2.5 cm in it (0.05 m/s) is walking.
    const PERIOD: f64 = 0.5;

    fn sample(&mut self, state: &MonitorState, players: &[u8]) {
        let Some(now) = state.sim_time else { return };
        self.last.resize(players.len(), None);
        for (i, player) in players.iter().enumerate() {
            let Some(robot) = robot_of(state, *player) else { continue };
            let here = [robot.position[0], robot.position[1]];
            match self.last[i] {
                Some((t, _)) if now - t < Self::PERIOD => {}
                Some((t, at)) => {
                    if standing(robot) {
                        self.upright_s += now - t;
                        if (here[0] - at[0]).hypot(here[1] - at[1]) > 0.05 * (now - t) {
                            self.walking_s += now - t;
                        }
                    }
                    self.last[i] = Some((now, here));
                }
                None => self.last[i] = Some((now, here)),
            }
        }
    }
}

struct PushRun {
    result: RunResult,
    pushes: Vec<Push>,
    falls: Vec<Fall>,
}

/// One server, one robot walking after the ball, pushed `pushes_per_run` times.
fn run_pushes(
    scenario: &Scenario,
    ctx: &Ctx<'_>,
    run: usize,
    bar: &ProgressBar,
) -> Result<PushRun> {
    let p = &scenario.pushes;
    let seed = ctx.seed(run);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7075_7368);
    let mut robot_launch = launch(scenario, ctx, p.player, p.beam, seed)?;
    if run == 0 {
        robot_launch.log = ctx.options.log.clone();
    }
    let mut session = Session::start(&[robot_launch], bar.clone())?;
    let joined = session.wait_for_robots(&[p.player])?;
    session.until(joined + p.ready)?;
    session.server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
    let kickoff = session.now;
    let mut motion = Motion::default();
    let mut pushes: Vec<Push> = Vec::new();
    let truth = |state: &MonitorState| robot_of(state, p.player).cloned();
    'pushes: for k in 0..p.pushes_per_run {
        let direction = p.directions[k % p.directions.len()];
        // Walking after a ball ahead, upright for the settle time.
        let settle = uniform(&mut rng, p.settle);
        let mut help = Help::new(session.now);
        let mut upright_since: Option<f64> = None;
        let mut chase_placed = f64::NEG_INFINITY;
        let robot = loop {
            let state = session.next()?;
            motion.sample(&state, &[p.player]);
            let Some(robot) = truth(&state) else { continue };
            if !standing(&robot) {
                upright_since = None;
                match help.step(session.now, p.recovery_timeout) {
                    HelpStep::Wait => {}
                    HelpStep::PutUpright => {
                        session.server.command(vec![help_up(p.player, &robot)]);
                    }
                    HelpStep::GiveUp => {
                        bar.println(format!(
                            "run {run}: the robot did not stand after {} help-ups; its \
                             remaining pushes are not made",
                            help.given
                        ));
                        if let Some(last) = pushes.last_mut() {
                            last.helped_up = true;
                        }
                        break 'pushes;
                    }
                }
                continue;
            }
            let since = *upright_since.get_or_insert(session.now);
            if session.now - chase_placed > 4.0 {
                let turn = rng.random_range(-0.6..0.6);
                session.server.command(vec![ball_ahead(&robot, p.chase_distance, turn)]);
                chase_placed = session.now;
            }
            if session.now - since >= settle && session.now - chase_placed > 1.0 {
                break robot;
            }
        };
        // Helped up while waiting: after the previous push.
        if let Some(last) = pushes.last_mut() {
            last.helped_up |= help.given > 0;
        }
        session.server.command(vec![push_command(p, &robot, direction)]);
        let at = session.now;
        let mut fell = false;
        let mut ball_stopped = false;
        while session.now < at + p.fall_window {
            let state = session.next()?;
            motion.sample(&state, &[p.player]);
            if truth(&state).is_some_and(|r| tilt_of(r.orientation) > FALL_ONSET_TILT) {
                fell = true;
            }
            // The shot ball would roll off the field: stopped once it has pushed.
            if !ball_stopped && p.method == PushMethod::Ball && session.now > at + 0.5 {
                if let Some(r) = truth(&state) {
                    session.server.command(vec![ball_ahead(&r, p.chase_distance, 0.0)]);
                }
                ball_stopped = true;
            }
        }
        pushes.push(Push { run, at, direction: direction.name(), fell, helped_up: false });
    }
    // Standing again after the last push, and long enough for the platform to call it so.
    let mut help = Help::new(session.now);
    let mut upright_since: Option<f64> = None;
    loop {
        let state = session.next()?;
        motion.sample(&state, &[p.player]);
        let Some(robot) = truth(&state) else { continue };
        if standing(&robot) {
            let since = *upright_since.get_or_insert(session.now);
            if session.now - since > UPRIGHT_HOLD + 0.5 {
                break;
            }
        } else {
            upright_since = None;
            match help.step(session.now, p.recovery_timeout) {
                HelpStep::Wait => {}
                HelpStep::PutUpright => {
                    session.server.command(vec![help_up(p.player, &robot)]);
                }
                HelpStep::GiveUp => break,
            }
        }
    }
    if let Some(last) = pushes.last_mut() {
        last.helped_up |= help.given > 0;
    }
    let played_s = session.now - kickoff;
    let reports = session.finish()?;
    let report = reports.into_iter().next().context("the pushed robot's report")?;
    let falls = push_falls(p, run, &report, &pushes);
    Ok(PushRun {
        result: RunResult {
            kind: "pushes",
            run,
            seed,
            robots: 1,
            played_s,
            walking_s: motion.walking_s,
            upright_s: motion.upright_s,
            falls: falls.len(),
            false_falls: report.false_falls,
            reactive_hz: report.reactive_hz,
            machine_load: load_average(),
        },
        pushes,
        falls,
    })
}

/// The robot's falls, each given the push that caused it (the last push at most the fall
/// window before its onset), else `walking`.
fn push_falls(p: &Pushes, run: usize, report: &RobotReport, pushes: &[Push]) -> Vec<Fall> {
    report
        .falls
        .iter()
        .map(|f| {
            let push = pushes
                .iter()
                .rev()
                .find(|push| push.at <= f.onset + 1e-9 && f.onset <= push.at + p.fall_window);
            fall_of("pushes", run, report.player, f, push)
        })
        .collect()
}

fn fall_of(
    kind: &'static str,
    run: usize,
    player: u8,
    f: &FallRecord,
    push: Option<&Push>,
) -> Fall {
    Fall {
        kind,
        run,
        player,
        cause: match (push, kind) {
            (Some(p), _) => format!("push {}", p.direction),
            (None, "walking") => "walking".to_owned(),
            // In a push run: after a get-up, or while walking after the ball.
            (None, _) => "no push".to_owned(),
        },
        onset: f.onset,
        crossing: f.crossing,
        ordered: f.ordered,
        onset_to_command: f.onset_to_order,
        percept_to_command: f.latency,
        reaction: f.reaction,
        onset_to_standing: f.upright.map(|u| u - f.onset),
        helped_up: push.is_some_and(|p| p.helped_up),
    }
}

/// One server, `robots` T1s chasing a ball the trainer moves, no pushes.
fn run_walking(
    scenario: &Scenario,
    ctx: &Ctx<'_>,
    run: usize,
    bar: &ProgressBar,
) -> Result<(RunResult, Vec<Fall>)> {
    let w = &scenario.walking;
    let seed = ctx.seed(run).wrapping_add(5000);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7761_6c6b);
    let players: Vec<u8> = (0..w.robots).map(|i| 2 + i).collect();
    let launches = players
        .iter()
        .enumerate()
        .map(|(i, player)| launch(scenario, ctx, *player, [-3.0, 3.0 - 2.0 * i as f64, 0.0], seed))
        .collect::<Result<Vec<_>>>()?;
    let mut session = Session::start(&launches, bar.clone())?;
    let joined = session.wait_for_robots(&players)?;
    session.until(joined + w.ready)?;
    session.server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
    let kickoff = session.now;
    let mut motion = Motion::default();
    let mut next_ball = kickoff + 1.0;
    let [[x0, x1], [y0, y1]] = w.ball_area;
    while session.now < kickoff + w.duration {
        let state = session.next()?;
        motion.sample(&state, &players);
        if session.now >= next_ball {
            session
                .server
                .command(vec![ball_at(uniform(&mut rng, [x0, x1]), uniform(&mut rng, [y0, y1]))]);
            next_ball += w.ball_every;
        }
    }
    let played_s = session.now - kickoff;
    let reports = session.finish()?;
    let falls: Vec<Fall> = reports
        .iter()
        .flat_map(|r| r.falls.iter().map(|f| fall_of("walking", run, r.player, f, None)))
        .collect();
    let result = RunResult {
        kind: "walking",
        run,
        seed,
        robots: reports.len(),
        played_s,
        walking_s: motion.walking_s,
        upright_s: motion.upright_s,
        falls: falls.len(),
        false_falls: reports.iter().flat_map(|r| r.false_falls.iter().copied()).collect(),
        reactive_hz: mean(&reports.iter().map(|r| r.reactive_hz).collect::<Vec<_>>()),
        machine_load: load_average(),
    };
    Ok((result, falls))
}

// ---------------------------------------------------------------------------------------------
// The experiment.

/// A target, what was measured against it, and whether it is met.
#[derive(Clone, Debug, Serialize)]
pub struct Target {
    pub target: f64,
    pub measured: f64,
    pub met: bool,
}

/// The 2D simulator's figures beside the physics ones.
#[derive(Clone, Debug, Serialize)]
pub struct Figures2d {
    /// `lockstep` when run in this command, `documented` when quoted from the docs.
    pub source: String,
    pub onset_to_command_median_ms: f64,
    pub percepts_to_command_median_ms: f64,
    pub standing_median_s: f64,
    pub false_positives: Option<usize>,
    pub walking_hours: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub engine: Engine,
    pub scenario: String,
    pub seed: u64,
    pub push_method: PushMethod,
    pub push_runs: usize,
    pub pushes: usize,
    pub pushes_with_fall: usize,
    /// Every fall, pushed or not (walking: collisions and stumbles).
    pub falls: usize,
    pub falls_pushed: usize,
    /// Falls in the push runs no push caused (after a get-up, or while walking).
    pub falls_unpushed: usize,
    /// Falls in the walking runs (collisions and stumbles).
    pub falls_walking: usize,
    /// Falls with a Fall order.
    pub detected: usize,
    /// Falls whose Fall order came before the onset perception (the detector predicted them).
    pub ordered_before_onset: usize,
    /// Interpolated ground-truth onset to the Fall order, s.
    pub onset_to_command: Distribution,
    /// The first percept past the onset tilt (its arrival) to the Fall order, s.
    pub percept_to_command: Distribution,
    /// The newest percept (its arrival) to the Fall order, s.
    pub reaction: Distribution,
    /// Onset to standing again, s (falls the robot got up from by itself).
    pub onset_to_standing: Distribution,
    pub stood_up: usize,
    pub helped_up: usize,
    /// Fall orders no fall followed, in the walking runs and in the push runs.
    pub false_positives_walking: usize,
    pub false_positives_pushes: usize,
    /// Robot-minutes of play in the walking runs, standing (the ground truth), chasing the
    /// ball: what the false-positive target counts.
    pub playing_robot_minutes: f64,
    /// Of them, moving faster than 0.05 m/s.
    pub walking_robot_minutes: f64,
    pub target_onset_to_command_ms: Target,
    pub target_percept_to_command_ms: Target,
    /// Measured: false positives; met: none in at least the target's minutes of walking.
    pub target_false_positives: Target,
    pub reactive_hz: Estimate,
    pub sim2d: Vec<Figures2d>,
    pub machine_load_1min: Vec<f64>,
}

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let push_runs = ctx.runs(scenario.pushes.runs);
    let expected = push_runs as f64
        * (scenario.pushes.ready + 20.0 * scenario.pushes.pushes_per_run as f64)
        + scenario.walking.runs as f64 * (scenario.walking.ready + scenario.walking.duration);
    // The 2D experiment first: it takes seconds, and a failure there should not wait for
    // minutes of physics.
    let sim2d = figures_2d(scenario, ctx)?;
    let bar = ctx.progress(expected.ceil() as u64, "simulated s (approx.)");
    let mut results = Vec::new();
    let mut pushes = Vec::new();
    let mut falls = Vec::new();
    for run in 0..push_runs {
        bar.set_message(format!("pushes, run {}/{push_runs}", run + 1));
        let r = run_pushes(scenario, ctx, run, &bar).with_context(|| format!("push run {run}"))?;
        results.push(r.result);
        pushes.extend(r.pushes);
        falls.extend(r.falls);
    }
    for run in 0..scenario.walking.runs {
        bar.set_message(format!("walking, run {}/{}", run + 1, scenario.walking.runs));
        let (result, walking_falls) =
            run_walking(scenario, ctx, run, &bar).with_context(|| format!("walking run {run}"))?;
        results.push(result);
        falls.extend(walking_falls);
    }
    bar.finish_and_clear();
    let summary = summarize(scenario, ctx, push_runs, &results, &pushes, &falls, sim2d);
    report::write_outputs(scenario, ctx, &results, &pushes, &falls, &summary)?;
    Ok(summary)
}

fn summarize(
    scenario: &Scenario,
    ctx: &Ctx<'_>,
    push_runs: usize,
    results: &[RunResult],
    pushes: &[Push],
    falls: &[Fall],
    sim2d: Vec<Figures2d>,
) -> Summary {
    let onset: Vec<f64> = falls.iter().filter_map(|f| f.onset_to_command).collect();
    let percept: Vec<f64> = falls.iter().filter_map(|f| f.percept_to_command).collect();
    let standing: Vec<f64> =
        falls.iter().filter(|f| !f.helped_up).filter_map(|f| f.onset_to_standing).collect();
    let walking_runs = || results.iter().filter(|r| r.kind == "walking");
    let false_walking: usize = walking_runs().map(|r| r.false_falls.len()).sum();
    let false_pushes: usize =
        results.iter().filter(|r| r.kind == "pushes").map(|r| r.false_falls.len()).sum();
    let walking_minutes: f64 = walking_runs().map(|r| r.walking_s).sum::<f64>() / 60.0;
    let playing_minutes: f64 = walking_runs().map(|r| r.upright_s).sum::<f64>() / 60.0;
    let onset_ms = 1000.0 * percentile(&onset, 0.5);
    let percept_ms = 1000.0 * percentile(&percept, 0.5);
    let t = &scenario.targets;
    Summary {
        experiment: NAME.to_owned(),
        engine: Engine::Rcssservermj,
        scenario: ctx.scenario_source.clone(),
        seed: ctx.options.seed,
        push_method: scenario.pushes.method,
        push_runs,
        pushes: pushes.len(),
        pushes_with_fall: pushes.iter().filter(|p| p.fell).count(),
        falls: falls.len(),
        falls_pushed: falls.iter().filter(|f| f.cause.starts_with("push ")).count(),
        falls_unpushed: falls.iter().filter(|f| f.cause == "no push").count(),
        falls_walking: falls.iter().filter(|f| f.cause == "walking").count(),
        detected: falls.iter().filter(|f| f.ordered.is_some()).count(),
        ordered_before_onset: falls
            .iter()
            .filter(|f| f.percept_to_command.is_some_and(|l| l < 0.0))
            .count(),
        onset_to_command: Distribution::of(&onset),
        percept_to_command: Distribution::of(&percept),
        reaction: Distribution::of(&falls.iter().filter_map(|f| f.reaction).collect::<Vec<_>>()),
        onset_to_standing: Distribution::of(&standing),
        stood_up: standing.len(),
        helped_up: pushes.iter().filter(|p| p.helped_up).count(),
        false_positives_walking: false_walking,
        false_positives_pushes: false_pushes,
        playing_robot_minutes: playing_minutes,
        walking_robot_minutes: walking_minutes,
        target_onset_to_command_ms: Target {
            target: t.onset_to_command_ms,
            measured: onset_ms,
            met: onset_ms <= t.onset_to_command_ms,
        },
        target_percept_to_command_ms: Target {
            target: t.percept_to_command_ms,
            measured: percept_ms,
            met: percept_ms <= t.percept_to_command_ms,
        },
        target_false_positives: Target {
            target: t.walking_minutes,
            measured: false_walking as f64,
            met: false_walking == 0 && playing_minutes >= t.walking_minutes,
        },
        reactive_hz: Estimate::of(&results.iter().map(|r| r.reactive_hz).collect::<Vec<_>>()),
        sim2d,
        machine_load_1min: results.iter().filter_map(|r| r.machine_load).collect(),
    }
}

/// The 2D figures: the documented real-time ones, and the lockstep run's if the scenario asks
/// for it (the 2D experiment's own code, its report in `2d/`).
fn figures_2d(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Vec<Figures2d>> {
    let s = &scenario.sim2d;
    let mut figures = vec![Figures2d {
        source: format!("documented: {}", s.documented_source),
        onset_to_command_median_ms: s.documented_onset_to_command_ms,
        percepts_to_command_median_ms: s.documented_percepts_to_command_ms,
        standing_median_s: s.documented_standing_s,
        false_positives: None,
        walking_hours: None,
    }];
    if !s.run {
        return Ok(figures);
    }
    let source = "built-in scenario crates/experiments/scenarios/fall.toml, host = lockstep";
    let mut scenario_2d: fall2d::Scenario = parse_scenario(fall2d::DEFAULT_SCENARIO, source)?;
    scenario_2d.host = HostKind::Lockstep;
    scenario_2d.validate(&Check { source_name: source }, None)?;
    let out_dir = ctx.out_dir.join("2d");
    std::fs::create_dir_all(&out_dir)
        .with_context(|| format!("creating the output directory {}", out_dir.display()))?;
    let options = Options {
        engine: Engine::Sim,
        out: Some(out_dir.clone()),
        scenario: None,
        runs: None,
        log: None,
        progress: false,
        ..ctx.options.clone()
    };
    let mut ctx_2d = Ctx {
        name: fall2d::NAME,
        options: &options,
        out_dir,
        scenario_source: source.to_owned(),
        scenario_text: fall2d::DEFAULT_SCENARIO.replace(
            "host = \"threaded\"",
            "host = \"lockstep\"   # set by strata experiment fall --engine rcssservermj",
        ),
        scenario_dir: None,
        files: Vec::new(),
    };
    let summary = fall2d::run(&scenario_2d, &mut ctx_2d).context("the 2D fall experiment")?;
    ctx.files.extend(ctx_2d.files);
    figures.push(Figures2d {
        source: "lockstep: this command, report in 2d/report.md".to_owned(),
        onset_to_command_median_ms: 1000.0 * summary.detection_latency.median,
        percepts_to_command_median_ms: 1000.0 * summary.sensing_to_command.median,
        standing_median_s: summary.standing_time.median,
        false_positives: Some(summary.false_positives),
        walking_hours: Some(summary.walking_hours),
    });
    Ok(figures)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_scenario_is_valid_and_walks_ten_robot_minutes() {
        let mut scenario: Scenario = parse_scenario(DEFAULT_SCENARIO, "built-in").expect("parses");
        scenario.validate(&Check { source_name: "built-in" }, None).expect("valid");
        let w = &scenario.walking;
        assert!(w.runs as f64 * f64::from(w.robots) * w.duration >= 600.0);
        assert_eq!(scenario.pushes.method, PushMethod::Tilt);
    }

    #[test]
    fn the_trainer_helps_a_robot_that_stays_down_a_bounded_number_of_times() {
        let mut help = Help::new(0.0);
        let mut steps = Vec::new();
        // A robot that never stands, sampled every 0.5 s for 10 minutes.
        for k in 0..1200 {
            match help.step(f64::from(k) * 0.5, 30.0) {
                HelpStep::Wait => {}
                step => steps.push((f64::from(k) * 0.5, step)),
            }
            if steps.last().is_some_and(|(_, s)| *s == HelpStep::GiveUp) {
                break;
            }
        }
        let puts: Vec<f64> =
            steps.iter().filter(|(_, s)| *s == HelpStep::PutUpright).map(|(t, _)| *t).collect();
        assert_eq!(puts, [30.5, 61.0, 91.5]);
        assert_eq!(steps.last(), Some(&(122.0, HelpStep::GiveUp)));
    }

    #[test]
    fn a_bad_value_names_the_field() {
        let text = DEFAULT_SCENARIO.replace("ball_distance = 0.6", "ball_distance = 0.1");
        let mut scenario: Scenario = parse_scenario(&text, "s.toml").expect("parses");
        let error = scenario.validate(&Check { source_name: "s.toml" }, None).expect_err("refused");
        assert!(error.to_string().contains("s.toml: field `pushes.ball_distance`"), "{error}");
    }

    #[test]
    fn a_tilt_towards_a_side_tilts_the_torso_that_much_and_keeps_the_heading() {
        for heading in [0.0, 1.0, -2.5] {
            for direction in [Direction::Front, Direction::Back, Direction::Left, Direction::Right]
            {
                let u = direction.unit(heading);
                let q = tilted_towards(heading, 0.4, u);
                assert!((tilt_of(q) - 0.4).abs() < 1e-9, "{direction:?} {heading}");
                // The torso's z axis leans towards the push.
                let [w, x, y, z] = q;
                let lean = [2.0 * (x * z + w * y), 2.0 * (y * z - w * x)];
                assert!(lean[0] * u[0] + lean[1] * u[1] > 0.3, "{direction:?} {heading}: {lean:?}");
                let back = tilted_towards(heading, 0.0, u);
                assert!((heading_of(back) - heading).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn falls_get_the_push_that_caused_them_and_the_others_are_walking() {
        let pushes = pushes_for_test();
        let record = |onset: f64| -> FallRecord {
            serde_json::from_value(serde_json::json!({
                "onset": onset, "crossing": onset - 0.01, "ordered": onset, "latency": 0.004,
                "onset_to_order": 0.014, "upright": onset + 7.0
            }))
            .expect("a fall record")
        };
        let report = RobotReport {
            player: 2,
            falls: vec![record(10.3), record(30.0)],
            false_falls: Vec::new(),
            reactive_hz: 50.0,
        };
        let p: Scenario = parse_scenario(DEFAULT_SCENARIO, "built-in").expect("parses");
        let falls = push_falls(&p.pushes, 0, &report, &pushes);
        assert_eq!(falls[0].cause, "push back");
        assert_eq!(falls[1].cause, "no push");
        assert_eq!(falls[0].onset_to_standing, Some(7.0));
        assert_eq!(falls[0].onset_to_command, Some(0.014));
    }

    fn pushes_for_test() -> Vec<Push> {
        vec![
            Push { run: 0, at: 5.0, direction: "front", fell: false, helped_up: false },
            Push { run: 0, at: 10.0, direction: "back", fell: true, helped_up: false },
        ]
    }

    #[test]
    fn histogram_bins_are_ten_ms_wide() {
        let (groups, counts) = report::histogram(&[-3.0, 2.0, 5.0, 14.0]);
        assert_eq!(groups, ["-10 to 0 ms", "0 to 10 ms", "10 to 20 ms"]);
        assert_eq!(counts.iter().map(|c| c.mean).collect::<Vec<_>>(), [1.0, 2.0, 1.0]);
    }
}
