//! Complete simulated games: two teams of soccer robots, every robot running the full
//! architecture (four modules, three layers), on the built-in simulator.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context as _, Result, bail};
use serde::{Deserialize, Serialize};
use strata_robot::assembly::RobotModules;
use strata_robot::edge::{RobotLinks, RobotPlatform};
use strata_runtime::{
    HostConfig, HostStats, LockstepHost, Tap, TapOutput, TapRecord, ThreadedHost, Time,
};
use strata_sim::{EventKind, RobotId};
use strata_sim::{
    GameState, NoiseLevel, SimConfig, SimHandle, Simulation, SimulatorPorts, add_simulator,
};
use strata_soccer::catalog::Role;
use strata_soccer::field::TeamField;
use strata_soccer::team::{SoccerRobotSpec, TeamConfig, add_soccer_robot};

/// What to play.
#[derive(Clone, Debug)]
pub struct MatchConfig {
    pub players: u8,
    pub seed: u64,
    pub home: TeamConfig,
    pub away: TeamConfig,
    /// Length of a half, simulated seconds.
    pub half_duration: f64,
    /// Stop after this much simulated time, whatever the game state.
    pub limit: Option<f64>,
    pub noise: NoiseLevel,
    pub field: String,
    /// Team-message loss, in [0, 1].
    pub packet_loss: f64,
    /// Run on the threaded host, paced to real time (otherwise: lockstep, as fast as possible).
    pub realtime: bool,
    /// A simulator configuration to start from (otherwise the defaults with GameController3's
    /// timing and the referee's signals, `RefereeConfig::game_controller3`).
    pub sim: Option<SimConfig>,
    /// The referee sends every state at once, without Standby or signals (GameController3's
    /// `--no-delay`), whatever `sim` says.
    pub no_delay: bool,
}

impl Default for MatchConfig {
    fn default() -> Self {
        MatchConfig {
            players: 7,
            seed: 1,
            home: TeamConfig::default(),
            away: TeamConfig::default(),
            half_duration: 600.0,
            limit: None,
            noise: NoiseLevel::Default,
            field: "spl".into(),
            packet_loss: 0.0,
            realtime: false,
            sim: None,
            no_delay: false,
        }
    }
}

/// One robot's layers, as Table 6 reports them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LayerRate {
    pub layer: String,
    pub cycles: u64,
    pub min_hz: f64,
    pub mean_hz: f64,
    pub max_hz: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotReport {
    pub name: String,
    pub team: usize,
    pub player: u8,
    pub layers: Vec<LayerRate>,
    /// Fraction of sampled playing time spent in each role.
    pub roles: BTreeMap<String, f64>,
    pub falls: usize,
}

/// How a team shared out its roles while playing.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RoleStats {
    /// Fraction of sampled playing time with exactly one robot going to the ball (the striker,
    /// or the active defender when the team defends).
    pub one_striker: f64,
    /// Fraction of sampled playing time with 0, 1, 2, 3 or more strikers.
    pub strikers_histogram: [f64; 4],
    /// Total time with two or more strikers, s.
    pub double_striker_s: f64,
    /// Role changes per robot-minute of play.
    pub role_switches_per_minute: f64,
    pub samples: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MatchEvent {
    pub time: f64,
    pub kind: String,
    pub detail: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeamReport {
    pub name: String,
    pub team_number: u8,
    pub goals: u8,
    pub falls: usize,
    pub penalties: usize,
    pub messages_sent: u64,
    pub message_budget_left: u16,
    pub roles: RoleStats,
}

/// Everything a match produced.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MatchReport {
    pub seed: u64,
    pub players_per_team: u8,
    pub host: String,
    pub score: [u8; 2],
    pub teams: [TeamReport; 2],
    pub finished: bool,
    pub simulated_s: f64,
    pub wall_s: f64,
    pub real_time_factor: f64,
    pub events: Vec<MatchEvent>,
    pub robots: Vec<RobotReport>,
    pub team_messages: TeamMessageStats,
    /// Games of T1s in rcssservermj only: halves, stand-ups, the CPU's split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physics: Option<crate::physics::game::PhysicsReport>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TeamMessageStats {
    pub sent: u64,
    pub delivered: u64,
    pub lost: u64,
    pub rejected_oversize: u64,
    pub over_budget: u64,
}

