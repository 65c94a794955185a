//! Helpers shared by the simulator's integration tests.

#![allow(dead_code)]

use std::time::Duration;

use strata_robot::platform::{ActuatorOrders, BodyOrder, HeadAngles, HeadOrder};
use strata_robot::{Point, Pose, Velocity};
use strata_sim::{GameState, RobotId, SimConfig, Simulation};

/// A world without noise, with a manual referee, in Playing.
pub fn quiet(adjust: impl FnOnce(&mut SimConfig)) -> Simulation {
    let mut config = SimConfig::default().without_noise();
    config.referee.auto = false;
    adjust(&mut config);
    let mut sim = Simulation::new(config).expect("a valid config");
    sim.set_game_state(GameState::Playing);
    sim
}

/// Takes every robot but `keep` out of the world.
pub fn only(sim: &mut Simulation, keep: &[RobotId]) {
    let ids: Vec<RobotId> = sim.robot_ids().collect();
    for id in ids {
        if !keep.contains(&id) {
            sim.remove_robot(id).expect("known robot");
        }
    }
}

pub fn walk(sim: &mut Simulation, robot: RobotId, vx: f64, vy: f64, omega: f64) {
    let orders = ActuatorOrders {
        head: None,
        body: Some(BodyOrder::Walk { velocity: Velocity::new(vx, vy, omega) }),
    };
    sim.apply_orders(robot, &orders).expect("valid orders");
}

pub fn look(sim: &mut Simulation, robot: RobotId, yaw: f64, pitch: f64) {
    let orders = ActuatorOrders {
        head: Some(HeadOrder { target: HeadAngles { yaw, pitch }, max_speed: 100.0 }),
        body: None,
    };
    sim.apply_orders(robot, &orders).expect("valid orders");
}

pub fn steps(sim: &mut Simulation, seconds: f64) {
    sim.run_for(Duration::from_secs_f64(seconds));
}

pub fn place(sim: &mut Simulation, robot: RobotId, x: f64, y: f64, theta: f64) {
    sim.teleport(robot, Pose::new(x, y, theta)).expect("known robot");
}

pub fn point(x: f64, y: f64) -> Point<strata_robot::Global> {
    Point::new(x, y)
}

pub const A1: RobotId = RobotId::new(0, 1);
pub const A2: RobotId = RobotId::new(0, 2);
pub const A3: RobotId = RobotId::new(0, 3);
pub const B1: RobotId = RobotId::new(1, 1);
pub const B2: RobotId = RobotId::new(1, 2);
