//! Behavior scenarios of the soccer application: a seeded simulator, a few seconds of play with
//! every robot running the full architecture on the lockstep host, and one invariant checked
//! against the simulator's ground truth and the robots' planning decisions. Deterministic: the
//! same seed gives the same play, so a scenario passes or fails the same way every time.

use std::collections::BTreeMap;
use std::f64::consts::FRAC_PI_4;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use strata_experiments::{Host, HostKind, Scene, SceneRobot};
use strata_games::matches::{Match, MatchConfig};
use strata_games::outputs;
use strata_robot::geometry::{Global as FieldFrame, Point, Pose, Vector};
use strata_runtime::{Tap, TapRecord};
use strata_sim::{BallScript, EventKind, FallDirection, GameState, NoiseLevel, RobotId, SimHandle};
use strata_soccer::catalog::{Mission, Role};
use strata_soccer::field::TeamField;
use strata_soccer::team::TeamConfig;

const SEED: u64 = 7;
const STEP: Duration = Duration::from_millis(100);

/// A robot's newest decision: mission, role, whether it is alone, and for each teammate why
/// it counts the teammate out (`None`: it counts on it).
type Latest = (Mission, Role, bool, Vec<(u8, Option<String>)>);

/// Each robot's newest assignment, from its planning layer's decisions.
#[derive(Default)]
struct Assignments {
    latest: Mutex<BTreeMap<u8, Latest>>,
}

impl Assignments {
    fn of(&self, player: u8) -> Option<(Mission, Role, bool)> {
        let latest = self.latest.lock().unwrap_or_else(PoisonError::into_inner);
        latest.get(&player).map(|(m, r, alone, _)| (*m, *r, *alone))
    }

    fn role(&self, player: u8) -> Option<Role> {
        self.of(player).map(|(_, role, _)| role)
    }

    /// Why `player` counts `teammate` out (`None`: it counts on it, or has not heard of it).
    fn counts_out(&self, player: u8, teammate: u8) -> Option<String> {
        let latest = self.latest.lock().unwrap_or_else(PoisonError::into_inner);
        latest
            .get(&player)
            .and_then(|(_, _, _, views)| views.iter().find(|(p, _)| *p == teammate).cloned())
            .and_then(|(_, reason)| reason)
    }

    fn strikers(&self) -> Vec<u8> {
        let latest = self.latest.lock().unwrap_or_else(PoisonError::into_inner);
        latest.iter().filter(|(_, (_, r, _, _))| *r == Role::Striker).map(|(p, _)| *p).collect()
    }
}

impl Tap for Assignments {
    fn package(&self, record: &TapRecord<'_>) {
        let Some(d) = record.value(outputs::DECISION) else { return };
        // Module names are `home/PLAYER/planning`.
        let Some(player) =
            record.sent_on.module_name.split('/').nth(1).and_then(|p| p.parse().ok())
        else {
            return;
        };
        let views = d.teammates.iter().map(|t| (t.member, t.unavailable.clone())).collect();
        self.latest
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(player, (d.assignment.mission, d.assignment.role, d.assignment.alone, views));
    }
}

/// A one-team scene of full-architecture robots at team-frame poses, with the ball placed.
struct Stage {
    scene: Scene,
    host: Host,
    assignments: Arc<Assignments>,
    field: Arc<TeamField>,
    t: f64,
}

impl Stage {
    fn new(robots: &[(u8, Pose)], ball: (f64, f64)) -> Stage {
        let robots: Vec<SceneRobot> = robots
            .iter()
            .map(|(player, start)| SceneRobot {
                player: *player,
                team: TeamConfig::preset("full").expect("the full team"),
                start: *start,
                gaze: None,
            })
            .collect();
        let mut scene = Scene::new("spl", NoiseLevel::Default, SEED, &robots).expect("scene");
        let field = Arc::clone(&scene.field);
        scene
            .sim
            .lock()
            .place_ball(field.to_team(ball.0, ball.1), Vector::new(0.0, 0.0))
            .expect("ball placed");
        let assignments = Arc::new(Assignments::default());
        let host = scene.host(HostKind::Lockstep, SEED, assignments.clone()).expect("host");
        Stage { scene, host, assignments, field, t: 0.0 }
    }

