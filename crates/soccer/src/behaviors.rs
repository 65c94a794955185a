//! Deliberative behaviors of robot soccer (paper Table 2), organised as a hierarchical state
//! machine whose top level follows the game state and whose playing states follow the role;
//! states are single behaviors or behavior trees (paper 3.4).
//!
//! ```text
//! Initial | Ready (going to field position) | Set | Finished | Penalized
//! Playing
//!   Goalie playing: Goal covering (tree: localizing / searching for object / cover) | Clearing (go to ball)
//!   Field playing:  Striker (tree: localizing / letting go / searching for object / avoiding obstacle / go to ball)
//!                   Striker cover (partner following) | Pass receiver | Active defender (go to ball)
//!                   Defender going to position (goal covering from the penalty area's edge)
//! ```
//!
//! Every behavior sets a goal for each resource: the body's goal directly, the head's through
//! the gaze strategy — value functions and active vision in the full architecture.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use strata_robot::control::active_vision::{
    ActiveVision, ActiveVisionConfig, ActiveVisionReport, Criterion, GazeCandidate, ValueFunction,
};
use strata_robot::control::bt::{
    Status, Tree, action, condition, force_failure, reactive_selector, reactive_sequence, sequence,
};
use strata_robot::control::deliberative::{
    DeliberativeInput, DeliberativeOutput, DeliberativePolicy,
};
use strata_robot::control::hsm::{BuildError, Builder, State, StateMachine};
use strata_robot::control::planning_module::PlanningDecision;
use strata_robot::control::reactive::Stability;
use strata_robot::control::scores::{GoalScore, ScoreVector};
use strata_robot::geometry::{Global as FieldFrame, Point, Pose};
use strata_robot::world::{ObjectCategory, ObjectEstimate, ObjectId, OdometryNoise, WorldState};
use strata_runtime::Time;
use strata_spl::gamecontroller::{GameState, SetPlay};

use crate::catalog::{GOALKEEPER_NUMBER, Mission, Role};
use crate::field::TeamField;
use crate::game::{GameDirective, Kicking};
use crate::gaze_override::{self, GazeOverride, Kind};
use crate::goals::{BodyGoal, GoalSide, HeadGoal, Kick, WholeBodyGoal};
use crate::predicted_motion::predicted_motion;
use crate::primitives::{
    BodyPrimitive, MotionModel, TOGETHER_RANGE, facing, nearest_point_of_line,
};
use crate::situation::{
    ball, best_instance, goal_posts, goal_side_of, obstacle_ahead, rival, rival_ahead, rival_track,
};
use crate::value::{
    AvoidingValue, GoToBallValue, GoalCoveringValue, PositionValue, RefereeVisibilityValue,
};
use crate::world_config::{BALL, OBSTACLE, landmark_groups};

/// What the planning layer sends soccer's deliberative layer.
pub type Decision = PlanningDecision<Mission, Role, GameDirective>;
pub type Output = DeliberativeOutput<HeadGoal, BodyGoal, WholeBodyGoal>;

/// How the head's score vector is made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GazeStrategy {
    /// The paper's: value functions, minimum expected value variance.
    #[default]
    ActiveVision,
    /// Value functions, maximum expected action task value.
    ActiveVisionTaskValue,
    /// Baseline: always look at the ball.
    AlwaysBall,
    /// Baseline: a fixed head scan pattern, as many SPL teams do.
    FixedScan,
    /// Baseline: look where the expected entropy of the belief (pose and ball) is smallest
    /// (after Seekircher, Laue and Röfer, RoboCup 2010).
    Entropy,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BehaviorConfig {
    pub gaze: GazeStrategy,
    /// Half the width the goalkeeper blocks, m.
    pub keeper_reach: f64,
    /// Distance of the keeper's covering position in front of the goal line, m.
    pub keeper_depth: f64,
    /// A robot going to the ball dribbles it instead of kicking within this distance of the
    /// opponent goal, m (under the second-touch rule a restart's taker still kicks). `strata
    /// robot --platform rcssservermj` sets it to the field's length when the team file leaves
    /// it at its default: the T1 dribbles the ball toward the goal at 0.23-0.27 m/s, and kicks
    /// it 2.2 m in a direction 4-47 degrees left of its heading.
    pub dribble_distance: f64,
    /// A ball unknown for longer than this is searched actively (walking), s.
    pub active_search_after: f64,
    /// Camera field of view for gaze candidates, rad.
    pub fov: f64,
    /// How far from the ball every robot keeps while the other team takes a set play (kick-in,
    /// corner, goal kick, free kick), m; 0: no such rule. rcssservermj's referee moves a robot
    /// nearer than its centre circle's radius (5.5 m) off the field, so `strata robot
    /// --platform rcssservermj` sets the radius plus half a metre when the team file leaves it
    /// at 0; the built-in simulator's referee has no such rule.
    pub set_play_distance: f64,
    /// The robot that takes a kick-off or a set play may not touch the ball again before
    /// another robot has: it keeps `let_go_distance` from the ball until the ball moves
    /// without it. rcssservermj's referee gives the other team a free kick for the second
    /// touch (rcsssmj's double-touch rule), so `strata robot --platform rcssservermj` turns
    /// this on; the built-in simulator's referee has no such rule.
    pub no_second_touch: bool,
    /// How far from the ball the taker keeps while it may not touch it, m.
    pub let_go_distance: f64,
    /// Where the head referee stands: on the halfway line, this far outside the side line at
    /// the field's negative y in the first half (teams change ends at half time, the referee
    /// stays), m (the built-in simulator's `referee.signals.behind_line`).
    pub referee_behind_line: f64,
    /// How far the referee's gesture can be seen, m.
    pub referee_range: f64,
    /// With `gaze = "active_vision_task_value"`: judge a look by the value expected after the
    /// acting primitive's predicted motion (the paper's criterion in full); false: where the
    /// robot stands (to compare the two).
    pub task_value_after_motion: bool,
    /// Active vision judges a look by the belief at the next decision, which the look holds
    /// until (an object it does not observe spreads for the deliberative period,
    /// `ActiveVisionConfig::horizon`); false: by the belief right after the look (to compare).
    pub look_held_for_period: bool,
    /// The keeper may look at a goal, both posts in one image, in place of a post's look
    /// (Table 3's "observe goal"). Off: measured in games, it cost the team more goals than
    /// it saved (docs/results.md, "The keeper's goal looks").
    pub keeper_goal_looks: bool,
}

impl Default for BehaviorConfig {
    fn default() -> Self {
        BehaviorConfig {
            gaze: GazeStrategy::ActiveVision,
            keeper_reach: 0.3,
            keeper_depth: 0.45,
            dribble_distance: 0.9,
            active_search_after: 4.0,
            fov: 1.06,
            set_play_distance: 0.0,
            no_second_touch: false,
            let_go_distance: 0.8,
            referee_behind_line: 0.6,
            referee_range: 10.0,
            task_value_after_motion: true,
            look_held_for_period: true,
            keeper_goal_looks: false,
        }
    }
}

/// The context the state machine and its trees run on.
pub struct Ctx {
    pub now: Time,
    pub world: Option<WorldState>,
    pub decision: Option<Decision>,
    pub stability: Stability,
    pub field: Arc<TeamField>,
    pub player: u8,
    pub config: BehaviorConfig,
    pub out: Output,
    vision: ActiveVision,
    pub vision_report: Option<ActiveVisionReport>,
    /// The last report's storage, reused by the next evaluation.
    spare_report: ActiveVisionReport,
    /// The last gaze candidates (their labels' storage reused) and what each looks at.
    gazes: Vec<GazeCandidate>,
    gaze_looks: Vec<Looks>,
    ball_unknown_since: Option<Time>,
    /// Since when the world model says the robot is lost.
    lost_since: Option<Time>,
    landmark_groups: Vec<String>,
    /// The body's camera geometry, for what each gaze candidate would show.
    motion: Arc<MotionModel>,
    /// Whether this robot was at the ball, in the last tick, while its team's kick-off or set
    /// play waited to be taken.
    at_own_restart: bool,
    /// Set while this robot, having taken the restart, may not touch the ball again.
    let_go: Option<LetGo>,
    /// Seconds between the last two ticks: how long the acting primitive chosen now is
    /// expected to run before the next decision.
    decision_period: f64,
    last_tick: Option<Time>,
    /// A gaze chosen from outside (a learning environment), in place of active vision's.
    gaze_override: Option<Arc<GazeOverride>>,
}

impl std::fmt::Debug for Ctx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ctx")
            .field("player", &self.player)
            .field("now", &self.now)
            .finish_non_exhaustive()
    }
}

impl Ctx {
    fn directive(&self) -> GameDirective {
        self.decision.as_ref().map(|d| d.directive.clone()).unwrap_or_default()
    }

    fn role(&self) -> Role {
        match &self.decision {
            Some(d) => d.assignment.role,
            None if self.player == GOALKEEPER_NUMBER => Role::Goalie,
            None => Role::Striker,
        }
    }

    fn lost(&self) -> bool {
        self.world.as_ref().is_none_or(|w| w.pose.lost)
    }

    fn pose(&self) -> Pose {
        self.world.as_ref().map_or_else(Pose::default, |w| w.pose.pose)
    }

    fn ball_known(&self) -> bool {
        self.world.as_ref().and_then(ball).is_some_and(|b| b.known)
    }

    fn ball_field(&self) -> Option<Point<FieldFrame>> {
        self.world.as_ref().and_then(ball).map(|b| b.field)
    }

    fn ball_unknown_for(&self) -> f64 {
        self.ball_unknown_since.map_or(0.0, |t| (self.now - t).as_secs_f64())
    }

    fn set_body(&mut self, goal: BodyGoal) {
        self.out.body = ScoreVector::single(goal);
    }

    fn ball_id(&self) -> Option<strata_robot::world::ObjectId> {
        self.world.as_ref().and_then(|w| w.object(BALL)).map(|o| o.id)
    }
}

/// The states of the machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum S {
    Initial,
    Standby,
    Ready,
    Set,
    Playing,
    Finished,
    Penalized,
    KeepingDistance,
    GoaliePlaying,
    GoalCovering,
    Clearing,
    FieldPlaying,
    Striker,
    StrikerCover,
    PassReceiver,
    ActiveDefender,
    DefenderPositioning,
}

const TOP: [S; 8] = [
    S::Initial,
    S::Standby,
    S::Ready,
    S::Set,
    S::Playing,
    S::Finished,
    S::Penalized,
    S::KeepingDistance,
];
const FIELD_ROLES: [(S, Role); 5] = [
    (S::Striker, Role::Striker),
    (S::StrikerCover, Role::StrikerCover),
    (S::PassReceiver, Role::PassReceiver),
    (S::ActiveDefender, Role::ActiveDefender),
    (S::DefenderPositioning, Role::DefenderGoingToPosition),
];

fn phase(ctx: &Ctx) -> S {
    let d = ctx.directive();
    if d.penalized {
        return S::Penalized;
    }
    match d.state {
        GameState::Initial => S::Initial,
        GameState::Standby => S::Standby,
        GameState::Ready => S::Ready,
        GameState::Set => S::Set,
        GameState::Playing if waits_for_kick_off(&d, ctx.player) => S::Ready,
        GameState::Playing if keeps_distance(&d, &ctx.config) => S::KeepingDistance,
        GameState::Playing => S::Playing,
        GameState::Finished => S::Finished,
    }
}

/// The player who takes the kick-off (the one [`kickoff_pose`] puts at the ball).
const KICKER_NUMBER: u8 = 2;
/// How far behind the ball the kicker waits for the kick-off under the second-touch rule, m
/// (a T1 beamed 0.25 m behind it touched it within 1.3 s of the kick-off in 3 of 4 halves,
/// barely moving it).
const KICKER_WAIT: f64 = 0.6;

