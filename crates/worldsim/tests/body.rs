//! The walking body: its limits, its falls and its stand-ups, as the robot's platform reports
//! them and as they really are.

use strata_robot::geometry::{Global, Point, Pose, Segment, Velocity};
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CycleStage, FallDirection, HeadAngles, HeadOrder,
    MotionName, SpecialMotion,
};
use strata_runtime::Time;
use strata_worldsim::{BodyEvent, Script, World, WorldSim, WorldSimConfig};

fn p(x: f64, y: f64) -> Point<Global> {
    Point::new(x, y)
}

fn sim(world: World) -> WorldSim {
    WorldSim::new(WorldSimConfig::default(), world, &[Pose::new(0.0, 0.0, 0.0)], 5)
        .expect("valid world")
}

fn order(body: BodyOrder) -> ActuatorOrders {
    ActuatorOrders { head: None, body: Some(body) }
}

fn at(seconds: f64) -> Time {
    Time::from_secs_f64(seconds)
}

/// Records every body event with its time.
#[derive(Debug, Default)]
struct Events(Vec<(f64, BodyEvent)>);

impl Script for Events {
    fn after_step(&mut self, sim: &mut WorldSim, events: &[BodyEvent]) {
        let now = sim.time().as_secs_f64();
        self.0.extend(events.iter().map(|e| (now, *e)));
    }
}

#[test]
fn walking_respects_the_speed_limits_the_acceleration_and_the_gait_stages() {
    let mut sim = sim(World::default());
    let limits = sim.config().body.clone();
    sim.apply_orders(0, &order(BodyOrder::Walk { velocity: Velocity::new(2.0, -1.0, 5.0) }))
        .expect("walk");
    sim.advance_to(at(0.06), &mut ());
    // The initialization stage: the gait starts, the body does not move yet.
    let Some(BodyMotionState::Walking { stage: CycleStage::Initialization, .. }) =
        sim.body(0).map(|b| b.motion_state())
    else {
        panic!("initializing: {:?}", sim.body(0))
    };
    assert!(sim.body(0).is_some_and(|b| b.velocity().is_zero()));
    sim.advance_to(at(0.4), &mut ());
    // Executing since the step at 0.1 s at the latest: 0.32 s at 0.8 m/s^2 and 3 rad/s^2.
    let v = sim.body(0).map(|b| b.velocity()).expect("robot 0");
    assert!(v.vx > 0.0 && v.vx <= limits.acceleration * 0.32 + 1e-9, "{v:?}");
    assert!(v.omega > 0.0 && v.omega <= limits.angular_acceleration * 0.32 + 1e-9, "{v:?}");
    sim.advance_to(at(3.0), &mut ());
    // The order asked for more than the body can: it walks at its limits.
    let v = sim.body(0).map(|b| b.velocity()).expect("robot 0");
    assert_eq!(
        v,
        Velocity::new(limits.max_velocity.vx, -limits.max_velocity.vy, limits.max_velocity.omega)
    );

    // Stand: the end stage, then standing still.
    sim.apply_orders(0, &order(BodyOrder::Stand)).expect("stand");
    sim.advance_to(at(3.1), &mut ());
    let Some(BodyMotionState::Walking { stage: CycleStage::End, .. }) =
        sim.body(0).map(|b| b.motion_state())
    else {
        panic!("stopping: {:?}", sim.body(0))
    };
    sim.advance_to(at(3.2), &mut ());
    assert_eq!(sim.body(0).map(|b| b.motion_state()), Some(BodyMotionState::Standing));
    assert!(sim.body(0).is_some_and(|b| b.velocity().is_zero()));
}

#[test]
fn the_walking_engine_believes_roughly_what_the_body_really_walked() {
    let mut sim = sim(World::default());
    sim.apply_orders(0, &order(BodyOrder::Walk { velocity: Velocity::new(0.3, 0.0, 0.0) }))
        .expect("walk");
    sim.advance_to(at(3.0), &mut ());
    let moved = sim.body(0).map(|b| b.pose().x).expect("robot 0");
    let reported = sim.take_feedback(0).expect("robot 0").odometry.dx;
    assert!(moved > 0.6 && (moved - reported).abs() < 0.15 * reported, "{moved} {reported}");
    assert_eq!(sim.take_feedback(0).expect("robot 0").odometry.dx, 0.0, "handed over once");
}

#[test]
fn a_wall_stops_a_walking_body() {
    let mut sim = sim(World::new(vec![Segment::new(p(0.5, -1.0), p(0.5, 1.0))]));
    sim.apply_orders(0, &order(BodyOrder::Walk { velocity: Velocity::new(0.35, 0.0, 0.0) }))
        .expect("walk");
    let mut events = Events::default();
    sim.advance_to(at(4.0), &mut events);
    let x = sim.body(0).map(|b| b.pose().x).expect("robot 0");
    assert!(x < 0.5 - sim.config().body.radius && x > 0.2, "{x}");
    assert!(sim.truth().bumps > 10);
    assert!(events.0.iter().all(|(_, e)| *e == BodyEvent::Bumped(0)) && !events.0.is_empty());
}

