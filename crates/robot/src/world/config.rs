//! What the application tells world modeling: its objects of interest, the known map, and the
//! noise models and thresholds the filters use. Loadable with serde (TOML in practice); every
//! value is checked by [`WorldModelConfig::validate`] with an error naming the field.

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

use crate::geometry::{Global, Odometry, Point, Pose};
use crate::platform::ObjectClass;

/// A configuration value world modeling cannot work with.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("world model configuration: `{field}` {problem}")]
pub struct ConfigError {
    /// Path of the offending value, e.g. `objects[2].kind.friction`.
    pub field: String,
    pub problem: String,
}

/// Everything world modeling needs from the application.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorldModelConfig {
    /// The objects of interest. Each gets one filter, or one per map instance (landmarks), or
    /// `max_tracks` (obstacles); object ids follow this order.
    pub objects: Vec<ObjectOfInterest>,
    /// Measurement noise used when a percept carries no usable sigma, and for the predicted
    /// observations of active vision.
    pub camera: CameraNoise,
    pub odometry: OdometryNoise,
    pub confidence: ConfidenceConfig,
    pub association: AssociationConfig,
    pub pose: PoseConfig,
    /// The painted field lines the pose filter is corrected with.
    pub lines: FieldLinesConfig,
    pub team: TeamConfig,
}

/// One object of interest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectOfInterest {
    /// Unique among the objects of interest; landmark instances and obstacle tracks are named
    /// `name#k`.
    pub name: String,
    /// The perception class whose observations concern this object.
    pub class: ObjectClass,
    /// When set, only observations with this variant concern the object; when unset, any
    /// variant of the class does.
    #[serde(default)]
    pub variant: Option<u16>,
    pub kind: ObjectKind,
    /// Overrides the confidence parameters of its kind.
    #[serde(default)]
    pub confidence: Option<ObjectConfidence>,
}

/// How an object of interest moves, and what is known about it a priori.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ObjectKind {
    /// A fixed object with a known position in the field frame. Several positions make
    /// indistinguishable instances (four identical goal posts, several L crossings): one filter
    /// each, and observations are associated to instances by Mahalanobis gating.
    Landmark {
        positions: Vec<Point<Global>>,
        /// Random-walk noise on the landmark's estimate, m^2/s: absorbs what the odometry
        /// model misses (slipping feet) so that a long-tracked landmark can still move.
        #[serde(default = "default_landmark_noise")]
        position_noise: f64,
    },
    /// A free object that rolls and slows down with a constant deceleration.
    Mobile {
        /// Rolling-friction deceleration, m/s^2.
        friction: f64,
        /// White acceleration noise density, m/s^(3/2) (pushes, bumps, model errors).
        acceleration_noise: f64,
        /// Largest plausible speed, m/s: the velocity uncertainty of a new or lost track.
        max_speed: f64,
    },
    /// Objects of which several may be present at once (other robots): a bank of `max_tracks`
    /// filters that start on unexplained observations and are forgotten when not confirmed.
    Obstacle {
        max_tracks: usize,
        /// White acceleration noise density, m/s^(3/2).
        acceleration_noise: f64,
        /// Time constant with which an unobserved velocity decays to zero, s.
        velocity_decay: f64,
        max_speed: f64,
    },
}

fn default_landmark_noise() -> f64 {
    1e-4
}

/// The camera's measurement noise: range noise grows with distance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraNoise {
    /// Range standard deviation at zero distance, m.
    pub range_sigma: f64,
    /// Additional range standard deviation per metre of distance.
    pub range_sigma_per_metre: f64,
    /// Bearing standard deviation, rad.
    pub bearing_sigma: f64,
    /// Use the sigmas perception attaches to each observation (otherwise always these).
    pub use_percept_sigmas: bool,
}

impl Default for CameraNoise {
    fn default() -> Self {
        CameraNoise {
            range_sigma: 0.05,
            range_sigma_per_metre: 0.08,
            bearing_sigma: 0.035,
            use_percept_sigmas: true,
        }
    }
}