/// Keeps each robot's newest role, from its planning layer's decisions.
#[derive(Default)]
struct RoleTap {
    roles: Mutex<BTreeMap<String, Role>>,
}

impl Tap for RoleTap {
    fn package(&self, record: &TapRecord<'_>) {
        // Other outputs still come when a logger shares the tap.
        if let Some(decision) = record.value(crate::outputs::DECISION) {
            let robot = record.sent_on.module_name.trim_end_matches("/planning").to_owned();
            self.roles
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .insert(robot, decision.assignment.role);
        }
    }

    fn wants(&self, output: &TapOutput<'_>) -> bool {
        output.is(crate::outputs::DECISION)
    }
}

/// A match ready to run: the world, the module graph, and what to watch.
pub struct Match {
    pub sim: SimHandle,
    pub robots: Vec<(RobotId, RobotModules)>,
    pub graph: Option<strata_runtime::Graph>,
    pub config: MatchConfig,
    team_names: [String; 2],
    role_tap: Arc<RoleTap>,
    extra_taps: Vec<Arc<dyn Tap>>,
}

impl std::fmt::Debug for Match {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Match").field("robots", &self.robots.len()).finish_non_exhaustive()
    }
}

/// Fans one tap out to several.
/// The module-name prefix of a robot: `home/3`, `away/1`.
pub fn robot_name(id: RobotId) -> String {
    format!("{}/{}", if id.team == 0 { "home" } else { "away" }, id.player)
}

impl Match {
    /// Builds the world and every robot.
    pub fn new(config: MatchConfig) -> Result<Match> {
        if config.players == 0 || config.players > 7 {
            bail!("--players must be between 1 and 7 (SPL teams), got {}", config.players);
        }
        if !(0.0..=1.0).contains(&config.packet_loss) {
            bail!("packet loss must be in [0, 1], got {}", config.packet_loss);
        }
        let mut sim_config = config.sim.clone().unwrap_or_else(|| {
            let mut sim = SimConfig::default();
            sim.referee = sim.referee.game_controller3();
            sim
        });
        if config.no_delay {
            sim_config.referee = sim_config.referee.no_delay();
        }
        sim_config.seed = config.seed;
        sim_config.field = config.field.clone();
        sim_config.noise.preset = config.noise;
        sim_config.referee.players_per_team = config.players;
        sim_config.referee.half_duration = config.half_duration;
        sim_config.broadcast.loss = config.packet_loss;
        sim_config.validate("match configuration").context("simulator configuration")?;
        let simulation =
            Simulation::new(sim_config.clone()).context("building the simulated world")?;
        let sim = SimHandle::new(simulation);
        let mut graph = strata_runtime::GraphBuilder::new();
        let ids: Vec<RobotId> = (0..2usize)
            .flat_map(|team| (1..=config.players).map(move |player| RobotId::new(team, player)))
            .collect();
        let served = add_simulator(&mut graph, sim.clone(), &ids);
        let mut robots = Vec::new();
        let field = sim.lock().field().clone();
        for team in 0..2usize {
            let team_config = if team == 0 { &config.home } else { &config.away };
            let (team_number, attack_sign) = {
                let s = sim.lock();
                (s.team_number(team), s.game().attack_sign[team])
            };
            let team_field = Arc::new(TeamField::new(field.clone(), attack_sign));
            for player in 1..=config.players {
                let id = RobotId::new(team, player);
                let spec = SoccerRobotSpec {
                    name: robot_name(id),
                    team_number,
                    player,
                    field: Arc::clone(&team_field),
                    platform: served_platform(&served, id)?,
                    links: served_links(&served, id)?,
                    half_duration: config.half_duration,
                    initial_pose: None,
                    relocations: Vec::new(),
                };
                let modules = add_soccer_robot(&mut graph, spec, team_config)
                    .map_err(|e| anyhow::anyhow!("robot {}: {e}", robot_name(id)))?;
                robots.push((id, modules));
            }
        }
        let graph = graph.build().context("wiring the match")?;
        Ok(Match {
            sim,
            robots,
            graph: Some(graph),
            team_names: [config.home.name.clone(), config.away.name.clone()],
            config,
            role_tap: Arc::new(RoleTap::default()),
            extra_taps: Vec::new(),
        })
    }

