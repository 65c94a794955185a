//! Key-frame motions: joint targets at times, interpolated every LoLA cycle.
//!
//! Sequences are data (TOML under `crates/nao/motions/`, embedded in the binary) so a team can
//! tune them without touching code, and can replace them on the robot from a directory
//! ([`MotionLibrary::with_overrides`]). A file:
//!
//! ```toml
//! name = "stand_up_front"
//! description = "Lying on the belly: push up, tuck the legs, squat, stand."
//! # Optional: the catalogue entry this sequence answers: the kind of motion the robot orders
//! # (stand_up, fall, or one the application names: kick, dive) and its number; `head = false`
//! # for a kind of the application's that leaves the head to head orders (a kick does).
//! motion = { kind = "stand_up", sequence = 1 }
//!
//! [[frames]]
//! duration = 0.5          # seconds from the previous frame (or the pose at start) to this one
//! stiffness = 0.8         # for every joint this file moves, from this frame's start
//! interpolation = "smooth"  # or "linear"
//! stiffness_overrides = { LKneePitch = 1.0 }
//! [frames.joints]         # degrees; hands 0 (closed) .. 1 (open)
//! LShoulderPitch = 0
//! ```
//!
//! A joint a frame does not name keeps its previous target; the sequence moves the union of
//! the joints its frames name and leaves the others to whoever owns them (the head to head
//! orders, unless the sequence names the head joints).

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use strata_robot::platform::{MotionSpec, SpecialMotion};

use crate::joints::{JOINT_COUNT, Joint, JointArray};

/// Key-frame files that ship with the crate.
pub const BUILTIN_MOTIONS: [(&str, &str); 5] = [
    ("stand.toml", include_str!("../motions/stand.toml")),
    ("sit.toml", include_str!("../motions/sit.toml")),
    ("stand_up_front.toml", include_str!("../motions/stand_up_front.toml")),
    ("stand_up_back.toml", include_str!("../motions/stand_up_back.toml")),
    ("fall_protection.toml", include_str!("../motions/fall_protection.toml")),
];

/// The sequences the platform itself relies on.
pub const STAND: &str = "stand";
pub const SIT: &str = "sit";

/// Targets may exceed the documented limits by this much in a file (real robots differ a
/// little; the value is clamped when sent). More than this is a typo, e.g. radians for degrees.
const LIMIT_MARGIN: f64 = 5.0 * PI / 180.0;

/// Longest single frame accepted: a longer one is almost certainly a unit mistake (ms for s).
const MAX_FRAME_DURATION: f64 = 10.0;

#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    #[error("motion file {file}: {source}")]
    Toml { file: String, source: Box<toml::de::Error> },
    #[error("motion file {file}: {reason}")]
    Invalid { file: String, reason: String },
    #[error("motion file {file}, frame {frame}: {reason}")]
    Frame { file: String, frame: usize, reason: String },
    #[error("cannot read motion directory {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("the motion library has no \"{0}\" sequence, which the platform needs")]
    Required(&'static str),
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    Linear,
    /// Cosine ease-in/ease-out: zero joint velocity at every key frame, which is what keeps a
    /// key-frame motion from jerking the robot at frame boundaries.
    #[default]
    Smooth,
}

