//! Keyframed get-up motions of the T1: from the front (face down, `StandUp(0)`) and from the
//! back (face up, `StandUp(1)`), the order of [`strata_robot::control::primitives::StandUp`].
//!
//! A motion is a list of keyframes, each a set of joint targets reached after its duration
//! with its gains; between keyframes the targets move along a smooth (cosine) ramp, sampled
//! once per 20 ms cycle. The motions live in a data file (the shipped
//! `assets/t1/getup.toml`, or any file in its format) so they can be tuned without a build.
//!
//! Joints a keyframe leaves out keep the previous keyframe's target; the first keyframe
//! starts from the pose the robot lies in. A pair of joints may be named once without its
//! side (`hip_pitch`): both sides take the value, the right side mirrored (roll and yaw axes
//! change sign in the mirror, pitch axes do not).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::controller::JointCommand;
use crate::joints::{JOINT_COUNT, JointArray};
use crate::policy::{JOINT_NAMES, JointTarget};

const SHIPPED_TOML: &str = include_str!("../assets/t1/getup.toml");
const SHIPPED_ORIGIN: &str = "the shipped assets/t1/getup.toml";

/// Why a get-up file could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum GetUpError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{origin}: {source}")]
    Syntax {
        origin: String,
        #[source]
        source: Box<toml::de::Error>,
    },
    #[error("{origin}: `{field}` {reason}")]
    Value { origin: String, field: String, reason: String },
}

/// One keyframe as written in the file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Keyframe {
    /// Time to move from the previous keyframe's targets to these, s.
    pub duration: f64,
    /// Stiffness and damping during this keyframe, as a factor of each joint's walking gains
    /// (`t1.toml`); the server clamps each joint's torque to the model's limit.
    #[serde(default = "one")]
    pub gain: f64,
    /// Joint targets, rad, by joint name (`left_hip_pitch`) or pair name (`hip_pitch`).
    #[serde(default)]
    pub targets: BTreeMap<String, f64>,
    /// Feed-forward torques, N m, by joint or pair name; joints left out get none.
    #[serde(default)]
    pub torques: BTreeMap<String, f64>,
}

fn one() -> f64 {
    1.0
}

/// The file: one keyframe list per side, and when the end of a motion counts as upright.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GetUpFile {
    /// At the end of a motion the torso must be tilted less than this, rad, for the robot to
    /// count as standing; otherwise it is still fallen.
    pub upright_angle: f64,
    /// From the front (face down): `StandUp(0)`. Empty: not supported.
    #[serde(default)]
    pub front: Vec<Keyframe>,
    /// From the back (face up): `StandUp(1)`. Empty: not supported.
    #[serde(default)]
    pub back: Vec<Keyframe>,
}

/// A keyframe with its names resolved to joints.
#[derive(Clone, Debug, PartialEq)]
struct Frame {
    duration: f64,
    gain: f64,
    targets: JointArray<Option<f64>>,
    torques: JointArray<f64>,
}

/// One get-up motion, ready to run.
#[derive(Clone, Debug, PartialEq)]
pub struct GetUpMotion {
    frames: Vec<Frame>,
    duration: f64,
}

/// The T1's get-up motions, by stand-up sequence number.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct GetUpMotions {
    /// Index 0 from the front, 1 from the back; `None`: that side has no motion.
    motions: [Option<GetUpMotion>; 2],
    upright_angle: f64,
}

impl GetUpMotions {
    /// The motions shipped with the crate, tuned in rcssservermj.
    pub fn shipped() -> Result<Self, GetUpError> {
        Self::from_toml_str(SHIPPED_TOML, SHIPPED_ORIGIN)
    }