impl CameraNoise {
    /// Predicted standard deviations (range, bearing) of an observation at `range`.
    pub fn sigmas(&self, range: f64) -> (f64, f64) {
        (self.range_sigma + self.range_sigma_per_metre * range.max(0.0), self.bearing_sigma)
    }
}

/// Odometry noise as variance densities: the variance of an increment is proportional to its
/// size, so summing (merging) increments does not change the predicted uncertainty.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OdometryNoise {
    /// Translation variance per metre travelled, m^2/m (each axis).
    pub translation_variance_per_metre: f64,
    /// Translation variance per radian turned, m^2/rad.
    pub translation_variance_per_radian: f64,
    /// Rotation variance per radian turned, rad^2/rad.
    pub rotation_variance_per_radian: f64,
    /// Rotation variance per metre travelled, rad^2/m.
    pub rotation_variance_per_metre: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        OdometryNoise {
            translation_variance_per_metre: 0.01,
            translation_variance_per_radian: 0.0004,
            rotation_variance_per_radian: 0.01,
            rotation_variance_per_metre: 0.0025,
        }
    }
}

impl OdometryNoise {
    /// Covariance of the error of the increment `odometry`, in its own (starting) frame.
    pub fn covariance(&self, odometry: &Odometry) -> Matrix3<f64> {
        let d = odometry.dx.hypot(odometry.dy);
        let a = odometry.dtheta.abs();
        let t = self.translation_variance_per_metre * d + self.translation_variance_per_radian * a;
        let r = self.rotation_variance_per_radian * a + self.rotation_variance_per_metre * d;
        Matrix3::from_diagonal(&nalgebra::Vector3::new(t, t, r))
    }
}

/// Confidence parameters of one kind of object.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectConfidence {
    /// Time after the last observation at which the age factor is one half, s.
    pub half_life: f64,
    /// Position uncertainty (sigma radius) at which the covariance factor is one half, m.
    pub sigma_half: f64,
}

/// How confidence is computed (see `docs/world-model.md`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ConfidenceConfig {
    /// Below this confidence an object is "unknown".
    pub unknown_threshold: f64,
    /// Below this confidence a filter is dropped (the object is forgotten).
    pub forget_threshold: f64,
    /// Probability that an object inside the view cone is detected.
    pub detection_probability: f64,
    /// Probability that a detection is spurious.
    pub false_alarm_probability: f64,
    /// Existence probability of a track started from one observation (low enough that a
    /// single detection, maybe a false positive, leaves the object unknown until confirmed).
    pub initial_existence: f64,
    /// Bounds of the existence probability (so that evidence can always change it).
    pub min_existence: f64,
    pub max_existence: f64,
    /// An object is "well inside" the view when it lies this far (rad) inside the cone edges,
    /// plus two bearing sigmas of its own uncertainty.
    pub view_margin: f64,
    /// Covariance inflation per frame in which an object well inside the view was not seen.
    pub miss_inflation: f64,
    pub landmark: ObjectConfidence,
    pub mobile: ObjectConfidence,
    pub obstacle: ObjectConfidence,
    /// Pose position uncertainty at which its position factor is one half, m.
    pub pose_sigma_half: f64,
    /// Pose heading uncertainty at which its heading factor is one half, rad.
    pub pose_heading_sigma_half: f64,
}

impl Default for ConfidenceConfig {
    fn default() -> Self {
        ConfidenceConfig {
            unknown_threshold: 0.3,
            forget_threshold: 0.05,
            detection_probability: 0.6,
            false_alarm_probability: 0.2,
            initial_existence: 0.3,
            min_existence: 0.02,
            max_existence: 0.98,
            view_margin: 0.1,
            miss_inflation: 1.02,
            landmark: ObjectConfidence { half_life: 15.0, sigma_half: 0.5 },
            mobile: ObjectConfidence { half_life: 3.0, sigma_half: 0.5 },
            obstacle: ObjectConfidence { half_life: 2.0, sigma_half: 0.5 },
            pose_sigma_half: 0.3,
            pose_heading_sigma_half: 0.25,
        }
    }
}

