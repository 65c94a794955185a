//! Reading the world state the way soccer behaviors need it.

use strata_robot::geometry::{Global as FieldFrame, Point, Robot, Vector};
use strata_robot::world::{ObjectCategory, ObjectEstimate, WorldState};
use strata_spl::field::Side;

use crate::goals::{GoalSide, HeadGoal};
use crate::world_config::{BALL, GOAL_POST, OBSTACLE, OPPONENT_GOAL_POST, OWN_GOAL_POST};

/// The ball as a behavior uses it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallView {
    pub robot: Point<Robot>,
    pub field: Point<FieldFrame>,
    pub velocity: Option<Vector<Robot>>,
    pub confidence: f64,
    /// Above the world model's "unknown" threshold.
    pub known: bool,
    /// Known from teammates only.
    pub from_team: bool,
}

/// The robot's own ball estimate if known; otherwise the team's fused ball (MAWM); otherwise
/// the own estimate, unknown.
pub fn ball(world: &WorldState) -> Option<BallView> {
    let own = world.object(BALL);
    if let Some(b) = own.filter(|b| b.known) {
        return Some(BallView {
            robot: b.position,
            field: b.global_position,
            velocity: b.velocity,
            confidence: b.confidence,
            known: true,
            from_team: false,
        });
    }
    if let Some(t) = world.team_object(BALL).filter(|t| !t.teammates.is_empty()) {
        return Some(BallView {
            robot: world.pose.pose.to_robot(t.position),
            field: t.position,
            velocity: None,
            confidence: 0.5,
            known: !world.pose.lost,
            from_team: true,
        });
    }
    own.map(|b| BallView {
        robot: b.position,
        field: b.global_position,
        velocity: b.velocity,
        confidence: b.confidence,
        known: false,
        from_team: false,
    })
}

/// Other robots seen recently, relative to this one.
pub fn obstacles(world: &WorldState) -> impl Iterator<Item = &ObjectEstimate> {
    world
        .objects
        .iter()
        .filter(|o| o.category == ObjectCategory::Obstacle && o.known && o.group == OBSTACLE)
}

/// The rival robot the world model tracks as obstacle track `track` (the `k` of
/// `obstacle#k`: robots are seen, not identified by their numbers), when known.
pub fn rival(world: &WorldState, track: u8) -> Option<&ObjectEstimate> {
    world.group(OBSTACLE).nth(usize::from(track)).filter(|o| o.known)
}

/// The obstacle track number of `object` (see [`rival`]).
pub fn rival_track(world: &WorldState, object: &ObjectEstimate) -> Option<u8> {
    let k = world.group(OBSTACLE).position(|o| o.id == object.id)?;
    u8::try_from(k).ok()
}

/// The nearest obstacle ahead within `range`, if any.
pub fn obstacle_ahead(world: &WorldState, range: f64, half_angle: f64) -> Option<Point<Robot>> {
    rival_ahead(world, range, half_angle).map(|o| o.position)
}

/// The estimate of [`obstacle_ahead`]'s obstacle.
pub fn rival_ahead(world: &WorldState, range: f64, half_angle: f64) -> Option<&ObjectEstimate> {
    obstacles(world)
        .filter(|o| {
            let p = o.position;
            p.range() < range && p.bearing().abs() < half_angle && p.x > 0.0
        })
        .min_by(|a, b| a.position.range().total_cmp(&b.position.range()))
}

/// The best-placed instance of a landmark group: the most confident, then the nearest.
pub fn best_instance<'a>(world: &'a WorldState, group: &'a str) -> Option<&'a ObjectEstimate> {
    world.group(group).filter(|o| o.tracked || !world.pose.lost).max_by(|a, b| {
        (a.confidence - 0.01 * a.position.range())
            .total_cmp(&(b.confidence - 0.01 * b.position.range()))
    })
}

