//! The world's behaviour: physics invariants, the referee, team broadcast emulation, experiment
//! controls and determinism. Fixed seeds throughout; no timing assertions.

mod common;

use std::time::Duration;

use common::*;
use strata_robot::Vector;
use strata_robot::platform::{
    ActuatorOrders, BodyMotionState, BodyOrder, CycleStage, FallDirection, LinkError, MotionName,
    SpecialMotion,
};
use strata_sim::{
    BallScript, EventKind, FallCause, GameState, NoiseConfig, NoiseLevel, Penalty, RobotId,
    SetPlay, SimConfig, Simulation,
};
use strata_spl::field::BallStatus;
use strata_spl::gamecontroller::{
    CONTROL_PACKET_SIZE, GameControlData, RobotInfo, TeamColour, TeamInfo,
};

/// The catalogue's first kick, as soccer orders it.
const KICK: SpecialMotion = SpecialMotion::new(
    MotionName::from_static(strata_spl::motions::KICK.name),
    0,
    strata_spl::motions::KICK.head,
);

fn events(sim: &Simulation) -> Vec<EventKind> {
    sim.events().iter().map(|e| e.kind.clone()).collect()
}

// ---------------------------------------------------------------------------------------------
// Physics.

#[test]
fn friction_stops_the_ball_and_it_stays() {
    let mut sim = quiet(|_| {});
    sim.place_ball(point(-2.0, 0.0), Vector::new(2.0, 0.5)).expect("valid ball");
    steps(&mut sim, 10.0);
    let ball = sim.ball();
    assert_eq!((ball.velocity.x, ball.velocity.y), (0.0, 0.0), "the ball stopped");
    assert!(ball.position.x > -1.0 && ball.position.x < 2.0, "{:?}", ball.position);
    steps(&mut sim, 2.0);
    assert_eq!(sim.ball().position, ball.position, "a resting ball does not move");
}

#[test]
fn robots_do_not_pass_through_each_other_or_the_posts() {
    let mut sim = quiet(|_| {});
    only(&mut sim, &[A1, B1, A2]);
    place(&mut sim, A1, -1.0, 0.0, 0.0);
    place(&mut sim, B1, 1.0, 0.02, std::f64::consts::PI);
    let post = sim.field().goal(strata_spl::field::Side::Opponent).left_post;
    place(&mut sim, A2, post.x - 1.0, post.y, 0.0);
    sim.place_ball(point(0.0, 2.5), Vector::new(0.0, 0.0)).expect("valid ball");
    walk(&mut sim, A1, 0.25, 0.0, 0.0);
    walk(&mut sim, B1, 0.25, 0.0, 0.0);
    walk(&mut sim, A2, 0.25, 0.0, 0.0);
    let radius = sim.config().robot.radius;
    let post_radius = sim.field().dimensions().goal_post_diameter / 2.0;
    let mut met = false;
    for _ in 0..1000 {
        sim.run_for(Duration::from_millis(12));
        let a = sim.robot(A1).expect("a").pose.position();
        let b = sim.robot(B1).expect("b").pose.position();
        assert!(a.distance(b) >= 2.0 * radius - 1e-9, "robots overlap: {a:?} {b:?}");
        met |= a.distance(b) < 2.0 * radius + 0.01;
        let c = sim.robot(A2).expect("c").pose.position();
        let to_post = c.distance(point(post.x, post.y));
        assert!(to_post >= radius + post_radius - 1e-9, "robot in the post: {c:?}");
    }
    assert!(met, "the robots met");
    assert!(events(&sim).iter().any(|e| matches!(e, EventKind::Collision { .. })));
}