    fn sim(&self) -> &SimHandle {
        &self.scene.sim
    }

    fn step(&mut self) {
        self.host.advance(STEP).expect("the robots run");
        self.t += STEP.as_secs_f64();
    }

    /// Steps until `done` holds, for at most `limit` seconds; the time it took.
    fn until(&mut self, limit: f64, what: &str, mut done: impl FnMut(&Stage) -> bool) -> f64 {
        let start = self.t;
        while !done(self) {
            assert!(self.t - start < limit, "after {limit} s, still not: {what}");
            self.step();
        }
        self.t - start
    }

    /// A robot's true position, team frame.
    fn robot(&self, player: u8) -> Pose {
        let truth = self.sim().lock().robot(RobotId::new(0, player)).expect("robot");
        let p = self.field.to_team(truth.pose.x, truth.pose.y);
        let theta = if self.field.attack_sign > 0.0 {
            truth.pose.theta
        } else {
            truth.pose.theta + std::f64::consts::PI
        };
        Pose::new(p.x, p.y, strata_robot::normalize_angle(theta))
    }

    fn ball(&self) -> Point<FieldFrame> {
        let ball = self.sim().lock().ball().position;
        self.field.to_team(ball.x, ball.y)
    }

    fn down(&self, player: u8) -> bool {
        let truth = self.sim().lock().robot(RobotId::new(0, player)).expect("robot");
        truth.fallen || truth.falling
    }
}

#[test]
fn a_striker_reaches_and_kicks_a_ball_in_front_of_it_toward_the_opponent_goal() {
    let mut stage = Stage::new(&[(2, Pose::new(-0.5, 0.3, 0.0))], (0.6, 0.0));
    let robot = RobotId::new(0, 2);
    let kicked =
        |stage: &Stage| {
            stage.sim().lock().events().iter().any(
                |e| matches!(e.kind, EventKind::Kick { robot: r, hit: true, .. } if r == robot),
            )
        };
    stage.until(30.0, "the striker kicked the ball", kicked);
    assert_eq!(
        stage.assignments.of(2).map(|(m, r, _)| (m, r)),
        Some((Mission::Attack, Role::Striker))
    );
    let at_kick = stage.ball();
    for _ in 0..20 {
        stage.step();
    }
    let rolled = stage.ball() - at_kick;
    assert!(rolled.norm() > 0.5, "the ball moved {:.2} m", rolled.norm());
    // Toward the opponent goal (+x in the team frame): within the angle its posts span from
    // the kick spot, with a margin for the kick's noise.
    let to_goal = stage.field.opponent_goal() - at_kick;
    let off = strata_robot::normalize_angle(rolled.angle() - to_goal.angle()).abs();
    assert!(off < FRAC_PI_4, "the ball rolled {:.0} deg off the goal direction", off.to_degrees());
}