/// Data association and track (re)initialization.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AssociationConfig {
    /// Probability mass of the Mahalanobis gate (chi-square, 2 dof).
    pub gate_probability: f64,
    /// When the two best candidates' costs (negative log-likelihoods) differ by less than
    /// this, the observation is ambiguous and updates nothing.
    pub ambiguity_margin: f64,
    /// Mutually consistent rejected observations needed to (re)start a track.
    pub reinit_observations: usize,
    /// Rejected observations closer than this to each other are consistent, m.
    pub reinit_radius: f64,
    /// Rejected observations older than this are forgotten, s; a track confirmed within it
    /// is never replaced.
    pub reinit_window: f64,
}

impl Default for AssociationConfig {
    fn default() -> Self {
        AssociationConfig {
            gate_probability: 0.99,
            ambiguity_margin: 4.0,
            reinit_observations: 3,
            reinit_radius: 0.5,
            reinit_window: 1.0,
        }
    }
}

/// A pose with the standard deviations of (x, y, theta).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PosePrior {
    pub pose: Pose,
    pub sigma: [f64; 3],
}

impl PosePrior {
    pub fn covariance(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&nalgebra::Vector3::new(
            self.sigma[0].powi(2),
            self.sigma[1].powi(2),
            self.sigma[2].powi(2),
        ))
    }
}

/// An axis-aligned region of the field frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    pub min_x: f64,
    pub max_x: f64,
    pub min_y: f64,
    pub max_y: f64,
}

impl Region {
    pub fn contains(&self, p: Point<Global>, margin: f64) -> bool {
        p.x >= self.min_x - margin
            && p.x <= self.max_x + margin
            && p.y >= self.min_y - margin
            && p.y <= self.max_y + margin
    }

    /// How far `p` lies outside the region (0 inside).
    pub fn distance_outside(&self, p: Point<Global>) -> f64 {
        let dx = (self.min_x - p.x).max(p.x - self.max_x).max(0.0);
        let dy = (self.min_y - p.y).max(p.y - self.max_y).max(0.0);
        dx.hypot(dy)
    }
}

strata_runtime::text_and_binary_enum! {
    /// What the application knows about the robot's pose that the landmarks cannot tell: how
    /// real teams break the field's symmetry (the robot starts in its own half, a penalized
    /// robot re-enters at known spots, the goalkeeper stays in its penalty area). Tagged by
    /// `type` in text (configuration files), externally in binary encodings (logs).
    #[derive(Clone, Debug, PartialEq)]
    pub enum SymmetryHint {
        /// The robot is inside this region.
        Region { region: Region },
        /// The robot faces roughly this direction.
        Heading { theta: f64, sigma: f64 },
        /// The robot is near one of these poses.
        NearPoses { poses: Vec<PosePrior> },
        /// The robot may have been moved to one of these poses without being told (a referee
        /// that takes robots off the field silently). Unlike `NearPoses` it costs nothing
        /// elsewhere: for 10 s after a kidnap, recovery tries each pose carried along by the
        /// odometry since the landmarks began to disagree, favours poses near one, and takes
        /// one landmark that fits there as enough.
        Relocations { poses: Vec<PosePrior> },
    }
    text: #[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
    binary: #[serde(rename_all = "snake_case")]
}

