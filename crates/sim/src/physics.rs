//! 2D physics: the rolling ball, the field's fixed obstacles (goal posts, goal nets, the edge of
//! the carpet), and collisions between robots, ball, posts and nets.
//!
//! Robots are discs; the ball is a disc with rolling resistance and drag. Collisions resolve
//! overlaps by moving the bodies apart and reflect the ball's velocity with restitution. The ball
//! is integrated in sub-steps short enough that it cannot tunnel through a post or a robot.

use serde::{Deserialize, Serialize};
use strata_robot::geometry::Segment;
use strata_robot::{Global as FieldFrame, Point, Vector};
use strata_spl::Field;
use strata_spl::field::Side;

use crate::config::BallConfig;
use crate::util::length;

/// The fixed obstacles of the field.
#[derive(Clone, Debug)]
pub(crate) struct Obstacles {
    /// Goal post centres and their radius.
    pub posts: Vec<Point<FieldFrame>>,
    pub post_radius: f64,
    /// Goal nets: the sides and back of each goal.
    pub nets: Vec<Segment<FieldFrame>>,
    /// Half extents of the carpet (field plus border strip).
    pub carpet: [f64; 2],
    /// Nothing closer to the halfway line than this (|x|) can touch a post or a net: most
    /// steps skip those tests.
    pub goal_zone: f64,
}

impl Obstacles {
    /// Whether a disc of `radius` at `x` may touch a post or a net.
    #[inline]
    fn near_goal(&self, x: f64, radius: f64) -> bool {
        x.abs() + radius >= self.goal_zone
    }
}

impl Obstacles {
    pub fn new(field: &Field) -> Obstacles {
        let d = field.dimensions();
        let mut posts = Vec::new();
        let mut nets = Vec::new();
        for side in [Side::Own, Side::Opponent] {
            let goal = field.goal(side);
            let left = Point::new(goal.left_post.x, goal.left_post.y);
            let right = Point::new(goal.right_post.x, goal.right_post.y);
            posts.push(left);
            posts.push(right);
            let back_x = side.sign() * (field.half_length() + d.goal_depth);
            let back_left = Point::new(back_x, left.y);
            let back_right = Point::new(back_x, right.y);
            nets.push(Segment::new(left, back_left));
            nets.push(Segment::new(back_left, back_right));
            nets.push(Segment::new(back_right, right));
        }
        let post_radius = d.goal_post_diameter / 2.0;
        let goal_zone =
            posts.iter().map(|p| p.x.abs()).fold(f64::INFINITY, f64::min) - post_radius - 1e-6;
        Obstacles {
            posts,
            post_radius,
            goal_zone,
            nets,
            carpet: [
                field.half_length() + d.border_strip_width,
                field.half_width() + d.border_strip_width,
            ],
        }
    }
}

/// The ball's motion along a polyline at constant speed, ignoring physics (experiments).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BallScript {
    pub waypoints: Vec<Point<FieldFrame>>,
    /// m/s.
    pub speed: f64,
    /// Start again from the first waypoint at the end.
    pub repeat: bool,
    /// Distance travelled along the polyline, m.
    #[serde(default)]
    pub travelled: f64,
}

impl BallScript {
    pub fn new(waypoints: Vec<Point<FieldFrame>>, speed: f64) -> BallScript {
        BallScript { waypoints, speed, repeat: false, travelled: 0.0 }
    }

    fn length(&self) -> f64 {
        self.waypoints.windows(2).map(|w| w[0].distance(w[1])).sum()
    }

    /// Position and velocity at `travelled` metres along the path.
    fn at(&self, travelled: f64) -> (Point<FieldFrame>, Vector<FieldFrame>) {
        let mut left = travelled;
        for w in self.waypoints.windows(2) {
            let length = w[0].distance(w[1]);
            if left <= length && length > 0.0 {
                let direction = (w[1] - w[0]).normalized();
                return (w[0].lerp(w[1], left / length), direction * self.speed);
            }
            left -= length;
        }
        (self.waypoints.last().copied().unwrap_or_default(), Vector::new(0.0, 0.0))
    }
}