#[test]
fn the_head_turns_at_its_speed_within_its_joint_limits() {
    let mut sim = sim(World::default());
    let head = HeadOrder { target: HeadAngles { yaw: 3.0, pitch: -1.0 }, max_speed: 1.0 };
    sim.apply_orders(0, &ActuatorOrders { head: Some(head), body: None }).expect("head");
    sim.advance_to(at(0.5), &mut ());
    let angles = sim.body(0).map(|b| b.head()).expect("robot 0");
    assert!((angles.yaw - 0.5).abs() < 1e-9, "1 rad/s for 0.5 s: {angles:?}");
    sim.advance_to(at(3.0), &mut ());
    let (yaw, pitch) = (sim.config().body.head_yaw_limits, sim.config().body.head_pitch_limits);
    assert_eq!(sim.body(0).map(|b| b.head()), Some(HeadAngles { yaw: yaw.1, pitch: pitch.0 }));
    assert!(sim.take_feedback(0).expect("robot 0").head_settled);
}

#[test]
fn a_slip_ends_on_the_floor_unseen_by_the_walking_engine_and_a_stand_up_gets_the_body_back() {
    let mut sim = sim(World::default());
    let body = sim.config().body.clone();
    let mut events = Events::default();
    sim.advance_to(at(1.0), &mut events);
    assert_eq!(sim.slip(0), Ok(true));
    sim.advance_to(at(1.4), &mut events);
    // Toppling: the walking engine reports standing, the IMU shows the lean, the camera is off.
    assert_eq!(sim.body(0).map(|b| b.motion_state()), Some(BodyMotionState::Standing));
    let frame = sim.take_frame(0).expect("robot 0").expect("a frame");
    assert!(frame.inertial.body_angles[1] > 0.05 && frame.inertial.gyroscope[1] > 0.0);
    sim.advance_to(at(1.0 + body.fall_time + 0.02), &mut events);
    assert_eq!(
        sim.body(0).map(|b| b.motion_state()),
        Some(BodyMotionState::Fallen { direction: FallDirection::Front })
    );
    assert_eq!(sim.slip(0), Ok(false), "already down");
    let frame = sim.take_frame(0).expect("robot 0").expect("a frame");
    assert!(frame.inertial.body_angles[1] > 1.0 && frame.camera.is_none());
    assert_eq!(frame.foot_contact.left + frame.foot_contact.right, 0.0);
    let [(fell, BodyEvent::Landed(0))] = events.0[..] else { panic!("{:?}", events.0) };
    assert!((fell - (1.0 + body.fall_time)).abs() < 0.021, "{fell}");
    assert_eq!(sim.truth().falls, vec![(0, fell)]);

    // A stand-up takes its time, then the body stands with its camera back.
    sim.apply_orders(0, &order(BodyOrder::Special { motion: SpecialMotion::stand_up(0) }))
        .expect("stand up");
    let start = sim.time().as_secs_f64();
    sim.advance_to(at(start + body.stand_up_time / 2.0), &mut events);
    let Some(BodyMotionState::Special { motion, .. }) = sim.body(0).map(|b| b.motion_state())
    else {
        panic!("standing up: {:?}", sim.body(0))
    };
    assert_eq!(motion, SpecialMotion::stand_up(0));
    sim.advance_to(at(start + body.stand_up_time + 0.04), &mut events);
    assert_eq!(sim.body(0).map(|b| b.motion_state()), Some(BodyMotionState::Standing));
    assert_eq!(sim.body(0).map(|b| b.tilt()), Some(0.0));
    assert!(matches!(events.0[..], [_, (_, BodyEvent::StoodUp(0))]), "{:?}", events.0);
    assert_eq!(sim.truth().stand_ups.len(), 1);
}

#[test]
fn a_motion_the_body_lacks_is_refused_by_name() {
    let mut sim = sim(World::default());
    let kick = SpecialMotion::new(MotionName::from_static("kick"), 0, false);
    let refused = sim
        .apply_orders(0, &order(BodyOrder::Special { motion: kick }))
        .expect_err("a walking body cannot kick");
    assert!(refused.to_string().contains("kick"), "{refused}");
    sim.advance_to(at(0.2), &mut ());
    assert_eq!(sim.body(0).map(|b| b.motion_state()), Some(BodyMotionState::Standing));
}

#[test]
fn a_protective_fall_sits_down_backwards_and_a_stand_up_while_standing_is_ignored() {
    let mut sim = sim(World::default());
    sim.apply_orders(0, &order(BodyOrder::Special { motion: SpecialMotion::stand_up(0) }))
        .expect("ignored, not refused");
    sim.advance_to(at(0.2), &mut ());
    assert_eq!(sim.body(0).map(|b| b.motion_state()), Some(BodyMotionState::Standing));

    sim.apply_orders(0, &order(BodyOrder::Special { motion: SpecialMotion::fall(0) }))
        .expect("fall");
    // The fall holds the head: a head order meanwhile changes nothing.
    let head = HeadOrder { target: HeadAngles { yaw: 1.0, pitch: 0.0 }, max_speed: 0.0 };
    sim.apply_orders(0, &ActuatorOrders { head: Some(head), body: None }).expect("head");
    let duration = sim.config().body.protective_fall_time;
    sim.advance_to(at(0.2 + duration + 0.02), &mut ());
    assert_eq!(
        sim.body(0).map(|b| b.motion_state()),
        Some(BodyMotionState::Fallen { direction: FallDirection::Back })
    );
    assert_eq!(sim.body(0).map(|b| b.head()), Some(HeadAngles::default()));
    let frame = sim.take_frame(0).expect("robot 0").expect("a frame");
    assert!(frame.inertial.body_angles[1] < -1.0, "on its back: {:?}", frame.inertial);
}