/// While a kick-off is being taken — Playing, no set play, the GameController's secondary time
/// counting down to the free ball — every field player but the kicker keeps to its kick-off
/// position (the Ready behavior): the other team may not enter the centre circle, nor the
/// kicker's teammates the opponent half. rcssservermj's referee moves a robot that does to the
/// side line, where it is lost. The goalkeeper, far from both, covers its goal.
fn waits_for_kick_off(d: &GameDirective, player: u8) -> bool {
    let pending = d.set_play == SetPlay::None && d.secondary_time > 0;
    pending
        && player != GOALKEEPER_NUMBER
        && match d.kicking {
            Kicking::Them => true,
            Kicking::Us => player != KICKER_NUMBER,
            Kicking::Nobody => false,
        }
}

/// During the other team's set play, where the rule sets a distance to keep from the ball.
fn keeps_distance(d: &GameDirective, config: &BehaviorConfig) -> bool {
    config.set_play_distance > 0.0 && d.set_play != SetPlay::None && d.kicking == Kicking::Them
}

/// The second-touch rule's memory: since when this robot, having taken its team's kick-off or
/// set play, has kept off the ball, and where the ball came to rest after its touch.
#[derive(Clone, Copy, Debug, PartialEq)]
struct LetGo {
    since: Time,
    rest: Option<Point<FieldFrame>>,
}

/// The ball rolls this long after a kick before where it lies says anything about who touches
/// it next, s.
const LET_GO_SETTLE: f64 = 3.0;
/// A ball this far from where it came to rest was moved by another robot, m (well beyond the
/// estimate's noise at a few metres).
const LET_GO_MOVED: f64 = 0.6;
/// Within this distance of the ball while the restart waits, a robot is its taker, m.
const TAKER_RANGE: f64 = 0.8;
/// Nobody touching the ball for this long releases the taker anyway, s: a ball left alone
/// for good would stop the game, which costs more than the free kick.
const LET_GO_LIMIT: f64 = 20.0;

/// Whether this robot's team has a kick-off or set play waiting to be taken. Ready and Set
/// count: a kick-off can be taken within a deliberative cycle of Playing (rcssservermj's
/// starts as the kicker walks up to the ball), and then Playing never showed it pending.
fn own_restart_pending(d: &GameDirective) -> bool {
    d.kicking == Kicking::Us
        && match d.state {
            GameState::Ready | GameState::Set => true,
            GameState::Playing => d.set_play != SetPlay::None || d.secondary_time > 0,
            _ => false,
        }
}

/// Keeps the second-touch rule's memory current, once per tick before the machine runs: the
/// robot at the ball when its team's restart ends (the server ends it at the first touch)
/// took it, and keeps off the ball until the ball moves without it, a new restart begins, or
/// `LET_GO_LIMIT` passes.
fn track_second_touch(ctx: &mut Ctx) {
    if !ctx.config.no_second_touch {
        return;
    }
    let d = ctx.directive();
    let ball = ctx.world.as_ref().and_then(ball).filter(|b| b.known);
    let restart = own_restart_pending(&d);
    let free_play = d.state == GameState::Playing
        && d.set_play == SetPlay::None
        && d.secondary_time <= 0
        && !d.penalized;
    if !free_play {
        ctx.let_go = None;
    } else if ctx.at_own_restart {
        ctx.let_go = Some(LetGo { since: ctx.now, rest: None });
    } else if let Some(let_go) = &mut ctx.let_go {
        let waited = (ctx.now - let_go.since).as_secs_f64();
        // Only what this robot sees itself: the team's ball lags, and may be this robot's.
        let seen = ball.filter(|b| !b.from_team);
        let moved = match (let_go.rest, seen) {
            (Some(rest), Some(b)) => b.field.distance(rest) > LET_GO_MOVED,
            (None, Some(b)) if waited >= LET_GO_SETTLE => {
                let_go.rest = Some(b.field);
                false
            }
            _ => false,
        };
        if moved || waited > LET_GO_LIMIT {
            ctx.let_go = None;
        }
    }
    ctx.at_own_restart = restart && ball.is_some_and(|b| b.robot.range() < TAKER_RANGE);
}

/// The longest step back letting go orders, m: the walk side-steps and backs up to targets
/// within 0.5 m and turns towards farther ones, and a 0.4 m step plus the pose's noise turned
/// a T1 beside the ball.
const LET_GO_STEP: f64 = 0.25;

/// Letting go of the ball after taking a restart: back away to `let_go_distance` from it,
/// facing it and watching it, so the next touch is somebody else's.
fn letting_go(ctx: &mut Ctx) -> Status {
    let Some(ball) = ctx.ball_field() else {
        ctx.set_body(BodyGoal::Stand);
        ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
        return Status::Running;
    };
    let here = ctx.pose().position();
    let distance = here.distance(ball);
    let spot = if distance >= ctx.config.let_go_distance {
        here
    } else {
        // Straight back from the ball, a short step at a time: a farther target would turn
        // the robot first, and a robot turning beside the ball touches it.
        let back = (here - ball).normalized();
        here + back * (ctx.config.let_go_distance - distance).min(LET_GO_STEP)
    };
    ctx.set_body(BodyGoal::GoToPosition { pose: facing(spot, ball) });
    ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
    Status::Running
}

fn letting_go_guard(ctx: &Ctx) -> bool {
    ctx.let_go.is_some()
}

fn role_state(role: Role) -> S {
    FIELD_ROLES.iter().find(|(_, r)| *r == role).map_or(S::Striker, |(s, _)| *s)
}

/// Where playing starts for `role`: the goalie's state, or the field role's own leaf. Entering
/// `Playing` (or `Field playing`) itself would run its initial child, the striker, for a tick.
fn playing_state(role: Role) -> S {
    if role == Role::Goalie { S::GoaliePlaying } else { role_state(role) }
}

/// The states `playing_state` can give.
const PLAYING_ENTRIES: [S; 6] = [
    S::GoaliePlaying,
    S::Striker,
    S::StrikerCover,
    S::PassReceiver,
    S::ActiveDefender,
    S::DefenderPositioning,
];

// ---------------------------------------------------------------------------------------------
// The head: gaze strategies.

/// What a gaze candidate looks at: the ball, a landmark (the label is its name), the ball and
/// a landmark together (the label is `ball+` and its name), and three more of Table 3's
/// observation goals: a goal (both posts), a painted line, a rival robot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Looks {
    Ball,
    Landmark,
    Together,
    /// The goal a landmark group's best post belongs to, both posts in one image: the
    /// group's look wherever they fit in one.
    Goal(GoalSide),
    /// By index in the field's lines.
    Line(u8),
    /// By obstacle track ([`crate::situation::rival`]).
    Rival(u8),
}

impl Looks {
    fn kind(self) -> Kind {
        match self {
            Looks::Ball => Kind::Ball,
            // A policy's k-th landmark look: the goal replaces its post.
            Looks::Landmark | Looks::Goal(_) => Kind::Landmark,
            Looks::Together => Kind::Together,
            Looks::Line(_) | Looks::Rival(_) => Kind::Other,
        }
    }

    /// The head goal of a candidate with this `label`.
    fn goal(self, label: &str) -> HeadGoal {
        match self {
            Looks::Ball => HeadGoal::ObserveBall,
            Looks::Landmark => HeadGoal::ObserveLandmark { name: label.to_owned() },
            Looks::Together => HeadGoal::ObserveTogether { objects: self.objects_of(label) },
            Looks::Goal(side) => HeadGoal::ObserveGoal { side },
            Looks::Line(line) => HeadGoal::ObserveFieldLine { line },
            Looks::Rival(player) => HeadGoal::ObserveRival { player },
        }
    }

    /// The objects a candidate with this `label` looks at (the head goal's objects).
    fn objects(self, label: &str, world: &WorldState) -> Vec<String> {
        match self {
            Looks::Rival(track) => {
                rival(world, track).map(|o| o.name.to_string()).into_iter().collect()
            }
            Looks::Goal(side) => {
                goal_posts(world, side).iter().map(|o| o.name.to_string()).collect()
            }
            _ => self.objects_of(label),
        }
    }

    /// [`Looks::objects`] for the looks whose label names them.
    fn objects_of(self, label: &str) -> Vec<String> {
        match self {
            Looks::Ball => vec![BALL.to_owned()],
            Looks::Landmark => vec![label.to_owned()],
            Looks::Together => {
                let landmark = label.strip_prefix(BALL).and_then(|l| l.strip_prefix('+'));
                vec![BALL.to_owned(), landmark.unwrap_or_default().to_owned()]
            }
            Looks::Goal(_) | Looks::Line(_) | Looks::Rival(_) => Vec::new(),
        }
    }
}

/// Line candidates: the lines whose nearest points are nearest, at least this far (a line
/// under the feet shows no direction) and within the lines' range.
const LINE_CANDIDATES: usize = 2;
const LINE_MIN_DISTANCE: f64 = 0.3;

/// Sensing candidates: the ball, the best instance of each landmark group, and the ball
/// together with the nearest landmarks when they fit in one gaze; the nearest painted lines,
/// for a world model that fuses lines it has seen; and the `rivals` the value function names.
/// Each with what it looks at. `gazes` keeps its labels' storage from the last tick.
fn gaze_candidates(
    ctx: &Ctx,
    world: &WorldState,
    rivals: &[ObjectId],
    gazes: &mut Vec<GazeCandidate>,
    looks: &mut Vec<Looks>,
) {
    looks.clear();
    let mut n = 0;
    // `range`: how far the gazed point is, which sets the head's pitch and so the stretch of
    // ground the image shows.
    let mut out = |direction: f64, range: f64, label: &[&str], what: Looks| {
        let footprint = ctx.motion.footprint(range);
        match gazes.get_mut(n) {
            Some(kept) => {
                kept.label.clear();
                kept.direction = direction;
                kept.footprint = footprint;
            }
            None => gazes.push(GazeCandidate { label: String::new(), direction, footprint }),
        }
        for part in label {
            gazes[n].label.push_str(part);
        }
        looks.push(what);
        n += 1;
    };
    let ball = world.object(BALL);
    if let Some(ball) = ball
        && let Some(direction) = GazeCandidate::toward_direction(world, ball.id)
    {
        out(direction, ball.position.range(), &[BALL], Looks::Ball);
    }
    let mut landmarks: Vec<_> = ctx
        .landmark_groups
        .iter()
        .filter_map(|g| best_instance(world, g))
        .filter(|o| o.category == ObjectCategory::Landmark)
        .collect();
    landmarks.sort_by(|a, b| a.position.range().total_cmp(&b.position.range()));
    // The keeper's alone: offered to field players, goal looks slowed the team's role
    // changes past what its scenario tests allow (docs/hybrid-control.md).
    let goals = ctx.config.keeper_goal_looks && ctx.role() == Role::Goalie;
    for landmark in landmarks.iter().take(6) {
        let range = landmark.position.range();
        let goal = goals.then(|| whole_goal(world, landmark, ctx.config.fov)).flatten();
        if let Some((side, direction)) = goal {
            let label = match side {
                GoalSide::Own => "own goal",
                GoalSide::Opponent => "opponent goal",
            };
            out(direction, range, &[label], Looks::Goal(side));
        } else if let Some(direction) = GazeCandidate::toward_direction(world, landmark.id) {
            out(direction, range, &[landmark.name.as_str()], Looks::Landmark);
        }
        if let Some(ball) = ball
            && let Some(direction) = GazeCandidate::covering_direction(
                world,
                [ball.id, landmark.id],
                ctx.config.fov * 0.8,
            )
        {
            // The look-at-target primitive aims at a point this far along the direction.
            out(direction, TOGETHER_RANGE, &[BALL, "+", landmark.name.as_str()], Looks::Together);
        }
    }
    if world.expects_lines() {
        let pose = world.pose.pose;
        let (lo, hi) = ctx.vision.config.yaw_limits;
        let reach = world.layout.lines.max_range;
        let mut near: Vec<(f64, f64, u8)> = (0..ctx.field.field.lines().len())
            .filter_map(|k| {
                let seen = nearest_point_of_line(&ctx.field, k, pose)?;
                let (range, bearing) = (seen.range(), seen.bearing());
                let usable = range >= LINE_MIN_DISTANCE
                    && range <= reach
                    && bearing >= lo.min(hi)
                    && bearing <= hi.max(lo);
                Some((range, bearing, u8::try_from(k).ok()?)).filter(|_| usable)
            })
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0));
        for &(range, bearing, line) in near.iter().take(LINE_CANDIDATES) {
            let number = line.to_string();
            out(bearing, range, &["field line ", &number], Looks::Line(line));
        }
    }
    for &id in rivals {
        let Some(object) = world.get(id).filter(|o| o.known) else { continue };
        let Some(track) = rival_track(world, object) else { continue };
        out(
            object.position.bearing(),
            object.position.range(),
            &[object.name.as_str()],
            Looks::Rival(track),
        );
    }
    gazes.truncate(n);
}