impl Interpolation {
    fn shape(self, t: f64) -> f64 {
        let t = t.clamp(0.0, 1.0);
        match self {
            Interpolation::Linear => t,
            Interpolation::Smooth => 0.5 - 0.5 * (PI * t).cos(),
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MotionFile {
    name: String,
    #[serde(default)]
    description: String,
    motion: Option<SpecialMotion>,
    frames: Vec<FrameFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameFile {
    duration: f64,
    stiffness: f64,
    #[serde(default)]
    interpolation: Interpolation,
    #[serde(default)]
    stiffness_overrides: BTreeMap<String, f64>,
    #[serde(default)]
    joints: BTreeMap<String, f64>,
}

/// One key frame, resolved: radians, one slot per joint.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyFrame {
    /// Seconds to reach this frame from the previous one.
    pub duration: f64,
    pub interpolation: Interpolation,
    /// Targets this frame names (rad; hands 0..1).
    pub targets: JointArray<Option<f64>>,
    /// Stiffness of every joint the sequence moves, from the start of this frame.
    pub stiffness: JointArray<f64>,
}

/// A parsed, validated sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyFrameSequence {
    pub name: String,
    pub description: String,
    /// The catalogue entry this sequence answers, if any.
    pub motion: Option<SpecialMotion>,
    /// The joints some frame names: the ones the sequence moves.
    pub joints: JointArray<bool>,
    pub frames: Vec<KeyFrame>,
}

impl KeyFrameSequence {
    /// Parses and validates a TOML key-frame file; `file` names it in errors.
    pub fn parse(file: &str, text: &str) -> Result<KeyFrameSequence, MotionError> {
        let parsed: MotionFile = toml::from_str(text).map_err(|source| MotionError::Toml {
            file: file.to_owned(),
            source: Box::new(source),
        })?;
        let invalid = |reason: String| MotionError::Invalid { file: file.to_owned(), reason };
        if parsed.name.trim().is_empty() {
            return Err(invalid("the name is empty".into()));
        }
        if parsed.frames.is_empty() {
            return Err(invalid("a sequence needs at least one frame".into()));
        }
        let motion = parsed.motion;
        let mut joints = [false; JOINT_COUNT];
        let mut frames = Vec::with_capacity(parsed.frames.len());
        for (index, frame) in parsed.frames.iter().enumerate() {
            let error =
                |reason: String| MotionError::Frame { file: file.to_owned(), frame: index, reason };
            if !(frame.duration.is_finite()
                && frame.duration > 0.0
                && frame.duration <= MAX_FRAME_DURATION)
            {
                return Err(error(format!(
                    "duration {} s is not in (0, {MAX_FRAME_DURATION}] s",
                    frame.duration
                )));
            }
            check_stiffness(frame.stiffness).map_err(|r| error(format!("stiffness {r}")))?;
            let mut targets = [None; JOINT_COUNT];
            for (name, value) in &frame.joints {
                let joint = Joint::from_name(name)
                    .ok_or_else(|| error(format!("unknown joint \"{name}\"")))?;
                let target = if joint.is_hand() { *value } else { value.to_radians() };
                let limits = joint.limits();
                let margin = if joint.is_hand() { 0.0 } else { LIMIT_MARGIN };
                if !target.is_finite() || !limits.contains(target, margin) {
                    let shown = if joint.is_hand() {
                        format!("{value} (hands take 0..1)")
                    } else {
                        format!(
                            "{value}° (limits {:.1}°..{:.1}°)",
                            limits.min.to_degrees(),
                            limits.max.to_degrees()
                        )
                    };
                    return Err(error(format!("{joint} = {shown} is out of range")));
                }
                targets[joint.index()] = Some(target);
                joints[joint.index()] = true;
            }
            let mut stiffness = [frame.stiffness; JOINT_COUNT];
            for (name, value) in &frame.stiffness_overrides {
                let joint = Joint::from_name(name).ok_or_else(|| {
                    error(format!("unknown joint \"{name}\" in stiffness_overrides"))
                })?;
                check_stiffness(*value).map_err(|r| error(format!("stiffness of {joint} {r}")))?;
                stiffness[joint.index()] = *value;
            }
            frames.push(KeyFrame {
                duration: frame.duration,
                interpolation: frame.interpolation,
                targets,
                stiffness,
            });
        }
        Ok(KeyFrameSequence {
            name: parsed.name,
            description: parsed.description,
            motion,
            joints,
            frames,
        })
    }

    /// Total duration, s.
    pub fn duration(&self) -> f64 {
        self.frames.iter().map(|f| f.duration).sum()
    }

    pub fn moves(&self, joint: Joint) -> bool {
        self.joints[joint.index()]
    }

    /// The pose the sequence ends in, for the joints it moves (others from `start`).
    pub fn final_pose(&self, start: &JointArray<f64>) -> JointArray<f64> {
        let mut pose = *start;
        for frame in &self.frames {
            for (slot, target) in pose.iter_mut().zip(frame.targets) {
                if let Some(target) = target {
                    *slot = target;
                }
            }
        }
        pose
    }
}

fn check_stiffness(value: f64) -> Result<(), String> {
    if value.is_finite() && (0.0..=1.0).contains(&value) {
        Ok(())
    } else {
        Err(format!("{value} is not in 0..1"))
    }
}

/// What a player commands for one cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlayerOutput {
    /// Targets for the joints the sequence moves (other slots hold the start pose).
    pub targets: JointArray<f64>,
    pub stiffness: JointArray<f64>,
    pub finished: bool,
}

/// Plays one sequence from a start pose, advanced by the LoLA cycle.
#[derive(Clone, Debug)]
pub struct Player {
    sequence: Arc<KeyFrameSequence>,
    /// Absolute targets at the end of each frame, index 0 being the start pose.
    poses: Vec<JointArray<f64>>,
    elapsed: f64,
    duration: f64,
}

impl Player {
    /// `start` is the pose the robot is in (measured, or the targets it holds).
    pub fn new(sequence: Arc<KeyFrameSequence>, start: JointArray<f64>) -> Player {
        let mut poses = Vec::with_capacity(sequence.frames.len() + 1);
        poses.push(start);
        let mut pose = start;
        for frame in &sequence.frames {
            for (slot, target) in pose.iter_mut().zip(frame.targets) {
                if let Some(target) = target {
                    *slot = target;
                }
            }
            poses.push(pose);
        }
        let duration = sequence.duration();
        Player { sequence, poses, elapsed: 0.0, duration }
    }

