//! The world state world modeling publishes (paper 3.6: the relevant variables the robot decides
//! with): the robot's pose, every object of interest with its uncertainty and confidence, the
//! map accuracy, the odometry error and the team's fused objects.

use nalgebra::{Matrix2, Matrix3};
use serde::{Deserialize, Serialize};
use strata_runtime::{Shared, Time};

use super::config::{CameraNoise, FieldLinesConfig};
use super::team::{SharedObject, TeamObject, TeammateEstimate};
use crate::geometry::{Global, Odometry, Point, Pose, Robot, Vector};
use crate::platform::ObjectClass;

/// Stable index of an object filter: its position in [`WorldState::objects`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ObjectId(pub u16);

impl ObjectId {
    pub fn index(self) -> usize {
        usize::from(self.0)
    }
}

/// What kind of object of interest an estimate belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectCategory {
    Landmark,
    Mobile,
    Obstacle,
}

/// The name of an object of interest, interned: every name with the same text is the same
/// `&'static str`. A world state is published tens of times a second with every object's name
/// (twice: instance and group), and read by several layers; copying an interned name copies a
/// pointer, where a shared (reference-counted) name paid an atomic increment and decrement per
/// copy. Equal names are the same pointer, so comparing two names is one comparison.
///
/// Names come from world-model layouts and from logs read back: a few hundred distinct texts in
/// a process, each kept for its whole life (see [`ObjectName::new`]). Compares with `&str` and
/// `String` like a string does.
#[derive(Clone, Debug, Eq, PartialOrd, Ord)]
pub struct ObjectName(&'static str);

impl ObjectName {
    /// The name with this text. The first use of a text stores it for the rest of the process:
    /// names are a small fixed vocabulary (a layout's objects), not data that grows.
    pub fn new(name: &str) -> ObjectName {
        static NAMES: std::sync::LazyLock<
            std::sync::Mutex<std::collections::HashSet<&'static str>>,
        > = std::sync::LazyLock::new(Default::default);
        // A panic elsewhere while the set was locked leaves it consistent (insertion is the only
        // change), so a poisoned lock is still usable.
        let mut names = NAMES.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(&interned) = names.get(name) {
            return ObjectName(interned);
        }
        let interned: &'static str = Box::leak(Box::from(name));
        names.insert(interned);
        ObjectName(interned)
    }

    pub fn as_str(&self) -> &'static str {
        self.0
    }
}

/// Interned: the same text is the same pointer (and a pointer holds one text).
impl PartialEq for ObjectName {
    fn eq(&self, other: &ObjectName) -> bool {
        std::ptr::eq(self.0, other.0)
    }
}

/// By the text, as `str` hashes (maps keyed by names are looked up with `&str`).
impl std::hash::Hash for ObjectName {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.0.hash(state);
    }
}

impl Serialize for ObjectName {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.0)
    }
}

impl<'de> Deserialize<'de> for ObjectName {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<ObjectName, D::Error> {
        let text = std::borrow::Cow::<'de, str>::deserialize(deserializer)?;
        Ok(ObjectName::new(&text))
    }
}

impl std::ops::Deref for ObjectName {
    type Target = str;
    fn deref(&self) -> &str {
        self.0
    }
}

impl std::fmt::Display for ObjectName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0)
    }
}

impl std::borrow::Borrow<str> for ObjectName {
    fn borrow(&self) -> &str {
        self.0
    }
}

impl From<&str> for ObjectName {
    fn from(name: &str) -> ObjectName {
        ObjectName::new(name)
    }
}

impl From<String> for ObjectName {
    fn from(name: String) -> ObjectName {
        ObjectName::new(&name)
    }
}

impl From<ObjectName> for String {
    fn from(name: ObjectName) -> String {
        name.0.to_owned()
    }
}

impl PartialEq<str> for ObjectName {
    fn eq(&self, other: &str) -> bool {
        self.0 == other
    }
}

impl PartialEq<&str> for ObjectName {
    fn eq(&self, other: &&str) -> bool {
        self.0 == *other
    }
}