#[test]
fn a_walking_robot_dribbles_the_ball_and_is_recorded_as_touching_it() {
    let mut sim = quiet(|_| {});
    only(&mut sim, &[B2]);
    place(&mut sim, B2, 0.0, 0.0, 0.0);
    sim.place_ball(point(0.5, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
    walk(&mut sim, B2, 0.2, 0.0, 0.0);
    steps(&mut sim, 4.0);
    let ball = sim.ball();
    assert!(ball.position.x > 0.7, "the ball was pushed: {:?}", ball.position);
    assert_eq!(ball.last_touch, Some(1));
}

#[test]
fn a_kick_sends_the_ball_only_when_it_is_within_reach() {
    let mut sim = quiet(|_| {});
    only(&mut sim, &[A1]);
    place(&mut sim, A1, 0.0, 0.0, 0.0);
    sim.place_ball(point(0.18, 0.05), Vector::new(0.0, 0.0)).expect("valid ball");
    let kick = ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion: KICK }) };
    sim.apply_orders(A1, &kick).expect("in the catalogue");
    steps(&mut sim, 0.3);
    assert!(matches!(
        sim.robot(A1).expect("a").body,
        BodyMotionState::Special { motion: KICK, .. }
    ));
    steps(&mut sim, 1.5);
    let ball = sim.ball();
    assert!(ball.position.x > 1.0, "kicked: {:?}", ball.position);
    assert!(events(&sim).iter().any(|e| matches!(e, EventKind::Kick { hit: true, .. })));
    // Out of reach: the foot swings through the air.
    steps(&mut sim, 10.0);
    sim.place_ball(point(-1.0, 0.0), Vector::new(0.0, 0.0)).expect("valid ball");
    sim.apply_orders(A1, &kick).expect("in the catalogue");
    steps(&mut sim, 2.0);
    assert_eq!(sim.ball().position, point(-1.0, 0.0));
    assert!(events(&sim).iter().any(|e| matches!(e, EventKind::Kick { hit: false, .. })));
    // A motion outside the catalogue is refused: a number beyond its kicks, a kind it lacks.
    let wave = SpecialMotion::new(MotionName::from_static("wave"), 0, false);
    for motion in [SpecialMotion { sequence: 42, ..KICK }, wave] {
        let unknown = ActuatorOrders { head: None, body: Some(BodyOrder::Special { motion }) };
        let refused = sim.apply_orders(A1, &unknown).expect_err("not in the catalogue");
        assert!(refused.to_string().contains(&motion.to_string()), "{refused}");
    }
}

// ---------------------------------------------------------------------------------------------
// The walk, falls and stand-ups.

#[test]
fn the_walk_reports_its_cyclic_stages_and_odometry_has_its_configured_error() {
    let mut sim = quiet(|c| {
        c.noise.odometry.scale_x = Some(0.1);
    });
    only(&mut sim, &[A1]);
    place(&mut sim, A1, -2.0, 0.0, 0.0);
    let _ = sim.read_motion(A1);
    walk(&mut sim, A1, 0.2, 0.0, 0.0);
    steps(&mut sim, 0.1);
    let feedback = sim.read_motion(A1).expect("motion");
    assert!(matches!(
        feedback.body,
        BodyMotionState::Walking { stage: CycleStage::Initialization, .. }
    ));
    let mut odometry = feedback.odometry;
    steps(&mut sim, 5.0);
    let feedback = sim.read_motion(A1).expect("motion");
    assert!(matches!(feedback.body, BodyMotionState::Walking { stage: CycleStage::Execution, .. }));
    odometry = odometry.then(feedback.odometry);
    let walked = sim.robot(A1).expect("a").pose.x + 2.0;
    assert!(walked > 0.8, "{walked}");
    assert!((odometry.dx - 1.1 * walked).abs() < 1e-9, "{} vs {walked}", odometry.dx);
    // A kidnapping is invisible to odometry.
    place(&mut sim, A1, 2.0, 2.0, 1.0);
    let _ = sim.read_motion(A1);
    walk(&mut sim, A1, 0.0, 0.0, 0.0);
    steps(&mut sim, 0.012);
    assert!(sim.read_motion(A1).expect("motion").odometry.dx.abs() < 0.01);
}

