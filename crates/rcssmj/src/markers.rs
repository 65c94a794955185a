//! What the server's marker names are to a camera: the ball, goal posts, line crossings,
//! penalty marks and robots, in the object codes the soccer application and the world model
//! share ([`strata_spl::ObjectKind`]).
//!
//! The server names each marker uniquely (`g_lup`: the left goal's upper post); a real
//! detector cannot tell one corner from another, so only the kind is kept and the world model
//! associates detections with landmarks by position, as it does on every platform.

use strata_robot::platform::ObjectClass;
use strata_spl::ObjectKind;

use crate::camera::DetectorKind;

/// The class and detector of a world marker, or `None` for a name this platform does not
/// know (a newer server's marker is ignored, not an error) or does not trust.
pub fn classify(name: &str) -> Option<(ObjectClass, DetectorKind)> {
    if is_misplaced(name) {
        return None;
    }
    let kind = match name {
        "B" => return Some((class(ObjectKind::Ball), DetectorKind::Ball)),
        _ if name.starts_with("g_") => {
            return Some((class(ObjectKind::GoalPost), DetectorKind::GoalPost));
        }
        _ if name.starts_with("l_") => ObjectKind::LCrossing,
        _ if name.starts_with("t_") => ObjectKind::TCrossing,
        _ if name.starts_with("x_") => ObjectKind::XCrossing,
        _ if name.starts_with("p_") => ObjectKind::PenaltyMark,
        _ => return None,
    };
    Some((class(kind), DetectorKind::FieldFeature))
}

/// rcsssmj 0.2.1 puts the markers of its goal areas (`l_luga`, `t_llga`, ...) and penalty
/// areas (`l_lupa`, `t_rlpa`, ...) at the area's full width from the centre line instead of
/// half of it: y = +-7.3 m and +-16.5 m where its drawn lines meet at +-3.65 m and +-8.25 m.
/// No camera would see a crossing there, and taken for the real corners they shift the
/// robot's pose by 3.65 m (seen near the goal), so they are not detections.
fn is_misplaced(name: &str) -> bool {
    (name.starts_with("l_") || name.starts_with("t_"))
        && (name.ends_with("ga") || name.ends_with("pa"))
}

/// The class of a robot.
pub fn robot_class() -> ObjectClass {
    class(ObjectKind::Robot)
}

fn class(kind: ObjectKind) -> ObjectClass {
    ObjectClass(kind.code())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_servers_markers_map_to_object_kinds() {
        let code = |name| classify(name).map(|(c, _)| c.0);
        assert_eq!(code("B"), Some(ObjectKind::Ball.code()));
        assert_eq!(code("g_rlp"), Some(ObjectKind::GoalPost.code()));
        assert_eq!(code("l_luf"), Some(ObjectKind::LCrossing.code()));
        assert_eq!(code("t_cuf"), Some(ObjectKind::TCrossing.code()));
        assert_eq!(code("x_clc"), Some(ObjectKind::XCrossing.code()));
        assert_eq!(code("p_lpm"), Some(ObjectKind::PenaltyMark.code()));
        assert_eq!(code("flag"), None);
        for misplaced in ["l_lupa", "l_rlpa", "t_llpa", "t_rupa", "l_luga", "t_rlga"] {
            assert_eq!(code(misplaced), None, "{misplaced}");
        }
    }
}