#[test]
fn the_goalkeeper_stays_between_ball_and_goal_while_the_ball_moves() {
    let mut stage = Stage::new(&[(1, Pose::new(-4.2, 0.0, 0.0))], (-2.5, -1.5));
    // The paper's speed (4.2): 0.2 m/s across the penalty area's front.
    let waypoints =
        [(-2.5, -1.5), (-2.5, 1.5), (-3.2, 0.5)].map(|(x, y)| stage.field.to_team(x, y)).to_vec();
    stage.sim().lock().script_ball(BallScript::new(waypoints, 0.2)).expect("scripted ball");
    // Time to walk out and localize.
    for _ in 0..60 {
        stage.step();
    }
    assert_eq!(stage.assignments.role(1), Some(Role::Goalie));
    let posts = stage.field.posts(strata_spl::field::Side::Own);
    let (mut samples, mut covering) = (0u32, 0u32);
    let (mut lowest, mut highest) = (f64::INFINITY, f64::NEG_INFINITY);
    while stage.t < 25.0 {
        stage.step();
        let (keeper, ball) = (stage.robot(1).position(), stage.ball());
        // Between ball and goal, and covering it: seen from the ball, the keeper stands near
        // the bisector of the angle the posts span (goal covering, Table 2), in front of the
        // goal line.
        let bearing = |p: Point<FieldFrame>| (p - ball).angle();
        let (a, b) = (bearing(posts[0]), bearing(posts[1]));
        let width = strata_robot::normalize_angle(a - b).abs();
        let bisector = b + strata_robot::normalize_angle(a - b) / 2.0;
        let off = strata_robot::normalize_angle(bearing(keeper) - bisector).abs();
        let in_front = keeper.x > -stage.field.half_length - 0.1 && keeper.x < ball.x;
        samples += 1;
        if in_front && off <= width / 4.0 + 0.05 {
            covering += 1;
        }
        lowest = lowest.min(keeper.y);
        highest = highest.max(keeper.y);
    }
    let fraction = f64::from(covering) / f64::from(samples);
    assert!(fraction >= 0.8, "the keeper covered the goal {:.0}% of the time", fraction * 100.0);
    // It followed the ball across the goal: a keeper standing still would not.
    assert!(highest - lowest > 0.3, "the keeper moved only {:.2} m sideways", highest - lowest);
}

#[test]
fn a_fallen_robot_gets_up_and_its_role_is_freed_then_reclaimed() {
    let mut stage = Stage::new(
        &[
            (1, Pose::new(-4.2, 0.0, 0.0)),
            (2, Pose::new(0.3, 0.0, 0.0)),
            (3, Pose::new(-2.8, 2.2, 0.0)),
        ],
        (1.0, 0.0),
    );
    stage.until(10.0, "robot 2 strikes and robot 3 does not", |s| {
        s.assignments.role(2) == Some(Role::Striker) && s.assignments.role(3) != Some(Role::Striker)
    });
    stage.sim().lock().force_fall(RobotId::new(0, 2), FallDirection::Front).expect("push");
    stage.until(2.0, "robot 2 is down", |s| s.down(2));
    stage.until(5.0, "robot 3 took the freed striker role", |s| {
        s.assignments.role(3) == Some(Role::Striker)
            && s.assignments.counts_out(3, 2).is_some_and(|why| why.contains("fall"))
    });
    let fallen = RobotId::new(0, 2);
    stage.until(20.0, "robot 2 stood up", |s| {
        s.sim().lock().events().iter().any(
            |e| matches!(e.kind, EventKind::StandUp { robot, success: true } if robot == fallen),
        )
    });

    // Its own planning kept its claim meanwhile; the team counts on it again once it is up
    // and localized, and the role follows the utilities (it is the nearest to the ball).
    stage.until(20.0, "robot 2 reclaimed the striker role", |s| {
        s.assignments.role(2) == Some(Role::Striker) && s.assignments.counts_out(3, 2).is_none()
    });
    stage.until(5.0, "one striker again", |s| s.assignments.strikers() == vec![2]);
}

#[test]
fn with_communication_cut_every_field_player_falls_back_to_attack_striker() {
    let mut stage = Stage::new(
        &[
            (1, Pose::new(-4.2, 0.0, 0.0)),
            (2, Pose::new(-0.5, 0.0, 0.0)),
            (3, Pose::new(-2.0, 1.5, 0.0)),
            (4, Pose::new(-2.0, -1.5, 0.0)),
        ],
        (0.5, 0.0),
    );
    stage.until(10.0, "a team with one striker", |s| s.assignments.strikers().len() == 1);
    stage.sim().lock().set_packet_loss(1.0).expect("loss");
    stage.until(15.0, "every field player alone, attacking as striker", |s| {
        (2..=4).all(|p| s.assignments.of(p) == Some((Mission::Attack, Role::Striker, true)))
    });
    assert_eq!(
        stage.assignments.of(1).map(|(m, r, _)| (m, r)),
        Some((Mission::DefendTheGoal, Role::Goalie))
    );
}