/// The ball.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Ball {
    pub position: Point<FieldFrame>,
    pub velocity: Vector<FieldFrame>,
    pub script: Option<BallScript>,
}

/// The robots as the ball sees them: discs by slot (none for a robot off the field), with
/// their field-frame velocities, and the diving ones' blocking bodies.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Discs<'a> {
    pub positions: &'a [Option<Point<FieldFrame>>],
    pub velocities: &'a [Vector<FieldFrame>],
    pub radius: f64,
    /// Where a diving robot's body blocks the ball, as a segment, by slot in increasing order.
    pub blocks: &'a [(usize, Segment<FieldFrame>)],
}

#[cfg(test)]
impl Discs<'_> {
    /// No robots.
    pub const NONE: Discs<'static> =
        Discs { positions: &[], velocities: &[], radius: 0.0, blocks: &[] };
}

/// The width of a diving body (half), m.
const BLOCK_RADIUS: f64 = 0.08;

impl Ball {
    /// Advances the ball by `dt`. Returns the index of the last robot that touched it.
    #[inline(never)]
    pub fn step(
        &mut self,
        dt: f64,
        config: &BallConfig,
        obstacles: &Obstacles,
        robots: &Discs<'_>,
    ) -> Option<usize> {
        if let Some(script) = &mut self.script {
            script.travelled += script.speed * dt;
            let length = script.length();
            if script.repeat && length > 0.0 {
                script.travelled %= length;
            }
            let (position, velocity) = script.at(script.travelled.min(length));
            self.position = position;
            self.velocity = velocity;
            if !script.repeat && script.travelled >= length {
                self.velocity = Vector::new(0.0, 0.0);
                self.script = None;
            }
            return None;
        }
        let speed = length(self.velocity.x, self.velocity.y);
        // Sub-steps: the ball moves at most half its radius per sub-step.
        let steps = ((speed * dt) / (0.5 * config.radius)).ceil().clamp(1.0, 64.0) as usize;
        let h = dt / steps as f64;
        let mut touched = None;
        for _ in 0..steps {
            self.roll(h, config);
            if let Some(robot) = self.collide(config, obstacles, robots) {
                touched = Some(robot);
            }
        }
        touched
    }

    fn roll(&mut self, h: f64, config: &BallConfig) {
        let speed = length(self.velocity.x, self.velocity.y);
        if speed <= 0.0 {
            return;
        }
        let direction = self.velocity * (1.0 / speed);
        let slowed = speed - (config.friction + config.drag * speed) * h;
        if slowed <= 0.0 {
            // Friction stops the ball within this sub-step: it does not roll backwards.
            let travel = speed * speed / (2.0 * (config.friction + config.drag * speed)).max(1e-9);
            self.position = self.position + direction * travel.min(speed * h);
            self.velocity = Vector::new(0.0, 0.0);
            return;
        }
        let slowed = slowed.min(config.max_speed);
        let mean = 0.5 * (speed + slowed);
        self.position = self.position + direction * (mean * h);
        self.velocity = direction * slowed;
    }

