//! The planning layer's soccer knowledge: which mission the team pursues (MAMS), how well each
//! robot would fill each role (ARS), and the team message codec.

use strata_robot::control::planning::{
    Candidate, MissionCatalog, OwnState, PlanningPolicy, TeamMessage, TeammateRecord,
};
use strata_robot::control::planning_module::TeamCodec;
use strata_robot::geometry::{Global as FieldFrame, Point};
use strata_runtime::Time;

use crate::catalog::{Mission, Role, catalog};
use crate::field::TeamField;
use crate::message;
use crate::world_config::BALL;

/// Tunables of mission and role selection.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SoccerPlanningConfig {
    /// The team defends (Defend mission) while the ball is behind this x (team frame), m.
    pub defend_line: f64,
    /// Hysteresis on the defend line, m: the mission does not flicker as the ball crosses it.
    pub mission_hysteresis: f64,
    /// Walking speed assumed when estimating time to reach the ball, m/s.
    pub walk_speed: f64,
    /// Turning speed assumed, rad/s.
    pub turn_speed: f64,
    /// A striker that has not come closer to the ball for this long is not accomplishing its
    /// mission (MAMC), s.
    pub striker_patience: f64,
    /// The most a teammate going to the ball is credited for walking since its message, s:
    /// beyond that, it may well have been held up.
    pub claim_progress_limit: f64,
}

impl Default for SoccerPlanningConfig {
    fn default() -> Self {
        SoccerPlanningConfig {
            defend_line: -1.2,
            mission_hysteresis: 0.3,
            walk_speed: 0.25,
            turn_speed: 1.0,
            striker_patience: 20.0,
            claim_progress_limit: 8.0,
        }
    }
}

/// The soccer planning policy.
#[derive(Debug, Clone)]
pub struct SoccerPlanning {
    catalog: MissionCatalog<Mission, Role>,
    config: SoccerPlanningConfig,
    field: TeamField,
    // Mission selection runs before role assignment in every evaluation; it leaves here what
    // the assignment needs, so that every candidate is measured against the same ball.
    defending: std::cell::Cell<bool>,
    team_ball: std::cell::Cell<Option<Point<FieldFrame>>>,
}

impl SoccerPlanning {
    pub fn new(field: TeamField, config: SoccerPlanningConfig) -> SoccerPlanning {
        SoccerPlanning {
            catalog: catalog(),
            config,
            field,
            defending: std::cell::Cell::new(false),
            team_ball: std::cell::Cell::new(None),
        }
    }
}

/// The ball as the candidates share it: the freshest, most confident estimate among them.
fn shared_ball<'a>(
    objects: impl Iterator<Item = &'a strata_robot::control::planning::SharedObject>,
) -> Option<Point<FieldFrame>> {
    objects
        .filter(|o| o.name == BALL && o.age < 5.0 && o.confidence > 0.1)
        .max_by(|a, b| (a.confidence - a.age * 0.1).total_cmp(&(b.confidence - b.age * 0.1)))
        .map(|o| o.position)
}

impl SoccerPlanning {
    fn time_to_ball(&self, candidate: &Candidate<'_>, ball: Point<FieldFrame>) -> f64 {
        let to_ball = ball - candidate.pose.position();
        let turn = strata_robot::normalize_angle(to_ball.angle() - candidate.pose.theta).abs();
        to_ball.norm() / self.config.walk_speed + turn / self.config.turn_speed
    }

    /// Where a supporting robot should stand: behind the ball, toward the own goal.
    fn cover_spot(&self, ball: Point<FieldFrame>) -> Point<FieldFrame> {
        let back = (self.field.own_goal() - ball).normalized() * 1.5;
        ball + back
    }
}

impl PlanningPolicy for SoccerPlanning {
    type Mission = Mission;
    type Role = Role;

    fn catalog(&self) -> &MissionCatalog<Mission, Role> {
        &self.catalog
    }