impl PartialEq<String> for ObjectName {
    fn eq(&self, other: &String) -> bool {
        self.0 == other.as_str()
    }
}

impl PartialEq<ObjectName> for str {
    fn eq(&self, other: &ObjectName) -> bool {
        self == other.0
    }
}

impl PartialEq<ObjectName> for &str {
    fn eq(&self, other: &ObjectName) -> bool {
        *self == other.0
    }
}

impl PartialEq<ObjectName> for String {
    fn eq(&self, other: &ObjectName) -> bool {
        self.as_str() == other.0
    }
}

/// String equality that looks at the first and last bytes before calling `memcmp`: object
/// names often have the same length and differ at one end ("l_crossing#3", "t_crossing#3",
/// "t_crossing#4").
fn same_text(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    a.len() == b.len() && a.first() == b.first() && a.last() == b.last() && a == b
}

/// A multiply-rotate hash over eight bytes at a time (as rustc's FxHash): object names are
/// short, and a name lookup runs several times per reactive cycle; SipHash, or hashing byte
/// by byte, would cost as much as the scan the index replaces.
#[derive(Clone, Copy, Debug, Default)]
struct NameHasher(u64);

impl NameHasher {
    fn add(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

impl std::hash::Hasher for NameHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        let mut words = bytes.chunks_exact(8);
        for word in &mut words {
            let mut w = [0u8; 8];
            w.copy_from_slice(word);
            self.add(u64::from_le_bytes(w));
        }
        let rest = words.remainder();
        if !rest.is_empty() {
            let mut w = [0u8; 8];
            w[..rest.len()].copy_from_slice(rest);
            self.add(u64::from_le_bytes(w));
        }
    }

    fn write_u8(&mut self, byte: u8) {
        self.add(u64::from(byte));
    }
}

/// Where each object of a world model's layout sits in [`WorldState::objects`], by name. The
/// layout is fixed when the model is built, so the index is made once and shared by every
/// published state; it only speeds up [`WorldState::object`], which checks each answer
/// against the objects themselves and falls back to scanning them.
#[derive(Clone, Debug, Default)]
pub struct ObjectIndex(
    std::sync::Arc<
        std::collections::HashMap<ObjectName, ObjectId, std::hash::BuildHasherDefault<NameHasher>>,
    >,
    /// How many objects the layout has.
    usize,
);

impl ObjectIndex {
    /// The index of `names` in order; a name that appears twice keeps its first position, as
    /// a scan would find it.
    pub fn new<'a>(names: impl IntoIterator<Item = &'a ObjectName>) -> ObjectIndex {
        let mut map = std::collections::HashMap::default();
        let mut count = 0;
        for (i, name) in names.into_iter().enumerate() {
            count = i + 1;
            let Ok(i) = u16::try_from(i) else { continue };
            map.entry(name.clone()).or_insert(ObjectId(i));
        }
        ObjectIndex(std::sync::Arc::new(map), count)
    }

    /// The object named `name` if `objects` is the layout the index was built from: as long,
    /// and holding at the indexed position the very name (the same shared text) the index
    /// was built with. `None` means "scan": the name is unknown or the objects were replaced.
    fn find<'a>(&self, objects: &'a [ObjectEstimate], name: &str) -> Option<&'a ObjectEstimate> {
        if objects.len() != self.1 {
            return None;
        }
        let (indexed, id) = self.0.get_key_value(name)?;
        objects.get(id.index()).filter(|o| o.name == *indexed)
    }
}

/// Derived from the objects: two states with equal objects are equal whatever their indexes.
impl PartialEq for ObjectIndex {
    fn eq(&self, _: &ObjectIndex) -> bool {
        true
    }
}