/// The robot-pose filter, losing and recovering the pose.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseConfig {
    /// Where the robot starts; without it the pose is lost until landmarks fix it.
    pub initial: Option<PosePrior>,
    /// Where the robot can be (the carpet): recovery hypotheses outside are discarded.
    #[serde(alias = "field_bounds")]
    pub bounds: Option<Region>,
    /// Standing symmetry hints (the application can change them with commands).
    pub hints: Vec<SymmetryHint>,
    /// The pose is lost when its position sigma (major axis) exceeds this, m.
    pub lost_position_sigma: f64,
    /// The pose is lost when its heading sigma exceeds this, rad.
    pub lost_heading_sigma: f64,
    /// Consecutive landmark estimates (from at least two landmarks) that disagree with the
    /// pose and the map before the robot is declared kidnapped.
    pub kidnap_rejections: usize,
    /// Whether the disagreements of a single landmark declare a kidnap too. Off, they must come
    /// from at least two, so that one persistent false positive cannot unseat the pose; on for
    /// a robot that may be moved without being told to where it sees one landmark (the side
    /// line of rcssservermj's field).
    pub kidnap_from_one_landmark: bool,
    /// A robot whose feet carried less than this (kg, both feet) and then touch the ground
    /// again was carried: it is declared kidnapped. `None` ignores foot contact.
    pub kidnap_on_lift: Option<f64>,
    /// After a kidnap declared because the landmarks disagree with the pose (not a placement,
    /// a lift or a command), recovery prefers poses near the estimate it lost, its covariance
    /// grown by these standard deviations (m, m, rad). For a platform that reports every move
    /// it sees (`Percepts::placed`), such a kidnap is the estimate gone wrong (odometry through
    /// a fall), not a carry: the robot is still near it, which tells a pose from its mirror
    /// image on a symmetric field. `None`: the robot may be anywhere.
    pub disagreement_prior: Option<[f64; 3]>,
    /// A fall moves the robot by what no odometry measured. When the torso, tilted beyond
    /// this (rad, roll or pitch), is upright again (below half of it), the pose and every
    /// tracked object grow uncertain by `fall_sigma`, so that what the robot sees next
    /// corrects them instead of being refused by a pose still sure of itself. `None`: falls
    /// are not looked for.
    pub fall_tilt: Option<f64>,
    /// Standard deviations of the unmeasured motion of a fall and a stand-up (m, m, rad).
    pub fall_sigma: [f64; 3],
    /// Only landmark estimates observed within this time take part in recovery, s.
    pub recovery_max_age: f64,
    /// Landmarks that must agree with a recovery hypothesis.
    pub recovery_min_landmarks: usize,
    /// A recovery hypothesis is accepted only if every clearly different hypothesis costs this
    /// much more (negative log-likelihood).
    pub recovery_margin: f64,
    /// A recovered pose is accepted only if its position is at least this sure (major sigma,
    /// m): landmarks that fix it worse (two close together, far away) leave the robot lost
    /// until it sees one that tells.
    pub recovery_max_sigma: f64,
    /// Hypotheses tried per recovery attempt (pairs of landmarks times map instances).
    pub recovery_max_hypotheses: usize,
    /// Time between two recovery attempts while lost, s (an attempt costs about 0.15 ms on a
    /// desktop core with ten landmarks tracked).
    pub recovery_period: f64,
    /// Estimate the odometry error from the landmarks and correct incoming odometry with it.
    pub correct_odometry: bool,
    /// The map accuracy compares the landmarks observed within this time with the map, s.
    pub map_accuracy_max_age: f64,
    /// What the pose filter is corrected with (docs/world-model.md, "What the pose filter is
    /// fed").
    pub feed: PoseFeed,
}

/// What the pose filter is corrected with from each landmark filter corrected in a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PoseFeed {
    /// The information the landmark filter gained from this frame's observation (its
    /// posterior information minus its prior): every observation counts once.
    #[default]
    Gained,
    /// The landmark filter's whole estimate, as the paper words it: each frame counts again
    /// every observation the filter ever fused (measured overconfident).
    Estimates,
}

/// The painted field lines as observations of the pose (paper 3.1: lines and their
/// crossings). A line observation is the nearest point of the line's visible piece and the
/// line's direction (modulo a half turn), both in the robot frame: together they tell how far
/// the robot is from the line and how it is turned to it, not where along it it stands.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FieldLinesConfig {
    /// The perception class of line observations; `None`: lines are not used.
    pub class: Option<ObjectClass>,
    /// The map's straight lines (line centres), field frame.
    pub segments: Vec<[Point<Global>; 2]>,
    /// Standard deviation of an observed line's direction, rad (observations carry none).
    pub direction_sigma: f64,
    /// How far beyond a segment's ends an observed point may lie and still be on it, m (the
    /// painted width, and the pose's error along the line).
    pub end_margin: f64,
    /// Lines observed farther than this are not used, m (far lines are seen at a grazing
    /// angle, their direction barely measured).
    pub max_range: f64,
    /// The shortest piece of a line the camera reports, m: active vision predicts no
    /// observation of a line of which a view would show less.
    pub min_length: f64,
}