    /// Reads a file in the shipped `getup.toml` format.
    pub fn load(path: &Path) -> Result<Self, GetUpError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| GetUpError::Read { path: path.to_path_buf(), source })?;
        Self::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and checks a get-up file; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, GetUpError> {
        let file: GetUpFile = toml::from_str(text).map_err(|source| GetUpError::Syntax {
            origin: origin.to_owned(),
            source: Box::new(source),
        })?;
        Self::from_file(&file, origin)
    }

    /// Checks a parsed file: known joint names, finite numbers, positive durations and gains,
    /// targets within the joints' ranges.
    pub fn from_file(file: &GetUpFile, origin: &str) -> Result<Self, GetUpError> {
        let fail = |field: String, reason: String| GetUpError::Value {
            origin: origin.to_owned(),
            field,
            reason,
        };
        if !(file.upright_angle.is_finite() && file.upright_angle > 0.0) {
            return Err(fail("upright_angle".into(), "must be a finite angle above zero".into()));
        }
        let mut motions = [None, None];
        for (slot, (side, keyframes)) in
            motions.iter_mut().zip([("front", &file.front), ("back", &file.back)])
        {
            if keyframes.is_empty() {
                continue;
            }
            let mut frames = Vec::with_capacity(keyframes.len());
            for (i, keyframe) in keyframes.iter().enumerate() {
                let field = |name: &str| format!("{side}[{i}].{name}");
                if !(keyframe.duration.is_finite() && keyframe.duration >= 0.0) {
                    return Err(fail(field("duration"), "must be a finite time >= 0".into()));
                }
                if !(keyframe.gain.is_finite() && keyframe.gain > 0.0) {
                    return Err(fail(field("gain"), "must be a finite factor above zero".into()));
                }
                let mut targets = [None; JOINT_COUNT];
                for (name, &value) in &keyframe.targets {
                    for (joint, q) in resolve(name, value)
                        .ok_or_else(|| fail(field("targets"), unknown_joint(name)))?
                    {
                        let (low, high) = JOINT_RANGES[joint];
                        if !(q.is_finite() && (low..=high).contains(&q)) {
                            return Err(fail(
                                field(&format!("targets.{name}")),
                                format!(
                                    "is {q} for {}, outside [{low}, {high}]",
                                    JOINT_NAMES[joint]
                                ),
                            ));
                        }
                        targets[joint] = Some(q);
                    }
                }
                let mut torques = [0.0; JOINT_COUNT];
                for (name, &value) in &keyframe.torques {
                    for (joint, tau) in resolve(name, value)
                        .ok_or_else(|| fail(field("torques"), unknown_joint(name)))?
                    {
                        if !tau.is_finite() {
                            return Err(fail(
                                field(&format!("torques.{name}")),
                                "must be finite".into(),
                            ));
                        }
                        torques[joint] = tau;
                    }
                }
                frames.push(Frame {
                    duration: keyframe.duration,
                    gain: keyframe.gain,
                    targets,
                    torques,
                });
            }
            let duration = frames.iter().map(|f| f.duration).sum();
            if duration <= 0.0 {
                return Err(fail(side.into(), "lasts no time: give a keyframe a duration".into()));
            }
            *slot = Some(GetUpMotion { frames, duration });
        }
        Ok(GetUpMotions { motions, upright_angle: file.upright_angle })
    }

    /// The motion of stand-up sequence `sequence` (0 front, 1 back), if this body has it.
    pub fn motion(&self, sequence: u8) -> Option<&GetUpMotion> {
        self.motions.get(usize::from(sequence)).and_then(Option::as_ref)
    }

    /// The largest torso tilt, rad, that counts as upright at the end of a motion.
    pub fn upright_angle(&self) -> f64 {
        self.upright_angle
    }
}

impl GetUpMotion {
    /// The whole motion, s.
    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// Every joint's command `elapsed` seconds into the motion, which started with the joints
    /// at `start`; `gains` are each joint's walking gains (the keyframes scale them). Past
    /// the end, the last keyframe holds.
    pub fn commands(
        &self,
        elapsed: f64,
        start: &JointArray<f64>,
        gains: &JointArray<JointTarget>,
    ) -> JointArray<JointCommand> {
        let mut from = *start;
        let mut begin = 0.0;
        for (i, frame) in self.frames.iter().enumerate() {
            let to: JointArray<f64> = std::array::from_fn(|j| frame.targets[j].unwrap_or(from[j]));
            let end = begin + frame.duration;
            if elapsed < end || i + 1 == self.frames.len() {
                let s = if frame.duration > 0.0 {
                    ((elapsed - begin) / frame.duration).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                // A cosine ramp: no velocity step at either keyframe.
                let w = 0.5 - 0.5 * (std::f64::consts::PI * s).cos();
                return std::array::from_fn(|j| JointCommand {
                    q: from[j] + w * (to[j] - from[j]),
                    dq: 0.0,
                    kp: frame.gain * gains[j].kp,
                    kd: frame.gain * gains[j].kd,
                    tau: frame.torques[j],
                });
            }
            from = to;
            begin = end;
        }
        // No frames: a motion is never built without one.
        gains.map(|g| JointCommand { q: g.q, dq: 0.0, kp: g.kp, kd: g.kd, tau: 0.0 })
    }
}

fn unknown_joint(name: &str) -> String {
    format!(
        "names `{name}`, not a T1 joint (one of {}, or a pair without `left_`/`right_`)",
        JOINT_NAMES.join(", ")
    )
}

/// The joints `name` sets and their values: one joint by its name, or both sides of a pair by
/// the name without its side, the right side mirrored.
fn resolve(name: &str, value: f64) -> Option<Vec<(usize, f64)>> {
    if let Some(joint) = JOINT_NAMES.iter().position(|n| *n == name) {
        return Some(vec![(joint, value)]);
    }
    let left = JOINT_NAMES.iter().position(|n| n.strip_prefix("left_") == Some(name))?;
    let right = JOINT_NAMES.iter().position(|n| n.strip_prefix("right_") == Some(name))?;
    let mirrored = if name.ends_with("_pitch") { value } else { -value };
    Some(vec![(left, value), (right, mirrored)])
}

/// Each joint's range in the server's T1 model (rcsssmj 0.2.1 `robots/T1/robot.xml`), rad.
const JOINT_RANGES: JointArray<(f64, f64)> = [
    (-1.57, 1.57),
    (-0.35, 1.22),
    (-3.31, 1.22),
    (-1.74, 1.57),
    (-2.27, 2.27),
    (-2.44, 0.0),
    (-3.31, 1.22),
    (-1.57, 1.74),
    (-2.27, 2.27),
    (0.0, 2.44),
    (-1.57, 1.57),
    (-1.8, 1.57),
    (-0.2, 1.57),
    (-1.0, 1.0),
    (0.0, 2.34),
    (-0.87, 0.35),
    (-0.44, 0.44),
    (-1.8, 1.57),
    (-1.57, 0.2),
    (-1.0, 1.0),
    (0.0, 2.34),
    (-0.87, 0.35),
    (-0.44, 0.44),
];

#[cfg(test)]
mod tests {
    use super::*;