/// The goal `post` belongs to and the direction that shows all its posts, when they fit in one
/// image (Table 3's "observe goal"): two posts seen together give the heading and the
/// position where one gives a bearing and a range.
fn whole_goal(world: &WorldState, post: &ObjectEstimate, fov: f64) -> Option<(GoalSide, f64)> {
    let side = goal_side_of(post)?;
    let posts = goal_posts(world, side);
    if posts.len() < 2 {
        return None;
    }
    let direction =
        GazeCandidate::covering_direction(world, posts.iter().map(|o| o.id), fov * 0.8)?;
    Some((side, direction))
}

/// The head's score vector for a behavior whose value function is `value`.
fn gaze(ctx: &mut Ctx, value: Option<&dyn ValueFunction>) {
    let strategy = ctx.config.gaze;
    let Some(world) = ctx.world.take() else {
        ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
        return;
    };
    ctx.out.head = match strategy {
        GazeStrategy::AlwaysBall => ScoreVector::single(HeadGoal::ObserveBall),
        GazeStrategy::FixedScan => ScoreVector::single(HeadGoal::Scan),
        GazeStrategy::ActiveVision
        | GazeStrategy::ActiveVisionTaskValue
        | GazeStrategy::Entropy => {
            let mut gazes = std::mem::take(&mut ctx.gazes);
            let mut looks = std::mem::take(&mut ctx.gaze_looks);
            let rivals: Vec<ObjectId> = value.map_or_else(Vec::new, |v| {
                v.objects()
                    .into_iter()
                    .filter(|id| world.get(*id).is_some_and(|o| o.group == OBSTACLE))
                    .collect()
            });
            gaze_candidates(ctx, &world, &rivals, &mut gazes, &mut looks);
            let entropy = if strategy == GazeStrategy::Entropy {
                Some(entropy_scores(&world, &gazes, &ctx.vision.config))
            } else {
                ctx.vision.config.criterion = if strategy == GazeStrategy::ActiveVisionTaskValue {
                    Criterion::MaxExpectedTaskValue
                } else {
                    Criterion::MinExpectedValueVariance
                };
                // The look holds until the next decision.
                ctx.vision.config.horizon =
                    if ctx.config.look_held_for_period { ctx.decision_period } else { 0.0 };
                let fallback = PositionValue { target: world.pose.pose.position() };
                let vf: &dyn ValueFunction = value.unwrap_or(&fallback);
                // The task value is the one expected after the acting primitive the body goal
                // just chosen runs until the next decision.
                let after_motion = ctx.config.task_value_after_motion;
                let motion = ctx.out.body.goals.first().filter(|_| after_motion).and_then(|body| {
                    let ball = world.object(BALL).map(|b| b.position);
                    predicted_motion(
                        &body.goal,
                        world.pose.pose,
                        ball,
                        &ctx.motion,
                        ctx.decision_period,
                        &OdometryNoise::default(),
                    )
                });
                let mut report = std::mem::take(&mut ctx.spare_report);
                ctx.vision.evaluate_after_into(&world, vf, &gazes, motion.as_ref(), &mut report);
                ctx.vision_report = Some(report);
                None
            };
            let scores: &[f64] = entropy.as_deref().unwrap_or_default();
            let evaluations = ctx.vision_report.as_ref().map_or(&[][..], |r| &r.candidates);
            let mut vector = ScoreVector::default();
            for (i, (candidate, what)) in gazes.iter().zip(&looks).enumerate() {
                let score = match &entropy {
                    Some(_) => scores.get(i).copied(),
                    None => evaluations.get(i).map(|e| e.score),
                };
                let Some(score) = score else { break };
                vector.push(GoalScore {
                    goal: what.goal(&candidate.label),
                    deliberative: score,
                    objects: what.objects(&candidate.label, &world),
                });
            }
            if let Some(choice) = ctx.gaze_override.as_ref().and_then(|o| o.get()) {
                let kinds: Vec<Kind> = looks.iter().map(|l| l.kind()).collect();
                gaze_override::apply(choice, &kinds, &mut vector);
            }
            ctx.gazes = gazes;
            ctx.gaze_looks = looks;
            if !vector.goals.iter().any(|g| g.goal == HeadGoal::ObserveBall) {
                // The ball must stay a goal even when no value function wants it: its reactive
                // score (its uncertainty) can still win the head.
                vector.push(GoalScore::new(HeadGoal::ObserveBall, 0.5).about(BALL));
            }
            vector
        }
    };
    ctx.world = Some(world);
}

/// Entropy baseline: the reduction of the expected entropy of the pose and ball beliefs,
/// normalised so the best candidate scores 1.
fn entropy_scores(
    world: &WorldState,
    gazes: &[GazeCandidate],
    config: &ActiveVisionConfig,
) -> Vec<f64> {
    let ball = world.object(BALL);
    let entropy = |pose: &nalgebra::Matrix3<f64>, ball_cov: Option<&nalgebra::Matrix2<f64>>| {
        0.5 * pose.determinant().max(1e-30).ln()
            + ball_cov.map_or(0.0, |c| 0.5 * c.determinant().max(1e-30).ln())
    };
    let prior = entropy(&world.pose.covariance, ball.map(|b| &b.covariance));
    let reductions: Vec<f64> = gazes
        .iter()
        .map(|g| {
            let view = strata_robot::percept::ViewCone {
                direction: g.direction.clamp(config.yaw_limits.0, config.yaw_limits.1),
                fov: config.fov,
                range: config.range,
                near: 0.0,
            };
            let candidate = world.sensing_candidate(&view, config.min_visibility);
            let belief = world.expected_update(&candidate);
            let ball_cov = ball.map(|b| belief.object(b.id).copied().unwrap_or(b.covariance));
            (prior - entropy(&belief.pose, ball_cov.as_ref())).max(0.0)
        })
        .collect();
    let best = reductions.iter().copied().fold(0.0, f64::max);
    reductions.iter().map(|r| if best > 1e-12 { r / best } else { 0.0 }).collect()
}

// ---------------------------------------------------------------------------------------------
// Behaviors (Table 2).

/// Going to field position.
fn going_to_field_position(ctx: &mut Ctx, target: Pose) -> Status {
    ctx.set_body(BodyGoal::GoToPosition { pose: target });
    let value = PositionValue { target: target.position() };
    gaze(ctx, Some(&value));
    Status::Running
}

/// Watching the referee (Standby): standing still, as the rules demand, the head trades the
/// referee, for its Ready gesture, against landmarks: the referee's value function says how
/// surely a look would show it (E[V], which the pose's uncertainty lowers), active vision how
/// much each landmark would raise that by localizing. Sure of its pose, the robot watches the
/// referee; unsure, it localizes first.
fn watching_referee(ctx: &mut Ctx) -> Status {
    ctx.set_body(BodyGoal::Stand);
    let referee = ctx.field.referee(ctx.config.referee_behind_line);
    // Teams change ends at half time and the referee does not: in the team frame it is on the
    // other side in the second half.
    let referee =
        if ctx.directive().first_half { referee } else { Point::new(-referee.x, -referee.y) };
    let watch = HeadGoal::ObserveReferee { position: referee };
    let active = matches!(
        ctx.config.gaze,
        GazeStrategy::ActiveVision | GazeStrategy::ActiveVisionTaskValue | GazeStrategy::Entropy
    );
    // The baselines have no value functions: they just watch.
    let Some(world) = ctx.world.take_if(|_| active) else {
        ctx.out.head = ScoreVector::single(watch);
        return Status::Running;
    };
    let (lo, hi) = ctx.vision.config.yaw_limits;
    let value = RefereeVisibilityValue {
        referee,
        gaze: world.pose.pose.to_robot(referee).bearing().clamp(lo.min(hi), hi.max(lo)),
        fov: ctx.config.fov,
        range: ctx.config.referee_range,
    };
    let mut gazes = std::mem::take(&mut ctx.gazes);
    let mut looks = std::mem::take(&mut ctx.gaze_looks);
    gaze_candidates(ctx, &world, &[], &mut gazes, &mut looks);
    ctx.vision.config.criterion = Criterion::MaxExpectedTaskValue;
    ctx.vision.config.horizon = ctx.decision_period;
    let mut report = std::mem::take(&mut ctx.spare_report);
    ctx.vision.evaluate_into(&world, &value, &gazes, &mut report);
    let worth = report.prior_expected_value.clamp(0.0, 1.0);
    let mut head = ScoreVector::default();
    head.push(GoalScore::new(watch, worth));
    for ((candidate, what), e) in gazes.iter().zip(&looks).zip(&report.candidates) {
        head.push(GoalScore {
            goal: what.goal(&candidate.label),
            deliberative: e.score * (1.0 - worth),
            objects: what.objects(&candidate.label, &world),
        });
    }
    ctx.out.head = head;
    ctx.vision_report = Some(report);
    ctx.gazes = gazes;
    ctx.gaze_looks = looks;
    ctx.world = Some(world);
    Status::Running
}

/// Localizing: look for landmarks, stand still.
fn localizing(ctx: &mut Ctx) -> Status {
    let mut head = ScoreVector::default();
    for group in &ctx.landmark_groups {
        head.push(
            GoalScore::new(HeadGoal::ObserveLandmark { name: group.clone() }, 0.8)
                .about(group.clone()),
        );
    }
    head.push(GoalScore::new(HeadGoal::ObserveBall, 0.3).about(BALL));
    ctx.out.head = head;
    // Standing, the head sees what is around; a robot still lost turns to see the rest, then
    // walks toward where it believes the field's centre is: where the referee puts a robot,
    // 3 m outside a side line, one landmark at most is in sight however it turns.
    let lost_for = ctx.lost_since.map_or(0.0, |t| (ctx.now - t).as_secs_f64());
    let pose = ctx.pose();
    match lost_for % LOCALIZE_CYCLE {
        t if t < LOCALIZE_STAND => ctx.set_body(BodyGoal::Stand),
        t if t < LOCALIZE_STAND + LOCALIZE_TURN => {
            let left = pose.to_global(Point::new(0.0, 1.0));
            ctx.set_body(BodyGoal::ObserveTarget { target: left });
        }
        _ => {
            let here = pose.position();
            let centre = Point::new(0.0, 0.0);
            let heading = (centre - here).angle();
            let step =
                here + (centre - here).normalized() * LOCALIZE_WALK.min(here.distance(centre));
            ctx.set_body(BodyGoal::GoToPosition { pose: Pose::new(step.x, step.y, heading) });
        }
    }
    Status::Running
}

/// The acting primitive's horizon before the deliberative layer has ticked twice (the paper's
/// 1 Hz), s; and the bounds of the measured one (a stalled layer must not predict a walk
/// across the field).
const DEFAULT_DECISION_PERIOD: f64 = 1.0;
const MIN_DECISION_PERIOD: f64 = 0.01;
const MAX_DECISION_PERIOD: f64 = 4.0;

/// Localizing stands this long, s, then turns on the spot ...
const LOCALIZE_STAND: f64 = 4.0;
/// ... this long, s (a turn and a half at the T1's 1 rad/s), then walks toward the centre
/// until the cycle starts again, s.
const LOCALIZE_TURN: f64 = 10.0;
const LOCALIZE_CYCLE: f64 = 24.0;
/// How far ahead of the robot each walk toward the centre aims, m: a target beyond the
/// odometry's drift, re-aimed every tick.
const LOCALIZE_WALK: f64 = 3.0;