#[test]
fn falls_show_in_the_imu_and_standing_up_takes_seconds() {
    let mut sim = quiet(|_| {});
    only(&mut sim, &[A1]);
    place(&mut sim, A1, 0.0, 0.0, 0.0);
    steps(&mut sim, 0.1);
    sim.force_fall(A1, FallDirection::Back).expect("known robot");
    let onset = sim.time();
    let mut pitches = Vec::new();
    for _ in 0..100 {
        sim.run_for(Duration::from_millis(12));
        if let Some(frame) = sim.take_sensor_frame(A1).expect("known") {
            pitches.push(frame.inertial.body_angles[1]);
        }
    }
    assert!(pitches.windows(2).take(40).all(|w| w[1] <= w[0]), "pitch falls backwards steadily");
    assert!(pitches.last().copied().unwrap_or(0.0) < -1.0, "lying on its back");
    let truth = sim.robot(A1).expect("a");
    assert!(truth.fallen);
    assert_eq!(truth.fall_onset, Some(onset));
    assert!(matches!(truth.body, BodyMotionState::Fallen { direction: FallDirection::Back }));
    let stand = ActuatorOrders {
        head: None,
        body: Some(BodyOrder::Special { motion: SpecialMotion::stand_up(1) }),
    };
    sim.apply_orders(A1, &stand).expect("in the catalogue");
    steps(&mut sim, 3.0);
    assert!(!matches!(sim.robot(A1).expect("a").body, BodyMotionState::Standing));
    steps(&mut sim, 2.0);
    assert_eq!(sim.robot(A1).expect("a").body, BodyMotionState::Standing);
    assert!(events(&sim).iter().any(|e| matches!(
        e,
        EventKind::Fall { cause: FallCause::Forced, direction: FallDirection::Back, .. }
    )));
    assert!(events(&sim).iter().any(|e| matches!(e, EventKind::StandUp { success: true, .. })));
}

#[test]
fn stand_ups_can_fail_and_collisions_and_pushes_make_robots_fall() {
    let mut sim = quiet(|c| {
        c.noise.falls.stand_up_failure = Some(1.0);
        c.noise.falls.collision_fall_per_mps = Some(10.0);
    });
    only(&mut sim, &[A1, B1, A2]);
    place(&mut sim, A1, -0.5, 0.0, 0.0);
    place(&mut sim, B1, 0.5, 0.0, std::f64::consts::PI);
    place(&mut sim, A2, -2.0, 2.0, 0.0);
    walk(&mut sim, A1, 0.25, 0.0, 0.0);
    walk(&mut sim, B1, 0.25, 0.0, 0.0);
    steps(&mut sim, 6.0);
    for robot in [A1, B1] {
        assert!(sim.robot(robot).expect("robot").fallen, "{robot} fell in the collision");
    }
    assert!(
        events(&sim)
            .iter()
            .any(|e| matches!(e, EventKind::Fall { cause: FallCause::Collision, .. }))
    );
    let stand = ActuatorOrders {
        head: None,
        body: Some(BodyOrder::Special { motion: SpecialMotion::stand_up(0) }),
    };
    sim.apply_orders(A1, &stand).expect("in the catalogue");
    steps(&mut sim, 6.0);
    assert!(sim.robot(A1).expect("a").fallen, "the stand-up failed");
    assert!(events(&sim).iter().any(|e| matches!(e, EventKind::StandUp { success: false, .. })));
    sim.push(A2, Vector::new(0.0, -0.6)).expect("known robot");
    steps(&mut sim, 1.0);
    let pushed = sim.robot(A2).expect("c");
    assert!(pushed.fallen && pushed.pose.y < 1.95, "{pushed:?}");
}

// ---------------------------------------------------------------------------------------------
// The referee.

#[test]
fn a_goal_is_detected_counted_and_restarts_the_game() {
    let mut sim = Simulation::new(SimConfig::default().without_noise()).expect("valid");
    sim.set_game_state(GameState::Playing);
    sim.place_ball(point(3.8, 0.2), Vector::new(3.0, 0.0)).expect("valid ball");
    steps(&mut sim, 2.0);
    let game = sim.game();
    assert_eq!(game.score, [1, 0], "team 0 attacks +x in the first half");
    assert_eq!(game.state, GameState::Ready);
    assert_eq!(game.kicking_team, Some(1), "the team that conceded kicks off");
    assert!(events(&sim).iter().any(|e| matches!(e, EventKind::Goal { team: 0, .. })));
}

