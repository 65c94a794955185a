//! The building: what the operator's floor plan says — walls, the landmarks on them, the points
//! of interest and where to inspect them from, each robot's beat — and the roadmap the
//! deliberative layer plans trajectories on (paper 3.4: "the deliberative layer is able to make
//! long-term decisions such as trajectory planning").
//!
//! The plan is the robots' prior knowledge. The simulated building ([`crate::sim`]) uses the
//! same walls and landmarks, but its points of interest may stand elsewhere than the plan says:
//! finding out where they really are is what an inspection is for.

use strata_robot::geometry::{Global, Point, Pose, Segment};
use strata_robot::world::Region;

/// A point of interest: something a patrol inspects (an extinguisher, a panel, a door).
#[derive(Clone, Debug, PartialEq)]
pub struct PointOfInterest {
    pub name: String,
    /// Where the floor plan puts it.
    pub nominal: Point<Global>,
    /// Where to stand to inspect it, facing it.
    pub viewpoint: Pose,
}

/// One stop of a beat. Reaching a waypoint with an inspection sends the robot off the route to
/// the point's viewpoint and back (patrol → inspect → return).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Waypoint {
    pub position: Point<Global>,
    pub inspect: Option<usize>,
}

/// The operator's floor plan.
#[derive(Clone, Debug)]
pub struct FloorPlan {
    pub bounds: Region,
    /// Walls, as zero-thickness segments.
    pub walls: Vec<Segment<Global>>,
    /// Fiducial markers on the walls, each uniquely identifiable (its index is its code).
    pub markers: Vec<Point<Global>>,
    /// Wall corners: identical features, told apart only by where they are.
    pub corners: Vec<Point<Global>>,
    pub points_of_interest: Vec<PointOfInterest>,
    /// One closed route per robot (player `p` walks `beats[p - 1]`).
    pub beats: Vec<Vec<Waypoint>>,
    /// Extra roadmap nodes (doorways, junctions).
    pub junctions: Vec<Point<Global>>,
    /// Distance a planned path keeps from the walls, m.
    pub clearance: f64,
    nodes: Vec<Point<Global>>,
    /// Roadmap edges between `nodes`, with their lengths.
    edges: Vec<Vec<(usize, f64)>>,
}

fn p(x: f64, y: f64) -> Point<Global> {
    Point::new(x, y)
}

impl FloorPlan {
    /// A 14 m x 8 m office floor split by a wall into a north and a south wing, joined at the
    /// east end: a U-shaped corridor with two beats and four points of interest.
    pub fn office() -> FloorPlan {
        let wall = |a: Point<Global>, b: Point<Global>| Segment::new(a, b);
        let walls = vec![
            wall(p(-7.0, -4.0), p(7.0, -4.0)),
            wall(p(7.0, -4.0), p(7.0, 4.0)),
            wall(p(7.0, 4.0), p(-7.0, 4.0)),
            wall(p(-7.0, 4.0), p(-7.0, -4.0)),
            // The dividing wall, open at its east end (3 m to 7 m).
            wall(p(-7.0, 0.0), p(3.0, 0.0)),
        ];
        // Markers stand 2 cm off their wall, on the side they face.
        let markers = vec![
            p(-5.5, 3.98),
            p(-2.0, 3.98),
            p(1.5, 3.98),
            p(5.0, 3.98),
            p(-5.0, 0.02),
            p(-1.5, 0.02),
            p(1.8, 0.02),
            p(-6.98, 2.0),
            p(6.98, 2.0),
            p(6.98, -2.0),
            p(-5.5, -3.98),
            p(-2.0, -3.98),
            p(1.5, -3.98),
            p(5.0, -3.98),
            p(-5.0, -0.02),
            p(-1.5, -0.02),
            p(1.8, -0.02),
            p(-6.98, -2.0),
        ];
        let corners = vec![p(-7.0, 4.0), p(7.0, 4.0), p(7.0, -4.0), p(-7.0, -4.0), p(3.0, 0.0)];
        let poi = |name: &str, nominal: Point<Global>, viewpoint: Point<Global>| PointOfInterest {
            name: name.to_owned(),
            nominal,
            viewpoint: Pose::new(viewpoint.x, viewpoint.y, (nominal - viewpoint).angle()),
        };
        let points_of_interest = vec![
            poi("extinguisher", p(-3.0, 3.95), p(-3.0, 2.75)),
            poi("panel", p(0.5, 0.05), p(0.5, 1.25)),
            poi("rack", p(-3.0, -3.95), p(-3.0, -2.75)),
            poi("exit door", p(6.95, -1.2), p(5.75, -1.2)),
        ];
        let w = |x: f64, y: f64, inspect: Option<usize>| Waypoint { position: p(x, y), inspect };
        let beats = vec![
            vec![
                w(-5.5, 1.6, None),
                w(-3.0, 1.6, Some(0)),
                w(0.5, 1.8, Some(1)),
                w(5.0, 1.6, None),
                w(5.0, 3.0, None),
                w(-5.5, 3.0, None),
            ],
            vec![
                w(-5.5, -1.6, None),
                w(-3.0, -1.6, Some(2)),
                w(1.0, -1.6, None),
                w(5.0, -1.2, Some(3)),
                w(5.0, -3.0, None),
                w(-5.5, -3.0, None),
            ],
        ];
        let junctions = vec![p(5.0, 0.0), p(4.5, 1.0), p(4.5, -1.0)];
        let bounds = Region { min_x: -7.0, max_x: 7.0, min_y: -4.0, max_y: 4.0 };
        FloorPlan::new(bounds, walls, markers, corners, points_of_interest, beats, junctions, 0.3)
    }