    fn collide(
        &mut self,
        config: &BallConfig,
        obstacles: &Obstacles,
        robots: &Discs<'_>,
    ) -> Option<usize> {
        let r = config.radius;
        // Posts and nets only near the goals (like robots, see `resolve_robots`).
        if obstacles.near_goal(self.position.x, r) {
            for &post in &obstacles.posts {
                self.bounce_off_point(
                    post,
                    obstacles.post_radius + r,
                    Vector::new(0.0, 0.0),
                    config.restitution_posts,
                );
            }
            for net in &obstacles.nets {
                let closest = net.closest_point(self.position);
                self.bounce_off_point(closest, r, Vector::new(0.0, 0.0), config.restitution_posts);
            }
        }
        let mut touched = None;
        let reach = robots.radius + r;
        let mut blocks = robots.blocks.iter().peekable();
        for (index, position) in robots.positions.iter().enumerate() {
            if let Some(position) = position {
                // Most robots are far from the ball: their velocity is not needed.
                let offset = self.position - *position;
                if offset.dot(offset) < reach * reach {
                    let velocity = robots.velocities.get(index).copied().unwrap_or_default();
                    if self.bounce_off_point(*position, reach, velocity, config.restitution_robots)
                    {
                        touched = Some(index);
                    }
                }
            }
            while let Some((_, block)) = blocks.next_if(|(slot, _)| *slot <= index) {
                let closest = block.closest_point(self.position);
                if self.bounce_off_point(
                    closest,
                    BLOCK_RADIUS + r,
                    Vector::new(0.0, 0.0),
                    config.restitution_robots,
                ) {
                    touched = Some(index);
                }
            }
        }
        // The edge of the carpet: the arena's wall.
        let [hx, hy] = obstacles.carpet;
        let e = config.restitution_posts;
        if self.position.x.abs() > hx - r {
            self.position.x = self.position.x.signum() * (hx - r);
            if self.velocity.x * self.position.x.signum() > 0.0 {
                self.velocity.x *= -e;
            }
        }
        if self.position.y.abs() > hy - r {
            self.position.y = self.position.y.signum() * (hy - r);
            if self.velocity.y * self.position.y.signum() > 0.0 {
                self.velocity.y *= -e;
            }
        }
        touched
    }

    /// Pushes the ball out of a disc of `distance` around `center` moving at `velocity`, and
    /// reflects the ball's relative velocity. Returns whether they were in contact.
    fn bounce_off_point(
        &mut self,
        center: Point<FieldFrame>,
        distance: f64,
        velocity: Vector<FieldFrame>,
        restitution: f64,
    ) -> bool {
        let offset = self.position - center;
        let d2 = offset.dot(offset);
        if d2 >= distance * distance {
            return false;
        }
        let d = d2.sqrt();
        let normal = if d > 1e-12 { offset * (1.0 / d) } else { Vector::new(1.0, 0.0) };
        self.position = center + normal * distance;
        let relative = self.velocity - velocity;
        let vn = relative.dot(normal);
        if vn < 0.0 {
            self.velocity = self.velocity - normal * ((1.0 + restitution) * vn);
        }
        true
    }
}

/// A contact between two robots during a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Contact {
    pub a: usize,
    pub b: usize,
    /// From a to b.
    pub normal: Vector<FieldFrame>,
    /// How fast they approached each other along the normal, m/s (0 if separating).
    pub approach_speed: f64,
    /// They were not in contact in the previous step.
    pub onset: bool,
    /// Which of the two was moving into the other (walking or pushed).
    pub a_pushing: bool,
    pub b_pushing: bool,
}