/// Searching for object (the ball): passive (head only) at first, active (turning, walking
/// toward where the team last saw it) after a while.
fn searching_for_object(ctx: &mut Ctx) -> Status {
    ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
    if ctx.ball_unknown_for() < ctx.config.active_search_after {
        ctx.set_body(BodyGoal::Stand);
    } else if let Some(team_ball) =
        ctx.world.as_ref().and_then(|w| w.team_object(BALL)).map(|t| t.position)
    {
        let pose = ctx.pose();
        ctx.set_body(BodyGoal::GoToPosition { pose: facing(pose.position(), team_ball) });
    } else {
        let pose = ctx.pose();
        let here = pose.position();
        // Where to look next: where this robot last had the ball, or the centre of the field
        // once there. A robot the referee moved to the side line, 20 m from a ball the team
        // lost, sees nothing from there however long it turns.
        let last = ctx.ball_field().filter(|b| b.distance(here) > SEARCH_ARRIVED);
        let spot = last.unwrap_or(Point::new(0.0, 0.0));
        let turned = ctx.ball_unknown_for() - ctx.config.active_search_after;
        if turned > SEARCH_TURN && spot.distance(here) > SEARCH_ARRIVED {
            ctx.set_body(BodyGoal::GoToPosition {
                pose: Pose::new(spot.x, spot.y, (spot - here).angle()),
            });
        } else {
            // Turn on the spot: a target to the left keeps the robot rotating.
            let left = pose.to_global(Point::new(0.0, 1.0));
            ctx.set_body(BodyGoal::ObserveTarget { target: left });
        }
    }
    Status::Running
}

/// How long an active search turns on the spot before it walks to where the ball may be, s
/// (a turn and a half at the T1's 1 rad/s).
const SEARCH_TURN: f64 = 10.0;
/// Within this distance of where it searches, a robot turns there, m.
const SEARCH_ARRIVED: f64 = 1.5;

/// Avoiding obstacle: a waypoint beside a robot standing in the way.
/// The rival in the way is worth a look ("observe rival"): its value function weighs the
/// room left to pass it.
fn avoiding_obstacle(ctx: &mut Ctx) -> Status {
    let Some(world) = ctx.world.as_ref() else { return Status::Failure };
    let Some(rival) = rival_ahead(world, 0.8, 0.5) else { return Status::Success };
    let (obstacle, rival) = (rival.position, rival.id);
    let side = if obstacle.y > 0.0 { -0.5 } else { 0.5 };
    let pose = world.pose.pose;
    let waypoint = pose.to_global(Point::new(obstacle.x, obstacle.y + side));
    ctx.set_body(BodyGoal::GoToPosition { pose: facing(pose.position(), waypoint) });
    gaze(ctx, Some(&AvoidingValue { waypoint, rival, clearance: AVOIDING_CLEARANCE }));
    Status::Running
}

/// The room a robot wants between its path and a rival it passes, m (two bodies' radii).
const AVOIDING_CLEARANCE: f64 = 0.4;

/// The striker localizes only when it is lost and does not see the ball (chasing a seen ball
/// needs no field pose).
fn striker_lost(ctx: &Ctx) -> bool {
    ctx.lost() && !ctx.ball_known()
}

fn obstacle_in_the_way(ctx: &Ctx) -> bool {
    let Some(world) = ctx.world.as_ref() else { return false };
    let ball_far = ball(world).is_none_or(|b| b.robot.range() > 1.0);
    ball_far && obstacle_ahead(world, 0.8, 0.5).is_some()
}

/// Where a shot should go: the side of the opponent goal farther from its keeper.
fn shot_target(ctx: &Ctx) -> Point<FieldFrame> {
    let goal = ctx.field.opponent_goal();
    let aim = ctx.field.goal_half_width * 0.5;
    let keeper = ctx.world.as_ref().and_then(|w| {
        crate::situation::obstacles(w)
            .map(|o| o.global_position)
            .filter(|p| p.distance(goal) < 1.2)
            .min_by(|a, b| a.distance(goal).total_cmp(&b.distance(goal)))
    });
    match keeper {
        Some(k) if k.y > 0.0 => Point::new(goal.x, -aim),
        Some(_) => Point::new(goal.x, aim),
        None => goal,
    }
}

/// Go to ball: evaluates the ball's target by role (a shot for the striker, a clearance for a
/// defender or the keeper), then kicks or dribbles.
fn go_to_ball(ctx: &mut Ctx) -> Status {
    if letting_go_guard(ctx) {
        return letting_go(ctx);
    }
    let Some(ball_field) = ctx.ball_field() else { return Status::Failure };
    let target = shot_target(ctx);
    let near_goal = ball_field.distance(ctx.field.opponent_goal())
        < ctx.config.dribble_distance + ctx.field.goal_half_width;
    // Under the second-touch rule a restart's taker kicks: a dribble touches the ball again
    // and again.
    let restart = ctx.config.no_second_touch && own_restart_pending(&ctx.directive());
    if near_goal && !restart {
        // Close to the goal a kick would rather miss: walk the ball in. The dribble (head and
        // body) wins over the separate goals once the ball is near; until then the body walks
        // to the ball as to a kick, which it may not make, and the head looks where the value
        // function says. It aims where a shot would: the side of the goal its keeper leaves.
        ctx.set_body(BodyGoal::GoToBallAndKick { kick: Kick::Forward, target });
        ctx.out.whole_body = ScoreVector::single(WholeBodyGoal::GoToBallAndDribble { target });
        ctx.out.deactivate(BodyPrimitive::KickBall);
    } else {
        let kick = if ctx.role() == Role::Striker { Kick::Forward } else { Kick::Pass };
        let target = if ctx.role() == Role::Striker { target } else { ctx.field.opponent_goal() };
        ctx.set_body(BodyGoal::GoToBallAndKick { kick, target });
    }
    let ball_range = ctx.world.as_ref().and_then(ball).map(|b| b.robot.range());
    if ctx.motion.vertical_fov > 0.0 && ball_range.is_some_and(|r| r < WATCH_BALL_RANGE) {
        // A camera that cannot show the feet and the landmarks at once (the T1's) loses a
        // ball this near whenever it looks up, and the kick needs it to a few centimetres:
        // the last metre of the approach watches the ball.
        ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
    } else if let Some(ball_id) = ctx.ball_id() {
        let value = GoToBallValue { field: Arc::clone(&ctx.field), ball: ball_id };
        gaze(ctx, Some(&value));
    }
    Status::Running
}

/// Within this distance of the ball, going to it watches the ball on a body whose camera
/// cannot see near and far at once, m (the approach circles to the kicking pose from 0.8 m).
const WATCH_BALL_RANGE: f64 = 1.0;

/// The keeper's covering position: on the bisector of the goal's angle seen from the ball, at
/// `keeper_depth` in front of the goal line, facing the ball.
pub fn covering_pose(field: &TeamField, ball: Point<FieldFrame>, depth: f64) -> Pose {
    let [left, right] = field.posts(strata_spl::field::Side::Own);
    let bisector = ((left - ball).normalized() + (right - ball).normalized()).normalized();
    let line = -field.half_length + depth;
    let point = if bisector.x < -0.05 && ball.x > line {
        let t = (line - ball.x) / bisector.x;
        let p = ball + bisector * t;
        Point::new(p.x, p.y.clamp(-field.goal_half_width, field.goal_half_width))
    } else {
        Point::new(line, 0.0)
    };
    facing(point, ball)
}

/// Goal covering: cover the maximal free angle of the goal seen from the ball, keep the
/// dive ready, and look where the value function says (ball or landmarks).
fn goal_covering(ctx: &mut Ctx, depth: f64) -> Status {
    let Some(ball_field) = ctx.ball_field() else { return Status::Failure };
    let pose = covering_pose(&ctx.field, ball_field, depth);
    ctx.set_body(BodyGoal::GoToPosition { pose });
    if ctx.role() == Role::Goalie {
        ctx.out.whole_body = ScoreVector::single(WholeBodyGoal::Dive { sequence: 0 });
    }
    if let Some(ball_id) = ctx.ball_id() {
        let value = GoalCoveringValue {
            field: Arc::clone(&ctx.field),
            ball: ball_id,
            reach: ctx.config.keeper_reach,
        };
        gaze(ctx, Some(&value));
    }
    Status::Running
}

/// Partner following: keep a supporting position near the striker.
fn partner_following(ctx: &mut Ctx) -> Status {
    let Some(ball_field) = ctx.ball_field() else { return searching_for_object(ctx) };
    let striker = ctx
        .decision
        .as_ref()
        .and_then(|d| d.teammates.iter().find(|t| t.role == Role::Striker && t.available))
        .map(|t| (t.member, t.pose.position()));
    let anchor = striker.map_or(ball_field, |(_, p)| p);
    let back = (ctx.field.own_goal() - ball_field).normalized() * 1.2;
    let lateral = if anchor.y > 0.0 { -0.8 } else { 0.8 };
    let spot = Point::new(
        (anchor.x + back.x).clamp(-ctx.field.half_length + 0.5, ctx.field.half_length - 0.5),
        (anchor.y + back.y + lateral)
            .clamp(-ctx.field.half_width + 0.3, ctx.field.half_width - 0.3),
    );
    going_to_field_position(ctx, facing(spot, ball_field));
    if let Some((player, position)) = striker {
        ctx.out.head.push(GoalScore::new(HeadGoal::ObservePartner { player, position }, 0.3));
    }
    Status::Running
}

/// Pass receiver: wait for a pass in a free position ahead of the ball, on the other side.
fn pass_receiving(ctx: &mut Ctx) -> Status {
    let Some(ball_field) = ctx.ball_field() else { return searching_for_object(ctx) };
    let x = (ball_field.x + 2.0).clamp(-ctx.field.half_length + 1.0, ctx.field.half_length - 1.0);
    let y = if ball_field.y > 0.0 { -1.5 } else { 1.5 };
    going_to_field_position(ctx, facing(Point::new(x, y), ball_field))
}

/// Kick-off positions (team frame), legal for the kicking and the defending team. Under the
/// second-touch rule (`no_second_touch`) the kicker waits further back: a touch while it
/// settles at its spot would take the kick-off and bar it from the ball.
pub fn kickoff_pose(field: &TeamField, player: u8, kicking: bool, no_second_touch: bool) -> Pose {
    let hl = field.half_length;
    let circle = field.center_circle_radius;
    let centre = Point::new(0.0, 0.0);
    let spot = match player {
        1 => Point::new(-hl + 0.3, 0.0),
        KICKER_NUMBER if kicking && no_second_touch => Point::new(-KICKER_WAIT, 0.0),
        KICKER_NUMBER if kicking => Point::new(-0.25, 0.0),
        KICKER_NUMBER => Point::new(-circle - 0.25, 0.0),
        3 => Point::new(-1.2, 1.5),
        4 => Point::new(-1.2, -1.5),
        5 => Point::new(-hl * 0.6, 0.7),
        6 => Point::new(-hl * 0.6, -0.7),
        _ => Point::new(-hl * 0.4, 0.0),
    };
    // Only the kicker stands in the centre circle, however large the field's circle is
    // (rcssservermj's referee moves a defender inside it off the field).
    let clear = circle + 0.25;
    let distance = spot.x.hypot(spot.y);
    let kicker = kicking && player == KICKER_NUMBER;
    let spot = if !kicker && distance < clear && distance > 0.0 {
        Point::new(spot.x * clear / distance, spot.y * clear / distance)
    } else {
        spot
    };
    facing(spot, centre)
}

/// Keeping distance during the other team's set play: a robot nearer the ball than
/// `set_play_distance` walks to the point that far from the ball towards its own goal; one
/// farther away stays where it is. Both face the ball.
fn keeping_distance(ctx: &mut Ctx) -> Status {
    let pose = ctx.pose();
    let Some(ball) = ctx.ball_field() else {
        ctx.set_body(BodyGoal::Stand);
        ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
        return Status::Running;
    };
    let radius = ctx.config.set_play_distance;
    let here = pose.position();
    if here.distance(ball) >= radius {
        ctx.set_body(BodyGoal::GoToPosition { pose: facing(here, ball) });
    } else {
        let goal = ctx.field.own_goal();
        let away = (goal - ball).normalized();
        let spot = ball + away * radius;
        ctx.set_body(BodyGoal::GoToPosition { pose: facing(spot, ball) });
    }
    ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
    Status::Running
}