    pub fn sequence(&self) -> &Arc<KeyFrameSequence> {
        &self.sequence
    }

    pub fn elapsed(&self) -> f64 {
        self.elapsed
    }

    pub fn duration(&self) -> f64 {
        self.duration
    }

    pub fn finished(&self) -> bool {
        self.elapsed >= self.duration
    }

    /// Advances by `dt` seconds and returns the targets for the new instant.
    pub fn advance(&mut self, dt: f64) -> PlayerOutput {
        if dt.is_finite() && dt > 0.0 {
            self.elapsed = (self.elapsed + dt).min(self.duration);
            // Summing 12 ms steps in floating point lands a hair short of the end.
            if self.duration - self.elapsed < 1e-9 {
                self.elapsed = self.duration;
            }
        }
        self.sample(self.elapsed)
    }

    /// The command at `time` seconds into the sequence.
    pub fn sample(&self, time: f64) -> PlayerOutput {
        let frames = &self.sequence.frames;
        let mut frame_start = 0.0;
        for (index, frame) in frames.iter().enumerate() {
            let frame_end = frame_start + frame.duration;
            if time < frame_end || index + 1 == frames.len() {
                let t = frame.interpolation.shape((time - frame_start) / frame.duration);
                let from = &self.poses[index];
                let to = &self.poses[index + 1];
                let mut targets = [0.0; JOINT_COUNT];
                for (j, target) in targets.iter_mut().enumerate() {
                    *target = from[j] + (to[j] - from[j]) * t;
                }
                return PlayerOutput {
                    targets,
                    stiffness: frame.stiffness,
                    finished: time >= self.duration,
                };
            }
            frame_start = frame_end;
        }
        // A sequence always has a frame (checked when parsed).
        PlayerOutput { targets: self.poses[0], stiffness: [0.0; JOINT_COUNT], finished: true }
    }
}

/// The sequences a robot can play, by name.
#[derive(Clone, Debug)]
pub struct MotionLibrary {
    sequences: BTreeMap<String, Arc<KeyFrameSequence>>,
}

impl MotionLibrary {
    /// The sequences shipped with the crate.
    pub fn builtin() -> Result<MotionLibrary, MotionError> {
        let mut sequences = BTreeMap::new();
        for (file, text) in BUILTIN_MOTIONS {
            let sequence = KeyFrameSequence::parse(file, text)?;
            sequences.insert(sequence.name.clone(), Arc::new(sequence));
        }
        MotionLibrary::from_sequences(sequences)
    }

    /// The built-in sequences, with every `*.toml` in `dir` added or replacing the built-in of
    /// the same name (tuning on the robot without recompiling).
    pub fn with_overrides(dir: &Path) -> Result<MotionLibrary, MotionError> {
        let io = |source| MotionError::Io { path: dir.to_owned(), source };
        let mut library = MotionLibrary::builtin()?;
        let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(io)?
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        paths.sort();
        for path in paths {
            let text = std::fs::read_to_string(&path)
                .map_err(|source| MotionError::Io { path: path.clone(), source })?;
            let sequence = KeyFrameSequence::parse(&path.display().to_string(), &text)?;
            library.sequences.insert(sequence.name.clone(), Arc::new(sequence));
        }
        MotionLibrary::from_sequences(library.sequences)
    }

    fn from_sequences(
        sequences: BTreeMap<String, Arc<KeyFrameSequence>>,
    ) -> Result<MotionLibrary, MotionError> {
        for required in [STAND, SIT] {
            if !sequences.contains_key(required) {
                return Err(MotionError::Required(required));
            }
        }
        let mut owners: BTreeMap<String, &str> = BTreeMap::new();
        for sequence in sequences.values() {
            if let Some(motion) = sequence.motion
                && let Some(other) =
                    owners.insert(format!("{} {}", motion.kind, motion.sequence), &sequence.name)
            {
                return Err(MotionError::Invalid {
                    file: sequence.name.clone(),
                    reason: format!("{motion} is already played by \"{other}\""),
                });
            }
        }
        Ok(MotionLibrary { sequences })
    }

    pub fn get(&self, name: &str) -> Option<&Arc<KeyFrameSequence>> {
        self.sequences.get(name)
    }