/// Separates overlapping robots and keeps them off the posts, the nets and the carpet's edge.
/// `positions` are updated in place; `previous` holds the pairs in contact in the last step
/// and is replaced by this step's.
#[inline(never)]
pub(crate) fn resolve_robots(
    positions: &mut [Option<Point<FieldFrame>>],
    velocities: &[Vector<FieldFrame>],
    radius: f64,
    obstacles: &Obstacles,
    previous: &mut Vec<(usize, usize)>,
    contacts: &mut Vec<Contact>,
) {
    contacts.clear();
    let n = positions.len();
    let reach = 2.0 * radius;
    // Separates a and b if they overlap; returns whether they did.
    let mut touch = |positions: &mut [Option<Point<FieldFrame>>], a: usize, b: usize| {
        let (Some(pa), Some(pb)) = (positions[a], positions[b]) else { return false };
        let offset = pb - pa;
        let d2 = offset.dot(offset);
        if d2 >= reach * reach {
            return false;
        }
        let d = d2.sqrt();
        // Coincident robots (a teleport onto another) separate along x.
        let normal = if d > 1e-9 { offset * (1.0 / d) } else { Vector::new(1.0, 0.0) };
        let overlap = reach - d;
        positions[a] = Some(pa - normal * (overlap / 2.0));
        positions[b] = Some(pb + normal * (overlap / 2.0));
        let relative = velocities[b] - velocities[a];
        let approach_speed = (-relative.dot(normal)).max(0.0);
        let onset = previous.binary_search(&(a, b)).is_err();
        contacts.push(Contact {
            a,
            b,
            normal,
            approach_speed,
            onset,
            a_pushing: velocities[a].dot(normal) > 1e-3,
            b_pushing: velocities[b].dot(normal) < -1e-3,
        });
        true
    };
    const COLUMN: usize = 32;
    if n <= COLUMN {
        // The robots on the field as columns, in slot order: a robot's distance tests against
        // all the later ones are one loop, four at a time without branches (most robots are
        // far from each other); after a contact moves it, the rest are tested from its new
        // place. Pairs are handled in the same order, with the same arithmetic, as one by one.
        let (mut xs, mut ys, mut slots) = ([0.0; COLUMN], [0.0; COLUMN], [0usize; COLUMN]);
        let mut m = 0;
        for (slot, p) in positions.iter().enumerate() {
            if let Some(p) = p {
                (xs[m], ys[m], slots[m]) = (p.x, p.y, slot);
                m += 1;
            }
        }
        for i in 0..m {
            let mut from = i + 1;
            while let Some(k) = first_within(&xs[from..m], &ys[from..m], xs[i], ys[i], reach) {
                let k = from + k;
                from = k + 1;
                if touch(positions, slots[i], slots[k]) {
                    for c in [i, k] {
                        if let Some(p) = positions[slots[c]] {
                            (xs[c], ys[c]) = (p.x, p.y);
                        }
                    }
                }
            }
        }
    } else {
        for a in 0..n {
            for b in (a + 1)..n {
                touch(positions, a, b);
            }
        }
    }
    // This step's pairs, in order (no allocation in the steady state).
    previous.clear();
    previous.extend(contacts.iter().map(|c| (c.a, c.b)));

    let [hx, hy] = obstacles.carpet;
    // As `clamp`, by plain comparisons (cheaper; a NaN stays NaN either way).
    let clamp = |v: f64, limit: f64| {
        if v < -limit {
            -limit
        } else if v > limit {
            limit
        } else {
            v
        }
    };
    for position in positions.iter_mut() {
        let Some(p) = position else { continue };
        if obstacles.near_goal(p.x, radius) {
            for &post in &obstacles.posts {
                push_out(p, post, radius + obstacles.post_radius);
            }
            for net in &obstacles.nets {
                let closest = net.closest_point(*p);
                push_out(p, closest, radius);
            }
        }
        p.x = clamp(p.x, hx - radius);
        p.y = clamp(p.y, hy - radius);
    }
}

/// The first of the points (xs, ys) closer than `reach` to (x, y), testing four at a time
/// without branches (most robots are far from each other).
#[inline]
fn first_within(xs: &[f64], ys: &[f64], x: f64, y: f64, reach: f64) -> Option<usize> {
    let n = xs.len().min(ys.len());
    let (xs, ys) = (&xs[..n], &ys[..n]);
    let near = |i: usize| {
        let (dx, dy) = (xs[i] - x, ys[i] - y);
        dx * dx + dy * dy < reach * reach
    };
    let mut start = 0;
    while start + 4 <= n {
        if near(start) | near(start + 1) | near(start + 2) | near(start + 3) {
            break;
        }
        start += 4;
    }
    (start..n).find(|&i| near(i))
}