fn should_clear(ctx: &Ctx) -> bool {
    let Some(world) = ctx.world.as_ref() else { return false };
    let Some(b) = ball(world).filter(|b| b.known && !b.from_team) else { return false };
    ctx.field.in_own_penalty_area(b.field, 0.0) && b.robot.range() < 1.2
}

// ---------------------------------------------------------------------------------------------
// The machine.

fn build_machine(goalie: bool) -> Result<StateMachine<S, Ctx>, BuildError<S>> {
    let builder = StateMachine::builder().initial(S::Initial);
    let builder = game_states(builder, goalie);
    let builder = goalie_states(builder);
    let builder = field_player_states(builder);
    builder.build()
}

/// The top level, which follows the game state.
fn game_states(mut builder: Builder<S, Ctx>, goalie: bool) -> Builder<S, Ctx> {
    let top_names = [
        (S::Initial, "Initial"),
        (S::Standby, "Standby"),
        (S::Ready, "Ready"),
        (S::Set, "Set"),
        (S::Playing, "Playing"),
        (S::Finished, "Finished"),
        (S::Penalized, "Penalized"),
        (S::KeepingDistance, "Keeping distance"),
    ];
    for (state, name) in top_names {
        let mut s = State::new(state).name(name);
        for other in TOP.iter().copied().filter(|o| *o != state) {
            if other == S::Playing {
                for entry in PLAYING_ENTRIES {
                    s = s.transition(
                        move |ctx: &Ctx, _| {
                            phase(ctx) == S::Playing && playing_state(ctx.role()) == entry
                        },
                        entry,
                    );
                }
            } else {
                s = s.transition(move |ctx: &Ctx, _| phase(ctx) == other, other);
            }
        }
        s = match state {
            S::Initial => s.behavior(|ctx: &mut Ctx, _| {
                ctx.set_body(BodyGoal::Stand);
                gaze(ctx, None);
                Status::Running
            }),
            S::Standby => s.behavior(|ctx: &mut Ctx, _| watching_referee(ctx)),
            S::Ready => s.behavior(|ctx: &mut Ctx, _| {
                let kicking = ctx.directive().kicking == Kicking::Us;
                let rule = ctx.config.no_second_touch;
                let target = kickoff_pose(&ctx.field, ctx.player, kicking, rule);
                going_to_field_position(ctx, target)
            }),
            S::Set | S::Finished => s.behavior(|ctx: &mut Ctx, _| {
                ctx.set_body(BodyGoal::Stand);
                ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
                Status::Running
            }),
            S::Penalized => s.behavior(|ctx: &mut Ctx, _| {
                ctx.set_body(BodyGoal::Stand);
                ctx.out.head = ScoreVector::single(HeadGoal::Scan);
                Status::Running
            }),
            S::KeepingDistance => s.behavior(|ctx: &mut Ctx, _| keeping_distance(ctx)),
            S::Playing => s.initial_child(if goalie { S::GoaliePlaying } else { S::FieldPlaying }),
            _ => s,
        };
        builder = builder.state(s);
    }
    builder
}

/// Playing as the goalie: goal covering and clearing. A keeper given a field role goes
/// straight to that role's state.
fn goalie_states(builder: Builder<S, Ctx>) -> Builder<S, Ctx> {
    let mut goalie_playing = State::new(S::GoaliePlaying)
        .name("Goalie playing")
        .parent(S::Playing)
        .initial_child(S::GoalCovering);
    for (state, _) in FIELD_ROLES {
        goalie_playing = goalie_playing.transition(
            move |ctx: &Ctx, _| ctx.role() != Role::Goalie && role_state(ctx.role()) == state,
            state,
        );
    }
    builder
        .state(goalie_playing)
        .state(
            State::new(S::GoalCovering)
                .name("Goal covering")
                .parent(S::GoaliePlaying)
                .transition(|ctx: &Ctx, _| should_clear(ctx), S::Clearing)
                .tree(Tree::new(reactive_selector(
                    "goal covering",
                    [
                        reactive_sequence(
                            "localizing",
                            [
                                condition("lost", |ctx: &Ctx| ctx.lost()),
                                action("look for landmarks", |ctx: &mut Ctx, _| localizing(ctx)),
                            ],
                        ),
                        reactive_sequence(
                            "searching for object",
                            [
                                condition("ball unknown", |ctx: &Ctx| {
                                    !ctx.ball_known() && ctx.ball_unknown_for() > 1.0
                                }),
                                action("passive search", |ctx: &mut Ctx, _| {
                                    let home = covering_pose(
                                        &ctx.field,
                                        Point::new(0.0, 0.0),
                                        ctx.config.keeper_depth,
                                    );
                                    ctx.set_body(BodyGoal::GoToPosition { pose: home });
                                    ctx.out.head = ScoreVector::single(HeadGoal::ObserveBall);
                                    Status::Running
                                }),
                            ],
                        ),
                        action("cover", |ctx: &mut Ctx, _| {
                            let depth = ctx.config.keeper_depth;
                            goal_covering(ctx, depth)
                        }),
                    ],
                ))),
        )
        .state(
            State::new(S::Clearing)
                .name("Clearing")
                .parent(S::GoaliePlaying)
                .transition(|ctx: &Ctx, _| !should_clear(ctx), S::GoalCovering)
                .behavior(|ctx: &mut Ctx, _| go_to_ball(ctx)),
        )
}

/// Playing as a field player: one state per field role.
fn field_player_states(mut builder: Builder<S, Ctx>) -> Builder<S, Ctx> {
    let mut field_playing = State::new(S::FieldPlaying)
        .name("Field playing")
        .parent(S::Playing)
        .initial_child(S::Striker)
        .transition(|ctx: &Ctx, _| ctx.role() == Role::Goalie, S::GoaliePlaying);
    field_playing = field_playing.name("Field playing");
    builder = builder.state(field_playing);
    for (state, role) in FIELD_ROLES {
        let mut s = State::new(state).name(role.name()).parent(S::FieldPlaying);
        for (other, other_role) in FIELD_ROLES.iter().copied().filter(|(o, _)| *o != state) {
            s = s.transition(
                move |ctx: &Ctx, _| role_state(ctx.role()) == other && ctx.role() == other_role,
                other,
            );
        }
        s = match state {
            // The striker's guards are memory sequences: once it searches for the ball (or
            // localizes, or detours), it keeps at it until that behavior says it is done (the
            // ball seen, the pose found, the way clear) instead of re-checking the guard every
            // tick as goal covering does, so a ball glimpsed once does not end a search that
            // would have found it for good. `force_failure` hands a finished guard over to the
            // next child in the same tick: a finished search is no reason to stand still for a
            // deliberative cycle.
            S::Striker => s.tree(Tree::new(reactive_selector(
                "go to ball",
                [
                    force_failure(sequence(
                        "localizing",
                        [
                            condition("lost", striker_lost),
                            action("look for landmarks", |ctx: &mut Ctx, _| {
                                if striker_lost(ctx) { localizing(ctx) } else { Status::Success }
                            }),
                        ],
                    )),
                    reactive_sequence(
                        "letting go",
                        [
                            condition("may not touch the ball again", letting_go_guard),
                            action("keep off the ball", |ctx: &mut Ctx, _| letting_go(ctx)),
                        ],
                    ),
                    force_failure(sequence(
                        "searching for object",
                        [
                            condition("ball unknown", |ctx: &Ctx| !ctx.ball_known()),
                            action("search ball", |ctx: &mut Ctx, _| {
                                if ctx.ball_known() {
                                    Status::Success
                                } else {
                                    searching_for_object(ctx)
                                }
                            }),
                        ],
                    )),
                    force_failure(sequence(
                        "avoiding obstacle",
                        [
                            condition("obstacle in the way", obstacle_in_the_way),
                            action("detour", |ctx: &mut Ctx, _| avoiding_obstacle(ctx)),
                        ],
                    )),
                    action("kick to goal", |ctx: &mut Ctx, _| go_to_ball(ctx)),
                ],
            ))),
            S::StrikerCover => s.behavior(|ctx: &mut Ctx, _| partner_following(ctx)),
            S::PassReceiver => s.behavior(|ctx: &mut Ctx, _| pass_receiving(ctx)),
            S::ActiveDefender => s.behavior(|ctx: &mut Ctx, _| {
                if ctx.ball_known() { go_to_ball(ctx) } else { searching_for_object(ctx) }
            }),
            S::DefenderPositioning => s.behavior(|ctx: &mut Ctx, _| match ctx.ball_field() {
                Some(_) => goal_covering(ctx, ctx.field.penalty_area_length + 0.3),
                None => searching_for_object(ctx),
            }),
            _ => s,
        };
        builder = builder.state(s);
    }
    builder
}

/// Soccer's deliberative layer.
pub struct SoccerBehavior {
    machine: StateMachine<S, Ctx>,
    ctx: Ctx,
    /// Busy computation added to every tick: `strata experiment rates` loads the deliberative
    /// layer to show the reactive layer keeps its rate (the paper's central claim).
    load: std::time::Duration,
}

impl std::fmt::Debug for SoccerBehavior {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SoccerBehavior")
            .field("path", &self.machine.active_path())
            .finish_non_exhaustive()
    }
}

impl SoccerBehavior {
    pub fn new(
        player: u8,
        field: Arc<TeamField>,
        config: BehaviorConfig,
        vision: ActiveVisionConfig,
        motion: Arc<MotionModel>,
    ) -> Result<SoccerBehavior, String> {
        let machine = build_machine(player == GOALKEEPER_NUMBER).map_err(|e| format!("{e:?}"))?;
        let groups = landmark_groups(&field);
        Ok(SoccerBehavior {
            machine,
            ctx: Ctx {
                now: Time::ZERO,
                world: None,
                decision: None,
                stability: Stability::Stable,
                field,
                player,
                config,
                out: Output::default(),
                vision: ActiveVision::new(vision),
                vision_report: None,
                spare_report: ActiveVisionReport::default(),
                gazes: Vec::new(),
                gaze_looks: Vec::new(),
                ball_unknown_since: None,
                lost_since: None,
                landmark_groups: groups,
                motion,
                at_own_restart: false,
                let_go: None,
                decision_period: DEFAULT_DECISION_PERIOD,
                last_tick: None,
                gaze_override: None,
            },
            load: std::time::Duration::ZERO,
        })
    }

    /// The same behavior, with `load` of busy computation after every tick.
    pub fn with_load(mut self, load: std::time::Duration) -> SoccerBehavior {
        self.load = load;
        self
    }

    /// The same behavior, its head's goal taken from `choice` whenever one is set there (with
    /// the value-function gazes: their candidates are what a choice names).
    pub fn with_gaze_override(mut self, choice: Arc<GazeOverride>) -> SoccerBehavior {
        self.ctx.gaze_override = Some(choice);
        self
    }

    pub fn active_path(&self) -> String {
        self.machine.active_path()
    }

    pub fn vision_report(&self) -> Option<&ActiveVisionReport> {
        self.ctx.vision_report.as_ref()
    }
}

impl DeliberativePolicy for SoccerBehavior {
    type HeadGoal = HeadGoal;
    type BodyGoal = BodyGoal;
    type WholeBodyGoal = WholeBodyGoal;
    type World = WorldState;
    type Assignment = Decision;

    fn tick(&mut self, input: &DeliberativeInput<'_, WorldState, Decision>) -> Output {
        let ctx = &mut self.ctx;
        ctx.now = input.now;
        if let Some(last) = ctx.last_tick.replace(input.now) {
            let period = input.now.saturating_since(last).as_secs_f64();
            ctx.decision_period = period.clamp(MIN_DECISION_PERIOD, MAX_DECISION_PERIOD);
        }
        ctx.world = input.world.cloned();
        ctx.decision = input.assignment.cloned();
        ctx.stability = input.stability;
        ctx.out = Output::default();
        if let Some(report) = ctx.vision_report.take() {
            ctx.spare_report = report;
        }
        if ctx.ball_known() {
            ctx.ball_unknown_since = None;
        } else if ctx.ball_unknown_since.is_none() {
            ctx.ball_unknown_since = Some(input.now);
        }
        if !ctx.lost() {
            ctx.lost_since = None;
        } else if ctx.lost_since.is_none() {
            ctx.lost_since = Some(input.now);
        }
        track_second_touch(ctx);
        self.machine.tick(&mut self.ctx, input.now);
        let mut out = std::mem::take(&mut self.ctx.out);
        out.behavior_path = self.machine.active_path();
        if !self.load.is_zero() {
            burn_cpu(self.load);
        }
        out
    }
}