    #[allow(clippy::too_many_arguments)]
    pub fn new(
        bounds: Region,
        walls: Vec<Segment<Global>>,
        markers: Vec<Point<Global>>,
        corners: Vec<Point<Global>>,
        points_of_interest: Vec<PointOfInterest>,
        beats: Vec<Vec<Waypoint>>,
        junctions: Vec<Point<Global>>,
        clearance: f64,
    ) -> FloorPlan {
        let mut plan = FloorPlan {
            bounds,
            walls,
            markers,
            corners,
            points_of_interest,
            beats,
            junctions,
            clearance,
            nodes: Vec::new(),
            edges: Vec::new(),
        };
        // The roadmap: every waypoint, viewpoint and junction, joined where the straight line
        // keeps clear of the walls. Built once; queries add only their two ends.
        let mut nodes: Vec<Point<Global>> =
            plan.beats.iter().flatten().map(|w| w.position).collect();
        nodes.extend(plan.points_of_interest.iter().map(|p| p.viewpoint.position()));
        nodes.extend(plan.junctions.iter().copied());
        let edges = (0..nodes.len())
            .map(|i| {
                (0..nodes.len())
                    .filter(|&j| j != i && plan.clear(nodes[i], nodes[j], clearance))
                    .map(|j| (j, nodes[i].distance(nodes[j])))
                    .collect()
            })
            .collect();
        plan.nodes = nodes;
        plan.edges = edges;
        plan
    }

    /// Distance from a point to the nearest wall.
    pub fn wall_distance(&self, point: Point<Global>) -> f64 {
        self.walls.iter().map(|w| w.distance_to(point)).fold(f64::INFINITY, f64::min)
    }

    /// Whether a camera at `from` sees `to`: no wall in between. A feature on a wall (a marker,
    /// a corner) touches its own wall, so a crossing within 5 mm of the target does not count;
    /// a marker 2 cm in front of its wall is still hidden from the wall's other side.
    pub fn line_of_sight(&self, from: Point<Global>, to: Point<Global>) -> bool {
        let ray = Segment::new(from, to);
        let length = ray.length();
        self.walls
            .iter()
            .all(|w| ray.intersection(w).is_none_or(|x| from.distance(x) > length - 0.005))
    }

    /// Whether walking straight from `a` to `b` keeps `clearance` from every wall.
    pub fn clear(&self, a: Point<Global>, b: Point<Global>, clearance: f64) -> bool {
        let path = Segment::new(a, b);
        self.walls.iter().all(|w| {
            let distance = if path.intersection(w).is_some() {
                0.0
            } else {
                [
                    w.distance_to(a),
                    w.distance_to(b),
                    path.distance_to(w.start),
                    path.distance_to(w.end),
                ]
                .into_iter()
                .fold(f64::INFINITY, f64::min)
            };
            distance >= clearance
        })
    }