#[test]
fn balls_out_become_set_plays_with_the_ball_placed_by_the_rules() {
    let config = SimConfig::default().without_noise();
    let (hl, hw) = (4.5, 3.0);
    // Over a side line, nobody touched it: a kick-in on the line where it left.
    let mut sim = Simulation::new(config.clone()).expect("valid");
    only(&mut sim, &[]);
    sim.set_game_state(GameState::Playing);
    sim.place_ball(point(1.0, hw - 0.3), Vector::new(0.0, 2.0)).expect("valid ball");
    steps(&mut sim, 1.0);
    let game = sim.game();
    assert_eq!(game.set_play, SetPlay::KickIn);
    assert_eq!(game.state, GameState::Playing);
    let ball = sim.ball().position;
    assert!((ball.y - hw).abs() < 1e-9 && (ball.x - 1.0).abs() < 0.05, "{ball:?}");
    // Over the goal line, by the attackers: a goal kick from the goal area's front corner.
    let mut sim = Simulation::new(config.clone()).expect("valid");
    only(&mut sim, &[]);
    sim.set_game_state(GameState::Playing);
    sim.place_ball(point(hl - 0.3, 1.5), Vector::new(2.0, 0.0)).expect("valid ball");
    steps(&mut sim, 1.0);
    assert_eq!(sim.game().set_play, SetPlay::GoalKick);
    assert_eq!(sim.game().kicking_team, Some(1));
    assert_eq!(sim.ball().position, point(hl - 0.6, 1.1));
    // Over the goal line, by a defender: a corner kick.
    let mut sim = Simulation::new(config).expect("valid");
    only(&mut sim, &[B1]);
    sim.set_game_state(GameState::Playing);
    place(&mut sim, B1, hl - 0.3, 1.5 + 0.17, 0.0);
    sim.place_ball(point(hl - 0.6, 1.5), Vector::new(1.5, 0.0)).expect("valid ball");
    steps(&mut sim, 2.0);
    let outs: Vec<_> =
        events(&sim).into_iter().filter(|e| matches!(e, EventKind::BallOut { .. })).collect();
    assert!(
        matches!(
            outs.first(),
            Some(EventKind::BallOut {
                status: BallStatus::OutOverGoalLine(_),
                set_play: SetPlay::CornerKick,
                team: Some(0),
                ..
            })
        ),
        "{outs:?}"
    );
    assert_eq!(sim.ball().position, point(hl, hw));
}

#[test]
fn the_referee_runs_both_halves_and_switches_sides() {
    let mut config = SimConfig::default().without_noise();
    config.referee.initial_duration = 1.0;
    config.referee.ready_duration = 2.0;
    config.referee.set_duration = 1.0;
    config.referee.half_duration = 5.0;
    config.referee.half_time_break = 1.0;
    let mut sim = Simulation::new(config).expect("valid");
    assert_eq!(sim.game().state, GameState::Initial);
    assert_eq!(sim.game().attack_sign, [1.0, -1.0]);
    steps(&mut sim, 30.0);
    let states: Vec<(GameState, bool)> = events(&sim)
        .into_iter()
        .filter_map(|e| match e {
            EventKind::GameState { state, first_half } => Some((state, first_half)),
            _ => None,
        })
        .collect();
    use GameState::*;
    assert_eq!(
        states,
        [
            (Ready, true),
            (Set, true),
            (Playing, true),
            (Finished, true),
            (Initial, false),
            (Ready, false),
            (Set, false),
            (Playing, false),
            (Finished, false),
        ]
    );
    let game = sim.game();
    assert!(game.game_over);
    assert_eq!(game.attack_sign, [-1.0, 1.0], "sides switched at half time");
    // Robots start the second half on the side lines of their new own half.
    let a1 = sim.robot(A1).expect("a");
    assert!(a1.pose.x > 0.0 && a1.team_pose.x < 0.0, "{a1:?}");
}