/// Busy computation for `duration` of wall time (not a sleep: a sleeping thread would not
/// compete for the CPU the way a heavy planner does).
fn burn_cpu(duration: std::time::Duration) {
    let start = std::time::Instant::now();
    let mut x = 0u64;
    while start.elapsed() < duration {
        for i in 0..1000u64 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(i));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use strata_robot::control::scores::PrimitiveId;

    #[test]
    fn the_machine_builds_for_goalie_and_field_players() {
        assert!(build_machine(true).is_ok());
        assert!(build_machine(false).is_ok());
    }

    /// A field player's behavior, told its role and the game state as planning would.
    fn decide(behavior: &mut SoccerBehavior, role: Role, state: GameState, at: f64) {
        let mission = if role == Role::Goalie { Mission::DefendTheGoal } else { Mission::Defend };
        behavior.ctx.decision = Some(Decision {
            assignment: strata_robot::control::planning::Assignment { mission, role, alone: false },
            directive: GameDirective { state, ..GameDirective::default() },
            teammates: Vec::new(),
            stats: Default::default(),
        });
        behavior.machine.tick(&mut behavior.ctx, Time::from_secs_f64(at));
    }

    fn behavior(player: u8) -> SoccerBehavior {
        let field =
            Arc::new(TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0));
        SoccerBehavior::new(
            player,
            field,
            BehaviorConfig::default(),
            ActiveVisionConfig::default(),
            Arc::new(MotionModel::default()),
        )
        .expect("behavior")
    }

    #[test]
    fn entering_playing_starts_the_roles_own_behavior_at_once() {
        let roles = [
            (Role::StrikerCover, S::StrikerCover),
            (Role::PassReceiver, S::PassReceiver),
            (Role::ActiveDefender, S::ActiveDefender),
            (Role::DefenderGoingToPosition, S::DefenderPositioning),
            (Role::Striker, S::Striker),
            (Role::Goalie, S::GoalCovering),
        ];
        for (role, leaf) in roles {
            for previous in [GameState::Set, GameState::Ready] {
                let mut b = behavior(3);
                decide(&mut b, role, previous, 0.0);
                decide(&mut b, role, previous, 0.1);
                decide(&mut b, role, GameState::Playing, 0.2);
                assert_eq!(b.machine.active_leaf(), Some(leaf), "{role:?} after {previous:?}");
            }
            // Back from a penalty, too.
            let mut b = behavior(4);
            decide(&mut b, role, GameState::Playing, 0.0);
            let mut penalized = b.ctx.decision.clone().expect("decided");
            penalized.directive.penalized = true;
            b.ctx.decision = Some(penalized);
            b.machine.tick(&mut b.ctx, Time::from_secs_f64(0.1));
            assert_eq!(b.machine.active_leaf(), Some(S::Penalized));
            decide(&mut b, role, GameState::Playing, 0.2);
            assert_eq!(b.machine.active_leaf(), Some(leaf), "{role:?} after a penalty");
        }
    }

    /// A striker that started searching for the ball ends the search when it sees the ball and
    /// goes for it in the same deliberative tick, with its role unchanged (a memory guard whose
    /// action never finished kept a lone striker searching beside the ball for good).
    /// A robot's world model fed sightings of the ball, and the decisions its behavior ticks
    /// on: one tick every 0.1 s.
    struct Scene {
        model: strata_robot::world::WorldModel,
        ball_class: strata_robot::platform::ObjectClass,
    }

    impl Scene {
        /// On the SPL field, at `pose` if given (else lost, as a robot starts).
        fn new(pose: Option<Pose>) -> Scene {
            use strata_robot::world::{PosePrior, WorldCommand, WorldModel};
            let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
            let config = crate::world_config::world_config(&field);
            let ball_class =
                config.objects.iter().find(|o| o.name == BALL).map(|o| o.class).expect("ball");
            let mut model = WorldModel::new(config).expect("valid config");
            if let Some(pose) = pose {
                let prior = PosePrior { pose, sigma: [0.05, 0.05, 0.02] };
                model.command(WorldCommand::SetPose { prior }).expect("pose");
            }
            Scene { model, ball_class }
        }

        /// Tick `k`: the ball seen `ball` m straight ahead (or nothing seen), then the
        /// behavior decides as `role` under `directive`.
        fn tick(
            &mut self,
            b: &mut SoccerBehavior,
            k: u32,
            ball: Option<f64>,
            role: Role,
            directive: GameDirective,
        ) -> Output {
            use strata_robot::control::deliberative::{DeliberativeInput, DeliberativePolicy};
            use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
            let now = Time::from_secs_f64(0.1 * f64::from(k));
            let observations = ball
                .map(|range| Observation {
                    class: self.ball_class,
                    variant: None,
                    range,
                    bearing: 0.0,
                    orientation: None,
                    range_sigma: 0.02,
                    bearing_sigma: 0.02,
                })
                .into_iter()
                .collect();
            let camera = Some(CameraPercepts {
                stamp: now,
                view: ViewCone { direction: 0.0, fov: 1.0, range: 6.0, near: 0.0 },
                observations,
            });
            self.model.process(
                strata_robot::geometry::Odometry::default(),
                &Percepts { stamp: now, camera, ..Percepts::default() },
            );
            let world = self.model.state();
            let mission =
                if role == Role::Goalie { Mission::DefendTheGoal } else { Mission::Attack };
            let decision = Decision {
                assignment: strata_robot::control::planning::Assignment {
                    mission,
                    role,
                    alone: false,
                },
                directive,
                teammates: Vec::new(),
                stats: Default::default(),
            };
            b.tick(&DeliberativeInput {
                now,
                world: Some(&world),
                assignment: Some(&decision),
                stability: Stability::default(),
            })
        }
    }

    fn playing() -> GameDirective {
        GameDirective { state: GameState::Playing, ..GameDirective::default() }
    }

    fn with_config(player: u8, config: BehaviorConfig) -> SoccerBehavior {
        let field =
            Arc::new(TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0));
        SoccerBehavior::new(
            player,
            field,
            config,
            ActiveVisionConfig::default(),
            Arc::new(MotionModel::default()),
        )
        .expect("behavior")
    }

    #[test]
    fn a_striker_ends_its_search_when_it_sees_the_ball() {
        let mut b = behavior(3);
        let mut scene = Scene::new(Some(Pose::new(-1.0, 0.0, 0.0)));
        let mut paths = Vec::new();
        for k in 0..40u32 {
            // The ball comes into view two seconds in, 1 m ahead.
            let ball = (k >= 20).then_some(1.0);
            let out = scene.tick(&mut b, k, ball, Role::Striker, playing());
            paths.push((k, out.behavior_path, !out.body.is_empty()));
        }
        let searching = |path: &str| path.contains("searching for object");
        assert!(paths[..20].iter().skip(1).all(|(_, p, _)| searching(p)), "{paths:#?}");
        let found = paths.iter().position(|(k, p, _)| *k >= 20 && !searching(p));
        let Some(found) = found else { panic!("the search never ended: {paths:#?}") };
        assert!(found <= 22, "the search ended only at tick {found}: {paths:#?}");
        for (_, path, body) in &paths[found..] {
            assert!(path.ends_with("kick to goal"), "{path}");
            assert!(body, "no body goal at {path}");
        }
    }

    #[test]
    fn a_search_that_finds_nothing_turns_then_walks_to_where_the_ball_may_be() {
        let mut b = behavior(3);
        let mut scene = Scene::new(Some(Pose::new(-3.0, -2.0, 0.0)));
        let mut goals = Vec::new();
        for k in 0..220u32 {
            let out = scene.tick(&mut b, k, None, Role::Striker, playing());
            goals.push(out.body.goals.first().map(|g| g.goal.clone()));
        }
        let at = |t: f64| goals[(t * 10.0) as usize].clone();
        // The head alone first, then turning on the spot, then walking to the centre (this
        // robot never saw the ball).
        assert_eq!(at(2.0), Some(BodyGoal::Stand));
        assert!(matches!(at(8.0), Some(BodyGoal::ObserveTarget { .. })), "{:?}", at(8.0));
        let Some(BodyGoal::GoToPosition { pose }) = at(20.0) else { panic!("{:?}", at(20.0)) };
        assert!(pose.position().distance(Point::new(0.0, 0.0)) < 0.01, "{pose:?}");
    }

    #[test]
    fn a_lost_robot_stands_then_turns_then_walks_toward_the_centre() {
        let mut b = behavior(3);
        let mut scene = Scene::new(None);
        let mut goals = Vec::new();
        for k in 0..200u32 {
            let out = scene.tick(&mut b, k, None, Role::Striker, playing());
            // (The machine leaves its initial state in the first tick.)
            assert!(
                k == 0 || out.behavior_path.contains("localizing"),
                "{k}: {}",
                out.behavior_path
            );
            goals.push(out.body.goals.first().map(|g| g.goal.clone()));
        }
        let at = |t: f64| goals[(t * 10.0) as usize].clone();
        assert_eq!(at(2.0), Some(BodyGoal::Stand));
        assert!(matches!(at(8.0), Some(BodyGoal::ObserveTarget { .. })), "{:?}", at(8.0));
        assert!(matches!(at(16.0), Some(BodyGoal::GoToPosition { .. })), "{:?}", at(16.0));
    }

    #[test]
    fn dribbling_walks_to_the_ball_until_the_dribble_takes_over() {
        // The T1's setting: dribble everywhere.
        let config = BehaviorConfig { dribble_distance: 100.0, ..BehaviorConfig::default() };
        let mut b = with_config(3, config);
        let mut scene = Scene::new(Some(Pose::new(-2.0, 0.0, 0.0)));
        let mut out = Output::default();
        for k in 0..10 {
            out = scene.tick(&mut b, k, Some(2.0), Role::Striker, playing());
        }
        assert!(
            matches!(
                out.body.goals.first().map(|g| &g.goal),
                Some(BodyGoal::GoToBallAndKick { .. })
            ),
            "the body walks to the ball: {:?}",
            out.body
        );
        assert!(matches!(
            out.whole_body.goals.first().map(|g| &g.goal),
            Some(WholeBodyGoal::GoToBallAndDribble { .. })
        ));
        assert!(out.deactivated.contains(BodyPrimitive::KickBall.name()), "{:?}", out.deactivated);
    }

    #[test]
    fn under_the_second_touch_rule_a_restart_taker_kicks_rather_than_dribbles() {
        let config = BehaviorConfig {
            dribble_distance: 100.0,
            no_second_touch: true,
            ..BehaviorConfig::default()
        };
        let mut b = with_config(KICKER_NUMBER, config);
        let mut scene = Scene::new(Some(Pose::new(-0.6, 0.0, 0.0)));
        let kick_off = GameDirective {
            state: GameState::Playing,
            kicking: Kicking::Us,
            secondary_time: 10,
            ..GameDirective::default()
        };
        let mut out = Output::default();
        for k in 0..10 {
            out = scene.tick(&mut b, k, Some(0.6), Role::Striker, kick_off.clone());
        }
        assert!(out.whole_body.is_empty(), "{:?}", out.whole_body);
        assert!(!out.deactivated.contains(BodyPrimitive::KickBall.name()));
        assert!(matches!(
            out.body.goals.first().map(|g| &g.goal),
            Some(BodyGoal::GoToBallAndKick { .. })
        ));
    }

    #[test]
    fn only_the_kicker_plays_until_the_kick_off_is_taken() {
        let kick_off = |b: &mut SoccerBehavior, kicking: Kicking, secondary_time: i16, at: f64| {
            decide(b, Role::Striker, GameState::Playing, at);
            let mut d = b.ctx.decision.clone().expect("decided");
            d.directive.kicking = kicking;
            d.directive.secondary_time = secondary_time;
            b.ctx.decision = Some(d);
            b.machine.tick(&mut b.ctx, Time::from_secs_f64(at + 0.01));
            b.machine.active_leaf()
        };
        // The other team's kick-off: everyone keeps to the kick-off positions until it is free.
        for player in [2, 3] {
            let mut b = behavior(player);
            assert_eq!(kick_off(&mut b, Kicking::Them, 12, 0.0), Some(S::Ready), "{player}");
            assert_eq!(kick_off(&mut b, Kicking::Them, 0, 1.0), Some(S::Striker), "{player}");
        }
        // Ours: the kicker plays at once, its teammates wait.
        assert_eq!(kick_off(&mut behavior(2), Kicking::Us, 12, 0.0), Some(S::Striker));
        assert_eq!(kick_off(&mut behavior(3), Kicking::Us, 12, 0.0), Some(S::Ready));
        // The goalkeeper covers its goal either way.
        let mut keeper = behavior(GOALKEEPER_NUMBER);
        decide(&mut keeper, Role::Goalie, GameState::Playing, 0.0);
        let mut d = keeper.ctx.decision.clone().expect("decided");
        d.directive.kicking = Kicking::Them;
        d.directive.secondary_time = 12;
        keeper.ctx.decision = Some(d);
        keeper.machine.tick(&mut keeper.ctx, Time::from_secs_f64(0.01));
        assert_eq!(keeper.machine.active_leaf(), Some(S::GoalCovering));
        // A set play's countdown is not a kick-off's.
        let mut b = behavior(3);
        decide(&mut b, Role::Striker, GameState::Playing, 0.0);
        let mut d = b.ctx.decision.clone().expect("decided");
        d.directive.set_play = SetPlay::KickIn;
        d.directive.kicking = Kicking::Them;
        d.directive.secondary_time = 20;
        b.ctx.decision = Some(d);
        b.machine.tick(&mut b.ctx, Time::from_secs_f64(0.01));
        assert_eq!(b.machine.active_leaf(), Some(S::Striker));
    }

    #[test]
    fn robots_keep_their_distance_during_the_other_teams_set_play_where_the_rule_is_set() {
        let set_play = |b: &mut SoccerBehavior, kicking: Kicking, at: f64| {
            decide(b, Role::Striker, GameState::Playing, at);
            let mut d = b.ctx.decision.clone().expect("decided");
            d.directive.set_play = SetPlay::KickIn;
            d.directive.kicking = kicking;
            b.ctx.decision = Some(d);
            b.machine.tick(&mut b.ctx, Time::from_secs_f64(at + 0.01));
            b.machine.active_leaf()
        };
        let mut b = behavior(3);
        b.ctx.config.set_play_distance = 6.0;
        assert_eq!(set_play(&mut b, Kicking::Them, 0.0), Some(S::KeepingDistance));
        // Ours: play it.
        assert_eq!(set_play(&mut b, Kicking::Us, 1.0), Some(S::Striker));
        // No rule (the built-in simulator's referee): play on.
        let mut b = behavior(3);
        assert_eq!(set_play(&mut b, Kicking::Them, 0.0), Some(S::Striker));
    }

    /// In Standby the robot stands and trades the referee against landmarks by how sure its
    /// pose is: the referee's value function (E[V]) against what localizing would add.
    #[test]
    fn in_standby_a_localized_robot_watches_the_referee_and_an_unsure_one_localizes_first() {
        use strata_robot::control::deliberative::{DeliberativeInput, DeliberativePolicy};
        use strata_robot::world::{PosePrior, WorldCommand, WorldModel};
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let referee = field.referee(BehaviorConfig::default().referee_behind_line);
        let head_in_standby = |sigma: [f64; 3]| {
            let mut b = behavior(3);
            let mut model =
                WorldModel::new(crate::world_config::world_config(&field)).expect("valid");
            // On the side line of the own half, facing the field.
            let prior =
                PosePrior { pose: Pose::new(-3.0, -3.0, std::f64::consts::FRAC_PI_2), sigma };
            model.command(WorldCommand::SetPose { prior }).expect("pose");
            let world = model.state();
            let decision = Decision {
                assignment: strata_robot::control::planning::Assignment {
                    mission: Mission::Defend,
                    role: Role::Striker,
                    alone: false,
                },
                directive: GameDirective { state: GameState::Standby, ..GameDirective::default() },
                teammates: Vec::new(),
                stats: Default::default(),
            };
            let input = |at: f64| DeliberativeInput {
                now: Time::from_secs_f64(at),
                world: Some(&world),
                assignment: Some(&decision),
                stability: Stability::default(),
            };
            // The machine starts in Initial and follows the game state from the first tick.
            b.tick(&input(1.0));
            let out = b.tick(&input(1.1));
            assert!(out.behavior_path.starts_with("Standby"), "{}", out.behavior_path);
            assert_eq!(out.body.goals.first().map(|g| g.goal.clone()), Some(BodyGoal::Stand));
            let best = out
                .head
                .goals
                .iter()
                .max_by(|a, b| a.deliberative.total_cmp(&b.deliberative))
                .expect("head goals")
                .clone();
            let watch = out
                .head
                .goals
                .iter()
                .find(|g| g.goal == HeadGoal::ObserveReferee { position: referee })
                .expect("the referee is always a goal")
                .deliberative;
            (best.goal, watch)
        };
        let (best, sure) = head_in_standby([0.05, 0.05, 0.03]);
        assert_eq!(best, HeadGoal::ObserveReferee { position: referee }, "watch: {sure}");
        assert!(sure > 0.9, "{sure}");
        let (best, unsure) = head_in_standby([0.5, 0.5, 0.6]);
        assert!(matches!(best, HeadGoal::ObserveLandmark { .. }), "{best:?} (watch: {unsure})");
        assert!(unsure < sure, "{unsure} {sure}");
    }

    #[test]
    fn a_keeper_given_a_field_role_starts_that_roles_behavior_at_once() {
        let mut b = behavior(GOALKEEPER_NUMBER);
        decide(&mut b, Role::Goalie, GameState::Playing, 0.0);
        decide(&mut b, Role::Goalie, GameState::Playing, 0.1);
        assert_eq!(b.machine.active_leaf(), Some(S::GoalCovering));
        decide(&mut b, Role::ActiveDefender, GameState::Playing, 0.2);
        assert_eq!(b.machine.active_leaf(), Some(S::ActiveDefender));
    }

    #[test]
    fn the_keeper_covers_from_the_bisector_and_stays_in_front_of_its_goal() {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let straight = covering_pose(&field, Point::new(-2.0, 0.0), 0.45);
        assert!((straight.y).abs() < 1e-9 && (straight.x - (-4.05)).abs() < 1e-9);
        let wide = covering_pose(&field, Point::new(-3.0, 2.5), 0.45);
        assert!(wide.y > 0.0 && wide.y <= field.goal_half_width + 1e-9, "{wide:?}");
        // It faces the ball.
        let to_ball = (Point::<FieldFrame>::new(-3.0, 2.5) - wide.position()).angle();
        assert!((strata_robot::normalize_angle(to_ball - wide.theta)).abs() < 1e-9);
    }

    /// Active vision scores a look at a painted line like any other (the value function's
    /// variance after the expected update, which now fuses the lines the view would show): a
    /// keeper sure of its pose does not take its head to a line; unsure, a line beats the ball
    /// and is among its best looks (the activation function averages S_d and S_r; for a line
    /// S_r is what the pose lacks). A keeper whose world model has never corrected its pose
    /// with a line is offered no line look.
    #[test]
    fn an_unsure_keeper_relocalizes_on_a_line_active_vision_chose() {
        use strata_robot::control::deliberative::{DeliberativeInput, DeliberativePolicy};
        use strata_robot::control::scores::ScoreCombination;
        use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
        use strata_robot::platform::ObjectClass;
        use strata_robot::world::{PosePrior, WorldCommand, WorldModel};
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let head_of_keeper = |sigma: [f64; 3], sees_lines: bool| {
            let mut b = behavior(GOALKEEPER_NUMBER);
            let mut model =
                WorldModel::new(crate::world_config::world_config(&field)).expect("valid");
            let view = ViewCone { direction: 0.0, fov: 1.0, range: 6.0, near: 0.0 };
            let frame = |model: &mut WorldModel, at: f64, observations: Vec<Observation>| {
                let stamp = Time::from_secs_f64(at);
                let camera = CameraPercepts { stamp, view, observations };
                let percepts = Percepts { stamp, camera: Some(camera), ..Percepts::default() };
                model.process(strata_robot::geometry::Odometry::default(), &percepts);
            };
            if sees_lines {
                // Sure of its pose, the keeper saw the touchline on its left (y = 3 m, along
                // its heading) before its pose got as unsure as `sigma`.
                let sure = PosePrior { pose: Pose::new(-4.0, 0.0, 0.0), sigma: [0.02; 3] };
                model.command(WorldCommand::SetPose { prior: sure }).expect("pose");
                let touchline = Observation {
                    class: ObjectClass(strata_spl::ObjectKind::FieldLine.code()),
                    variant: None,
                    range: 3.0,
                    bearing: std::f64::consts::FRAC_PI_2,
                    orientation: Some(0.0),
                    range_sigma: 0.1,
                    bearing_sigma: 0.03,
                };
                frame(&mut model, 0.45, vec![touchline]);
            }
            let prior = PosePrior { pose: Pose::new(-4.0, 0.0, 0.0), sigma };
            model.command(WorldCommand::SetPose { prior }).expect("pose");
            // The ball 2 m ahead, seen in a few images.
            for k in 1..=5 {
                let ball = Observation {
                    class: ObjectClass(strata_spl::ObjectKind::Ball.code()),
                    variant: None,
                    range: 2.0,
                    bearing: 0.0,
                    orientation: None,
                    range_sigma: 0.1,
                    bearing_sigma: 0.03,
                };
                frame(&mut model, 0.5 + 0.03 * f64::from(k), vec![ball]);
            }
            let world = model.state();
            assert_eq!(world.diagnostics.line_corrections > 0, sees_lines);
            let decision = Decision {
                assignment: strata_robot::control::planning::Assignment {
                    mission: Mission::DefendTheGoal,
                    role: Role::Goalie,
                    alone: false,
                },
                directive: GameDirective { state: GameState::Playing, ..GameDirective::default() },
                teammates: Vec::new(),
                stats: Default::default(),
            };
            let input = |at: f64| DeliberativeInput {
                now: Time::from_secs_f64(at),
                world: Some(&world),
                assignment: Some(&decision),
                stability: Stability::default(),
            };
            b.tick(&input(1.0));
            let out = b.tick(&input(1.1));
            assert!(out.behavior_path.contains("Goal covering"), "{}", out.behavior_path);
            // The activation function's second stage: S_d and S_r averaged, S_r the need to
            // look (1 - confidence) of the goal's objects, or of the pose for a line.
            let need = |g: &GoalScore<HeadGoal>| match &g.goal {
                HeadGoal::ObserveFieldLine { .. } => 1.0 - world.pose.confidence,
                _ => {
                    let objects = crate::situation::head_goal_objects(&world, &g.goal);
                    objects.iter().map(|o| 1.0 - o.confidence).fold(0.0, f64::max)
                }
            };
            let total = |g: &GoalScore<HeadGoal>| {
                ScoreCombination::Average.combine(g.deliberative, need(g))
            };
            let total_of =
                |goal: &HeadGoal| out.head.goals.iter().find(|g| &g.goal == goal).map(&total);
            let best = out.head.goals.iter().map(&total).fold(0.0, f64::max);
            let line_total = out
                .head
                .goals
                .iter()
                .filter(|g| matches!(g.goal, HeadGoal::ObserveFieldLine { .. }))
                .map(&total)
                .reduce(f64::max);
            let ball_total = total_of(&HeadGoal::ObserveBall).unwrap_or(0.0);
            (line_total, ball_total, best, world.pose.confidence)
        };
        let (line_total, _, best, confidence) = head_of_keeper([0.02, 0.02, 0.02], true);
        let line_total = line_total.expect("line goal");
        assert!(confidence > 0.8, "{confidence}");
        assert!(line_total < best, "sure ({confidence}): line {line_total}, best {best}");
        // Unsure, the line beats looking at the ball alone; a look at a landmark the pose
        // cannot place (need 1) may still beat it: both localize.
        let (line_total, ball_total, best, confidence) = head_of_keeper([0.5, 0.5, 0.4], true);
        let line_total = line_total.expect("line goal");
        assert!(confidence < 0.2, "{confidence}");
        assert!(line_total > ball_total, "unsure: line {line_total}, ball {ball_total}");
        assert!(line_total > 0.9 * best, "unsure: line {line_total}, best {best}");
        // Without a line ever fused, unsure or not, the look would only take the head off the
        // ball.
        let (line_total, _, _, confidence) = head_of_keeper([0.5, 0.5, 0.4], false);
        assert!(confidence < 0.2, "{confidence}");
        assert_eq!(line_total, None);
    }

    /// The candidates as made before their storage was reused: each with a new label and a
    /// list of the objects it looks at.
    fn plain_candidates(ctx: &Ctx, world: &WorldState) -> Vec<(GazeCandidate, Vec<String>)> {
        let mut out = Vec::new();
        let ball_id = world.object(BALL).map(|o| o.id);
        if let Some(id) = ball_id
            && let Some(c) = GazeCandidate::toward(world, id, BALL)
        {
            out.push((c, vec![BALL.to_owned()]));
        }
        let mut landmarks: Vec<_> = ctx
            .landmark_groups
            .iter()
            .filter_map(|g| best_instance(world, g))
            .filter(|o| o.category == ObjectCategory::Landmark)
            .collect();
        landmarks.sort_by(|a, b| a.position.range().total_cmp(&b.position.range()));
        for landmark in landmarks.iter().take(6) {
            let side = crate::situation::goal_side_of(landmark)
                .filter(|_| ctx.config.keeper_goal_looks && ctx.role() == Role::Goalie);
            let posts: Vec<_> = side.map(|s| goal_posts(world, s)).unwrap_or_default();
            let ids: Vec<_> = posts.iter().map(|o| o.id).collect();
            let label = if side == Some(GoalSide::Own) { "own goal" } else { "opponent goal" };
            let goal = GazeCandidate::covering(world, &ids, ctx.config.fov * 0.8, label);
            if let Some(c) = goal.filter(|_| ids.len() >= 2) {
                out.push((c, posts.iter().map(|o| o.name.to_string()).collect()));
            } else if let Some(c) = GazeCandidate::toward(world, landmark.id, landmark.name.clone())
            {
                out.push((c, vec![landmark.name.to_string()]));
            }
            if let Some(ball) = ball_id {
                let label = format!("{BALL}+{}", landmark.name);
                let ids = [ball, landmark.id];
                if let Some(c) = GazeCandidate::covering(world, &ids, ctx.config.fov * 0.8, label) {
                    out.push((c, vec![BALL.to_owned(), landmark.name.to_string()]));
                }
            }
        }
        out
    }

    /// A keeper with the goal looks on, on the SPL field, and a world model of that field.
    fn keeper_with_goal_looks() -> (Arc<TeamField>, SoccerBehavior, strata_robot::world::WorldModel)
    {
        let field =
            Arc::new(TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0));
        let behavior = SoccerBehavior::new(
            GOALKEEPER_NUMBER,
            Arc::clone(&field),
            BehaviorConfig { keeper_goal_looks: true, ..BehaviorConfig::default() },
            ActiveVisionConfig::default(),
            Arc::new(MotionModel::default()),
        )
        .expect("behavior");
        let model = strata_robot::world::WorldModel::new(crate::world_config::world_config(&field))
            .expect("valid config");
        (field, behavior, model)
    }

    #[test]
    fn gaze_candidates_in_reused_storage_are_the_plain_ones() {
        use strata_robot::world::{PosePrior, WorldCommand};
        let (_, behavior, mut model) = keeper_with_goal_looks();
        let (mut gazes, mut looks) = (Vec::new(), Vec::new());
        let mut lengths = std::collections::BTreeSet::new();
        let mut goal_looks = 0;
        for k in 0..60 {
            let t = f64::from(k);
            let pose = Pose::new(-4.0 + 0.14 * t, 2.5 * (0.3 * t).sin(), 0.37 * t);
            let prior = PosePrior { pose, sigma: [0.1, 0.1, 0.05] };
            let _ = model.command(WorldCommand::SetPose { prior });
            let world = model.state();
            gaze_candidates(&behavior.ctx, &world, &[], &mut gazes, &mut looks);
            let plain = plain_candidates(&behavior.ctx, &world);
            assert_eq!(gazes.len(), plain.len());
            assert_eq!(looks.len(), plain.len());
            for ((gaze, what), (c, objects)) in gazes.iter().zip(&looks).zip(&plain) {
                assert_eq!(gaze.label, c.label);
                assert_eq!(gaze.direction.to_bits(), c.direction.to_bits());
                assert_eq!(&what.objects(&gaze.label, &world), objects);
            }
            lengths.insert(plain.len());
            goal_looks += looks.iter().filter(|l| matches!(l, Looks::Goal(_))).count();
        }
        // Longer and shorter lists followed one another, goals among them.
        assert!(lengths.len() > 2, "{lengths:?}");
        assert!(goal_looks > 0);
    }

    /// Facing a goal from afar, the post's look is the goal's, centred between the posts, and
    /// the head looks there; near the goal, where both posts do not fit in one image, it is
    /// the post's.
    #[test]
    fn a_goal_whose_posts_fit_in_one_image_is_looked_at_between_them() {
        use strata_robot::world::{PosePrior, WorldCommand};
        let (field, behavior, mut model) = keeper_with_goal_looks();
        let (mut gazes, mut looks) = (Vec::new(), Vec::new());
        let goal_line = field.field.dimensions().field_length / 2.0;
        let mut looks_at = |x: f64| {
            let prior = PosePrior { pose: Pose::new(x, 0.3, 0.1), sigma: [0.05, 0.05, 0.02] };
            let _ = model.command(WorldCommand::SetPose { prior });
            let world = model.state();
            gaze_candidates(&behavior.ctx, &world, &[], &mut gazes, &mut looks);
            let goal = looks.iter().position(|l| *l == Looks::Goal(GoalSide::Opponent));
            (world, goal.map(|i| gazes[i].direction))
        };
        let (world, direction) = looks_at(0.0);
        let direction = direction.expect("a look at the opponent goal");
        let head = HeadGoal::ObserveGoal { side: GoalSide::Opponent };
        let target = crate::primitives::look_target(&field, &world, &head, 1.06).expect("target");
        let bearings: Vec<f64> = crate::situation::goal_posts(&world, GoalSide::Opponent)
            .iter()
            .map(|o| o.position.bearing())
            .collect();
        assert_eq!(bearings.len(), 2);
        let (lo, hi) = (bearings[0].min(bearings[1]), bearings[0].max(bearings[1]));
        assert!((target.bearing() - direction).abs() < 1e-9, "{target:?} {direction}");
        assert!(lo < direction && direction < hi, "{lo} < {direction} < {hi}");
        assert!((direction - (lo + hi) / 2.0).abs() < 1e-9);
        // A step in front of the goal, the posts are farther apart than the image.
        let (_, near) = looks_at(goal_line - 0.5);
        assert_eq!(near, None);
        assert!(looks.contains(&Looks::Landmark));
        // A field player looks at the post, wherever it stands, and so does a keeper whose
        // team leaves the goal looks off (the default).
        let prior = PosePrior { pose: Pose::new(0.0, 0.3, 0.1), sigma: [0.05, 0.05, 0.02] };
        let _ = model.command(WorldCommand::SetPose { prior });
        let world = model.state();
        let on = BehaviorConfig { keeper_goal_looks: true, ..BehaviorConfig::default() };
        for (player, config) in [(2, on), (GOALKEEPER_NUMBER, BehaviorConfig::default())] {
            let other = SoccerBehavior::new(
                player,
                Arc::clone(&field),
                config,
                ActiveVisionConfig::default(),
                Arc::new(MotionModel::default()),
            )
            .expect("behavior");
            gaze_candidates(&other.ctx, &world, &[], &mut gazes, &mut looks);
            assert!(!looks.iter().any(|l| matches!(l, Looks::Goal(_))), "player {player}");
            assert!(looks.contains(&Looks::Landmark));
        }
    }

    #[test]
    fn kickoff_positions_are_legal() {
        for preset in strata_spl::field::PRESETS {
            kickoff_positions_are_legal_on(preset);
        }
    }

    fn kickoff_positions_are_legal_on(preset: &str) {
        let field = TeamField::new(strata_spl::Field::preset(preset).expect("preset"), 1.0);
        for player in 1..=7 {
            for (kicking, rule) in [(true, false), (false, false), (true, true), (false, true)] {
                let p = kickoff_pose(&field, player, kicking, rule).position();
                assert!(p.x < 0.0 && field.is_inside(p, 0.0), "player {player}: {p:?}");
                let in_circle = p.range() < field.center_circle_radius;
                assert!(
                    !in_circle || (kicking && player == 2),
                    "{preset}: player {player} kicking {kicking}"
                );
                if kicking && player == 2 {
                    // Under the second-touch rule, clear of a ball 0.11 m in radius and a
                    // T1's feet.
                    assert!(p.range() > if rule { 0.5 } else { 0.2 }, "{p:?}");
                }
            }
        }
    }

    /// rcsssmj's double-touch rule: the robot at the ball when its team's kick-off is taken
    /// keeps off the ball while it lies where the kick left it, and plays it again once the
    /// ball has moved without it.
    #[test]
    fn the_kick_off_taker_lets_go_until_the_ball_moves_without_it() {
        // The kick-off pending in Playing, and taken before Playing showed it (rcssservermj's
        // kicker touches the ball walking up to it).
        for pending in [GameState::Playing, GameState::Ready] {
            kick_off_taker_lets_go(pending);
        }
    }

    fn kick_off_taker_lets_go(pending: GameState) {
        let config = BehaviorConfig { no_second_touch: true, ..BehaviorConfig::default() };
        let mut b = with_config(KICKER_NUMBER, config);
        let mut scene = Scene::new(Some(Pose::new(-0.25, 0.0, 0.0)));
        let mut tick = |k: u32, state: GameState, secondary_time: i16, ball_range: f64| {
            let directive = GameDirective {
                state,
                kicking: Kicking::Us,
                secondary_time,
                ..GameDirective::default()
            };
            scene.tick(&mut b, k, Some(ball_range), Role::Striker, directive).behavior_path
        };
        // The kick-off waits; the kicker stands at the ball (and goes for it once Playing).
        for k in 0..10 {
            let path = tick(k, pending, 10, 0.25);
            // (The machine leaves its initial state in the first tick.)
            let expected = if pending == GameState::Playing { "kick to goal" } else { "Ready" };
            assert!(k == 0 || path.ends_with(expected), "{k}: {path}");
        }
        // Taken: the ball lies 0.6 m ahead (a weak kick), and the taker keeps off it.
        for k in 10..60 {
            let path = tick(k, GameState::Playing, 0, 0.6);
            assert!(path.ends_with("keep off the ball"), "{pending:?} {k}: {path}");
        }
        // Someone else plays it: the ball lies 1.5 m further on, and the taker may go again.
        let mut released = None;
        for k in 60..80 {
            let path = tick(k, GameState::Playing, 0, 2.1);
            if path.ends_with("kick to goal") {
                released.get_or_insert(k);
            }
        }
        assert!(released.is_some_and(|k| k <= 70), "{pending:?}: released at tick {released:?}");
    }

    /// Without the rule (the built-in simulator), the kick-off taker plays on.
    #[test]
    fn without_the_rule_the_taker_plays_on() {
        let mut b = behavior(KICKER_NUMBER);
        b.ctx.at_own_restart = true;
        decide(&mut b, Role::Striker, GameState::Playing, 0.0);
        track_second_touch(&mut b.ctx);
        assert_eq!(b.ctx.let_go, None);
    }
}
