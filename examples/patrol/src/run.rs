//! A patrol run: the building, its robots and an observer in one module graph, on either host,
//! and what came out of it.

use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Duration;

use strata_robot::assembly::RobotModules;
use strata_robot::edge::RobotPlatform;
use strata_robot::geometry::{Point, Pose};
use strata_runtime::{
    Graph, GraphBuilder, HostConfig, HostStats, LockstepHost, ThreadedHost, Time,
};

use crate::behaviors::waypoint_of_path;
use crate::building::FloorPlan;
use crate::goals::GazeKind;
use crate::observer::{Observations, PatrolObserver};
use crate::planning::Role;
use crate::robot::{PatrolConfig, PatrolRobotSpec, add_patrol_robot};
use crate::sim::{
    AlarmEvent, Building, BuildingConfig, BuildingHandle, ConsoleLink, GroundTruth, RadioLink,
    Scenario, Slip, add_building,
};

/// The demonstration: two robots on the office floor, two points of interest not where the plan
/// says, an alarm in the north wing after 75 s, and a slip in the south wing at 30 s.
pub fn demo_scenario(plan: &FloorPlan, seed: u64) -> Scenario {
    let start = |beat: usize| {
        let w = plan.beats[beat][0].position;
        Pose::new(w.x, w.y, 0.0)
    };
    let moved = [(0.3, -0.05), (0.0, 0.0), (-0.25, 0.05), (0.0, 0.0)];
    Scenario {
        seed,
        robots: vec![start(0), start(1)],
        points_of_interest: plan
            .points_of_interest
            .iter()
            .zip(moved)
            .map(|(p, (dx, dy))| Point::new(p.nominal.x + dx, p.nominal.y + dy))
            .collect(),
        alarms: vec![AlarmEvent {
            at: 75.0,
            id: 1,
            point: Point::new(-5.0, 2.4),
            intruder: Point::new(-6.0, 3.2),
            hold: 6.0,
        }],
        slips: vec![Slip { robot: 1, at: 30.0 }],
    }
}

/// The module-name prefix of player `player`.
pub fn robot_name(player: u8) -> String {
    format!("patrol/{player}")
}

/// A patrol ready to run.
pub struct PatrolRun {
    pub plan: Arc<FloorPlan>,
    pub building: BuildingHandle,
    pub robots: Vec<RobotModules>,
    pub observer: Arc<PatrolObserver>,
    seed: u64,
    graph: Graph,
}

impl std::fmt::Debug for PatrolRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PatrolRun").field("robots", &self.robots.len()).finish_non_exhaustive()
    }
}

/// What a run produced.
#[derive(Debug)]
pub struct Outcome {
    pub plan: Arc<FloorPlan>,
    pub truth: GroundTruth,
    pub observations: Observations,
    pub stats: HostStats,
    pub duration: f64,
}

impl PatrolRun {
    pub fn new(
        plan: Arc<FloorPlan>,
        scenario: Scenario,
        building: BuildingConfig,
        config: &PatrolConfig,
    ) -> Result<PatrolRun, String> {
        let seed = scenario.seed;
        let starts = scenario.robots.clone();
        let handle = BuildingHandle::new(
            Building::simulation(&plan, building, scenario).map_err(|e| e.to_string())?,
        );
        let mut graph = GraphBuilder::new();
        let indices: Vec<usize> = (0..starts.len()).collect();
        // The building is the robots' platform: its step triggers their perception.
        let served =
            add_building(&mut graph, handle.clone(), &indices).map_err(|e| e.to_string())?;
        let mut robots = Vec::new();
        for (index, start) in starts.into_iter().enumerate() {
            let player = u8::try_from(index + 1).map_err(|_| "too many robots".to_owned())?;
            let platform =
                served.platform(index).ok_or_else(|| format!("robot {index} is not served"))?;
            let spec = PatrolRobotSpec {
                name: robot_name(player),
                player,
                plan: Arc::clone(&plan),
                start,
                platform: RobotPlatform::Module(platform),
                team_link: Some(Box::new(
                    RadioLink::new(&handle, index).map_err(|e| e.to_string())?,
                )),
                console_link: Some(Box::new(
                    ConsoleLink::new(&handle, index).map_err(|e| e.to_string())?,
                )),
            };
            robots.push(add_patrol_robot(&mut graph, spec, config)?);
        }
        let graph = graph.build().map_err(|e| e.to_string())?;
        Ok(PatrolRun {
            plan,
            building: handle,
            robots,
            observer: Arc::new(PatrolObserver::default()),
            seed,
            graph,
        })
    }

    /// The demonstration scenario with the default configuration.
    pub fn demo(seed: u64) -> Result<PatrolRun, String> {
        let plan = Arc::new(FloorPlan::office());
        let scenario = demo_scenario(&plan, seed);
        PatrolRun::new(plan, scenario, BuildingConfig::default(), &PatrolConfig::default())
    }

    fn outcome(
        plan: Arc<FloorPlan>,
        building: &BuildingHandle,
        observer: &PatrolObserver,
        stats: HostStats,
    ) -> Outcome {
        let simulation = building.lock();
        Outcome {
            plan,
            truth: simulation.script.truth(&simulation.sim),
            observations: observer.snapshot(),
            stats,
            duration: simulation.sim.time().as_secs_f64(),
        }
    }

    /// Runs `seconds` of simulated time on the deterministic lockstep host.
    pub fn run_lockstep(self, seconds: f64) -> Result<Outcome, String> {
        let mut host = LockstepHost::new(self.graph, HostConfig::with_seed(self.seed));
        host.set_tap(self.observer.clone());
        host.run_until(Time::from_secs_f64(seconds)).map_err(|e| e.to_string())?;
        host.stop();
        Ok(Self::outcome(self.plan, &self.building, &self.observer, host.stats()))
    }