    /// The sequence tagged with this catalogue entry (its kind and number).
    pub fn for_motion(&self, motion: SpecialMotion) -> Option<&Arc<KeyFrameSequence>> {
        self.sequences.values().find(|s| s.motion.is_some_and(|m| m.same_sequence(&motion)))
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.sequences.keys().map(String::as_str)
    }

    /// The catalogue entries of the tagged sequences, in catalogue order.
    pub fn catalogue(&self) -> Vec<MotionSpec> {
        let mut specs: Vec<MotionSpec> = self
            .sequences
            .values()
            .filter_map(|s| {
                s.motion.map(|motion| MotionSpec {
                    motion,
                    name: s.name.clone(),
                    duration: Duration::from_secs_f64(s.duration()),
                })
            })
            .collect();
        specs.sort_by(|a, b| {
            let key = |s: &MotionSpec| (s.motion.kind.as_str().to_owned(), s.motion.sequence);
            key(a).cmp(&key(b))
        });
        specs
    }
}

#[cfg(test)]
// A panic is how a test reports failure.
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn builtin_sequences_parse_and_stay_within_limits() {
        let library = MotionLibrary::builtin().unwrap();
        for name in ["stand", "sit", "stand_up_front", "stand_up_back", "fall_protection"] {
            let sequence = library.get(name).unwrap_or_else(|| panic!("{name} missing"));
            assert!(sequence.duration() > 0.0);
            for frame in &sequence.frames {
                for joint in Joint::ALL {
                    if let Some(t) = frame.targets[joint.index()] {
                        assert!(joint.limits().contains(t, LIMIT_MARGIN), "{name} {joint} {t}");
                    }
                }
            }
        }
        assert!(library.for_motion(SpecialMotion::stand_up(1)).is_some());
        assert!(library.for_motion(SpecialMotion::stand_up(2)).is_some());
        assert!(library.for_motion(SpecialMotion::fall(0)).is_some());
        assert!(library.for_motion(kick(0)).is_none());
    }

    #[test]
    fn stand_up_sequences_end_in_the_stand_pose() {
        let library = MotionLibrary::builtin().unwrap();
        let stand = library.get(STAND).unwrap().final_pose(&[0.0; JOINT_COUNT]);
        for name in ["stand_up_front", "stand_up_back"] {
            let end = library.get(name).unwrap().final_pose(&[0.0; JOINT_COUNT]);
            for joint in Joint::ALL.into_iter().filter(|j| !j.is_head()) {
                assert!((end[joint.index()] - stand[joint.index()]).abs() < 1e-9, "{name} {joint}");
            }
        }
    }

    const TWO_FRAMES: &str = r#"
        name = "test"
        motion = { kind = "kick", sequence = 3 }
        [[frames]]
        duration = 1.0
        stiffness = 0.5
        interpolation = "linear"
        joints = { LKneePitch = 90 }
        [[frames]]
        duration = 0.5
        stiffness = 0.9
        stiffness_overrides = { HeadYaw = 0.1 }
        joints = { LKneePitch = 0, HeadYaw = 10 }
    "#;

    /// A kick as soccer orders it: the body only.
    fn kick(sequence: u8) -> SpecialMotion {
        SpecialMotion::new(
            strata_robot::platform::MotionName::new("kick").unwrap(),
            sequence,
            false,
        )
    }

    #[test]
    fn player_interpolates_from_the_start_pose() {
        let sequence = Arc::new(KeyFrameSequence::parse("test.toml", TWO_FRAMES).unwrap());
        assert_eq!(sequence.motion, Some(kick(3)));
        assert!(sequence.moves(Joint::LKneePitch) && sequence.moves(Joint::HeadYaw));
        assert!(!sequence.moves(Joint::RKneePitch));
        let mut start = [0.0; JOINT_COUNT];
        start[Joint::LKneePitch.index()] = 0.5;
        start[Joint::HeadYaw.index()] = -0.2;
        let player = Player::new(sequence, start);
        let knee = Joint::LKneePitch.index();
        let head = Joint::HeadYaw.index();
        let halfway = player.sample(0.5);
        assert!((halfway.targets[knee] - (0.5 + (90f64.to_radians() - 0.5) / 2.0)).abs() < 1e-9);
        // The head is not named in frame 0, so it holds its start value there.
        assert_eq!(halfway.targets[head], -0.2);
        assert_eq!(halfway.stiffness[knee], 0.5);
        assert!(!halfway.finished);
        let second = player.sample(1.25);
        assert!((second.targets[knee] - 90f64.to_radians() / 2.0).abs() < 1e-9, "smooth midpoint");
        assert_eq!(second.stiffness[head], 0.1);
        assert_eq!(second.stiffness[knee], 0.9);
        let end = player.sample(10.0);
        assert!(end.finished);
        assert!((end.targets[head] - 10f64.to_radians()).abs() < 1e-12);
        assert_eq!(end.targets[knee], 0.0);
    }

