//! The planning layer: MAMC availability, MAMS default mission, ARS role assignment and
//! double-role resolution, instant messages, and the message budget.

use serde::{Deserialize, Serialize};
use strata_robot::control::planning::{
    Candidate, MessageBudget, MessageKind, MissionCatalog, MissionSpec, OwnState, Planner,
    PlanningConfig, PlanningPolicy, RoleSpec, SharedObject, StandingStatus, TeamMessage,
    TeammateRecord,
};
use strata_robot::geometry::{Point, Pose};
use strata_runtime::Time;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
enum Mission {
    DefendGoal,
    Attack,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
enum Role {
    Goalie,
    Striker,
    StrikerCover,
}

struct Soccerish {
    catalog: MissionCatalog<Mission, Role>,
}

impl Soccerish {
    fn new() -> Soccerish {
        Soccerish {
            catalog: MissionCatalog {
                missions: vec![
                    MissionSpec {
                        mission: Mission::DefendGoal,
                        roles: vec![RoleSpec {
                            role: Role::Goalie,
                            max_robots: Some(1),
                            designated: Some(1),
                        }],
                    },
                    MissionSpec {
                        mission: Mission::Attack,
                        roles: vec![
                            RoleSpec { role: Role::Striker, max_robots: Some(1), designated: None },
                            RoleSpec {
                                role: Role::StrikerCover,
                                max_robots: None,
                                designated: None,
                            },
                        ],
                    },
                ],
                default_mission: Mission::Attack,
                default_role: Role::Striker,
            },
        }
    }
}

fn ball_distance(candidate: &Candidate<'_>) -> f64 {
    candidate
        .objects
        .iter()
        .find(|o| o.name == "ball")
        .map_or(f64::INFINITY, |b| candidate.pose.position().distance(b.position))
}

impl PlanningPolicy for Soccerish {
    type Mission = Mission;
    type Role = Role;

    fn catalog(&self) -> &MissionCatalog<Mission, Role> {
        &self.catalog
    }

    fn select_mission(
        &self,
        _: &OwnState,
        _: Option<(Mission, Role)>,
        _: &[&TeammateRecord<Mission, Role>],
    ) -> Mission {
        Mission::Attack
    }