impl FieldLinesConfig {
    /// Whether observations of `class` are line observations.
    pub fn accepts(&self, class: ObjectClass) -> bool {
        self.class == Some(class) && !self.segments.is_empty()
    }
}

impl Default for PoseConfig {
    fn default() -> Self {
        PoseConfig {
            initial: None,
            bounds: None,
            hints: Vec::new(),
            lost_position_sigma: 1.0,
            lost_heading_sigma: 0.6,
            kidnap_rejections: 5,
            kidnap_from_one_landmark: false,
            kidnap_on_lift: None,
            disagreement_prior: None,
            fall_tilt: None,
            fall_sigma: [0.4, 0.4, 0.3],
            recovery_max_age: 3.0,
            recovery_min_landmarks: 2,
            recovery_margin: 6.0,
            recovery_max_sigma: 0.75,
            recovery_max_hypotheses: 600,
            recovery_period: 0.1,
            correct_odometry: false,
            map_accuracy_max_age: 2.0,
            feed: PoseFeed::Gained,
        }
    }
}

/// Fusing teammates' estimates (MAWM, paper 3.3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TeamConfig {
    /// Teammate estimates older than this are ignored, s.
    pub max_age: f64,
    /// Probability mass of the gate that decides whether two estimates agree.
    pub gate_probability: f64,
    /// Position variance added per second of age of an estimate, m^2/s.
    pub position_noise: f64,
    /// Weights (pose confidence times object confidence) are floored at this.
    pub min_weight: f64,
}

impl Default for TeamConfig {
    fn default() -> Self {
        TeamConfig { max_age: 3.0, gate_probability: 0.99, position_noise: 0.1, min_weight: 0.05 }
    }
}

fn err(field: impl Into<String>, problem: impl Into<String>) -> ConfigError {
    ConfigError { field: field.into(), problem: problem.into() }
}

fn positive(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(err(field, format!("must be > 0 (got {v})")))
    }
}

fn non_negative(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(err(field, format!("must be >= 0 (got {v})")))
    }
}

fn probability(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 && v < 1.0 {
        Ok(())
    } else {
        Err(err(field, format!("must be strictly between 0 and 1 (got {v})")))
    }
}

fn region(field: &str, r: &Region) -> Result<(), ConfigError> {
    let finite = [r.min_x, r.max_x, r.min_y, r.max_y].iter().all(|v| v.is_finite());
    if finite && r.min_x <= r.max_x && r.min_y <= r.max_y {
        Ok(())
    } else {
        Err(err(field, "must have finite bounds with min <= max"))
    }
}

/// Checks a pose prior (also used for priors arriving by command).
pub fn validate_pose_prior(field: &str, p: &PosePrior) -> Result<(), ConfigError> {
    if !p.pose.is_finite() {
        return Err(err(format!("{field}.pose"), "must be finite"));
    }
    for (i, s) in p.sigma.iter().enumerate() {
        positive(&format!("{field}.sigma[{i}]"), *s)?;
    }
    Ok(())
}

/// Most landmark instances of one object of interest (keeps recovery's pairing bounded).
pub const MAX_INSTANCES: usize = 64;