/// The estimate of one object of interest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectEstimate {
    pub id: ObjectId,
    /// The object of interest's name; `name#k` for landmark instances and obstacle tracks.
    pub name: ObjectName,
    /// The object of interest's name without the instance suffix.
    pub group: ObjectName,
    pub class: ObjectClass,
    pub variant: Option<u16>,
    pub category: ObjectCategory,
    /// A filter follows the object (it was observed and not forgotten). An untracked landmark
    /// is reported where the map and the pose put it.
    pub tracked: bool,
    /// Tracked, and confident enough (`confidence >= unknown_threshold`).
    pub known: bool,
    pub position: Point<Robot>,
    /// Covariance of `position` (robot frame).
    pub covariance: Matrix2<f64>,
    pub global_position: Point<Global>,
    /// Covariance of `global_position`, including the pose's uncertainty.
    pub global_covariance: Matrix2<f64>,
    /// Mobile objects and obstacles.
    pub velocity: Option<Vector<Robot>>,
    pub velocity_covariance: Option<Matrix2<f64>>,
    pub global_velocity: Option<Vector<Global>>,
    /// In [0, 1]; see `docs/world-model.md`.
    pub confidence: f64,
    pub last_seen: Option<Time>,
    /// Landmarks: the known position of this instance.
    pub map_position: Option<Point<Global>>,
}

/// Why the pose is lost.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LostReason {
    /// No initial pose was given and the landmarks have not fixed it yet.
    Uninitialized,
    /// The uncertainty grew beyond the configured limits (no landmarks for a long time).
    Uncertain,
    /// The landmarks persistently disagree with the pose, or the robot was carried.
    Kidnapped,
    /// The application asked for it.
    Reset,
}

/// The robot-pose estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseEstimate {
    pub pose: Pose,
    /// Covariance of (x, y, theta).
    pub covariance: Matrix3<f64>,
    /// In [0, 1]; zero when lost.
    pub confidence: f64,
    pub lost: bool,
    pub lost_reason: Option<LostReason>,
    /// When the pose was last corrected by a landmark.
    pub last_correction: Option<Time>,
}

/// Distance between the estimated landmark map (the landmark filters placed on the field with
/// the estimated pose) and the known one: a global measure of localization accuracy (3.1).
/// Only the landmarks observed recently take part (`pose.map_accuracy_max_age`): a landmark
/// unseen for long is uncertain because of odometry alone.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapAccuracy {
    /// Mean distance over the known landmark instances, m.
    pub mean_error: f64,
    pub rms_error: f64,
    pub max_error: f64,
    /// How many landmark instances took part.
    pub landmarks: usize,
}

/// What the landmarks say about the odometry's error (estimated even when the pose is lost:
/// it only needs the landmarks' positions relative to the robot).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OdometryErrorEstimate {
    /// The motion the odometry missed in the last frame whose landmark observations determine
    /// it (landmarks at two places at least), in the robot frame (true motion = reported
    /// motion followed by this); zero, with a zero covariance, until such a frame.
    pub last_correction: Odometry,
    pub last_correction_covariance: Matrix3<f64>,
    /// Estimated relative error of the odometry's (dx, dy, dtheta): true = (1 + e) * reported.
    pub relative_error: [f64; 3],
    pub relative_error_sigma: [f64; 3],
    /// Frames that contributed.
    pub samples: u64,
    /// Whether incoming odometry is corrected with `relative_error`.
    pub applied: bool,
}

/// Counters of what world modeling did with its input, since it started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct WorldDiagnostics {
    pub frames: u64,
    pub observations: u64,
    /// Observations that corrected (or started) a filter.
    pub associated: u64,
    /// Observations outside every gate (outliers, false positives, moved objects).
    pub rejected: u64,
    /// Observations that fit several instances equally well.
    pub ambiguous: u64,
    /// Observations of classes that are no object of interest, or with invalid numbers.
    pub ignored: u64,
    /// Tracks started again from consistent rejected observations.
    pub reinitialized: u64,
    /// Landmark estimates the pose filter rejected.
    pub pose_rejections: u64,
    /// Field-line observations that corrected the pose (also counted in `associated`): none
    /// while the robot's perception reports no lines or the model is configured without them.
    #[serde(default)]
    pub line_corrections: u64,
    /// Landmark instances relabelled to another map instance.
    pub relabels: u64,
    pub kidnaps: u64,
    pub recoveries: u64,
    /// Teammate messages refused as malformed.
    pub team_rejected: u64,
}

