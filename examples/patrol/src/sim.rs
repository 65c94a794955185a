//! The simulated building: the floor plan's walls and landmarks, the points of interest where
//! they really are, the operator's console with its alarms and intruder, the team radio, and
//! the ground truth a run is judged by. The robots, their bodies and their camera are
//! `strata-worldsim`'s: this module only says what the building holds and what happens in it
//! (paper 3.7: the robot's code runs over an abstract hardware layer; simulation swaps the
//! platform). Everything random comes from the scenario's seed: a run is the same run every
//! time.

mod links;

use serde::{Deserialize, Serialize};
use strata_robot::geometry::{Global, Point, Pose};
use strata_robot::platform::ReceivedPacket;
use strata_runtime::{GraphBuilder, Time};
use strata_worldsim::{
    Marker, MarkerId, Script, Simulation, World, WorldHandle, WorldSim, WorldSimConfig,
    WorldSimError, WorldSimPorts, add_world_sim,
};

use crate::building::FloorPlan;
use crate::console::PoiReport;
use crate::world_config::{
    CORNER, CORNER_GROUP, INTRUDER, MARKER, PERSON, POINT_OF_INTEREST, marker_name, poi_name,
};

pub use links::{ConsoleLink, RadioLink};

/// The robots' world and the building's own devices.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BuildingConfig {
    /// Bodies, camera and sensor period.
    pub world: WorldSimConfig,
    /// Team radio delay, s, and loss probability.
    pub radio_delay: f64,
    pub radio_loss: f64,
    /// The console broadcasts its state this often, s.
    pub console_period: f64,
}

impl Default for BuildingConfig {
    fn default() -> Self {
        BuildingConfig {
            world: WorldSimConfig { name: "patrol building".into(), ..WorldSimConfig::default() },
            radio_delay: 0.03,
            radio_loss: 0.0,
            console_period: 0.5,
        }
    }
}

/// An alarm the operator raises at `at` seconds: someone is at `intruder`; the robots are sent
/// to `point`. The console clears it `hold` seconds after a robot reports from there that it
/// sees the intruder.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlarmEvent {
    pub at: f64,
    pub id: u16,
    pub point: Point<Global>,
    pub intruder: Point<Global>,
    pub hold: f64,
}

/// A robot (index) slips at `at` seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Slip {
    pub robot: usize,
    pub at: f64,
}

/// What happens in the building.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scenario {
    pub seed: u64,
    /// Where each robot starts (player `i + 1`).
    pub robots: Vec<Pose>,
    /// Where the points of interest really are (the plan may be wrong).
    pub points_of_interest: Vec<Point<Global>>,
    pub alarms: Vec<AlarmEvent>,
    pub slips: Vec<Slip>,
}

/// Why the building could not be built or refused a request.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BuildingError {
    #[error("no robot {0} in the building")]
    NoRobot(usize),
    #[error("the scenario lists {found} points of interest, the plan {expected}")]
    PointsOfInterest { expected: usize, found: usize },
    #[error("scenario.slips[{index}] names robot {robot}; the scenario has {robots} robots")]
    SlipRobot { index: usize, robot: usize, robots: usize },
    #[error("building configuration: `{field}` must be {requirement}, got {value}")]
    Config { field: &'static str, requirement: &'static str, value: f64 },
    #[error(transparent)]
    World(#[from] WorldSimError),
}