#[test]
fn control_packets_are_real_gamecontroller_bytes_at_2_hz() {
    let mut sim = Simulation::new(SimConfig::default().without_noise()).expect("valid");
    steps(&mut sim, 0.99);
    let packets = sim.take_control_packets(A1).expect("known robot");
    assert_eq!(packets.len(), 2, "2 Hz");
    let bytes = &packets[0].bytes;
    assert_eq!(bytes.len(), CONTROL_PACKET_SIZE);
    assert_eq!(&bytes[..4], b"RGme");
    assert_eq!(bytes[4], 18);
    let team = |number, field_player_colour, goalkeeper_colour| TeamInfo {
        team_number: number,
        field_player_colour,
        goalkeeper_colour,
        goalkeeper: 1,
        score: 0,
        penalty_shot: 0,
        single_shots: 0,
        message_budget: 1200,
        players: [RobotInfo::default(); 20],
    };
    let expected = GameControlData {
        packet_number: 0,
        players_per_team: 7,
        state: GameState::Initial,
        first_half: true,
        kicking_team: Some(10),
        secs_remaining: 600,
        secondary_time: 0,
        teams: [
            team(10, TeamColour::Blue, TeamColour::Yellow),
            team(20, TeamColour::Red, TeamColour::Black),
        ],
        ..GameControlData::default()
    };
    assert_eq!(bytes.as_slice(), expected.encode().as_slice(), "byte-exact");
    let second = GameControlData::decode(&packets[1].bytes).expect("valid packet");
    assert_eq!(second.packet_number, 1);
    // A penalty shows in the packet.
    sim.penalize(A2, Penalty::Manual, Some(30.0)).expect("known robot");
    steps(&mut sim, 0.5);
    let packet = sim.take_control_packets(A1).expect("known robot").pop().expect("a packet");
    let data = GameControlData::decode(&packet.bytes).expect("valid packet");
    let slot = data.team(10).and_then(|t| t.player(2)).copied().expect("player 2");
    assert_eq!(slot.penalty, Penalty::Manual);
    assert_eq!(slot.secs_till_unpenalised, 30, "the timer runs only in Ready and Playing");
}

#[test]
fn leaving_the_field_is_penalized_and_the_robot_comes_back() {
    let mut sim = Simulation::new(SimConfig::default().without_noise()).expect("valid");
    only(&mut sim, &[A1]);
    sim.set_game_state(GameState::Playing);
    place(&mut sim, A1, 0.0, 2.9, std::f64::consts::FRAC_PI_2);
    walk(&mut sim, A1, 0.25, 0.0, 0.0);
    steps(&mut sim, 5.0);
    let truth = sim.robot(A1).expect("a");
    assert_eq!(truth.penalty, Penalty::LeavingTheField);
    assert!(
        events(&sim)
            .iter()
            .any(|e| matches!(e, EventKind::Penalty { penalty: Penalty::LeavingTheField, .. }))
    );
    steps(&mut sim, 46.0);
    let truth = sim.robot(A1).expect("a");
    assert_eq!(truth.penalty, Penalty::None);
    assert!(sim.field().is_inside_field(truth.pose.x, truth.pose.y), "{:?}", truth.pose);
}

// ---------------------------------------------------------------------------------------------
// Team broadcast emulation.

#[test]
fn team_messages_reach_teammates_only_after_the_delay() {
    let mut sim = quiet(|c| {
        c.broadcast.delay = 0.05;
        c.broadcast.jitter = 0.0;
    });
    sim.send_team_message(A1, &[7u8; 100]).expect("within the limit");
    steps(&mut sim, 0.036);
    assert!(sim.take_team_messages(A2).expect("known").is_empty(), "not before the delay");
    steps(&mut sim, 0.036);
    for player in 2..=7 {
        let received = sim.take_team_messages(RobotId::new(0, player)).expect("known");
        assert_eq!(received.len(), 1, "teammate {player}");
        assert_eq!(received[0].bytes, vec![7u8; 100]);
    }
    assert!(sim.take_team_messages(A1).expect("known").is_empty(), "not to the sender");
    assert!(sim.take_team_messages(B1).expect("known").is_empty(), "not to opponents");
    let budget = sim.game().message_budget;
    assert_eq!(budget, [1199, 1200], "counted in Playing");
    // Oversized messages are rejected and counted; the GameController calls them illegal.
    assert!(matches!(
        sim.send_team_message(A1, &[0u8; 129]),
        Err(LinkError::TooLarge { size: 129, limit: 128 })
    ));
    assert_eq!(sim.comms_stats().rejected_oversize, 1);
    assert!(events(&sim).iter().any(|e| matches!(e, EventKind::IllegalCommunication { team: 0 })));
}