    fn role_utility(&self, candidate: &Candidate<'_>, role: Role, _: Mission) -> f64 {
        match role {
            Role::Striker => -ball_distance(candidate),
            _ => 0.0,
        }
    }
}

fn ball_at(x: f64) -> Vec<SharedObject> {
    vec![SharedObject {
        name: "ball".into(),
        position: Point::new(x, 0.0),
        sigma: 0.1,
        confidence: 0.9,
        age: 0.0,
    }]
}

fn own(id: u8, x: f64, ball: f64) -> OwnState {
    OwnState {
        id,
        status: StandingStatus::Stable,
        penalized: false,
        localized: true,
        pose: Pose::new(x, 0.0, 0.0),
        pose_confidence: 0.9,
        objects: ball_at(ball),
    }
}

fn message(sender: u8, x: f64, ball: f64, role: Role) -> TeamMessage<Mission, Role> {
    TeamMessage {
        sender,
        mission: Mission::Attack,
        role,
        status: StandingStatus::Stable,
        penalized: false,
        localized: true,
        since_last_received: 0.0,
        data_received: true,
        utility: 0.0,
        conflict: false,
        pose: Pose::new(x, 0.0, 0.0),
        pose_confidence: 0.9,
        objects: ball_at(ball),
        signal: None,
    }
}

fn t(s: f64) -> Time {
    Time::from_secs_f64(s)
}

#[test]
fn without_communication_every_field_player_attacks_as_striker_and_the_goalie_keeps_goal() {
    for id in 2..=5 {
        let mut planner = Planner::new(Soccerish::new(), PlanningConfig::default());
        planner.evaluate(t(1.0), own(id, 0.0, 1.0));
        let a = planner.assignment();
        assert_eq!(
            (a.mission, a.role, a.alone),
            (Mission::Attack, Role::Striker, true),
            "robot {id}"
        );
    }
    let mut goalie = Planner::new(Soccerish::new(), PlanningConfig::default());
    goalie.evaluate(t(1.0), own(1, -4.0, 1.0));
    assert_eq!(goalie.assignment().role, Role::Goalie);
}

#[test]
fn the_robot_nearest_the_ball_is_striker_and_the_other_covers() {
    let mut near = Planner::new(Soccerish::new(), PlanningConfig::default());
    let mut far = Planner::new(Soccerish::new(), PlanningConfig::default());
    near.receive(t(0.5), message(3, -2.0, 1.0, Role::Striker));
    far.receive(t(0.5), message(2, 0.5, 1.0, Role::Striker));
    near.evaluate(t(1.0), own(2, 0.5, 1.0));
    far.evaluate(t(1.0), own(3, -2.0, 1.0));
    assert_eq!(near.assignment().role, Role::Striker);
    assert_eq!(far.assignment().role, Role::StrikerCover);
    assert!(!near.assignment().alone);
}

#[test]
fn a_double_striker_is_detected_announced_and_resolved_deterministically() {
    // Both robots are equally far from the ball; each still believes the other is striker.
    let mut a = Planner::new(Soccerish::new(), PlanningConfig::default());
    let mut b = Planner::new(Soccerish::new(), PlanningConfig::default());
    a.receive(t(0.5), message(4, -1.0, 0.0, Role::Striker));
    b.receive(t(0.5), message(2, 1.0, 0.0, Role::Striker));
    a.evaluate(t(1.0), own(2, 1.0, 0.0));
    b.evaluate(t(1.0), own(4, -1.0, 0.0));
    // Equal utilities: the lower number keeps the role, the other yields.
    assert_eq!(a.assignment().role, Role::Striker);
    assert_eq!(b.assignment().role, Role::StrikerCover);
    // Robot 2 saw 4 claiming its single-robot role: it reports the conflict at once.
    assert_eq!(a.stats.conflicts_detected, 1);
    assert_eq!(a.message_due(t(1.0)), Some(MessageKind::Instant));
    let sent = a.compose(t(1.0), MessageKind::Instant).expect("a message");
    assert!(sent.conflict);
    // Once 4 hears the new state, nobody claims striker twice.
    b.receive(t(1.1), sent);
    b.evaluate(t(1.2), own(4, -1.0, 0.0));
    assert_eq!(b.assignment().role, Role::StrikerCover);
}

#[test]
fn a_silent_or_fallen_teammate_is_freed_from_its_role_until_it_recovers() {
    let mut planner = Planner::new(
        Soccerish::new(),
        PlanningConfig { teammate_timeout: 5.0, ..PlanningConfig::default() },
    );
    planner.receive(t(0.0), message(3, 0.9, 1.0, Role::Striker));
    planner.evaluate(t(1.0), own(2, -3.0, 1.0));
    assert_eq!(planner.assignment().role, Role::StrikerCover);
    // The striker falls: its role is freed and this robot takes it.
    let mut fallen = message(3, 0.9, 1.0, Role::Striker);
    fallen.status = StandingStatus::Fallen;
    planner.receive(t(2.0), fallen);
    planner.evaluate(t(2.1), own(2, -3.0, 1.0));
    assert_eq!(planner.assignment().role, Role::Striker);
    let record = planner.teammates().next().expect("teammate");
    assert_eq!(record.unavailable.as_deref(), Some("fallen"));
    // It stands up and reports: the nearer robot reclaims striker.
    planner.receive(t(8.0), message(3, 0.9, 1.0, Role::StrikerCover));
    planner.evaluate(t(8.1), own(2, -3.0, 1.0));
    assert_eq!(planner.assignment().role, Role::StrikerCover);
    // Then it goes silent beyond the timeout: alone again, default mission.
    planner.evaluate(t(14.0), own(2, -3.0, 1.0));
    assert_eq!(planner.assignment().role, Role::Striker);
    assert!(planner.assignment().alone);
    assert!(
        planner
            .teammates()
            .next()
            .expect("teammate")
            .unavailable
            .as_deref()
            .is_some_and(|u| u.starts_with("silent"))
    );
}

#[test]
fn a_fall_triggers_an_instant_message_without_waiting_for_the_period() {
    let mut planner = Planner::new(
        Soccerish::new(),
        PlanningConfig { message_interval: 10.0, ..PlanningConfig::default() },
    );
    planner.evaluate(t(0.0), own(2, 0.0, 1.0));
    assert_eq!(planner.message_due(t(0.0)), Some(MessageKind::Periodic));
    planner.compose(t(0.0), MessageKind::Periodic);
    planner.evaluate(t(1.0), own(2, 0.0, 1.0));
    assert_eq!(planner.message_due(t(1.0)), None, "nothing new, period not over");
    let mut fallen = own(2, 0.0, 1.0);
    fallen.status = StandingStatus::Fallen;
    planner.evaluate(t(2.0), fallen);
    assert_eq!(planner.message_due(t(2.0)), Some(MessageKind::Instant));
    let m = planner.compose(t(2.0), MessageKind::Instant).expect("message");
    assert_eq!(m.status, StandingStatus::Fallen);
    assert_eq!(planner.stats.sent_instant, 1);
}

#[test]
fn the_message_budget_is_never_exceeded_and_lasts_the_game() {
    let mut planner = Planner::new(
        Soccerish::new(),
        PlanningConfig {
            message_interval: 1.0,
            min_message_spacing: 0.0,
            ..PlanningConfig::default()
        },
    );
    // 5 robots share 1200 messages over a 600 s game: 240 each, 4 kept for instant messages.
    planner.budget = MessageBudget {
        team_remaining: 1200,
        robots: 5,
        time_left: 600.0,
        reserve: 4,
        vital_reserve: 0,
    };
    assert!((planner.budget.sustainable_interval() - 600.0 / 240.0).abs() < 1e-9);
    let mut sent = 0;
    let mut time = 0.0;
    while time < 600.0 {
        planner.budget.time_left = 600.0 - time;
        planner.evaluate(t(time), own(2, 0.0, 1.0));
        if let Some(kind) = planner.message_due(t(time)) {
            planner.compose(t(time), kind);
            sent += 1;
            // The other four robots spend at the same pace.
            planner.budget.team_remaining = planner.budget.team_remaining.saturating_sub(4);
        }
        time += 0.1;
    }
    assert!(sent <= 240, "{sent} messages sent");
    assert!(sent >= 200, "the budget should be used, not hoarded: {sent}");
    // With nothing left, not even an instant message goes out.
    planner.budget.team_remaining = 0;
    let mut fallen = own(2, 0.0, 1.0);
    fallen.status = StandingStatus::Fallen;
    planner.evaluate(t(601.0), fallen);
    assert_eq!(planner.message_due(t(601.0)), None);
    assert!(planner.stats.withheld > 0);
}

/// A robot without teammates (`Alone`, `NoCodec`): its one mission and role, whatever it
/// hears; its messages encode to nothing and no bytes decode as a teammate's.
#[test]
fn a_lone_robot_keeps_its_one_mission_and_role() {
    use strata_robot::application::{Alone, NoCodec, Solo, TeamCodec};
    let mut planner = Planner::new(Alone::default(), PlanningConfig::default());
    planner.evaluate(t(1.0), own(1, 0.0, 1.0));
    let a = planner.assignment();
    assert_eq!((a.mission, a.role, a.alone), (Solo::Alone, Solo::Alone, true));
    let stray = message(2, 1.0, 1.0, Role::Striker);
    let stray = TeamMessage {
        sender: stray.sender,
        mission: Solo::Alone,
        role: Solo::Alone,
        status: stray.status,
        penalized: stray.penalized,
        localized: stray.localized,
        since_last_received: stray.since_last_received,
        data_received: stray.data_received,
        utility: stray.utility,
        conflict: stray.conflict,
        pose: stray.pose,
        pose_confidence: stray.pose_confidence,
        objects: stray.objects,
        signal: None,
    };
    assert_eq!(NoCodec.encode(&stray), Ok(Vec::new()));
    assert!(TeamCodec::<Solo, Solo>::decode(&NoCodec, &[1, 2, 3]).is_err());
    planner.receive(t(1.5), stray);
    planner.evaluate(t(2.0), own(1, 0.0, 1.0));
    assert_eq!(
        (planner.assignment().mission, planner.assignment().role),
        (Solo::Alone, Solo::Alone)
    );
}