impl WorldModelConfig {
    /// Checks every value; the error names the first offending field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let mut names = std::collections::HashSet::new();
        let mut total = 0usize;
        for (i, o) in self.objects.iter().enumerate() {
            let f = format!("objects[{i}]");
            if o.name.trim().is_empty() || o.name.contains('#') {
                return Err(err(format!("{f}.name"), "must be non-empty and contain no '#'"));
            }
            if !names.insert(o.name.as_str()) {
                return Err(err(format!("{f}.name"), format!("`{}` is used twice", o.name)));
            }
            match &o.kind {
                ObjectKind::Landmark { positions, position_noise } => {
                    if positions.is_empty() || positions.len() > MAX_INSTANCES {
                        return Err(err(
                            format!("{f}.kind.positions"),
                            format!("must list 1 to {MAX_INSTANCES} map positions"),
                        ));
                    }
                    for (k, p) in positions.iter().enumerate() {
                        if !p.is_finite() {
                            return Err(err(format!("{f}.kind.positions[{k}]"), "must be finite"));
                        }
                    }
                    non_negative(&format!("{f}.kind.position_noise"), *position_noise)?;
                    total += positions.len();
                }
                ObjectKind::Mobile { friction, acceleration_noise, max_speed } => {
                    non_negative(&format!("{f}.kind.friction"), *friction)?;
                    non_negative(&format!("{f}.kind.acceleration_noise"), *acceleration_noise)?;
                    positive(&format!("{f}.kind.max_speed"), *max_speed)?;
                    total += 1;
                }
                ObjectKind::Obstacle {
                    max_tracks,
                    acceleration_noise,
                    velocity_decay,
                    max_speed,
                } => {
                    if *max_tracks == 0 || *max_tracks > MAX_INSTANCES {
                        return Err(err(
                            format!("{f}.kind.max_tracks"),
                            format!("must be between 1 and {MAX_INSTANCES}"),
                        ));
                    }
                    non_negative(&format!("{f}.kind.acceleration_noise"), *acceleration_noise)?;
                    positive(&format!("{f}.kind.velocity_decay"), *velocity_decay)?;
                    positive(&format!("{f}.kind.max_speed"), *max_speed)?;
                    total += max_tracks;
                }
            }
            if let Some(c) = &o.confidence {
                positive(&format!("{f}.confidence.half_life"), c.half_life)?;
                positive(&format!("{f}.confidence.sigma_half"), c.sigma_half)?;
            }
        }
        if total > usize::from(u16::MAX) {
            return Err(err("objects", "describe more filters than object ids can number"));
        }
        let c = &self.camera;
        positive("camera.range_sigma", c.range_sigma)?;
        non_negative("camera.range_sigma_per_metre", c.range_sigma_per_metre)?;
        positive("camera.bearing_sigma", c.bearing_sigma)?;
        let o = &self.odometry;
        non_negative("odometry.translation_variance_per_metre", o.translation_variance_per_metre)?;
        non_negative(
            "odometry.translation_variance_per_radian",
            o.translation_variance_per_radian,
        )?;
        non_negative("odometry.rotation_variance_per_radian", o.rotation_variance_per_radian)?;
        non_negative("odometry.rotation_variance_per_metre", o.rotation_variance_per_metre)?;
        let k = &self.confidence;
        probability("confidence.unknown_threshold", k.unknown_threshold)?;
        probability("confidence.forget_threshold", k.forget_threshold)?;
        if k.forget_threshold >= k.unknown_threshold {
            return Err(err("confidence.forget_threshold", "must be below unknown_threshold"));
        }
        probability("confidence.detection_probability", k.detection_probability)?;
        probability("confidence.false_alarm_probability", k.false_alarm_probability)?;
        probability("confidence.initial_existence", k.initial_existence)?;
        probability("confidence.min_existence", k.min_existence)?;
        probability("confidence.max_existence", k.max_existence)?;
        if k.min_existence > k.initial_existence || k.initial_existence > k.max_existence {
            return Err(err(
                "confidence.initial_existence",
                "must lie between min_existence and max_existence",
            ));
        }
        non_negative("confidence.view_margin", k.view_margin)?;
        if !(k.miss_inflation.is_finite() && k.miss_inflation >= 1.0) {
            return Err(err("confidence.miss_inflation", "must be >= 1"));
        }
        for (name, oc) in [("landmark", k.landmark), ("mobile", k.mobile), ("obstacle", k.obstacle)]
        {
            positive(&format!("confidence.{name}.half_life"), oc.half_life)?;
            positive(&format!("confidence.{name}.sigma_half"), oc.sigma_half)?;
        }
        positive("confidence.pose_sigma_half", k.pose_sigma_half)?;
        positive("confidence.pose_heading_sigma_half", k.pose_heading_sigma_half)?;
        let a = &self.association;
        probability("association.gate_probability", a.gate_probability)?;
        non_negative("association.ambiguity_margin", a.ambiguity_margin)?;
        if a.reinit_observations == 0 {
            return Err(err("association.reinit_observations", "must be at least 1"));
        }
        positive("association.reinit_radius", a.reinit_radius)?;
        positive("association.reinit_window", a.reinit_window)?;
        let p = &self.pose;
        if let Some(initial) = &p.initial {
            validate_pose_prior("pose.initial", initial)?;
        }
        if let Some(bounds) = &p.bounds {
            region("pose.bounds", bounds)?;
        }
        for (i, hint) in p.hints.iter().enumerate() {
            validate_hint(&format!("pose.hints[{i}]"), hint)?;
        }
        positive("pose.lost_position_sigma", p.lost_position_sigma)?;
        positive("pose.lost_heading_sigma", p.lost_heading_sigma)?;
        if p.kidnap_rejections == 0 {
            return Err(err("pose.kidnap_rejections", "must be at least 1"));
        }
        if let Some(kg) = p.kidnap_on_lift {
            positive("pose.kidnap_on_lift", kg)?;
        }
        if let Some(sigma) = p.disagreement_prior {
            for (i, s) in sigma.iter().enumerate() {
                positive(&format!("pose.disagreement_prior[{i}]"), *s)?;
            }
        }
        if let Some(tilt) = p.fall_tilt
            && !(tilt > 0.0 && tilt < std::f64::consts::PI)
        {
            return Err(err("pose.fall_tilt", "must lie between 0 and pi (rad)"));
        }
        for (i, s) in p.fall_sigma.iter().enumerate() {
            non_negative(&format!("pose.fall_sigma[{i}]"), *s)?;
        }
        positive("pose.recovery_max_age", p.recovery_max_age)?;
        if p.recovery_min_landmarks < 2 {
            return Err(err("pose.recovery_min_landmarks", "must be at least 2"));
        }
        non_negative("pose.recovery_margin", p.recovery_margin)?;
        if !(p.recovery_max_sigma > 0.0 && p.recovery_max_sigma.is_finite()) {
            return Err(err("pose.recovery_max_sigma", "must be positive and finite"));
        }
        if p.recovery_max_hypotheses == 0 {
            return Err(err("pose.recovery_max_hypotheses", "must be at least 1"));
        }
        non_negative("pose.recovery_period", p.recovery_period)?;
        positive("pose.map_accuracy_max_age", p.map_accuracy_max_age)?;
        let l = &self.lines;
        for (i, segment) in l.segments.iter().enumerate() {
            let [a, b] = segment;
            if !(a.is_finite() && b.is_finite()) {
                return Err(err(format!("lines.segments[{i}]"), "must be finite"));
            }
            if a.distance(*b) < 1e-6 {
                return Err(err(format!("lines.segments[{i}]"), "must have two distinct ends"));
            }
        }
        if l.class.is_some() {
            positive("lines.direction_sigma", l.direction_sigma)?;
            non_negative("lines.end_margin", l.end_margin)?;
            positive("lines.max_range", l.max_range)?;
        }
        let t = &self.team;
        positive("team.max_age", t.max_age)?;
        probability("team.gate_probability", t.gate_probability)?;
        non_negative("team.position_noise", t.position_noise)?;
        probability("team.min_weight", t.min_weight)?;
        Ok(())
    }
}

/// Checks a hint (also used for hints arriving by command).
pub fn validate_hint(field: &str, hint: &SymmetryHint) -> Result<(), ConfigError> {
    match hint {
        SymmetryHint::Region { region: r } => region(&format!("{field}.region"), r),
        SymmetryHint::Heading { theta, sigma } => {
            if !theta.is_finite() {
                return Err(err(format!("{field}.theta"), "must be finite"));
            }
            positive(&format!("{field}.sigma"), *sigma)
        }
        SymmetryHint::NearPoses { poses } | SymmetryHint::Relocations { poses } => {
            if poses.is_empty() {
                return Err(err(format!("{field}.poses"), "must not be empty"));
            }
            for (i, p) in poses.iter().enumerate() {
                validate_pose_prior(&format!("{field}.poses[{i}]"), p)?;
            }
            Ok(())
        }
    }
}