/// What really happened, for tests and summaries (never for robots).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    /// Per robot: (time, true pose) every 0.1 s.
    pub trajectories: Vec<Vec<(f64, Pose)>>,
    /// (robot, time) of each landing on the floor.
    pub falls: Vec<(usize, f64)>,
    /// (robot, time) of each completed stand-up.
    pub stand_ups: Vec<(usize, f64)>,
    pub alarms: Vec<AlarmRecord>,
    /// Every point-of-interest report the console received.
    pub reports: Vec<ReportRecord>,
    pub points_of_interest: Vec<Point<Global>>,
    /// Steps in which a robot walked into a wall.
    pub bumps: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlarmRecord {
    pub id: u16,
    pub point: Point<Global>,
    pub raised: f64,
    /// The first robot (player) that reported from the spot, and when.
    pub on_site: Option<(u8, f64)>,
    pub cleared: Option<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReportRecord {
    pub time: f64,
    pub player: u8,
    pub report: PoiReport,
}

impl GroundTruth {
    /// A robot's true pose at time `t` (the nearest sample).
    pub fn pose_at(&self, robot: usize, t: f64) -> Option<Pose> {
        strata_worldsim::pose_at(self.trajectories.get(robot)?, t)
    }
}

#[derive(Debug)]
struct LiveAlarm {
    event: AlarmEvent,
    record: usize,
    on_site_since: Option<Time>,
}

/// What happens in the building besides the robots' own doings: the script of its simulation.
/// The console and the radio live here too, so the links reach them under the simulation's
/// lock.
#[derive(Debug)]
pub struct Building {
    config: BuildingConfig,
    scenario: Scenario,
    /// The intruder is a marker in the world while an alarm is live.
    intruder: MarkerId,
    /// The console's own clock: its last step (it runs on the world's steps, whichever of the
    /// world's module and a link reaches a step first).
    console_clock: Time,
    alarm: Option<LiveAlarm>,
    next_alarm: usize,
    next_broadcast: Time,
    broadcast_seq: u8,
    /// Per robot, what the console broadcast and the robot has not read.
    console_inboxes: Vec<Vec<ReceivedPacket>>,
    /// Radio messages on their way: (arrival, sequence, recipient, payload).
    radio: Vec<(Time, u64, usize, Vec<u8>)>,
    radio_seq: u64,
    alarms: Vec<AlarmRecord>,
    reports: Vec<ReportRecord>,
}

/// A shared handle to the building's simulation. Clones refer to the same building.
pub type BuildingHandle = WorldHandle<Building>;

/// The building's world: the plan's walls, markers and corners; the points of interest where
/// the scenario puts them; the intruder, absent until an alarm. The camera considers them in
/// this order.
fn world(plan: &FloorPlan, scenario: &Scenario) -> (World, MarkerId) {
    let mut world = World::new(plan.walls.clone());
    let code = |k: usize| u16::try_from(k).ok();
    for (k, position) in plan.markers.iter().enumerate() {
        world.add_marker(Marker::at(marker_name(k), MARKER, code(k), *position));
    }
    for position in &plan.corners {
        world.add_marker(Marker::at(CORNER_GROUP, CORNER, None, *position));
    }
    for (k, position) in scenario.points_of_interest.iter().enumerate() {
        world.add_marker(Marker::at(poi_name(k), POINT_OF_INTEREST, code(k), *position));
    }
    let intruder = world.add_marker(Marker {
        name: INTRUDER.into(),
        class: PERSON,
        variant: None,
        position: None,
    });
    (world, intruder)
}

impl Building {
    /// The building's simulation: the robots standing where the scenario starts them.
    pub fn simulation(
        plan: &FloorPlan,
        config: BuildingConfig,
        scenario: Scenario,
    ) -> Result<Simulation<Building>, BuildingError> {
        if scenario.points_of_interest.len() != plan.points_of_interest.len() {
            return Err(BuildingError::PointsOfInterest {
                expected: plan.points_of_interest.len(),
                found: scenario.points_of_interest.len(),
            });
        }
        let robots = scenario.robots.len();
        if let Some((index, slip)) =
            scenario.slips.iter().enumerate().find(|(_, s)| s.robot >= robots)
        {
            return Err(BuildingError::SlipRobot { index, robot: slip.robot, robots });
        }
        for (field, value) in
            [("radio_delay", config.radio_delay), ("console_period", config.console_period)]
        {
            if !(value.is_finite() && value >= 0.0) {
                let requirement = "zero or positive";
                return Err(BuildingError::Config { field, requirement, value });
            }
        }
        if !(0.0..=1.0).contains(&config.radio_loss) {
            let (field, requirement, value) = ("radio_loss", "in [0, 1]", config.radio_loss);
            return Err(BuildingError::Config { field, requirement, value });
        }
        let (world, intruder) = world(plan, &scenario);
        let sim = WorldSim::new(config.world.clone(), world, &scenario.robots, scenario.seed)?;
        let building = Building {
            config,
            intruder,
            console_clock: Time::ZERO,
            alarm: None,
            next_alarm: 0,
            next_broadcast: Time::ZERO,
            broadcast_seq: 0,
            console_inboxes: vec![Vec::new(); robots],
            radio: Vec::new(),
            radio_seq: 0,
            alarms: Vec::new(),
            reports: Vec::new(),
            scenario,
        };
        Ok(Simulation::new(sim, building))
    }

    /// What really happened so far, the bodies' history from the simulator.
    pub fn truth(&self, sim: &WorldSim) -> GroundTruth {
        let bodies = sim.truth();
        GroundTruth {
            trajectories: bodies.trajectories.clone(),
            falls: bodies.falls.clone(),
            stand_ups: bodies.stand_ups.clone(),
            alarms: self.alarms.clone(),
            reports: self.reports.clone(),
            points_of_interest: self.scenario.points_of_interest.clone(),
            bumps: bodies.bumps,
        }
    }
}

impl Script for Building {
    fn before_step(&mut self, sim: &mut WorldSim) {
        self.advance_console(sim.time(), sim.period());
        let intruder = self.alarm.as_ref().map(|live| live.event.intruder);
        sim.world_mut().place(self.intruder, intruder);
        let now = sim.time().as_secs_f64();
        let dt = sim.period().as_secs_f64();
        for slip in &self.scenario.slips {
            if (now - dt..now).contains(&slip.at) {
                // The robot exists (checked when the building was built); one already down
                // cannot slip.
                let _ = sim.slip(slip.robot);
            }
        }
    }
}

/// Adds the module (named `building`) that steps the building and is the platform of
/// `robots`: connect each robot to [`WorldSimPorts::platform`].
pub fn add_building(
    graph: &mut GraphBuilder,
    building: BuildingHandle,
    robots: &[usize],
) -> Result<WorldSimPorts, BuildingError> {
    Ok(add_world_sim(graph, "building", building, robots)?)
}

/// The building of the tests below and of `links`'.
#[cfg(test)]
fn test_building(slips: Vec<Slip>) -> Simulation<Building> {
    let plan = FloorPlan::office();
    let scenario = Scenario {
        seed: 3,
        robots: vec![Pose::new(-5.0, 2.0, 0.0), Pose::new(-5.0, -2.0, 0.0)],
        points_of_interest: plan.points_of_interest.iter().map(|p| p.nominal).collect(),
        alarms: vec![AlarmEvent {
            at: 1.0,
            id: 4,
            point: Point::new(-5.0, 2.4),
            intruder: Point::new(-6.0, 3.2),
            hold: 2.0,
        }],
        slips,
    };
    let mut config = BuildingConfig::default();
    config.world.camera.detection_probability = 1.0;
    Building::simulation(&plan, config, scenario).expect("building")
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_2;

    use super::*;

    #[test]
    fn the_camera_sees_the_plans_markers_that_face_it_and_not_through_the_dividing_wall() {
        let mut b = test_building(Vec::new());
        // Facing north from (-5, 2): marker 0 at (-5.5, 3.98) is ahead.
        b.sim.set_pose(0, Pose::new(-5.0, 2.0, FRAC_PI_2)).expect("robot 0");
        let seen = b.sim.look(0);
        assert!(seen.iter().any(|d| d.class == MARKER && d.variant == Some(0)));
        // Facing south: the dividing wall hides the south wing's markers, its own stay.
        b.sim.set_pose(0, Pose::new(-5.0, 2.0, -FRAC_PI_2)).expect("robot 0");
        let seen = b.sim.look(0);
        assert!(seen.iter().any(|d| d.class == MARKER && d.variant == Some(4)));
        assert!(!seen.iter().any(|d| d.class == MARKER && d.variant == Some(14)));
    }

    #[test]
    fn the_intruder_is_in_the_building_while_its_alarm_is_live() {
        let mut b = test_building(Vec::new());
        b.sim.set_pose(0, Pose::new(-5.0, 2.0, 2.5)).expect("robot 0");
        let sees_person =
            |b: &mut Simulation<Building>| b.sim.look(0).iter().any(|d| d.class == PERSON);
        b.advance_to(Time::from_secs_f64(0.98));
        assert!(!sees_person(&mut b));
        b.advance_to(Time::from_secs_f64(1.0));
        assert!(sees_person(&mut b));
        assert_eq!(b.script.truth(&b.sim).alarms.len(), 1);
    }

    #[test]
    fn a_scripted_slip_ends_on_the_floor_in_the_ground_truth() {
        let mut b = test_building(vec![Slip { robot: 1, at: 0.5 }]);
        b.advance_to(Time::from_secs_f64(2.0));
        let truth = b.script.truth(&b.sim);
        assert_eq!(truth.falls.len(), 1);
        assert_eq!(truth.falls[0].0, 1);
        assert!(b.sim.body(1).is_some_and(|body| body.is_fallen()));
        assert!(b.sim.body(0).is_some_and(|body| !body.is_fallen()));
        assert_eq!(truth.trajectories[1].len(), 21, "at the first step, then every 0.1 s");
    }

    #[test]
    fn a_slip_of_a_robot_the_scenario_lacks_is_named() {
        let plan = FloorPlan::office();
        let scenario = Scenario {
            seed: 1,
            robots: vec![Pose::default()],
            points_of_interest: plan.points_of_interest.iter().map(|p| p.nominal).collect(),
            alarms: Vec::new(),
            slips: vec![Slip { robot: 0, at: 1.0 }, Slip { robot: 3, at: 2.0 }],
        };
        let error =
            Building::simulation(&plan, BuildingConfig::default(), scenario).expect_err("robot 3");
        assert_eq!(error, BuildingError::SlipRobot { index: 1, robot: 3, robots: 1 });
    }
}
