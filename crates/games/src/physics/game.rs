//! A game of T1s in rcssservermj (`strata match --engine rcssservermj`): the server started
//! from the project's environment, headless and in sync mode, one `strata robot` process per
//! robot with the full architecture, the server's referee ruling (kick-offs, goals, the ball
//! out of play), and the same report as a 2D match.
//!
//! The server plays one half per run (its referee ends the game at the end of the half it
//! started in), so each half is a fresh server started in that half (`--phase`), with the
//! play clock set so the half lasts the requested time (`--time`). The team that connects
//! first is the server's left team: the home team in the first half, the away team in the
//! second, so the teams change ends. The left team kicks off each half.
//!
//! Robots are processes rather than threads of this one: each runs as it would on a robot (its
//! own host, its own real-time pacing), a robot that fails ends alone, and each one's CPU time
//! is its own (`/proc`), to set against the server's physics.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use serde::{Deserialize, Serialize};
use strata_rcssmj::protocol::FieldSide;
use strata_rcssmj::protocol::PlayMode;
use strata_rcssmj::protocol::monitor::{MonitorCommand, MonitorState};
use strata_rcssmj::server::{ServerOptions, ServerProcess};
use strata_soccer::behaviors::kickoff_pose;
use strata_soccer::catalog::Role;
use strata_soccer::field::TeamField;
use strata_soccer::team::TeamConfig;
use strata_spl::Field;

use super::cpu::process_cpu_seconds;
use super::robot::{T1Launch, T1Process, free_udp_ports};
use crate::matches::{
    LayerRate, MatchEvent, MatchReport, RobotReport, RoleSampler, TeamMessageStats, TeamReport,
};

/// The length of a half in the server's `ssim` rule book, play seconds.
pub const RULES_HALF_TIME: f64 = 300.0;
/// The SPL's team-message budget per team and game, which the referee's packets announce.
pub const MESSAGE_BUDGET: u16 = 1200;
/// The most robots per team the server's rule book allows.
pub const MAX_PLAYERS: u8 = 7;

/// What a game needs.
#[derive(Clone, Debug)]
pub struct GameConfig {
    /// The `strata` executable the robots run.
    pub exe: PathBuf,
    /// Robots per team.
    pub players: u8,
    /// Seeds what Strata draws (camera models, modules); the physics is not seeded.
    pub seed: u64,
    /// Built-in team names or team TOML files.
    pub home: String,
    pub away: String,
    /// Play seconds per half, at most [`RULES_HALF_TIME`].
    pub half: f64,
    /// Stop after this many play seconds (both halves counted); `None`: the whole game.
    pub limit: Option<f64>,
    /// Record each robot into `STEM-hN-home-P.mcap` beside this path.
    pub log: Option<PathBuf>,
    /// How long a robot may take to join before the game is called off.
    pub join_timeout: Duration,
    /// Wall seconds without the simulation advancing after which the server counts as hung.
    pub stall_timeout: Duration,
}

impl GameConfig {
    pub fn validate(&self) -> Result<()> {
        if self.players == 0 || self.players > MAX_PLAYERS {
            bail!(
                "--players must be 1 to {MAX_PLAYERS} on rcssservermj (its rule book's team \
                 size), got {}",
                self.players
            );
        }
        if !(self.half.is_finite() && self.half > 0.0 && self.half <= RULES_HALF_TIME) {
            bail!(
                "--half must be more than 0 and at most {RULES_HALF_TIME} s on rcssservermj (its \
                 rule book's half), got {}",
                self.half
            );
        }
        if self.limit.is_some_and(|l| !(l.is_finite() && l > 0.0)) {
            bail!("--duration must be a number of seconds > 0");
        }
        Ok(())
    }
}