    /// Adds a tap (a logger, a viewer) that sees every package.
    pub fn add_tap(&mut self, tap: Arc<dyn Tap>) {
        self.extra_taps.push(tap);
    }

    /// The match's taps: the role tap and the added ones (each host shows each tap only the
    /// outputs it wants).
    fn taps(&self) -> Vec<Arc<dyn Tap>> {
        let mut taps: Vec<Arc<dyn Tap>> = vec![self.role_tap.clone()];
        taps.extend(self.extra_taps.iter().cloned());
        taps
    }

    /// A lockstep host over this match's graph (experiments drive it themselves).
    pub fn lockstep(&mut self) -> Result<LockstepHost> {
        let graph = self.graph.take().context("the match's graph was already taken")?;
        let mut host = LockstepHost::new(graph, HostConfig::with_seed(self.config.seed));
        for tap in self.taps() {
            host.add_tap(tap);
        }
        Ok(host)
    }

    /// Plays the match to its end (or the limit), calling `progress` with the fraction done.
    pub fn play(mut self, progress: &mut dyn FnMut(f64, &str)) -> Result<MatchReport> {
        // Without a limit the game ends when the referee says so; this only guards against a
        // game that never ends (every kick-off adds Ready and Set, 50 s by default, and the
        // clock stops while they run).
        let total = self.config.limit.unwrap_or(2.0 * self.config.half_duration + 1800.0);
        let wall = Instant::now();
        let mut sampler = RoleSampler::default();
        let stats = if self.config.realtime {
            let graph = self.graph.take().context("the match's graph was already taken")?;
            let mut host = ThreadedHost::new(graph, HostConfig::with_seed(self.config.seed));
            for tap in self.taps() {
                host.add_tap(tap);
            }
            let running = host.start()?;
            running.stop_on_interrupt()?;
            let stop = running.stop_handle();
            loop {
                std::thread::sleep(Duration::from_millis(250));
                let (now, over) = self.observe(&mut sampler);
                progress((now / total).min(1.0), &self.score_line());
                if over || now >= total || stop.is_stop_requested() {
                    break;
                }
            }
            running.stop()?
        } else {
            let mut host = self.lockstep()?;
            let interrupt = strata_runtime::signal::interrupt_flag().map_err(anyhow::Error::msg)?;
            host.set_interrupt(interrupt.clone());
            let end = Time::from_secs_f64(total);
            loop {
                // The simulator's clock trails the host's by a frame: the host's decides when
                // the limit is reached, so `--duration 4` is 4 s and not 5.
                host.run_until(end.min(host.now() + Duration::from_secs(1)))?;
                let (now, over) = self.observe(&mut sampler);
                progress((now / total).min(1.0), &self.score_line());
                if over || host.now() >= end || host.interrupted() {
                    break;
                }
            }
            host.stop();
            host.stats()
        };
        let wall_s = wall.elapsed().as_secs_f64();
        Ok(self.report(&stats, &sampler, wall_s))
    }

    fn score_line(&self) -> String {
        let game = self.sim.lock().game();
        format!(
            "{} {} - {} {}",
            self.team_names[0], game.score[0], game.score[1], self.team_names[1]
        )
    }