#[test]
fn broadcast_loss_drops_the_configured_fraction_and_can_change_at_run_time() {
    let mut sim = quiet(|c| c.broadcast.loss = 0.3);
    for _ in 0..1000 {
        sim.send_team_message(B1, b"hello").expect("small message");
        steps(&mut sim, 0.012);
    }
    steps(&mut sim, 0.1);
    let received = sim.take_team_messages(B2).expect("known").len();
    assert!((640..=760).contains(&received), "received {received} of 1000 at 30 % loss");
    let stats = sim.comms_stats().clone();
    assert_eq!(stats.sent, 1000);
    assert_eq!(stats.delivered + stats.lost, 6000, "six teammates each");
    sim.set_packet_loss(1.0).expect("a probability");
    sim.send_team_message(B1, b"lost").expect("small message");
    steps(&mut sim, 0.1);
    assert!(sim.take_team_messages(B2).expect("known").is_empty());
    assert!(sim.set_packet_loss(1.5).is_err());
}

#[test]
fn the_budget_counts_only_in_ready_set_and_playing() {
    let mut sim = Simulation::new(SimConfig::default().without_noise()).expect("valid");
    sim.send_team_message(A1, b"initial").expect("sent");
    assert_eq!(sim.game().message_budget, [1200, 1200]);
    sim.set_game_state(GameState::Ready);
    sim.send_team_message(A1, b"ready").expect("sent");
    sim.send_team_message(B1, b"ready").expect("sent");
    assert_eq!(sim.game().message_budget, [1199, 1199]);
}

// ---------------------------------------------------------------------------------------------
// Experiment controls.

#[test]
fn a_scripted_ball_moves_at_its_speed_and_removed_robots_leave_the_world() {
    let mut sim = quiet(|_| {});
    let script = BallScript::new(vec![point(-3.0, 0.0), point(-3.0, 1.0), point(-2.0, 1.0)], 0.2);
    sim.script_ball(script).expect("valid script");
    steps(&mut sim, 5.5);
    let ball = sim.ball();
    assert!(ball.scripted);
    // 1.1 m along the path: past the corner.
    assert!((ball.position.y - 1.0).abs() < 1e-6 && (ball.position.x + 2.9).abs() < 1e-6);
    assert!((ball.velocity.x - 0.2).abs() < 1e-9, "turned the corner: {:?}", ball.velocity);
    sim.remove_robot(A3).expect("known robot");
    assert!(!sim.is_present(A3));
    steps(&mut sim, 0.1);
    assert_eq!(sim.take_sensor_frame(A3).expect("known"), None);
    sim.add_robot(A3).expect("known robot");
    steps(&mut sim, 0.1);
    assert!(sim.take_sensor_frame(A3).expect("known").is_some());
    assert!(sim.robot(RobotId::new(2, 1)).is_err());
    assert!(sim.robot(RobotId::new(0, 8)).is_err());
}

// ---------------------------------------------------------------------------------------------
// Determinism.

fn busy_run(seed: u64, seconds: f64) -> String {
    let config =
        SimConfig { seed, noise: NoiseConfig::level(NoiseLevel::High), ..SimConfig::default() };
    let mut sim = Simulation::new(config).expect("valid");
    sim.set_game_state(GameState::Playing);
    let ids: Vec<RobotId> = sim.robot_ids().collect();
    let steps = (seconds / 0.012) as usize;
    for step in 0..steps {
        if step % 25 == 0 {
            for (i, id) in ids.iter().enumerate() {
                let t = step as f64 * 0.012 + i as f64;
                walk(&mut sim, *id, 0.25, 0.05 * t.cos(), 0.8 * (0.7 * t).sin());
                look(&mut sim, *id, (1.3 * t).sin(), 0.3);
                let _ = sim.send_team_message(*id, &[i as u8; 40]);
            }
        }
        sim.step(Duration::from_millis(12));
        for id in &ids {
            let _ = sim.take_sensor_frame(*id);
            let _ = sim.read_motion(*id);
            let _ = sim.take_team_messages(*id);
        }
    }
    serde_json::to_string(&sim.ground_truth()).expect("serializable")
}

#[test]
fn the_same_seed_gives_the_same_world_bit_for_bit() {
    let a = busy_run(3, 30.0);
    let b = busy_run(3, 30.0);
    assert!(a == b, "two runs with the same seed differ");
    assert!(a != busy_run(4, 30.0), "another seed gives another world");
    assert!(a.contains("\"event\":\"fall\""), "the run was eventful");
}