/// An object of interest as the world model's configuration lays it out: what every
/// publication says of it the same way.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectInfo {
    /// `name#k` for landmark instances and obstacle tracks.
    pub name: ObjectName,
    /// The object of interest's name without the instance suffix.
    pub group: ObjectName,
    pub class: ObjectClass,
    pub variant: Option<u16>,
    pub category: ObjectCategory,
    /// Landmarks: the known position of this instance.
    pub map_position: Option<Point<Global>>,
}

/// What every world state of one world model shares: its objects of interest, in the order of
/// [`WorldState::objects`], and the parameters its readers use. Fixed when the model is built,
/// so a log stores it once ([`Shared`]) and every world state refers to it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WorldLayout {
    pub objects: Vec<ObjectInfo>,
    /// The camera model, for predicted observations (active vision).
    pub camera: CameraNoise,
    /// Detection probability of an object inside the view, for predicted observations.
    pub detection_probability: f64,
    /// Angular margin inside the view cone edges, rad.
    pub view_margin: f64,
    /// Confidence from which a tracked object is known.
    pub unknown_threshold: f64,
    /// The map's lines and how the model fuses them, for predicted line observations (active
    /// vision); no class: the model does not fuse lines. Logs written before it have none.
    #[serde(default)]
    pub lines: FieldLinesConfig,
    /// The objects by name, made once per layout.
    #[serde(skip)]
    index: std::sync::OnceLock<ObjectIndex>,
}

impl WorldLayout {
    pub fn new(
        objects: Vec<ObjectInfo>,
        camera: CameraNoise,
        detection_probability: f64,
        view_margin: f64,
        unknown_threshold: f64,
    ) -> WorldLayout {
        WorldLayout {
            objects,
            camera,
            detection_probability,
            view_margin,
            unknown_threshold,
            lines: FieldLinesConfig::default(),
            index: std::sync::OnceLock::new(),
        }
    }

    /// The layout with the map's lines, for predicted line observations.
    pub fn with_lines(mut self, lines: FieldLinesConfig) -> WorldLayout {
        self.lines = lines;
        self
    }

    /// The objects by name.
    pub fn index(&self) -> &ObjectIndex {
        self.index.get_or_init(|| ObjectIndex::new(self.objects.iter().map(|o| &o.name)))
    }
}

/// The world state, published by the world-modeling module (Latest).
///
/// Serialized as what the world model decided — the pose, each object's confidence and filter
/// estimate — with a reference to its [`WorldLayout`]; what follows from those (field-frame
/// estimates, where untracked landmarks should be) is worked out again when a state is read
/// (`wire.rs`).
#[derive(Clone, Debug, PartialEq)]
pub struct WorldState {
    /// The measurement time of the newest percepts included.
    pub stamp: Time,
    pub pose: PoseEstimate,
    /// Indexed by [`ObjectId`].
    /// Shared: every reader of a world state gets the same list, not a copy of it.
    pub objects: std::sync::Arc<[ObjectEstimate]>,
    pub map_accuracy: Option<MapAccuracy>,
    pub odometry_error: OdometryErrorEstimate,
    /// Mobile objects fused with the teammates' estimates (MAWM).
    pub team: Vec<TeamObject>,
    /// The camera model, for predicted observations (active vision).
    pub camera: CameraNoise,
    /// Detection probability of an object inside the view, for predicted observations.
    pub detection_probability: f64,
    /// Angular margin inside the view cone edges, rad.
    pub view_margin: f64,
    pub unknown_threshold: f64,
    pub diagnostics: WorldDiagnostics,
    /// The layout of `objects` (names, classes, map positions) and the parameters above.
    pub layout: Shared<WorldLayout>,
    /// The pose filter's heading as filtered, where the pose is usable: untracked landmarks
    /// are predicted from it (it can differ from `pose.pose.theta`, normalized again, in the
    /// last bit).
    pub(crate) filter_heading: Option<f64>,
    /// Name lookups without scanning `objects` (the layout's).
    pub index: ObjectIndex,
}