/// What only a game in physics reports, beside the 2D match's report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhysicsReport {
    /// The server's executable.
    pub server: String,
    /// Play seconds per half.
    pub half_s: f64,
    pub halves: Vec<HalfReport>,
    pub robots: Vec<PhysicsRobot>,
    pub cpu: CpuShare,
    /// Whether a seed reproduces the game, and why not.
    pub reproducible: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HalfReport {
    pub half: u8,
    /// The team on the server's left (defending x < 0, kicking off).
    pub left: String,
    /// Play seconds the server's referee counted.
    pub play_s: f64,
    /// Simulated seconds (MuJoCo's clock, including before the kick-off and after goals).
    pub simulated_s: f64,
    pub wall_s: f64,
    /// Goals in this half: home, away.
    pub goals: [u8; 2],
    /// The server's referee ended the half.
    pub finished: bool,
    /// How far the ball rolled during play, m (ground truth, sampled ten times a second).
    pub ball_travel_m: f64,
    /// How close the ball came to the centre of the goal each team defends (home, away), m.
    pub ball_nearest_goal_m: [f64; 2],
}

/// One robot over the whole game (both its processes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhysicsRobot {
    pub name: String,
    /// Falls by the ground truth (the torso tilted past the onset angle).
    pub falls: usize,
    /// Falls after which the robot stood again.
    pub stood_up: usize,
    /// From each fall's onset perception to the protective-fall order, ms.
    pub fall_latency_ms: Vec<f64>,
    /// CPU time of its processes, s.
    pub cpu_s: f64,
    /// Its share of the game's CPU time (server and every robot).
    pub cpu_share: f64,
    /// Mean self-localization error against the ground truth, m, per half.
    pub localization_mean_m: Vec<f64>,
    /// How each of its processes ended.
    pub ended: Vec<String>,
}

/// How the game's CPU time split between the physics and Strata.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CpuShare {
    pub server_s: f64,
    pub robots_s: f64,
    /// Every robot's share together.
    pub strata_share: f64,
    /// The largest one robot's share.
    pub max_robot_share: f64,
    /// The target: every robot under 10 % of the game's CPU.
    pub target_share: f64,
    pub target_met: bool,
}

const TARGET_ROBOT_SHARE: f64 = 0.10;

/// One team as the game knows it.
#[derive(Clone, Debug)]
struct Side {
    /// 0 home, 1 away.
    index: usize,
    number: u8,
    /// The team's name in the server.
    server_name: String,
    config_arg: String,
    config: TeamConfig,
}

/// Plays a game; `progress` gets the fraction of play done and the score line.
pub fn play(config: &GameConfig, progress: &mut dyn FnMut(f64, &str)) -> Result<MatchReport> {
    config.validate()?;
    super::check_interrupt()?;
    let resolve = |arg: &str, which: &str| {
        TeamConfig::resolve(arg).with_context(|| format!("{which} team configuration `{arg}`"))
    };
    let mut sides = [
        Side {
            index: 0,
            number: 1,
            server_name: "StrataHome".to_owned(),
            config_arg: config.home.clone(),
            config: resolve(&config.home, "home")?,
        },
        Side {
            index: 1,
            number: 2,
            server_name: "StrataAway".to_owned(),
            config_arg: config.away.clone(),
            config: resolve(&config.away, "away")?,
        },
    ];
    if sides[0].config.name == sides[1].config.name {
        // Reports name teams by their configuration: two of the same need telling apart.
        for (side, place) in sides.iter_mut().zip(["home", "away"]) {
            side.config.name = format!("{} ({place})", side.config.name);
        }
    }
    let field = Field::preset("rcssservermj").context("the rcssservermj field")?;
    let workdir = tempdir_for(config.seed)?;
    let rcss_config = workdir.join("t1.toml");
    std::fs::write(&rcss_config, format!("players_per_team = {}\n", config.players))
        .with_context(|| format!("writing {}", rcss_config.display()))?;

    let started = Instant::now();
    let mut state = GameState::default();
    for half in 0..2u8 {
        let done = f64::from(half) * config.half;
        let remaining = config.limit.map_or(config.half, |l| (l - done).min(config.half));
        if remaining <= 0.0 {
            break;
        }
        let left = if half == 0 { &sides[0] } else { &sides[1] };
        let right = if half == 0 { &sides[1] } else { &sides[0] };
        let run = HalfRun {
            config,
            half,
            play: remaining,
            left,
            right,
            field: &field,
            rcss_config: &rcss_config,
        };
        run.play(&mut state, progress)?;
    }
    let _ = std::fs::remove_dir_all(&workdir);
    Ok(state.report(config, &sides, started.elapsed().as_secs_f64()))
}