/// The goal posts of one goal, whether the field's posts are coloured or not.
pub fn goal_posts(world: &WorldState, side: GoalSide) -> Vec<&ObjectEstimate> {
    let coloured = match side {
        GoalSide::Own => OWN_GOAL_POST,
        GoalSide::Opponent => OPPONENT_GOAL_POST,
    };
    let posts: Vec<_> = world.group(coloured).collect();
    if !posts.is_empty() {
        return posts;
    }
    let sign = match side {
        GoalSide::Own => -1.0,
        GoalSide::Opponent => 1.0,
    };
    world.group(GOAL_POST).filter(|o| o.map_position.is_some_and(|m| m.x * sign > 0.0)).collect()
}

/// Which goal a goal post belongs to: by its group where the posts are coloured, by the side
/// of the field its map position is on where they are not.
pub fn goal_side_of(post: &ObjectEstimate) -> Option<GoalSide> {
    match post.group.as_str() {
        OWN_GOAL_POST => Some(GoalSide::Own),
        OPPONENT_GOAL_POST => Some(GoalSide::Opponent),
        GOAL_POST => {
            let x = post.map_position?.x;
            Some(if x < 0.0 { GoalSide::Own } else { GoalSide::Opponent })
        }
        _ => None,
    }
}

pub fn side_of(side: GoalSide) -> Side {
    match side {
        GoalSide::Own => Side::Own,
        GoalSide::Opponent => Side::Opponent,
    }
}

/// How many objects of a head goal are held without a `Vec` (the ball and a landmark, say).
const FEW: usize = 4;

/// The world-model objects a head goal is about. Usually one, rarely more than a few: it is
/// asked for several times per reactive cycle, so they are not put in a `Vec` unless many.
#[derive(Debug)]
pub enum GoalObjects<'a> {
    One(Option<&'a ObjectEstimate>),
    /// The first `len` entries (the rest repeat the first).
    Few([&'a ObjectEstimate; FEW], usize),
    Several(Vec<&'a ObjectEstimate>),
}

impl<'a> GoalObjects<'a> {
    pub(crate) fn collect(
        mut objects: impl Iterator<Item = &'a ObjectEstimate>,
    ) -> GoalObjects<'a> {
        let Some(first) = objects.next() else { return GoalObjects::Several(Vec::new()) };
        let mut few = [first; FEW];
        let mut len = 1;
        for object in objects.by_ref() {
            if len == FEW {
                let mut several = few.to_vec();
                several.push(object);
                several.extend(objects);
                return GoalObjects::Several(several);
            }
            few[len] = object;
            len += 1;
        }
        GoalObjects::Few(few, len)
    }
}

impl<'a> std::ops::Deref for GoalObjects<'a> {
    type Target = [&'a ObjectEstimate];

    fn deref(&self) -> &[&'a ObjectEstimate] {
        match self {
            GoalObjects::One(one) => one.as_slice(),
            GoalObjects::Few(few, len) => &few[..*len],
            GoalObjects::Several(several) => several,
        }
    }
}

pub fn head_goal_objects<'a>(world: &'a WorldState, goal: &'a HeadGoal) -> GoalObjects<'a> {
    let one = match goal {
        HeadGoal::ObserveBall => world.object(BALL),
        // The goal is its posts, seen together.
        HeadGoal::ObserveGoal { side } => {
            return GoalObjects::collect(goal_posts(world, *side).into_iter());
        }
        HeadGoal::ObserveLandmark { name } => {
            world.object(name).or_else(|| best_instance(world, name))
        }
        HeadGoal::ObserveTogether { objects } => {
            return GoalObjects::collect(
                objects.iter().filter_map(|n| world.object(n).or_else(|| best_instance(world, n))),
            );
        }
        HeadGoal::ObserveRival { player } => rival(world, *player),
        HeadGoal::ObservePartner { .. }
        | HeadGoal::ObserveFieldLine { .. }
        | HeadGoal::ObserveReferee { .. }
        | HeadGoal::Scan => None,
    };
    GoalObjects::One(one)
}