    fn select_mission(
        &self,
        own: &OwnState,
        held: Option<(Mission, Role)>,
        teammates: &[&TeammateRecord<Mission, Role>],
    ) -> Mission {
        let ball = shared_ball(
            own.objects.iter().chain(teammates.iter().flat_map(|t| t.message.objects.iter())),
        );
        self.team_ball.set(ball);
        // The robot going to the ball leads the mission: the others follow the mission it
        // announces, so that the team agrees even when their ball estimates straddle the
        // defend line (each deciding alone, they would split between Attack and Defend and
        // leave the ball to nobody, or to two). Two claimants: the lower number leads, as ARS
        // breaks ties; this robot is one of them when it holds the claim, and then leads from
        // its own ball (following the other claimant, while the other follows it, the two
        // would swap missions at every message and both keep going to the ball).
        let claims = |mission: Mission, role: Role| {
            matches!(role, Role::Striker | Role::ActiveDefender)
                && matches!(mission, Mission::Attack | Mission::Defend)
        };
        let leader = teammates
            .iter()
            .filter(|t| claims(t.message.mission, t.message.role))
            .min_by_key(|t| t.message.sender);
        let leading = held.is_some_and(|(m, r)| claims(m, r));
        if let Some(leader) = leader
            && !(leading && own.id < leader.message.sender)
        {
            self.defending.set(leader.message.mission == Mission::Defend);
            return leader.message.mission;
        }
        let Some(ball) = ball else { return Mission::Attack };
        // Hysteresis: once defending, the ball must come clearly forward again.
        let line = if self.defending.get() {
            self.config.defend_line + self.config.mission_hysteresis
        } else {
            self.config.defend_line
        };
        let defending = ball.x < line;
        self.defending.set(defending);
        if defending { Mission::Defend } else { Mission::Attack }
    }

    fn role_utility(&self, candidate: &Candidate<'_>, role: Role, _mission: Mission) -> f64 {
        // The same ball for every candidate: the best the team shares. A candidate measured
        // against its own, older estimate would disagree with the others' computation.
        let Some(ball) = self.team_ball.get().or_else(|| shared_ball(candidate.objects.iter()))
        else {
            // A robot that does not see the ball knows where it stands only.
            return match role {
                Role::Striker | Role::ActiveDefender => -100.0,
                _ => 0.0,
            };
        };
        match role {
            Role::Striker | Role::ActiveDefender => -self.time_to_ball(candidate, ball),
            Role::StrikerCover => -candidate.pose.position().distance(self.cover_spot(ball)),
            Role::DefenderGoingToPosition => {
                -candidate.pose.position().distance(self.field.own_goal())
            }
            Role::PassReceiver | Role::Goalie => 0.0,
        }
    }

    fn accomplishing(&self, teammate: &TeammateRecord<Mission, Role>, _now: Time) -> bool {
        // A striker that has lost the ball for long is not striking.
        teammate.message.role != Role::Striker
            || teammate
                .message
                .objects
                .iter()
                .any(|o| o.name == BALL && o.age < self.config.striker_patience)
    }

    fn instant_worthy(&self, previous: &OwnState, current: &OwnState) -> bool {
        let sees = |s: &OwnState| s.objects.iter().any(|o| o.name == BALL && o.age < 1.0);
        sees(previous) != sees(current)
    }

    fn claim_progress(&self, role: Role, age: f64) -> f64 {
        // The robot going to the ball has walked toward it since it spoke: its time to the
        // ball (the utility) has shrunk by about as much time as has passed.
        match role {
            Role::Striker | Role::ActiveDefender => {
                // max/min, not clamp: a configured limit below zero must not panic.
                age.max(0.0).min(self.config.claim_progress_limit)
            }
            _ => 0.0,
        }
    }

    fn same_claim(&self, held: Role, role: Role) -> bool {
        let to_ball = |r: Role| matches!(r, Role::Striker | Role::ActiveDefender);
        held == role || (to_ball(held) && to_ball(role))
    }
}

/// The Fig. 2 message in 128 bytes.
#[derive(Debug, Clone, Copy, Default)]
pub struct SoccerCodec;

impl TeamCodec<Mission, Role> for SoccerCodec {
    fn encode(&self, m: &TeamMessage<Mission, Role>) -> Result<Vec<u8>, String> {
        message::encode(m).map_err(|e| e.to_string())
    }