    #[test]
    fn advance_reaches_the_end_exactly() {
        let sequence = Arc::new(KeyFrameSequence::parse("test.toml", TWO_FRAMES).unwrap());
        let mut player = Player::new(sequence, [0.0; JOINT_COUNT]);
        let mut cycles = 0;
        while !player.advance(0.012).finished {
            cycles += 1;
            assert!(cycles < 1000);
        }
        assert_eq!(player.elapsed(), player.duration());
        assert_eq!(cycles, 124);
    }

    fn error_of(text: &str) -> String {
        KeyFrameSequence::parse("bad.toml", text).unwrap_err().to_string()
    }

    #[test]
    fn bad_files_get_errors_that_point_at_the_problem() {
        let unknown = error_of(
            "name = \"x\"\n[[frames]]\nduration = 1.0\nstiffness = 0.5\njoints = { LKnee = 3 }",
        );
        assert_eq!(unknown, "motion file bad.toml, frame 0: unknown joint \"LKnee\"");
        let radians = error_of(
            "name = \"x\"\n[[frames]]\nduration = 1.0\nstiffness = 0.5\njoints = { LKneePitch = 150 }",
        );
        assert!(
            radians.contains("LKneePitch = 150° (limits -5.3°..121.0°) is out of range"),
            "{radians}"
        );
        let hand = error_of(
            "name = \"x\"\n[[frames]]\nduration = 1.0\nstiffness = 0.5\njoints = { LHand = 45 }",
        );
        assert!(hand.contains("hands take 0..1"), "{hand}");
        let duration =
            error_of("name = \"x\"\n[[frames]]\nduration = 0\nstiffness = 0.5\njoints = {}");
        assert!(duration.contains("frame 0: duration 0 s"), "{duration}");
        let stiffness =
            error_of("name = \"x\"\n[[frames]]\nduration = 1\nstiffness = 2\njoints = {}");
        assert!(stiffness.contains("stiffness 2 is not in 0..1"), "{stiffness}");
        let empty = error_of("name = \"x\"\nframes = []");
        assert!(empty.contains("at least one frame"), "{empty}");
        let typo = error_of("name = \"x\"\nframez = []");
        assert!(typo.starts_with("motion file bad.toml: "), "{typo}");
        let long =
            error_of(&TWO_FRAMES.replace("\"kick\"", "\"a kick with the left foot, forward\""));
        assert!(long.contains("a motion name has 1 to 31 bytes"), "{long}");
    }

    #[test]
    fn a_sequence_answers_a_kind_the_application_names_and_may_leave_the_head_free() {
        let text = TWO_FRAMES.replace("kind = \"kick\"", "kind = \"wave\", head = false");
        let sequence = KeyFrameSequence::parse("wave.toml", &text).unwrap();
        let wave = strata_robot::platform::MotionName::new("wave").unwrap();
        assert_eq!(sequence.motion, Some(SpecialMotion::new(wave, 3, false)));
    }

    #[test]
    fn overrides_replace_builtins_by_name() {
        let dir = std::env::temp_dir().join(format!("strata-nao-motions-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("stand.toml"),
            "name = \"stand\"\n[[frames]]\nduration = 2.0\nstiffness = 0.6\njoints = { LKneePitch = 40 }",
        )
        .unwrap();
        std::fs::write(dir.join("kick.toml"), TWO_FRAMES).unwrap();
        std::fs::write(dir.join("notes.txt"), "ignored").unwrap();
        let library = MotionLibrary::with_overrides(&dir).unwrap();
        assert_eq!(library.get(STAND).unwrap().duration(), 2.0);
        assert!(library.for_motion(kick(3)).is_some());
        assert!(library.catalogue().iter().any(|s| s.motion == kick(3)));
        std::fs::write(dir.join("z_clash.toml"), TWO_FRAMES.replace("\"test\"", "\"other\""))
            .unwrap();
        let clash = MotionLibrary::with_overrides(&dir).unwrap_err().to_string();
        assert!(clash.contains("already played by"), "{clash}");
        std::fs::remove_dir_all(&dir).unwrap();
        let missing = MotionLibrary::with_overrides(&dir).unwrap_err().to_string();
        assert!(missing.starts_with("cannot read motion directory"), "{missing}");
    }
}
