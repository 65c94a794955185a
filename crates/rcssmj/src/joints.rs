//! The T1's 23 joints as rcssservermj names them: effectors (what the agent commands) and
//! perceptors (what it measures), in the order of the robot model and of Booster's deployment
//! configuration (head, left arm, right arm, waist, left leg, right leg).

/// Number of actuated joints.
pub const JOINT_COUNT: usize = 23;

/// A value per joint, in [`JOINTS`] order.
pub type JointArray<T> = [T; JOINT_COUNT];

/// One joint: its effector and perceptor names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Joint {
    /// In commands: `(he1 q dq kp kd tau)`.
    pub effector: &'static str,
    /// In the joint-state perceptor: `(HJ (n q_hj1) ...)`.
    pub perceptor: &'static str,
}

macro_rules! joints {
    ($( $effector:literal $perceptor:literal ),+ $(,)?) => {
        [$( Joint { effector: $effector, perceptor: $perceptor } ),+]
    };
}

/// Every joint, in the model's order.
pub const JOINTS: JointArray<Joint> = joints![
    "he1" "q_hj1", "he2" "q_hj2",
    "lae1" "q_laj1", "lae2" "q_laj2", "lae3" "q_laj3", "lae4" "q_laj4",
    "rae1" "q_raj1", "rae2" "q_raj2", "rae3" "q_raj3", "rae4" "q_raj4",
    "te1" "q_tj1",
    "lle1" "q_llj1", "lle2" "q_llj2", "lle3" "q_llj3", "lle4" "q_llj4", "lle5" "q_llj5", "lle6" "q_llj6",
    "rle1" "q_rlj1", "rle2" "q_rlj2", "rle3" "q_rlj3", "rle4" "q_rlj4", "rle5" "q_rlj5", "rle6" "q_rlj6",
];

/// Head yaw (left positive) and pitch (down positive).
pub const HEAD_YAW: usize = 0;
pub const HEAD_PITCH: usize = 1;
/// The first of the twelve leg joints (left hip pitch); the walking policy drives these.
pub const FIRST_LEG: usize = 11;
pub const LEG_COUNT: usize = 12;

/// The joint a perceptor name measures.
pub fn by_perceptor(name: &str) -> Option<usize> {
    JOINTS.iter().position(|j| j.perceptor == name)
}

/// Head joint ranges of the server's T1 model (`AAHead_yaw`, `Head_pitch`), rad.
pub const HEAD_YAW_LIMITS: (f64, f64) = (-1.57, 1.57);
pub const HEAD_PITCH_LIMITS: (f64, f64) = (-0.35, 1.22);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_legs_come_last() {
        for (i, a) in JOINTS.iter().enumerate() {
            assert_eq!(by_perceptor(a.perceptor), Some(i));
            assert!(JOINTS[i + 1..].iter().all(|b| b.effector != a.effector));
        }
        assert_eq!(JOINTS[FIRST_LEG].effector, "lle1");
        assert_eq!(FIRST_LEG + LEG_COUNT, JOINT_COUNT);
        assert_eq!(JOINTS[HEAD_PITCH].perceptor, "q_hj2");
    }
}