    /// Samples roles (once per simulated second, while playing); returns the time and whether
    /// the game is over.
    fn observe(&self, sampler: &mut RoleSampler) -> (f64, bool) {
        let (now, game, penalized) = {
            let sim = self.sim.lock();
            let penalized: Vec<RobotId> = sim
                .robot_ids()
                // A penalized, absent or fallen robot plays no role, whatever it last claimed.
                .filter(|id| {
                    sim.robot(*id).is_ok_and(|r| {
                        r.penalty != strata_sim::Penalty::None
                            || !r.present
                            || r.fallen
                            || r.falling
                    })
                })
                .collect();
            (sim.time(), sim.game(), penalized)
        };
        if game.state == GameState::Playing {
            let roles = self.role_tap.roles.lock().unwrap_or_else(|e| e.into_inner()).clone();
            let playing: Vec<(String, usize, Role)> = self
                .robots
                .iter()
                .filter(|(id, _)| !penalized.contains(id))
                .filter_map(|(id, _)| {
                    let name = robot_name(*id);
                    roles.get(&name).map(|role| (name, id.team, *role))
                })
                .collect();
            sampler.sample(now.as_secs_f64(), &playing);
        }
        (now.as_secs_f64(), game.game_over)
    }

    fn report(&self, stats: &HostStats, sampler: &RoleSampler, wall_s: f64) -> MatchReport {
        let sim = self.sim.lock();
        let game = sim.game();
        let mut events = Vec::new();
        let mut falls = [0usize; 2];
        let mut penalties = [0usize; 2];
        let mut robot_falls: BTreeMap<RobotId, usize> = BTreeMap::new();
        let mut state = GameState::Initial;
        for event in sim.events() {
            let time = event.time.as_secs_f64();
            match &event.kind {
                EventKind::GameState { state: now, .. } => state = *now,
                EventKind::Goal { team, score, scorer } => events.push(MatchEvent {
                    time,
                    kind: "goal".into(),
                    detail: format!(
                        "{} scores ({}-{}){}",
                        self.team_names[*team],
                        score[0],
                        score[1],
                        scorer
                            .map(|s| format!(", last touch {}", robot_name(s)))
                            .unwrap_or_default()
                    ),
                }),
                EventKind::Fall { robot, cause, .. } => {
                    falls[robot.team] += 1;
                    *robot_falls.entry(*robot).or_default() += 1;
                    events.push(MatchEvent {
                        time,
                        kind: "fall".into(),
                        detail: format!("{} ({cause:?})", robot_name(*robot)),
                    });
                }
                EventKind::Penalty { robot, penalty, .. } => {
                    penalties[robot.team] += 1;
                    events.push(MatchEvent {
                        time,
                        kind: "penalty".into(),
                        detail: format!("{} {penalty:?}", robot_name(*robot)),
                    });
                }
                // A robot's whistle detector firing with no whistle: in Set it starts the
                // robot, and its teammates, too early.
                EventKind::FalseWhistle { robot } => events.push(MatchEvent {
                    time,
                    kind: "false whistle".into(),
                    detail: format!("{} in {state:?}", robot_name(*robot)),
                }),
                _ => {}
            }
        }
        let comms = sim.comms_stats().clone();
        let robots: Vec<RobotReport> = self
            .robots
            .iter()
            .map(|(id, modules)| RobotReport {
                name: robot_name(*id),
                team: id.team,
                player: id.player,
                layers: modules
                    .layers()
                    .iter()
                    .filter_map(|(layer, name)| {
                        stats.module(name).map(|m| LayerRate {
                            layer: (*layer).to_owned(),
                            cycles: m.cycles,
                            min_hz: m.rate.min_hz,
                            mean_hz: m.rate.mean_hz,
                            max_hz: m.rate.max_hz,
                        })
                    })
                    .collect(),
                roles: sampler.robot_roles(&robot_name(*id)),
                falls: robot_falls.get(id).copied().unwrap_or(0),
            })
            .collect();
        let initial_budget = sim.config().referee.message_budget;
        let per_team_sent =
            [0, 1].map(|t| u64::from(initial_budget.saturating_sub(game.message_budget[t])));
        let teams = [0, 1].map(|t| TeamReport {
            name: self.team_names[t].clone(),
            team_number: game.team_numbers[t],
            goals: game.score[t],
            falls: falls[t],
            penalties: penalties[t],
            messages_sent: per_team_sent[t],
            message_budget_left: game.message_budget[t],
            roles: sampler.team_stats(t, self.config.players),
        });
        let simulated_s = sim.time().as_secs_f64();
        MatchReport {
            seed: self.config.seed,
            players_per_team: self.config.players,
            host: if self.config.realtime { "threaded".into() } else { "lockstep".into() },
            score: game.score,
            teams,
            finished: game.game_over,
            simulated_s,
            wall_s,
            real_time_factor: simulated_s / wall_s.max(1e-9),
            events,
            robots,
            team_messages: TeamMessageStats {
                sent: comms.sent,
                delivered: comms.delivered,
                lost: comms.lost,
                rejected_oversize: comms.rejected_oversize,
                over_budget: comms.over_budget,
            },
            physics: None,
        }
    }
}