    /// The shortest path on the roadmap from `from` to `to`: the points to walk through, `to`
    /// last (empty if `from` is `to`). `None` when the roadmap does not connect them.
    pub fn route(&self, from: Point<Global>, to: Point<Global>) -> Option<Vec<Point<Global>>> {
        // A robot that ended up close to a wall (a fall, a bump) may leave it at less than the
        // usual clearance: the first and last legs accept what the ends allow.
        let end_clearance =
            |q: Point<Global>| self.clearance.min((self.wall_distance(q) - 0.05).max(0.0));
        let (cf, ct) = (end_clearance(from), end_clearance(to));
        if self.clear(from, to, cf.min(ct)) {
            return Some(vec![to]);
        }
        let n = self.nodes.len();
        let (start, goal) = (n, n + 1);
        let mut distance = vec![f64::INFINITY; n + 2];
        let mut previous = vec![usize::MAX; n + 2];
        let mut done = vec![false; n + 2];
        distance[start] = 0.0;
        // Dijkstra on a couple of dozen nodes: a linear scan beats a heap here.
        loop {
            let u = (0..n + 2)
                .filter(|&i| !done[i] && distance[i].is_finite())
                .min_by(|&a, &b| distance[a].total_cmp(&distance[b]))?;
            if u == goal {
                break;
            }
            done[u] = true;
            let here = if u == start { from } else { self.nodes[u] };
            let mut relax = |v: usize, length: f64| {
                if distance[u] + length < distance[v] {
                    distance[v] = distance[u] + length;
                    previous[v] = u;
                }
            };
            if u == start {
                for (v, node) in self.nodes.iter().enumerate() {
                    if self.clear(from, *node, cf) {
                        relax(v, from.distance(*node));
                    }
                }
            } else {
                for &(v, length) in &self.edges[u] {
                    relax(v, length);
                }
                if self.clear(here, to, ct) {
                    relax(goal, here.distance(to));
                }
            }
        }
        let mut path = vec![to];
        let mut at = previous[goal];
        while at != start {
            path.push(self.nodes[at]);
            at = previous[at];
        }
        path.reverse();
        Some(path)
    }

    /// Length of the shortest roadmap path (infinite if there is none).
    pub fn path_length(&self, from: Point<Global>, to: Point<Global>) -> f64 {
        match self.route(from, to) {
            Some(path) => {
                let mut length = 0.0;
                let mut at = from;
                for q in path {
                    length += at.distance(q);
                    at = q;
                }
                length
            }
            None => f64::INFINITY,
        }
    }

    /// The beat of a player (players are numbered from 1); players beyond the beats share
    /// them in turn.
    pub fn beat(&self, player: u8) -> &[Waypoint] {
        let index = usize::from(player.max(1) - 1) % self.beats.len().max(1);
        &self.beats[index]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dividing_wall_blocks_sight_and_paths_go_around_it() {
        let plan = FloorPlan::office();
        assert!(!plan.line_of_sight(p(0.0, 2.0), p(0.0, -2.0)));
        assert!(plan.line_of_sight(p(5.0, 2.0), p(5.0, -2.0)));
        // A marker on a wall is seen from its own side only.
        assert!(plan.line_of_sight(p(-1.5, 2.0), p(-1.5, 0.02)));
        assert!(!plan.line_of_sight(p(-1.5, -2.0), p(-1.5, 0.02)));
        let path = plan.route(p(-5.0, 2.0), p(-5.0, -2.0)).expect("connected");
        assert!(path.iter().any(|q| q.x > 3.0), "goes round the east end: {path:?}");
        let direct = 4.0;
        assert!(plan.path_length(p(-5.0, 2.0), p(-5.0, -2.0)) > 4.0 * direct);
        assert_eq!(plan.route(p(-5.0, 2.0), p(-3.0, 2.0)), Some(vec![p(-3.0, 2.0)]));
    }

    #[test]
    fn every_stop_of_every_beat_is_reachable_from_the_previous_one() {
        let plan = FloorPlan::office();
        for beat in &plan.beats {
            for (i, w) in beat.iter().enumerate() {
                let next = beat[(i + 1) % beat.len()];
                assert!(plan.route(w.position, next.position).is_some());
                if let Some(k) = w.inspect {
                    let vp = plan.points_of_interest[k].viewpoint.position();
                    assert_eq!(plan.route(w.position, vp), Some(vec![vp]));
                    assert!(plan.line_of_sight(vp, plan.points_of_interest[k].nominal));
                }
            }
        }
    }
}