    fn gains() -> JointArray<JointTarget> {
        [JointTarget { q: 0.0, kp: 100.0, kd: 2.0 }; JOINT_COUNT]
    }

    fn parse(text: &str) -> Result<GetUpMotions, GetUpError> {
        GetUpMotions::from_toml_str(text, "test.toml")
    }

    #[test]
    fn the_shipped_file_loads() -> Result<(), GetUpError> {
        let motions = GetUpMotions::shipped()?;
        assert!(motions.motion(0).is_some() || motions.motion(1).is_some());
        Ok(())
    }

    #[test]
    fn keyframes_ramp_from_the_start_pose_and_hold_left_out_joints() -> Result<(), GetUpError> {
        let motions = parse(
            "upright_angle = 0.5\n\
             [[front]]\nduration = 1.0\ngain = 2.0\ntargets = { knee_pitch = 1.0 }\n\
             [[front]]\nduration = 0.5\ntargets = { left_hip_pitch = -1.0, ankle_roll = 0.2 }\n\
             torques = { knee_pitch = 5.0 }\n",
        )?;
        assert!(motions.motion(1).is_none(), "no back motion in the file");
        let front = motions.motion(0).expect("a front motion");
        assert_eq!(front.duration(), 1.5);
        let start = [0.2; JOINT_COUNT];
        let knee = JOINT_NAMES.iter().position(|n| *n == "left_knee_pitch").expect("knee");
        let right_knee = JOINT_NAMES.iter().position(|n| *n == "right_knee_pitch").expect("knee");
        let hip = JOINT_NAMES.iter().position(|n| *n == "left_hip_pitch").expect("hip");
        let left_roll = JOINT_NAMES.iter().position(|n| *n == "left_ankle_roll").expect("roll");
        let right_roll = JOINT_NAMES.iter().position(|n| *n == "right_ankle_roll").expect("roll");

        let at_start = front.commands(0.0, &start, &gains());
        assert_eq!(at_start[knee].q, 0.2);
        assert_eq!((at_start[knee].kp, at_start[knee].kd), (200.0, 4.0));
        let halfway = front.commands(0.5, &start, &gains());
        assert!((halfway[knee].q - 0.6).abs() < 1e-12 && halfway[right_knee].q == halfway[knee].q);
        let first_done = front.commands(1.0, &start, &gains());
        assert!((first_done[knee].q - 1.0).abs() < 1e-12);
        assert_eq!(first_done[hip].q, 0.2, "a joint no keyframe named holds its start");

        let end = front.commands(9.0, &start, &gains());
        assert_eq!(end[knee].q, 1.0, "the knee holds the first keyframe's target");
        assert_eq!((end[hip].q, end[hip].kp, end[knee].tau), (-1.0, 100.0, 5.0));
        assert_eq!((end[left_roll].q, end[right_roll].q), (0.2, -0.2), "pairs are mirrored");
        assert_eq!(end[hip].tau, 0.0);
        Ok(())
    }

    #[test]
    fn errors_name_the_file_and_the_field() {
        let cases = [
            (
                "upright_angle = 0.5\n[[back]]\nduration = 1.0\ntargets = { elbow = 1.0 }",
                "back[0].targets",
            ),
            ("upright_angle = 0.5\n[[front]]\nduration = -1.0", "front[0].duration"),
            ("upright_angle = 0.5\n[[front]]\nduration = 1.0\ngain = 0.0", "front[0].gain"),
            (
                "upright_angle = 0.5\n[[front]]\nduration = 1\n[[front]]\nduration = 1\ntargets = { knee_pitch = 3.0 }",
                "front[1].targets.knee_pitch",
            ),
            ("upright_angle = 0.0", "upright_angle"),
            ("upright_angle = 0.5\n[[front]]\nduration = 0.0", "front"),
        ];
        for (text, field) in cases {
            let error = parse(text).expect_err(text).to_string();
            assert!(error.starts_with("test.toml: "), "{error}");
            assert!(error.contains(&format!("`{field}`")), "{field}: {error}");
        }
        let error = parse("upright_angle = 0.5\n[[front]]\nduraton = 1.0").expect_err("typo");
        assert!(error.to_string().contains("duraton"), "{error}");
        let missing = GetUpMotions::load(Path::new("/nonexistent/getup.toml")).expect_err("none");
        assert!(missing.to_string().contains("/nonexistent/getup.toml"), "{missing}");
    }
}