#[test]
fn two_equally_close_robots_resolve_a_double_striker() {
    // Mirror images about the line through the ball: the same distance and the same turn.
    let mut stage = Stage::new(
        &[(2, Pose::new(0.0, 1.0, -FRAC_PI_4)), (3, Pose::new(0.0, -1.0, FRAC_PI_4))],
        (1.0, 0.0),
    );
    // Alone at first, each attacks as striker by default: the conflict is there to resolve.
    stage.until(2.0, "both started as strikers", |s| s.assignments.strikers() == vec![2, 3]);
    stage.until(5.0, "one striker", |s| s.assignments.strikers().len() == 1);
    let mut doubles = 0;
    for _ in 0..50 {
        stage.step();
        if stage.assignments.strikers().len() != 1 {
            doubles += 1;
        }
    }
    assert_eq!(doubles, 0, "the conflict came back");
}

/// Under GameController3's timing the robots must see the referee's gesture to start Ready;
/// with `--no-delay` the packets say Ready at once. Either way the robots walk to their
/// kick-off positions, and Ready ends in legal positions.
#[test]
fn ready_ends_in_legal_positions() {
    for no_delay in [false, true] {
        ready_ends_in_legal_positions_with(no_delay);
    }
}

fn ready_ends_in_legal_positions_with(no_delay: bool) {
    let config = MatchConfig { players: 7, seed: SEED, no_delay, ..MatchConfig::default() };
    let mut game = Match::new(config).expect("match");
    let mut host = game.lockstep().expect("host");
    let sim = game.sim.clone();
    let state = || sim.lock().game().state;
    let mut waited = 0.0;
    // Where each robot stood at the end of Ready, before the referee's placement at Set.
    let mut end_of_ready = BTreeMap::new();
    while state() != GameState::Set {
        assert!(waited < 120.0, "no Set after {waited} s (state {:?})", state());
        if state() == GameState::Ready {
            let world = sim.lock();
            for id in world.robot_ids() {
                end_of_ready.insert(id, world.robot(id).expect("robot").team_pose);
            }
        }
        host.run_for(STEP).expect("the robots run");
        waited += STEP.as_secs_f64();
    }
    let world = sim.lock();
    let field = world.field().clone();
    let kicking_team = world.game().kicking_team;
    let far: Vec<_> = end_of_ready
        .iter()
        .map(|(id, pose)| {
            let team_field = TeamField::new(field.clone(), world.game().attack_sign[id.team]);
            let kicking = kicking_team == Some(id.team);
            let target =
                strata_soccer::behaviors::kickoff_pose(&team_field, id.player, kicking, false);
            (*id, pose.position().distance(target.position()))
        })
        .filter(|(_, d)| *d > 0.5)
        .collect();
    assert!(far.is_empty(), "no delay {no_delay}: robots away from their kick-off spots: {far:?}");
    let game_truth = world.game();
    for id in world.robot_ids() {
        let truth = world.robot(id).expect("robot");
        let team = &truth.team_pose;
        let kicking = game_truth.kicking_team == Some(id.team);
        let half_length = world.field().dimensions().field_length / 2.0;
        let half_width = world.field().dimensions().field_width / 2.0;
        let radius = world.field().dimensions().center_circle_diameter / 2.0;
        assert!(team.x <= 0.05, "{id:?} is not in its own half: {team:?}");
        assert!(
            team.x.abs() <= half_length + 0.05 && team.y.abs() <= half_width + 0.05,
            "{id:?} is off the field: {team:?}"
        );
        let in_circle = team.position().range() < radius - 0.05;
        assert!(!in_circle || kicking, "{id:?} of the defending team is in the centre circle");
    }
}