    fn decode(&self, bytes: &[u8]) -> Result<TeamMessage<Mission, Role>, String> {
        message::decode(bytes).map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_robot::control::planning::{
        Planner, PlanningConfig, SharedObject, StandingStatus, TeamMessage,
    };
    use strata_robot::geometry::Pose;

    fn ball() -> Vec<SharedObject> {
        vec![SharedObject {
            name: BALL.into(),
            position: Point::new(1.0, 0.0),
            sigma: 0.05,
            confidence: 0.9,
            age: 0.0,
        }]
    }

    fn own(x: f64) -> OwnState {
        OwnState {
            id: 3,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            pose: Pose::new(x, 0.0, 0.0),
            pose_confidence: 0.9,
            objects: ball(),
        }
    }

    /// Robot 2, going to the ball from 2 m behind it (8 s away at the assumed walking speed).
    fn striker() -> TeamMessage<Mission, Role> {
        TeamMessage {
            sender: 2,
            mission: Mission::Attack,
            role: Role::Striker,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            since_last_received: 0.0,
            data_received: true,
            utility: -8.0,
            conflict: false,
            pose: Pose::new(-1.0, 0.0, 0.0),
            pose_confidence: 0.9,
            objects: ball(),
            signal: None,
        }
    }

    fn supporter() -> Planner<SoccerPlanning> {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let mut planner = Planner::new(
            SoccerPlanning::new(field, SoccerPlanningConfig::default()),
            PlanningConfig::default(),
        );
        planner.receive(Time::from_secs_f64(0.0), striker());
        planner.evaluate(Time::from_secs_f64(0.0), own(-3.0));
        assert_eq!(planner.assignment().role, Role::StrikerCover);
        planner
    }

    #[test]
    fn a_striker_heard_seconds_ago_is_credited_with_its_walk_toward_the_ball() {
        // Four seconds later robot 3 stands half a metre from the ball. Robot 2 has been
        // walking to the ball meanwhile: no takeover on its four-second-old pose.
        let mut planner = supporter();
        planner.evaluate(Time::from_secs_f64(4.0), own(0.5));
        assert_eq!(planner.assignment().role, Role::StrikerCover);
        // Had robot 2 just said it was still 2 m behind the ball, robot 3 would take over.
        let mut planner = supporter();
        planner.receive(Time::from_secs_f64(4.0), striker());
        planner.evaluate(Time::from_secs_f64(4.0), own(0.5));
        assert_eq!(planner.assignment().role, Role::Striker);
    }

    #[test]
    fn two_robots_going_to_the_ball_follow_the_lower_numbered_one_s_mission() {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let policy = SoccerPlanning::new(field, SoccerPlanningConfig::default());
        // The ball deep in the own half; robot 2 defends it as active defender, robot 6 still
        // announces itself striker of the Attack mission.
        let deep = |id: u8| OwnState {
            id,
            objects: vec![SharedObject { position: Point::new(-3.0, 0.0), ..ball()[0].clone() }],
            ..own(0.0)
        };
        let record = |message: TeamMessage<Mission, Role>| TeammateRecord {
            message,
            last_heard: Time::from_secs_f64(0.0),
            messages: 1,
            unavailable: None,
        };
        let six = record(TeamMessage { sender: 6, objects: Vec::new(), ..striker() });
        let two = record(TeamMessage {
            sender: 2,
            mission: Mission::Defend,
            role: Role::ActiveDefender,
            objects: Vec::new(),
            ..striker()
        });
        // Each following the other, robot 2 would attack and robot 6 defend, both keeping
        // their claim to the ball: robot 2 leads, robot 6 follows it.
        let held = Some((Mission::Defend, Role::ActiveDefender));
        assert_eq!(policy.select_mission(&deep(2), held, &[&six]), Mission::Defend);
        let held = Some((Mission::Attack, Role::Striker));
        assert_eq!(policy.select_mission(&deep(6), held, &[&two]), Mission::Defend);
        // A robot not going to the ball follows whoever is.
        assert_eq!(policy.select_mission(&deep(2), None, &[&six]), Mission::Attack);
    }

    #[test]
    fn going_to_the_ball_is_one_claim_whether_attacking_or_defending() {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let policy = SoccerPlanning::new(field, SoccerPlanningConfig::default());
        assert!(policy.same_claim(Role::Striker, Role::ActiveDefender));
        assert!(!policy.same_claim(Role::StrikerCover, Role::Striker));
        assert_eq!(policy.claim_progress(Role::StrikerCover, 3.0), 0.0);
        assert_eq!(policy.claim_progress(Role::Striker, 100.0), 8.0);
    }
}
