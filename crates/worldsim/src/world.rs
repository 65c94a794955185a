//! The world the bodies walk in: walls, which block sight and movement, and markers, which the
//! camera reports. A marker is anything a camera can recognise — a landmark on a wall, an object
//! on the floor, a person — and the application places, moves or removes it between steps.

use strata_robot::geometry::{Global, Point, Segment};
use strata_robot::platform::ObjectClass;

/// A marker on a wall touches its own wall: a wall crossed this close to the target does not
/// hide it (a marker 2 cm in front of its wall is still hidden from the wall's other side).
const ON_WALL: f64 = 0.005;

/// One thing the camera can report.
#[derive(Clone, Debug, PartialEq)]
pub struct Marker {
    /// The application's name for it (for lookups and messages; robots never see it).
    pub name: String,
    pub class: ObjectClass,
    /// What tells it apart from others of its class, if the camera can.
    pub variant: Option<u16>,
    /// Where it is; `None` while it is not in the world.
    pub position: Option<Point<Global>>,
}

impl Marker {
    /// A marker at `position`.
    pub fn at(
        name: impl Into<String>,
        class: ObjectClass,
        variant: Option<u16>,
        position: Point<Global>,
    ) -> Marker {
        Marker { name: name.into(), class, variant, position: Some(position) }
    }
}

/// A marker's place in the world (the order the application added them in).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MarkerId(pub usize);

/// Walls and markers.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct World {
    walls: Vec<Segment<Global>>,
    markers: Vec<Marker>,
}

impl World {
    pub fn new(walls: Vec<Segment<Global>>) -> World {
        World { walls, markers: Vec::new() }
    }

    pub fn walls(&self) -> &[Segment<Global>] {
        &self.walls
    }

    /// Adds a marker; the camera considers markers in the order they were added.
    pub fn add_marker(&mut self, marker: Marker) -> MarkerId {
        self.markers.push(marker);
        MarkerId(self.markers.len() - 1)
    }

    pub fn markers(&self) -> &[Marker] {
        &self.markers
    }

    pub fn marker(&self, id: MarkerId) -> Option<&Marker> {
        self.markers.get(id.0)
    }

    /// The first marker named `name`.
    pub fn marker_id(&self, name: &str) -> Option<MarkerId> {
        self.markers.iter().position(|m| m.name == name).map(MarkerId)
    }

    /// Moves a marker (`None` takes it out of the world); false if there is no such marker.
    pub fn place(&mut self, id: MarkerId, position: Option<Point<Global>>) -> bool {
        match self.markers.get_mut(id.0) {
            Some(marker) => {
                marker.position = position;
                true
            }
            None => false,
        }
    }

    /// Distance from a point to the nearest wall (infinite without walls).
    pub fn wall_distance(&self, point: Point<Global>) -> f64 {
        self.walls.iter().map(|w| w.distance_to(point)).fold(f64::INFINITY, f64::min)
    }

    /// Whether a camera at `from` sees `to`: no wall in between, a wall the target stands on
    /// excepted.
    pub fn line_of_sight(&self, from: Point<Global>, to: Point<Global>) -> bool {
        let ray = Segment::new(from, to);
        let length = ray.length();
        self.walls
            .iter()
            .all(|w| ray.intersection(w).is_none_or(|x| from.distance(x) > length - ON_WALL))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64) -> Point<Global> {
        Point::new(x, y)
    }

    #[test]
    fn a_wall_hides_what_is_behind_it_but_not_a_marker_on_its_near_side() {
        let world = World::new(vec![Segment::new(p(0.0, -1.0), p(0.0, 1.0))]);
        assert!(!world.line_of_sight(p(-1.0, 0.0), p(1.0, 0.0)));
        assert!(world.line_of_sight(p(-1.0, 0.0), p(-0.02, 0.0)));
        assert!(world.line_of_sight(p(-1.0, 0.0), p(0.0, 0.5)), "on the wall itself");
        assert!(!world.line_of_sight(p(1.0, 0.0), p(-0.02, 0.0)), "from the other side");
        assert!(world.line_of_sight(p(-1.0, 2.0), p(1.0, 2.0)), "past its end");
        assert!((world.wall_distance(p(0.5, 3.0)) - 4.25f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn markers_are_found_by_name_and_moved_in_and_out_of_the_world() {
        let mut world = World::default();
        let id = world.add_marker(Marker::at("door", ObjectClass(3), Some(1), p(1.0, 2.0)));
        assert_eq!(world.marker_id("door"), Some(id));
        assert!(world.place(id, None));
        assert_eq!(world.marker(id).and_then(|m| m.position), None);
        assert!(!world.place(MarkerId(7), None));
    }
}