    /// Runs for `seconds` of real time on the threaded host (a thread per module).
    pub fn run_threaded(self, seconds: f64) -> Result<Outcome, String> {
        let mut host = ThreadedHost::new(self.graph, HostConfig::with_seed(self.seed));
        host.set_tap(self.observer.clone());
        let running = host.start().map_err(|e| e.to_string())?;
        let stats = running.run_for(Duration::from_secs_f64(seconds)).map_err(|e| e.to_string())?;
        Ok(Self::outcome(self.plan, &self.building, &self.observer, stats))
    }
}

/// A waypoint the deliberative layer reached: it moved on to the next one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Visit {
    pub time: f64,
    pub waypoint: usize,
    /// Where the robot really was then, and how far that is from the waypoint.
    pub true_position: Point<strata_robot::Global>,
    pub miss: f64,
}

impl Outcome {
    /// The waypoints robot `index` (player `index + 1`) reached, in order: each time its
    /// deliberative layer moved on from one, with where it really was then.
    pub fn visits(&self, index: usize) -> Vec<Visit> {
        let player = u8::try_from(index + 1).unwrap_or(u8::MAX);
        let Some(log) = self.observations.robots.get(&robot_name(player)) else {
            return Vec::new();
        };
        let beat = self.plan.beat(player);
        let mut visits = Vec::new();
        let mut current: Option<usize> = None;
        for (t, path) in &log.paths {
            let Some(w) = waypoint_of_path(path) else { continue };
            if let Some(previous) = current
                && previous != w
                && let Some(pose) = self.truth.pose_at(index, *t)
            {
                let at = beat[previous].position;
                visits.push(Visit {
                    time: *t,
                    waypoint: previous,
                    true_position: pose.position(),
                    miss: pose.position().distance(at),
                });
            }
            current = Some(w);
        }
        visits
    }

    /// The console's best (smallest sigma) report of each point of interest: (report, error
    /// against the true position).
    pub fn best_reports(&self) -> Vec<Option<(crate::sim::ReportRecord, f64)>> {
        (0..self.plan.points_of_interest.len())
            .map(|k| {
                self.truth
                    .reports
                    .iter()
                    .filter(|r| usize::from(r.report.poi) == k)
                    .min_by(|a, b| a.report.sigma.total_cmp(&b.report.sigma))
                    .map(|r| (*r, r.report.position.distance(self.truth.points_of_interest[k])))
            })
            .collect()
    }

    /// A short human-readable summary.
    pub fn summary(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "patrol: {:.0} s simulated, {} robots",
            self.duration,
            self.truth.trajectories.len()
        );
        for (index, (name, log)) in self.observations.robots.iter().enumerate() {
            let visits = self.visits(index);
            let order: Vec<String> = visits.iter().map(|v| v.waypoint.to_string()).collect();
            let worst = visits.iter().map(|v| v.miss).fold(0.0, f64::max);
            let _ = writeln!(
                out,
                "{name}: waypoints reached {} (worst true miss {worst:.2} m)",
                order.join(" ")
            );
            let roles: Vec<String> = log
                .assignments
                .iter()
                .map(|(t, m, r, alone)| {
                    format!("{t:.0}s {m:?}/{r:?}{}", if *alone { " (alone)" } else { "" })
                })
                .collect();
            let _ = writeln!(out, "  roles: {}", roles.join(", "));
            let gaze = |state: &str| {
                format!(
                    "{} inspecting / {} localizing",
                    log.gaze_cycles(state, GazeKind::Inspecting),
                    log.gaze_cycles(state, GazeKind::Localizing)
                )
            };
            let _ = writeln!(
                out,
                "  gaze cycles while inspecting: {}; while patrolling: {}",
                gaze("Inspect"),
                gaze("Patrol")
            );
            if !log.reflexes.is_empty() {
                let _ = writeln!(out, "  reflexes (cycles): {:?}", log.reflexes);
            }
        }
        for (k, best) in self.best_reports().into_iter().enumerate() {
            let name = &self.plan.points_of_interest[k].name;
            match best {
                Some((r, error)) => {
                    let _ = writeln!(
                        out,
                        "{name}: reported by patrol/{} at ({:.2}, {:.2}) ± {:.2} m, {error:.2} m from the truth",
                        r.player, r.report.position.x, r.report.position.y, r.report.sigma
                    );
                }
                None => {
                    let _ = writeln!(out, "{name}: not reported");
                }
            }
        }
        for alarm in &self.truth.alarms {
            let responder = alarm.on_site.map_or("nobody on site".to_owned(), |(p, t)| {
                format!("patrol/{p} on site at {t:.0} s")
            });
            let cleared =
                alarm.cleared.map_or("not cleared".to_owned(), |t| format!("cleared at {t:.0} s"));
            let _ = writeln!(
                out,
                "alarm {} raised at {:.0} s: {responder}, {cleared}",
                alarm.id, alarm.raised
            );
        }
        let _ =
            writeln!(out, "falls: {:?}, stand-ups: {:?}", self.truth.falls, self.truth.stand_ups);
        out
    }

    /// Robots (players) holding the responder role at time `t`.
    pub fn responders_at(&self, t: f64) -> Vec<u8> {
        (1..=u8::try_from(self.truth.trajectories.len()).unwrap_or(u8::MAX))
            .filter(|p| {
                self.observations.robots.get(&robot_name(*p)).and_then(|log| log.role_at(t))
                    == Some(Role::Responder)
            })
            .collect()
    }
}