impl WorldState {
    pub fn get(&self, id: ObjectId) -> Option<&ObjectEstimate> {
        self.objects.get(id.index())
    }

    /// The object (or instance, `name#k`) with this name.
    pub fn object(&self, name: &str) -> Option<&ObjectEstimate> {
        // The index answers for the layout it was built from: the object it names must carry
        // that very name (the same shared text), or the objects were replaced and only a scan
        // can tell.
        if let Some(o) = self.index.find(&self.objects, name) {
            return Some(o);
        }
        self.objects.iter().find(|o| same_text(&o.name, name))
    }

    /// The instances of one object of interest.
    pub fn group<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a ObjectEstimate> + 'a {
        // The instances of a group share one name: its text is compared once per group, not
        // once per instance.
        let mut last: Option<(*const u8, bool)> = None;
        self.objects.iter().filter(move |o| {
            let text = o.group.as_str().as_ptr();
            match last {
                Some((seen, matches)) if seen == text => matches,
                _ => {
                    let matches = same_text(&o.group, name);
                    last = Some((text, matches));
                    matches
                }
            }
        })
    }

    pub fn objects_of_class(&self, class: ObjectClass) -> impl Iterator<Item = &ObjectEstimate> {
        self.objects.iter().filter(move |o| o.class == class)
    }

    /// The known object of this class with the highest confidence.
    pub fn best_of_class(&self, class: ObjectClass) -> Option<&ObjectEstimate> {
        self.objects_of_class(class)
            .filter(|o| o.known)
            .max_by(|a, b| a.confidence.total_cmp(&b.confidence))
    }

    /// The team's fused estimate of a mobile object of interest, by name.
    pub fn team_object(&self, name: &str) -> Option<&TeamObject> {
        self.team.iter().find(|t| t.name == name)
    }

    /// The known mobile objects as this robot shares them with its teammates.
    pub fn to_shared(&self, member: u8) -> TeammateEstimate {
        let objects = self
            .objects
            .iter()
            .filter(|o| o.known && o.category == ObjectCategory::Mobile)
            .map(|o| SharedObject {
                class: o.class,
                variant: o.variant,
                position: o.global_position,
                velocity: o.global_velocity,
                covariance: o.global_covariance,
                confidence: o.confidence,
                age: o.last_seen.map_or(f64::INFINITY, |t| (self.stamp - t).as_secs_f64()),
            })
            .filter(|o| o.age.is_finite())
            .collect();
        TeammateEstimate {
            member,
            stamp: self.stamp,
            pose: self.pose.pose,
            pose_covariance: self.pose.covariance,
            pose_confidence: self.pose.confidence,
            objects,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_with_the_same_text_are_one_interned_name() {
        let made = ObjectName::new("goal_post#2");
        let from_string = ObjectName::from(String::from("goal_post#2"));
        assert_eq!(made, from_string);
        assert!(std::ptr::eq(made.as_str(), from_string.as_str()));
        assert_ne!(made, ObjectName::new("goal_post#3"));
        assert_eq!(made, "goal_post#2");
        assert_eq!(String::from(made.clone()), "goal_post#2");
    }

    #[test]
    fn a_name_read_back_from_json_is_the_interned_name() {
        let name = ObjectName::new("ball");
        let text = serde_json::to_string(&name).expect("a name serializes");
        assert_eq!(text, "\"ball\"");
        let read: ObjectName = serde_json::from_str(&text).expect("a name deserializes");
        assert!(std::ptr::eq(read.as_str(), name.as_str()));
    }

    #[test]
    fn maps_keyed_by_names_are_looked_up_with_text() {
        let mut ids = std::collections::HashMap::new();
        ids.insert(ObjectName::new("penalty_mark#1"), ObjectId(7));
        assert_eq!(ids.get("penalty_mark#1"), Some(&ObjectId(7)));
        let index = ObjectIndex::new([&ObjectName::new("ball"), &ObjectName::new("robot#1")]);
        assert_eq!(index.1, 2);
    }
}