/// Each robot's believed game state (its planning decision's directive), by module prefix,
/// with the time it last changed.
#[derive(Default)]
struct Beliefs {
    states: Mutex<BTreeMap<String, (GameState, f64)>>,
}

impl Beliefs {
    fn all_in(&self, state: GameState) -> bool {
        let states = self.states.lock().unwrap_or_else(PoisonError::into_inner);
        states.len() == 14 && states.values().all(|(s, _)| *s == state)
    }

    fn latest_change(&self) -> f64 {
        let states = self.states.lock().unwrap_or_else(PoisonError::into_inner);
        states.values().map(|(_, t)| *t).fold(0.0, f64::max)
    }
}

impl Tap for Beliefs {
    fn package(&self, record: &TapRecord<'_>) {
        if let Some(package) = record.package(outputs::DECISION) {
            let robot = record.sent_on.module_name.trim_end_matches("/planning").to_owned();
            let state = package.value.directive.state;
            let mut states = self.states.lock().unwrap_or_else(PoisonError::into_inner);
            if states.get(&robot).is_none_or(|(s, _)| *s != state) {
                states.insert(robot, (state, package.stamp.as_secs_f64()));
            }
        }
    }

    fn wants(&self, output: &strata_runtime::TapOutput<'_>) -> bool {
        output.is(outputs::DECISION)
    }
}

/// Under GameController3's timing the packets say Standby through Ready and Set for 15 s of
/// Playing: the robots see the referee's gesture and hear the whistle themselves (or from a
/// teammate) and act on them, and the packets confirm them later.
#[test]
fn robots_follow_the_referees_gesture_and_whistle_ahead_of_the_packets() {
    let config = MatchConfig { players: 7, seed: SEED, ..MatchConfig::default() };
    let mut game = Match::new(config).expect("match");
    let beliefs = Arc::new(Beliefs::default());
    game.add_tap(beliefs.clone());
    let mut host = game.lockstep().expect("host");
    let sim = game.sim.clone();
    let packets = || sim.lock().control_data().state;
    let truth = || sim.lock().game().state;
    let run_until =
        |host: &mut strata_runtime::LockstepHost, what: &str, done: &dyn Fn() -> bool| {
            for _ in 0..1200 {
                if done() {
                    return;
                }
                host.run_for(STEP).expect("the robots run");
            }
            panic!("{what}: not within 120 s");
        };

    run_until(&mut host, "Ready", &|| truth() == GameState::Ready);
    let ready_at = sim.lock().time().as_secs_f64();
    run_until(&mut host, "every robot in Ready", &|| beliefs.all_in(GameState::Ready));
    assert_eq!(packets(), GameState::Standby, "the packets still lag");
    let followed = beliefs.latest_change() - ready_at;
    assert!(followed < 3.0, "the last robot went Ready {followed:.1} s after the gesture");

    run_until(&mut host, "Playing", &|| truth() == GameState::Playing);
    let whistle = sim.lock().events().iter().rev().find_map(|e| match &e.kind {
        EventKind::Whistle { robots } => Some((e.time.as_secs_f64(), robots.len())),
        _ => None,
    });
    let Some((whistle_at, heard)) = whistle else { panic!("no kick-off whistle") };
    assert!(heard > 0, "nobody heard the whistle");
    run_until(&mut host, "every robot in Playing", &|| beliefs.all_in(GameState::Playing));
    assert_eq!(packets(), GameState::Set, "the packets still lag");
    let started = beliefs.latest_change() - whistle_at;
    assert!(started <= 1.0, "the last robot started {started:.2} s after the whistle");
}