/// Role samples, once per second of play: which role each robot playing holds (penalized,
/// absent and fallen robots play none).
#[derive(Debug, Default)]
pub(crate) struct RoleSampler {
    last_time: Option<f64>,
    per_robot: BTreeMap<String, BTreeMap<String, u64>>,
    robot_samples: BTreeMap<String, u64>,
    last_role: BTreeMap<String, Role>,
    switches: [u64; 2],
    strikers: [[u64; 4]; 2],
    double_s: [f64; 2],
    samples: [u64; 2],
}

impl RoleSampler {
    /// One sample at `now` s: each playing robot's name, team (0 home, 1 away) and role.
    pub(crate) fn sample(&mut self, now: f64, playing: &[(String, usize, Role)]) {
        if self.last_time.is_some_and(|t| now - t < 0.999) {
            return;
        }
        let dt = self.last_time.map_or(1.0, |t| (now - t).min(2.0));
        self.last_time = Some(now);
        let mut strikers = [0usize; 2];
        for (name, team, role) in playing {
            let team = (*team).min(1);
            *self
                .per_robot
                .entry(name.clone())
                .or_default()
                .entry(role.name().to_owned())
                .or_default() += 1;
            *self.robot_samples.entry(name.clone()).or_default() += 1;
            if self.last_role.insert(name.clone(), *role).is_some_and(|previous| previous != *role)
            {
                self.switches[team] += 1;
            }
            // The robot going to the ball: the striker when attacking, the active defender when
            // defending (Table 1); two of them at once is the conflict ARS must resolve.
            if matches!(role, Role::Striker | Role::ActiveDefender) {
                strikers[team] += 1;
            }
        }
        for (team, count) in strikers.into_iter().enumerate() {
            self.samples[team] += 1;
            self.strikers[team][count.min(3)] += 1;
            if count >= 2 {
                self.double_s[team] += dt;
            }
        }
    }

    pub(crate) fn robot_roles(&self, robot: &str) -> BTreeMap<String, f64> {
        let total = self.robot_samples.get(robot).copied().unwrap_or(0).max(1) as f64;
        self.per_robot
            .get(robot)
            .map(|m| m.iter().map(|(k, v)| (k.clone(), *v as f64 / total)).collect())
            .unwrap_or_default()
    }

    pub(crate) fn team_stats(&self, team: usize, players: u8) -> RoleStats {
        let n = self.samples[team].max(1) as f64;
        let histogram = self.strikers[team].map(|c| c as f64 / n);
        let robot_minutes = self.samples[team] as f64 * f64::from(players) / 60.0;
        RoleStats {
            one_striker: histogram[1],
            strikers_histogram: histogram,
            double_striker_s: self.double_s[team],
            role_switches_per_minute: if robot_minutes > 0.0 {
                self.switches[team] as f64 / robot_minutes
            } else {
                0.0
            },
            samples: self.samples[team],
        }
    }
}

/// The links of robot `id` (team radio, GameController), as the simulator module serves them
/// through the graph.
pub fn served_links(served: &SimulatorPorts, id: RobotId) -> Result<RobotLinks> {
    served
        .links(id)
        .map(RobotLinks::Module)
        .ok_or_else(|| anyhow::anyhow!("robot {} is not served by the simulator", robot_name(id)))
}

/// The platform of robot `id`, as the simulator module serves it through the graph.
pub fn served_platform(served: &SimulatorPorts, id: RobotId) -> Result<RobotPlatform> {
    served
        .platform(id)
        .map(RobotPlatform::Module)
        .ok_or_else(|| anyhow::anyhow!("robot {} is not served by the simulator", robot_name(id)))
}