fn tempdir_for(seed: u64) -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("strata-game-{}-{seed}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}

/// What the halves gather for the report.
#[derive(Default)]
struct GameState {
    events: Vec<MatchEvent>,
    goals: [u8; 2],
    halves: Vec<HalfReport>,
    sampler: RoleSampler,
    /// Per robot name: the final reports of its processes.
    reports: BTreeMap<String, Vec<serde_json::Value>>,
    ended: BTreeMap<String, Vec<String>>,
    robot_cpu: BTreeMap<String, f64>,
    server_cpu: f64,
    server: String,
    simulated_s: f64,
}

struct HalfRun<'a> {
    config: &'a GameConfig,
    half: u8,
    /// Play seconds this half lasts.
    play: f64,
    left: &'a Side,
    right: &'a Side,
    field: &'a Field,
    rcss_config: &'a Path,
}

/// A robot of this half, with its name in reports.
struct Player {
    name: String,
    side: usize,
    process: T1Process,
}

impl HalfRun<'_> {
    fn play(&self, state: &mut GameState, progress: &mut dyn FnMut(f64, &str)) -> Result<()> {
        let half_start = f64::from(self.half) * RULES_HALF_TIME + (RULES_HALF_TIME - self.play);
        let options = ServerOptions {
            extra: vec![
                "--phase".to_owned(),
                self.half.to_string(),
                "--time".to_owned(),
                format!("{half_start}"),
            ],
            ..ServerOptions::default()
        };
        let mut server = ServerProcess::start(&options).context("starting rcssservermj")?;
        state.server = server.program().display().to_string();
        let wall = Instant::now();
        // One port per team, shared by its robots.
        let ports = free_udp_ports::<2>()?;
        let mut players = Vec::new();
        // The first team to connect is the left one: all of it first.
        for (side, field_side) in [(self.left, FieldSide::Left), (self.right, FieldSide::Right)] {
            for player in 1..=self.config.players {
                players.push(self.spawn(&server, side, field_side, player, ports[side.index])?);
            }
            if field_side == FieldSide::Left {
                self.wait_until("the left team is listed", &mut players, || {
                    server
                        .truth()
                        .game
                        .and_then(|g| g.team_left)
                        .is_some_and(|name| name == side.server_name)
                })?;
            }
        }
        let total = usize::from(self.config.players) * 2;
        self.wait_until("every robot is on the field", &mut players, || {
            server.truth().robots.len() >= total
        })?;
        // Beamed robots stand up from their placement before the whistle.
        let joined = server.truth().sim_time.unwrap_or(0.0);
        self.wait_until("the robots stand", &mut players, || {
            server.truth().sim_time.is_some_and(|t| t >= joined + 2.0)
        })?;
        server.command(vec![MonitorCommand::KickOff(Some(FieldSide::Left))]);
        state.events.push(MatchEvent {
            time: f64::from(self.half) * self.config.half,
            kind: "kick-off".into(),
            detail: format!("{} kicks off half {}", self.left.config.name, self.half + 1),
        });

        let result = self.follow(&server, state, &mut players, progress);
        let server_cpu = process_cpu_seconds(server.pid());
        // Stop the robots before the server so none reports a lost server.
        for p in &mut players {
            p.process.interrupt();
        }
        for p in &mut players {
            let cpu = p.process.sample_cpu();
            let (report, status) = p.process.finish(Duration::from_secs(30));
            let cpu = p.process.sample_cpu().max(cpu);
            *state.robot_cpu.entry(p.name.clone()).or_default() += cpu;
            let ended = match (&report, status) {
                (Some(r), _) => r["ended"].as_str().unwrap_or("ended").to_owned(),
                (None, status) => format!(
                    "no report ({}); stderr: {}",
                    status.map_or("killed".to_owned(), |s| s.to_string()),
                    p.process.stderr_tail(3)
                ),
            };
            state.ended.entry(p.name.clone()).or_default().push(ended);
            if let Some(report) = report {
                state.reports.entry(p.name.clone()).or_default().push(report);
            }
        }
        state.server_cpu += server_cpu.unwrap_or(0.0);
        server.kill();
        let half = result?;
        state.simulated_s += half.simulated_s;
        state.halves.push(HalfReport { wall_s: wall.elapsed().as_secs_f64(), ..half });
        Ok(())
    }

    fn spawn(
        &self,
        server: &ServerProcess,
        side: &Side,
        field_side: FieldSide,
        player: u8,
        team_port: u16,
    ) -> Result<Player> {
        let attack_sign = match field_side {
            FieldSide::Left => 1.0,
            FieldSide::Right => -1.0,
        };
        let team_field = TeamField::new(self.field.clone(), attack_sign);
        let pose = kickoff_pose(&team_field, player, field_side == FieldSide::Left, true);
        // The server leaves a beam's y in its own frame: the right team's is mirrored.
        let beam = [pose.x, attack_sign * pose.y, pose.theta.to_degrees()];
        let name = format!("{}/{player}", if side.index == 0 { "home" } else { "away" });
        let log = self.config.log.as_ref().map(|path| {
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("game");
            let file = format!(
                "{stem}-h{}-{}-{player}.mcap",
                self.half + 1,
                if side.index == 0 { "home" } else { "away" }
            );
            path.with_file_name(file)
        });
        let launch = T1Launch {
            exe: self.config.exe.clone(),
            server: server.agent_address(),
            team: side.number,
            team_name: side.server_name.clone(),
            player,
            beam,
            team_config: side.config_arg.clone(),
            seed: self.config.seed * 1000 + u64::from(side.number) * 100 + u64::from(player),
            team_port: Some(team_port),
            log,
            status_interval: 1.0,
            duration: None,
            extra: vec![
                "--rcss-config".to_owned(),
                self.rcss_config.display().to_string(),
                "--half-duration".to_owned(),
                RULES_HALF_TIME.to_string(),
            ],
        };
        let process = T1Process::spawn(&launch)?;
        Ok(Player { name, side: side.index, process })
    }

    /// Waits for `ready`, failing if a robot ends or the join takes too long.
    fn wait_until(
        &self,
        what: &str,
        players: &mut [Player],
        mut ready: impl FnMut() -> bool,
    ) -> Result<()> {
        let deadline = Instant::now() + self.config.join_timeout;
        loop {
            super::check_interrupt()?;
            if ready() {
                return Ok(());
            }
            for p in players.iter_mut() {
                if let Some(status) = p.process.exited() {
                    bail!(
                        "robot {} ended ({status}) before {what}: {}",
                        p.name,
                        p.process.stderr_tail(5)
                    );
                }
            }
            if Instant::now() > deadline {
                bail!(
                    "gave up waiting {:?} for: {what} (is the machine overloaded?)",
                    self.config.join_timeout
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Follows the half until the server's referee ends it; returns the half's figures.
    fn follow(
        &self,
        server: &ServerProcess,
        state: &mut GameState,
        players: &mut [Player],
        progress: &mut dyn FnMut(f64, &str),
    ) -> Result<HalfReport> {
        let start = server.truth();
        let sim_start = start.sim_time.unwrap_or(0.0);
        let half_start = start.game.as_ref().map_or(0.0, |g| g.play_time);
        let base = f64::from(self.half) * self.config.half;
        let total = self.config.limit.unwrap_or(2.0 * self.config.half);
        let mut last_mode: Option<PlayMode> = None;
        let mut last_score = (0u32, 0u32);
        let mut advanced = (sim_start, Instant::now());
        let mut exited: Vec<bool> = vec![false; players.len()];
        let mut last_sample = Instant::now();
        let goal_x = self.field.dimensions().field_length / 2.0;
        let mut ball_travel = 0.0;
        let mut last_ball: Option<[f64; 2]> = None;
        // The ball starts each half on the centre spot; the left team defends x < 0.
        let mut nearest = [goal_x; 2];
        loop {
            std::thread::sleep(Duration::from_millis(100));
            super::check_interrupt()?;
            let truth: MonitorState = server.truth();
            let sim = truth.sim_time.unwrap_or(sim_start);
            if sim > advanced.0 {
                advanced = (sim, Instant::now());
            } else if advanced.1.elapsed() > self.config.stall_timeout {
                bail!(
                    "rcssservermj stopped stepping: the simulation stood at {sim:.2} s for {:?} \
                     (a robot that stopped answering holds a server in sync mode)",
                    self.config.stall_timeout
                );
            }
            let Some(game) = truth.game.clone() else { continue };
            if let Some([x, y, _]) = truth.ball_position {
                if let Some([px, py]) = last_ball {
                    let step = (x - px).hypot(y - py);
                    // A jump is the referee placing the ball, not a roll.
                    if step < 2.0 {
                        ball_travel += step;
                    }
                }
                last_ball = Some([x, y]);
                nearest[self.left.index] = nearest[self.left.index].min((x + goal_x).hypot(y));
                nearest[self.right.index] = nearest[self.right.index].min((x - goal_x).hypot(y));
            }
            let played = (game.play_time - half_start).max(0.0);
            let t = base + played;
            // Goals: the server's left team is `self.left`.
            let score = (game.score_left, game.score_right);
            if score != last_score {
                for (side, before, after) in
                    [(self.left, last_score.0, score.0), (self.right, last_score.1, score.1)]
                {
                    for _ in before..after {
                        state.goals[side.index] = state.goals[side.index].saturating_add(1);
                        state.events.push(MatchEvent {
                            time: t,
                            kind: "goal".into(),
                            detail: format!(
                                "{} scores ({}-{})",
                                side.config.name, state.goals[0], state.goals[1]
                            ),
                        });
                    }
                }
                last_score = score;
            }
            if game.play_mode != last_mode {
                if let Some(mode) = game.play_mode {
                    state.events.push(MatchEvent {
                        time: t,
                        kind: "play mode".into(),
                        detail: self.describe(mode),
                    });
                }
                last_mode = game.play_mode;
            }
            for (i, p) in players.iter_mut().enumerate() {
                if !exited[i]
                    && let Some(status) = p.process.exited()
                {
                    exited[i] = true;
                    state.events.push(MatchEvent {
                        time: t,
                        kind: "robot ended".into(),
                        detail: format!("{} ({status}): {}", p.name, p.process.stderr_tail(3)),
                    });
                }
            }
            if last_sample.elapsed() >= Duration::from_secs(1) {
                last_sample = Instant::now();
                sample_roles(&mut state.sampler, t, players);
            }
            let line = format!(
                "{} {} - {} {}  (half {}, {:?})",
                "home",
                state.goals[0],
                state.goals[1],
                "away",
                self.half + 1,
                game.play_mode.map_or("", PlayMode::as_str)
            );
            progress((t / total).clamp(0.0, 1.0), &line);
            let over = game.play_mode == Some(PlayMode::GameOver);
            if over || played >= self.play + 0.5 {
                let mut goals = [0u8; 2];
                goals[self.left.index] = u8::try_from(score.0).unwrap_or(u8::MAX);
                goals[self.right.index] = u8::try_from(score.1).unwrap_or(u8::MAX);
                return Ok(HalfReport {
                    half: self.half + 1,
                    left: self.left.config.name.clone(),
                    play_s: played,
                    simulated_s: sim - sim_start,
                    wall_s: 0.0,
                    goals,
                    finished: over,
                    ball_travel_m: ball_travel,
                    ball_nearest_goal_m: nearest,
                });
            }
        }
    }

    fn describe(&self, mode: PlayMode) -> String {
        let name = mode.as_str();
        let lower = name.to_ascii_lowercase();
        let side = if lower.ends_with("left") {
            Some(self.left)
        } else if lower.ends_with("right") {
            Some(self.right)
        } else {
            None
        };
        match side {
            Some(side) => format!("{name} ({})", side.config.name),
            None => name.to_owned(),
        }
    }
}

/// One role sample: each robot playing (its newest status says Playing, not penalized).
fn sample_roles(sampler: &mut RoleSampler, t: f64, players: &mut [Player]) {
    let mut playing = Vec::new();
    for p in players.iter_mut() {
        p.process.sample_cpu();
        let Some(status) = p.process.latest("status") else { continue };
        if status["game_state"].as_str() != Some("Playing") || status["penalized"] == true {
            continue;
        }
        let role =
            status["role"].as_str().and_then(|r| Role::ALL.into_iter().find(|x| x.name() == r));
        if let Some(role) = role {
            playing.push((p.name.clone(), p.side, role));
        }
    }
    sampler.sample(t, &playing);
}

impl GameState {
    fn report(&self, config: &GameConfig, sides: &[Side; 2], wall_s: f64) -> MatchReport {
        let mut robots = Vec::new();
        let mut physics_robots = Vec::new();
        let total_cpu = self.server_cpu + self.robot_cpu.values().sum::<f64>();
        let mut sent = [0u64; 2];
        let mut received = 0u64;
        let mut team_falls = [0usize; 2];
        for side in sides {
            for player in 1..=config.players {
                let name = format!("{}/{player}", if side.index == 0 { "home" } else { "away" });
                let reports = self.reports.get(&name).map(Vec::as_slice).unwrap_or_default();
                let falls: Vec<&serde_json::Value> = reports
                    .iter()
                    .flat_map(|r| r["falls"].as_array().into_iter().flatten())
                    .collect();
                team_falls[side.index] += falls.len();
                for r in reports {
                    sent[side.index] += r["team_link"]["sent"].as_u64().unwrap_or(0);
                    received += r["team_link"]["received"].as_u64().unwrap_or(0);
                }
                let cpu_s = self.robot_cpu.get(&name).copied().unwrap_or(0.0);
                robots.push(RobotReport {
                    name: name.clone(),
                    team: side.index,
                    player,
                    layers: merge_layers(reports),
                    roles: self.sampler.robot_roles(&name),
                    falls: falls.len(),
                });
                physics_robots.push(PhysicsRobot {
                    name: name.clone(),
                    falls: falls.len(),
                    stood_up: falls.iter().filter(|f| f["upright"].is_number()).count(),
                    fall_latency_ms: falls
                        .iter()
                        .filter_map(|f| f["latency"].as_f64())
                        .map(|s| s * 1e3)
                        .collect(),
                    cpu_s,
                    cpu_share: if total_cpu > 0.0 { cpu_s / total_cpu } else { 0.0 },
                    localization_mean_m: reports
                        .iter()
                        .filter_map(|r| r["localization"]["mean_error_m"].as_f64())
                        .collect(),
                    ended: self.ended.get(&name).cloned().unwrap_or_default(),
                });
            }
        }
        let robots_s: f64 = self.robot_cpu.values().sum();
        let max_robot_share = physics_robots.iter().map(|r| r.cpu_share).fold(0.0, f64::max);
        let cpu = CpuShare {
            server_s: self.server_cpu,
            robots_s,
            strata_share: if total_cpu > 0.0 { robots_s / total_cpu } else { 0.0 },
            max_robot_share,
            target_share: TARGET_ROBOT_SHARE,
            target_met: total_cpu > 0.0 && max_robot_share < TARGET_ROBOT_SHARE,
        };
        let teams = [0, 1].map(|i| TeamReport {
            name: sides[i].config.name.clone(),
            team_number: sides[i].number,
            goals: self.goals[i],
            falls: team_falls[i],
            // The server's referee penalizes nobody: it moves misplaced robots.
            penalties: 0,
            messages_sent: sent[i],
            message_budget_left: MESSAGE_BUDGET
                .saturating_sub(u16::try_from(sent[i]).unwrap_or(u16::MAX)),
            roles: self.sampler.team_stats(i, config.players),
        });
        let finished = self.halves.len() == 2 && self.halves.iter().all(|h| h.finished);
        MatchReport {
            seed: config.seed,
            players_per_team: config.players,
            host: "rcssservermj, a threaded host per robot process".into(),
            score: self.goals,
            teams,
            finished,
            simulated_s: self.simulated_s,
            wall_s,
            real_time_factor: self.simulated_s / wall_s.max(1e-9),
            events: self.events.clone(),
            robots,
            team_messages: TeamMessageStats {
                sent: sent[0] + sent[1],
                delivered: received,
                // UDP on the loopback network: a message no teammate read is not counted.
                lost: 0,
                rejected_oversize: 0,
                over_budget: 0,
            },
            physics: Some(PhysicsReport {
                server: self.server.clone(),
                half_s: config.half,
                halves: self.halves.clone(),
                robots: physics_robots,
                cpu,
                reproducible: "no: MuJoCo runs in the server's process and steps when every \
                               robot has answered, the robots run in real time on threads, \
                               and the server's audio model draws from an unseeded generator; \
                               the seed fixes what Strata draws (camera models, modules)"
                    .into(),
            }),
        }
    }
}

/// A layer's rates over several processes: cycles add up, the mean is cycles over the time
/// they took, the extremes are the extremes.
fn merge_layers(reports: &[serde_json::Value]) -> Vec<LayerRate> {
    let mut merged: Vec<(LayerRate, f64)> = Vec::new();
    for report in reports {
        let Some(layers) = report["layers"].as_array() else { continue };
        for layer in layers {
            let Ok(rate) = serde_json::from_value::<LayerRate>(layer.clone()) else { continue };
            let seconds = if rate.mean_hz > 0.0 { rate.cycles as f64 / rate.mean_hz } else { 0.0 };
            match merged.iter_mut().find(|(m, _)| m.layer == rate.layer) {
                Some((m, time)) => {
                    m.cycles += rate.cycles;
                    *time += seconds;
                    m.min_hz = m.min_hz.min(rate.min_hz);
                    m.max_hz = m.max_hz.max(rate.max_hz);
                    m.mean_hz = if *time > 0.0 { m.cycles as f64 / *time } else { 0.0 };
                }
                None => merged.push((rate, seconds)),
            }
        }
    }
    merged.into_iter().map(|(rate, _)| rate).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layer(name: &str, cycles: u64, min: f64, mean: f64, max: f64) -> serde_json::Value {
        serde_json::json!({"layer": name, "cycles": cycles, "min_hz": min, "mean_hz": mean, "max_hz": max})
    }

    #[test]
    fn layer_rates_of_two_halves_merge_by_time() {
        let first = serde_json::json!({"layers": [layer("reactive", 500, 40.0, 50.0, 60.0)]});
        let second = serde_json::json!({"layers": [layer("reactive", 250, 20.0, 25.0, 55.0)]});
        let merged = merge_layers(&[first, second]);
        let [reactive] = merged.as_slice() else { panic!("one layer: {merged:?}") };
        // 10 s at 50 Hz and 10 s at 25 Hz: 750 cycles in 20 s.
        assert_eq!(reactive.cycles, 750);
        assert!((reactive.mean_hz - 37.5).abs() < 1e-9, "{reactive:?}");
        assert_eq!((reactive.min_hz, reactive.max_hz), (20.0, 60.0));
    }

    fn config() -> GameConfig {
        GameConfig {
            exe: PathBuf::from("strata"),
            players: 3,
            seed: 1,
            home: "full".into(),
            away: "full".into(),
            half: 60.0,
            limit: None,
            log: None,
            join_timeout: Duration::from_secs(60),
            stall_timeout: Duration::from_secs(60),
        }
    }

    #[test]
    fn a_game_the_server_cannot_hold_is_refused_before_it_starts() {
        assert!(config().validate().is_ok());
        let error =
            GameConfig { players: 8, ..config() }.validate().expect_err("refused").to_string();
        assert!(error.contains("--players") && error.contains("7"), "{error}");
        let error =
            GameConfig { half: 301.0, ..config() }.validate().expect_err("refused").to_string();
        assert!(error.contains("--half"), "{error}");
        assert!(GameConfig { limit: Some(-1.0), ..config() }.validate().is_err());
    }
}