fn push_out(p: &mut Point<FieldFrame>, center: Point<FieldFrame>, distance: f64) {
    let offset = *p - center;
    let d2 = offset.dot(offset);
    if d2 < distance * distance {
        let d = d2.sqrt();
        let normal =
            if d > 1e-9 { offset * (1.0 / d) } else { Vector::new(-center.x.signum(), 0.0) };
        *p = center + normal * distance;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obstacles() -> Obstacles {
        Obstacles::new(&Field::preset("spl").expect("preset"))
    }

    #[test]
    fn friction_stops_a_rolling_ball() {
        let config = BallConfig::default();
        let mut ball =
            Ball { position: Point::new(0.0, 0.0), velocity: Vector::new(2.0, 0.0), script: None };
        let mut t = 0.0;
        while ball.velocity.norm() > 0.0 && t < 30.0 {
            ball.step(0.012, &config, &obstacles(), &Discs::NONE);
            t += 0.012;
        }
        assert!(t < 10.0, "the ball stopped after {t} s");
        // Constant friction plus drag: shorter than the friction-only distance v^2 / 2a.
        assert!(ball.position.x > 1.0 && ball.position.x < 4.0, "{:?}", ball.position);
        let resting = ball.position;
        ball.step(0.012, &config, &obstacles(), &Discs::NONE);
        assert_eq!(ball.position, resting);
    }

    #[test]
    fn a_fast_ball_bounces_off_a_post_instead_of_passing_through() {
        let config = BallConfig::default();
        let obstacles = obstacles();
        let post = obstacles.posts[0];
        let mut ball = Ball {
            position: Point::new(post.x + 1.0, post.y),
            velocity: Vector::new(-7.0, 0.0),
            script: None,
        };
        for _ in 0..40 {
            ball.step(0.012, &config, &obstacles, &Discs::NONE);
            assert!(ball.position.distance(post) >= obstacles.post_radius + config.radius - 1e-9);
        }
        assert!(ball.position.x > post.x, "bounced back: {:?}", ball.position);
    }

    #[test]
    fn robots_do_not_overlap_and_contacts_start_once() {
        let obstacles = obstacles();
        let mut positions = vec![Some(Point::new(0.0, 0.0)), Some(Point::new(0.2, 0.0)), None];
        let velocities = vec![Vector::new(0.3, 0.0), Vector::new(0.0, 0.0), Vector::new(0.0, 0.0)];
        let mut previous = Vec::new();
        let mut contacts = Vec::new();
        resolve_robots(&mut positions, &velocities, 0.13, &obstacles, &mut previous, &mut contacts);
        let (a, b) = (positions[0].expect("a"), positions[1].expect("b"));
        assert!((a.distance(b) - 0.26).abs() < 1e-9);
        assert_eq!(contacts.len(), 1);
        assert!(contacts[0].onset && contacts[0].a_pushing && !contacts[0].b_pushing);
        assert!((contacts[0].approach_speed - 0.3).abs() < 1e-9);
        positions[0] = Some(Point::new(a.x + 0.004, a.y));
        resolve_robots(&mut positions, &velocities, 0.13, &obstacles, &mut previous, &mut contacts);
        assert!(!contacts[0].onset);
    }

    #[test]
    fn a_scripted_ball_follows_its_polyline_at_its_speed() {
        let config = BallConfig::default();
        let mut ball = Ball {
            position: Point::new(0.0, 0.0),
            velocity: Vector::new(0.0, 0.0),
            script: Some(BallScript::new(
                vec![Point::new(0.0, 0.0), Point::new(1.0, 0.0), Point::new(1.0, 1.0)],
                0.2,
            )),
        };
        for _ in 0..500 {
            ball.step(0.01, &config, &obstacles(), &Discs::NONE);
        }
        // 5 s at 0.2 m/s: 1 m along x.
        assert!((ball.position.x - 1.0).abs() < 1e-9 && ball.position.y.abs() < 1e-9);
        for _ in 0..600 {
            ball.step(0.01, &config, &obstacles(), &Discs::NONE);
        }
        assert!(ball.script.is_none(), "the script ended");
        assert!((ball.position.y - 1.0).abs() < 1e-9);
    }
}
