//! The field as data: dimensions from TOML, and everything derived from them.
//!
//! Field frame: origin at the centre of the field, x towards the opponent goal, y to the left,
//! metres and radians. "Own" is the half and goal at negative x. "Left" is positive y, which is
//! on the left of a player facing the opponent goal (and of a goalkeeper facing out of its own
//! goal). Like the rule book, dimensions are measured to the centres of the painted lines.

use std::collections::HashSet;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::objects::{LandmarkKind, ObjectKind};

const SPL_TOML: &str = include_str!("../fields/spl.toml");
const PAPER2010_TOML: &str = include_str!("../fields/paper2010.toml");
const RCSSSERVERMJ_TOML: &str = include_str!("../fields/rcssservermj.toml");

/// Names accepted by [`Field::preset`].
pub const PRESETS: [&str; 3] = ["spl", "paper2010", "rcssservermj"];

/// A field that could not be loaded: the message names the source and the offending value.
#[derive(Debug, Error)]
pub enum FieldError {
    #[error("{source_name}: {message}")]
    Parse { source_name: String, message: String },
    #[error("{source_name}: {field} must be {requirement}, got {value}")]
    Invalid { source_name: String, field: String, requirement: String, value: String },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("unknown field preset {0:?} (known: spl, paper2010, rcssservermj)")]
    UnknownPreset(String),
}

/// A colour painted on a field object.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Colour {
    #[default]
    White,
    Yellow,
    SkyBlue,
    Pink,
    Blue,
    Green,
    Orange,
}

impl Colour {
    /// A stable code for the colour: how a camera that tells coloured goal posts apart reports
    /// them (the detection's variant), shared by the simulator and the applications.
    pub fn code(self) -> u16 {
        match self {
            Colour::White => 0,
            Colour::Yellow => 1,
            Colour::SkyBlue => 2,
            Colour::Pink => 3,
            Colour::Blue => 4,
            Colour::Green => 5,
            Colour::Orange => 6,
        }
    }
}

/// Length (along x) and width (along y) of a box in front of a goal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AreaDimensions {
    pub length: f64,
    pub width: f64,
}

/// The colours of the goals (posts and crossbar).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalColours {
    /// The goal at negative x.
    pub own: Colour,
    /// The goal at positive x.
    pub opponent: Colour,
}

/// A coloured pole beside the field (2010-era fields).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Beacon {
    pub name: String,
    pub x: f64,
    pub y: f64,
    pub diameter: f64,
    pub height: f64,
    /// Segment colours from bottom to top.
    pub colours: Vec<Colour>,
}

/// The dimensions of a field, as in the SPL rule book (metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldDimensions {
    pub name: String,
    /// Between the centres of the goal lines.
    pub field_length: f64,
    /// Between the centres of the side lines.
    pub field_width: f64,
    pub line_width: f64,
    /// Carpet outside the lines on every side.
    pub border_strip_width: f64,
    pub penalty_area: AreaDimensions,
    /// The small box inside the penalty area; 2010-era fields have none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_area: Option<AreaDimensions>,
    /// From the goal line to the centre of the penalty mark.
    pub penalty_mark_distance: f64,
    pub penalty_mark_size: f64,
    pub center_circle_diameter: f64,
    /// Between the inner faces of the goal posts.
    pub goal_inner_width: f64,
    pub goal_post_diameter: f64,
    pub goal_depth: f64,
    pub goal_height: f64,
    #[serde(default)]
    pub goal_colours: GoalColours,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub beacons: Vec<Beacon>,
}

/// A point in the field frame (metres).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
}

impl Point {
    /// The point (x, y).
    pub const fn new(x: f64, y: f64) -> Point {
        Point { x, y }
    }

    /// Euclidean distance.
    pub fn distance(self, other: Point) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }
}

/// A straight painted line, from the centre of one end to the other.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LineSegment {
    pub start: Point,
    pub end: Point,
}

impl LineSegment {
    /// Length from end to end.
    pub fn length(&self) -> f64 {
        self.start.distance(self.end)
    }

    /// Direction from start to end (radians).
    pub fn direction(&self) -> f64 {
        (self.end.y - self.start.y).atan2(self.end.x - self.start.x)
    }
}

/// A circle (the centre circle: radius to the centre of the line).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Circle {
    pub centre: Point,
    pub radius: f64,
}

/// An axis-aligned rectangle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rect {
    pub min: Point,
    pub max: Point,
}

impl Rect {
    /// Whether the point is inside or on the boundary.
    pub fn contains(&self, p: Point) -> bool {
        (self.min.x..=self.max.x).contains(&p.x) && (self.min.y..=self.max.y).contains(&p.y)
    }
}

/// One end of the field: the half and goal at negative x (own) or positive x (opponent).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Own,
    Opponent,
}

impl Side {
    /// -1 for own, +1 for opponent: the sign of x on this side.
    pub const fn sign(self) -> f64 {
        match self {
            Side::Own => -1.0,
            Side::Opponent => 1.0,
        }
    }

    /// The opposite side.
    pub const fn other(self) -> Side {
        match self {
            Side::Own => Side::Opponent,
            Side::Opponent => Side::Own,
        }
    }
}

/// Left (positive y) or right (negative y).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Lateral {
    Left,
    Right,
}

impl Lateral {
    /// +1 for left, -1 for right: the sign of y on this side.
    pub const fn sign(self) -> f64 {
        match self {
            Lateral::Left => 1.0,
            Lateral::Right => -1.0,
        }
    }
}

/// The shape of a line crossing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum CrossingKind {
    L,
    T,
    X,
}

/// A fixed landmark of the field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Landmark {
    GoalPost {
        position: Point,
        goal: Side,
        post: Lateral,
    },
    /// `orientation` says where the arms point: for an L the bisector of its two arms, for a T
    /// its stem, for an X one of its four arms (the others are at multiples of pi/2).
    Crossing {
        position: Point,
        crossing: CrossingKind,
        orientation: f64,
    },
    CenterCircle {
        centre: Point,
        radius: f64,
    },
    PenaltyMark {
        position: Point,
        side: Side,
    },
    Beacon {
        position: Point,
        /// Index into [`FieldDimensions::beacons`].
        index: usize,
    },
}

impl Landmark {
    /// The landmark's kind.
    pub fn kind(&self) -> LandmarkKind {
        match self {
            Landmark::GoalPost { .. } => LandmarkKind::GoalPost,
            Landmark::Crossing { crossing: CrossingKind::L, .. } => LandmarkKind::LCrossing,
            Landmark::Crossing { crossing: CrossingKind::T, .. } => LandmarkKind::TCrossing,
            Landmark::Crossing { crossing: CrossingKind::X, .. } => LandmarkKind::XCrossing,
            Landmark::CenterCircle { .. } => LandmarkKind::CenterCircle,
            Landmark::PenaltyMark { .. } => LandmarkKind::PenaltyMark,
            Landmark::Beacon { .. } => LandmarkKind::Beacon,
        }
    }

    /// The landmark's kind as a detectable object.
    pub fn object_kind(&self) -> ObjectKind {
        self.kind().object_kind()
    }

    /// Where it is (a circle's centre).
    pub fn position(&self) -> Point {
        match *self {
            Landmark::GoalPost { position, .. }
            | Landmark::Crossing { position, .. }
            | Landmark::PenaltyMark { position, .. }
            | Landmark::Beacon { position, .. } => position,
            Landmark::CenterCircle { centre, .. } => centre,
        }
    }

    /// Directions (radians) in which a crossing's painted arms leave it; empty for others.
    pub fn arm_directions(&self) -> Vec<f64> {
        match *self {
            Landmark::Crossing { crossing: CrossingKind::L, orientation, .. } => {
                vec![orientation - FRAC_PI_4, orientation + FRAC_PI_4]
            }
            Landmark::Crossing { crossing: CrossingKind::T, orientation, .. } => {
                vec![orientation, orientation + FRAC_PI_2, orientation - FRAC_PI_2]
            }
            Landmark::Crossing { crossing: CrossingKind::X, orientation, .. } => {
                (0..4).map(|k| orientation + f64::from(k) * FRAC_PI_2).collect()
            }
            _ => Vec::new(),
        }
    }
}

/// A goal: the posts and the space behind the goal line between them.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Goal {
    pub side: Side,
    /// Centres of the posts.
    pub left_post: Point,
    pub right_post: Point,
    /// From the outer edge of the goal line to the back of the goal, between the posts.
    pub inside: Rect,
}

/// Where the ball is, as a referee sees it (2D: no crossbar).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BallStatus {
    InPlay,
    /// Wholly past a side line.
    OutOverSideLine(Lateral),
    /// Wholly past a goal line, not between the posts.
    OutOverGoalLine(Side),
    /// Wholly past a goal line between the posts: a goal in that side's goal.
    Goal(Side),
}

/// A validated field with its derived geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    dimensions: FieldDimensions,
    landmarks: Vec<Landmark>,
    lines: Vec<LineSegment>,
}

impl Field {
    /// A built-in field: "spl" (current rules), "paper2010" (the paper's field with beacons) or
    /// "rcssservermj" (the physics simulator's FIFA 7 vs 7 field).
    pub fn preset(name: &str) -> Result<Field, FieldError> {
        match name {
            "spl" => Field::from_toml_str(SPL_TOML, "fields/spl.toml"),
            "paper2010" => Field::from_toml_str(PAPER2010_TOML, "fields/paper2010.toml"),
            "rcssservermj" => Field::from_toml_str(RCSSSERVERMJ_TOML, "fields/rcssservermj.toml"),
            other => Err(FieldError::UnknownPreset(other.to_owned())),
        }
    }

    /// Parses and validates TOML; `source_name` (usually the path) prefixes every error.
    pub fn from_toml_str(text: &str, source_name: &str) -> Result<Field, FieldError> {
        let dimensions: FieldDimensions = toml::from_str(text).map_err(|e| FieldError::Parse {
            source_name: source_name.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        Field::new(dimensions, source_name)
    }

    /// Reads, parses and validates a TOML file.
    pub fn load(path: impl AsRef<Path>) -> Result<Field, FieldError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|source| FieldError::Io { path: path.to_owned(), source })?;
        Field::from_toml_str(&text, &path.display().to_string())
    }

    /// Validates dimensions and derives the geometry.
    pub fn new(dimensions: FieldDimensions, source_name: &str) -> Result<Field, FieldError> {
        validate(&dimensions, source_name)?;
        let landmarks = derive_landmarks(&dimensions);
        let lines = derive_lines(&dimensions);
        Ok(Field { dimensions, landmarks, lines })
    }

    /// The validated dimensions.
    pub fn dimensions(&self) -> &FieldDimensions {
        &self.dimensions
    }

    /// All landmarks. The order is fixed for given dimensions, so an index identifies one:
    /// goal posts, crossings, the centre circle, penalty marks, beacons.
    pub fn landmarks(&self) -> &[Landmark] {
        &self.landmarks
    }

    /// The landmarks of one kind, in the order of [`Field::landmarks`].
    pub fn landmarks_of(&self, kind: LandmarkKind) -> impl Iterator<Item = &Landmark> + '_ {
        self.landmarks.iter().filter(move |l| l.kind() == kind)
    }

    /// The straight painted lines (line centres); the centre circle is [`Field::centre_circle`].
    pub fn lines(&self) -> &[LineSegment] {
        &self.lines
    }

    /// The centre circle (radius to the line centre).
    pub fn centre_circle(&self) -> Circle {
        Circle {
            centre: Point::new(0.0, 0.0),
            radius: self.dimensions.center_circle_diameter / 2.0,
        }
    }

    /// x of the goal lines' centres.
    pub fn half_length(&self) -> f64 {
        self.dimensions.field_length / 2.0
    }

    /// y of the side lines' centres.
    pub fn half_width(&self) -> f64 {
        self.dimensions.field_width / 2.0
    }

    /// Inside the field, lines included (the lines belong to the field).
    pub fn is_inside_field(&self, x: f64, y: f64) -> bool {
        let edge = self.dimensions.line_width / 2.0;
        x.abs() <= self.half_length() + edge && y.abs() <= self.half_width() + edge
    }

    /// On the carpet: the field and its border strip.
    pub fn is_on_carpet(&self, x: f64, y: f64) -> bool {
        let border = self.dimensions.border_strip_width;
        x.abs() <= self.half_length() + border && y.abs() <= self.half_width() + border
    }

    /// The half that contains x (the halfway line counts as the opponent half).
    pub fn half(&self, x: f64) -> Side {
        if x < 0.0 { Side::Own } else { Side::Opponent }
    }

    /// One side's goal.
    pub fn goal(&self, side: Side) -> Goal {
        let d = &self.dimensions;
        let s = side.sign();
        let line_edge = self.half_length() + d.line_width / 2.0;
        let back = self.half_length() + d.goal_depth;
        let (x0, x1) = if s > 0.0 { (line_edge, back) } else { (-back, -line_edge) };
        Goal {
            side,
            left_post: goal_post(d, side, Lateral::Left),
            right_post: goal_post(d, side, Lateral::Right),
            inside: Rect {
                min: Point::new(x0, -d.goal_inner_width / 2.0),
                max: Point::new(x1, d.goal_inner_width / 2.0),
            },
        }
    }

    /// The goal whose inside contains the point, if any.
    pub fn is_in_goal(&self, x: f64, y: f64) -> Option<Side> {
        [Side::Own, Side::Opponent]
            .into_iter()
            .find(|&side| self.goal(side).inside.contains(Point::new(x, y)))
    }

    /// The penalty area of one side, to the line centres.
    pub fn penalty_area(&self, side: Side) -> Rect {
        self.area(side, self.dimensions.penalty_area)
    }

    /// The goal area of one side, if the field has one.
    pub fn goal_area(&self, side: Side) -> Option<Rect> {
        self.dimensions.goal_area.map(|area| self.area(side, area))
    }

    fn area(&self, side: Side, area: AreaDimensions) -> Rect {
        let inner = self.half_length() - area.length;
        let (x0, x1) = match side {
            Side::Own => (-self.half_length(), -inner),
            Side::Opponent => (inner, self.half_length()),
        };
        Rect { min: Point::new(x0, -area.width / 2.0), max: Point::new(x1, area.width / 2.0) }
    }

    /// The referee's view of a ball of `ball_radius` centred at (x, y). Out means wholly past
    /// the outer edge of a line. Past a goal line and a side line at once counts as over the
    /// goal line, so call this every step to see the first line crossed.
    pub fn ball_status(&self, x: f64, y: f64, ball_radius: f64) -> BallStatus {
        let out = self.dimensions.line_width / 2.0 + ball_radius;
        if x.abs() > self.half_length() + out {
            let side = self.half(x);
            if y.abs() < self.dimensions.goal_inner_width / 2.0 {
                BallStatus::Goal(side)
            } else {
                BallStatus::OutOverGoalLine(side)
            }
        } else if y.abs() > self.half_width() + out {
            BallStatus::OutOverSideLine(if y > 0.0 { Lateral::Left } else { Lateral::Right })
        } else {
            BallStatus::InPlay
        }
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let d = &self.dimensions;
        write!(f, "{} ({} m x {} m)", d.name, d.field_length, d.field_width)
    }
}

/// The centre of a goal post: its front touches the field-side edge of the goal line.
fn goal_post(d: &FieldDimensions, goal: Side, post: Lateral) -> Point {
    let x = d.field_length / 2.0 - d.line_width / 2.0 + d.goal_post_diameter / 2.0;
    let y = d.goal_inner_width / 2.0 + d.goal_post_diameter / 2.0;
    Point::new(goal.sign() * x, post.sign() * y)
}

fn derive_landmarks(d: &FieldDimensions) -> Vec<Landmark> {
    let hl = d.field_length / 2.0;
    let hw = d.field_width / 2.0;
    let mut out = Vec::new();
    let sides = [Side::Own, Side::Opponent];
    let laterals = [Lateral::Left, Lateral::Right];

    for goal in sides {
        for post in laterals {
            out.push(Landmark::GoalPost { position: goal_post(d, goal, post), goal, post });
        }
    }

    let crossing = |x: f64, y: f64, crossing, orientation| Landmark::Crossing {
        position: Point::new(x, y),
        crossing,
        orientation,
    };
    // Corners: both arms run back into the field.
    for side in sides {
        for lateral in laterals {
            let (sx, sy) = (side.sign(), lateral.sign());
            out.push(crossing(sx * hl, sy * hw, CrossingKind::L, (-sy).atan2(-sx)));
        }
    }
    // Halfway line against the side lines (stem into the field) and the centre circle.
    for lateral in laterals {
        let sy = lateral.sign();
        out.push(crossing(0.0, sy * hw, CrossingKind::T, -sy * FRAC_PI_2));
    }
    let radius = d.center_circle_diameter / 2.0;
    for lateral in laterals {
        out.push(crossing(0.0, lateral.sign() * radius, CrossingKind::X, 0.0));
    }
    // Each box: a T where it meets the goal line (stem towards the centre), an L at each front
    // corner (arms towards the goal line and towards the long axis).
    for side in sides {
        for area in std::iter::once(d.penalty_area).chain(d.goal_area) {
            let sx = side.sign();
            let stem = if sx > 0.0 { PI } else { 0.0 };
            for lateral in laterals {
                out.push(crossing(
                    sx * hl,
                    lateral.sign() * area.width / 2.0,
                    CrossingKind::T,
                    stem,
                ));
            }
            for lateral in laterals {
                let sy = lateral.sign();
                let front = sx * (hl - area.length);
                out.push(crossing(front, sy * area.width / 2.0, CrossingKind::L, (-sy).atan2(sx)));
            }
        }
    }

    out.push(Landmark::CenterCircle { centre: Point::new(0.0, 0.0), radius });
    for side in sides {
        let position = Point::new(side.sign() * (hl - d.penalty_mark_distance), 0.0);
        out.push(Landmark::PenaltyMark { position, side });
    }
    for (index, beacon) in d.beacons.iter().enumerate() {
        out.push(Landmark::Beacon { position: Point::new(beacon.x, beacon.y), index });
    }
    out
}

fn derive_lines(d: &FieldDimensions) -> Vec<LineSegment> {
    let hl = d.field_length / 2.0;
    let hw = d.field_width / 2.0;
    let seg = |x0, y0, x1, y1| LineSegment { start: Point::new(x0, y0), end: Point::new(x1, y1) };
    let mut out = vec![
        seg(-hl, hw, hl, hw),
        seg(-hl, -hw, hl, -hw),
        seg(-hl, -hw, -hl, hw),
        seg(hl, -hw, hl, hw),
        seg(0.0, -hw, 0.0, hw),
    ];
    for sx in [-1.0, 1.0] {
        for area in std::iter::once(d.penalty_area).chain(d.goal_area) {
            let front = sx * (hl - area.length);
            let hy = area.width / 2.0;
            out.push(seg(sx * hl, hy, front, hy));
            out.push(seg(sx * hl, -hy, front, -hy));
            out.push(seg(front, -hy, front, hy));
        }
    }
    out
}

struct Validator<'a> {
    source_name: &'a str,
}

impl Validator<'_> {
    fn fail(&self, field: &str, requirement: String, value: impl fmt::Display) -> FieldError {
        FieldError::Invalid {
            source_name: self.source_name.to_owned(),
            field: field.to_owned(),
            requirement,
            value: value.to_string(),
        }
    }

    fn check(
        &self,
        ok: bool,
        field: &str,
        requirement: String,
        value: f64,
    ) -> Result<(), FieldError> {
        // NaN fails every comparison, so a NaN value is always reported here.
        if ok && value.is_finite() { Ok(()) } else { Err(self.fail(field, requirement, value)) }
    }

    fn positive(&self, field: &str, value: f64) -> Result<(), FieldError> {
        self.check(value > 0.0, field, "> 0".into(), value)
    }

    fn below(&self, field: &str, value: f64, limit: f64, what: &str) -> Result<(), FieldError> {
        self.check(value < limit, field, format!("< {limit} ({what})"), value)
    }
}

fn validate(d: &FieldDimensions, source_name: &str) -> Result<(), FieldError> {
    let v = Validator { source_name };
    if d.name.trim().is_empty() {
        return Err(v.fail("name", "non-empty".into(), "\"\""));
    }
    for (field, value) in [
        ("field_length", d.field_length),
        ("field_width", d.field_width),
        ("line_width", d.line_width),
        ("penalty_area.length", d.penalty_area.length),
        ("penalty_area.width", d.penalty_area.width),
        ("penalty_mark_distance", d.penalty_mark_distance),
        ("penalty_mark_size", d.penalty_mark_size),
        ("center_circle_diameter", d.center_circle_diameter),
        ("goal_inner_width", d.goal_inner_width),
        ("goal_post_diameter", d.goal_post_diameter),
        ("goal_depth", d.goal_depth),
        ("goal_height", d.goal_height),
    ] {
        v.positive(field, value)?;
    }
    v.check(
        d.border_strip_width >= 0.0,
        "border_strip_width",
        ">= 0".into(),
        d.border_strip_width,
    )?;

    let half_length = d.field_length / 2.0;
    v.below("line_width", d.line_width, d.penalty_area.length, "penalty_area.length")?;
    v.below("penalty_area.length", d.penalty_area.length, half_length, "half the field_length")?;
    v.below("penalty_area.width", d.penalty_area.width, d.field_width, "field_width")?;
    let mut narrowest_box = (d.penalty_area.width, "penalty_area.width");
    if let Some(area) = d.goal_area {
        v.positive("goal_area.length", area.length)?;
        v.positive("goal_area.width", area.width)?;
        v.below("goal_area.length", area.length, d.penalty_area.length, "penalty_area.length")?;
        v.below("goal_area.width", area.width, d.penalty_area.width, "penalty_area.width")?;
        narrowest_box = (area.width, "goal_area.width");
    }
    v.below(
        "penalty_mark_distance",
        d.penalty_mark_distance,
        half_length,
        "half the field_length",
    )?;
    let circle_limit = d.field_length.min(d.field_width);
    v.below("center_circle_diameter", d.center_circle_diameter, circle_limit, "the field")?;
    v.below("goal_inner_width", d.goal_inner_width, narrowest_box.0, narrowest_box.1)?;
    v.check(
        d.goal_depth <= d.border_strip_width,
        "goal_depth",
        format!("<= {} (border_strip_width)", d.border_strip_width),
        d.goal_depth,
    )?;

    let mut names = HashSet::new();
    let (carpet_x, carpet_y) =
        (half_length + d.border_strip_width, d.field_width / 2.0 + d.border_strip_width);
    for (i, beacon) in d.beacons.iter().enumerate() {
        let field = |name: &str| format!("beacons[{i}].{name}");
        if beacon.name.trim().is_empty() || !names.insert(beacon.name.as_str()) {
            return Err(v.fail(&field("name"), "non-empty and unique".into(), &beacon.name));
        }
        v.positive(&field("diameter"), beacon.diameter)?;
        v.positive(&field("height"), beacon.height)?;
        v.check(
            beacon.x.abs() <= carpet_x,
            &field("x"),
            format!("within ±{carpet_x} (the carpet)"),
            beacon.x,
        )?;
        v.check(
            beacon.y.abs() <= carpet_y,
            &field("y"),
            format!("within ±{carpet_y} (the carpet)"),
            beacon.y,
        )?;
        let inside = beacon.x.abs() <= half_length && beacon.y.abs() <= d.field_width / 2.0;
        if inside {
            return Err(v.fail(
                &field("x, y"),
                "outside the field lines".into(),
                format!("({}, {})", beacon.x, beacon.y),
            ));
        }
        if beacon.colours.is_empty() {
            return Err(v.fail(&field("colours"), "non-empty".into(), "[]"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spl() -> Field {
        match Field::preset("spl") {
            Ok(field) => field,
            Err(e) => panic!("{e}"),
        }
    }

    fn paper() -> Field {
        match Field::preset("paper2010") {
            Ok(field) => field,
            Err(e) => panic!("{e}"),
        }
    }

    fn count(field: &Field, kind: LandmarkKind) -> usize {
        field.landmarks_of(kind).count()
    }

    fn error_of(text: &str) -> String {
        match Field::from_toml_str(text, "fields/x.toml") {
            Ok(_) => panic!("expected an error for:\n{text}"),
            Err(e) => e.to_string(),
        }
    }

    fn approx(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn presets_load_with_rule_book_values() {
        let d = spl().dimensions().clone();
        assert_eq!((d.field_length, d.field_width), (9.0, 6.0));
        assert_eq!(d.penalty_area, AreaDimensions { length: 1.65, width: 4.0 });
        assert_eq!(d.goal_area, Some(AreaDimensions { length: 0.6, width: 2.2 }));
        assert_eq!(d.penalty_mark_distance, 1.3);
        assert!(d.beacons.is_empty());

        let p = paper().dimensions().clone();
        assert_eq!((p.field_length, p.field_width, p.goal_inner_width), (6.0, 4.0, 1.4));
        assert_eq!(p.goal_area, None);
        assert_eq!(p.goal_colours, GoalColours { own: Colour::SkyBlue, opponent: Colour::Yellow });
        assert_eq!(p.beacons.len(), 2);
        assert!(matches!(Field::preset("rcss"), Err(FieldError::UnknownPreset(_))));
    }

    #[test]
    fn spl_landmark_counts() {
        let f = spl();
        assert_eq!(count(&f, LandmarkKind::GoalPost), 4);
        assert_eq!(count(&f, LandmarkKind::PenaltyMark), 2);
        assert_eq!(count(&f, LandmarkKind::CenterCircle), 1);
        assert_eq!(count(&f, LandmarkKind::Beacon), 0);
        // 4 corners + 2 per box front x 4 boxes.
        assert_eq!(count(&f, LandmarkKind::LCrossing), 12);
        // 2 on the halfway line + 2 per box at the goal line x 4 boxes.
        assert_eq!(count(&f, LandmarkKind::TCrossing), 10);
        // Halfway line through the centre circle.
        assert_eq!(count(&f, LandmarkKind::XCrossing), 2);
        // 4 boundary lines + halfway line + 3 per box x 4 boxes.
        assert_eq!(f.lines().len(), 17);
    }

    #[test]
    fn paper_landmark_counts() {
        let f = paper();
        assert_eq!(count(&f, LandmarkKind::GoalPost), 4);
        assert_eq!(count(&f, LandmarkKind::PenaltyMark), 2);
        assert_eq!(count(&f, LandmarkKind::Beacon), 2);
        assert_eq!(count(&f, LandmarkKind::LCrossing), 8);
        assert_eq!(count(&f, LandmarkKind::TCrossing), 6);
        assert_eq!(count(&f, LandmarkKind::XCrossing), 2);
        assert_eq!(f.lines().len(), 11);
        let beacon = f.landmarks_of(LandmarkKind::Beacon).next().map(Landmark::position);
        assert_eq!(beacon, Some(Point::new(0.0, 2.4)));
    }

    #[test]
    fn goal_posts_stand_on_the_goal_line() {
        let f = spl();
        for post in f.landmarks_of(LandmarkKind::GoalPost) {
            let Landmark::GoalPost { position, goal, post } = *post else { unreachable!() };
            // The post's front touches the field-side edge of the goal line.
            assert!(approx(position.x, goal.sign() * 4.525), "{position:?}");
            assert!(approx(position.y, post.sign() * 0.8), "{position:?}");
        }
        let goal = f.goal(Side::Opponent);
        assert!(approx(goal.left_post.x, 4.525) && approx(goal.left_post.y, 0.8));
        assert!(approx(goal.inside.max.x, 5.0));
    }

    #[test]
    fn crossings_lie_on_lines_and_arms_follow_lines() {
        for f in [spl(), paper()] {
            let circle = f.centre_circle();
            for landmark in f.landmarks_of(LandmarkKind::LCrossing).chain(
                f.landmarks_of(LandmarkKind::TCrossing)
                    .chain(f.landmarks_of(LandmarkKind::XCrossing)),
            ) {
                let p = landmark.position();
                for arm in landmark.arm_directions() {
                    // A short step along every arm stays on a painted line (or the circle).
                    let q = Point::new(p.x + 0.1 * arm.cos(), p.y + 0.1 * arm.sin());
                    let on_line = f.lines().iter().any(|l| distance_to_segment(q, l) < 1e-6);
                    let on_circle = (q.distance(circle.centre) - circle.radius).abs() < 0.01;
                    assert!(on_line || on_circle, "{landmark:?}: arm {arm} leaves the lines");
                }
            }
        }
    }

    fn distance_to_segment(p: Point, l: &LineSegment) -> f64 {
        let (dx, dy) = (l.end.x - l.start.x, l.end.y - l.start.y);
        let t = (((p.x - l.start.x) * dx + (p.y - l.start.y) * dy) / (dx * dx + dy * dy))
            .clamp(0.0, 1.0);
        p.distance(Point::new(l.start.x + t * dx, l.start.y + t * dy))
    }

    #[test]
    fn corner_orientation_points_into_the_field() {
        let f = spl();
        let corner = f
            .landmarks_of(LandmarkKind::LCrossing)
            .find(|l| l.position() == Point::new(4.5, 3.0))
            .map(|l| l.arm_directions());
        let Some(mut arms) = corner else { panic!("no corner at (4.5, 3)") };
        arms.sort_by(f64::total_cmp);
        assert!(approx(arms[0], -PI) && approx(arms[1], -FRAC_PI_2), "{arms:?}");
    }

    #[test]
    fn referee_helpers() {
        let f = spl();
        let r = 0.05;
        assert!(f.is_inside_field(4.52, 3.02));
        assert!(!f.is_inside_field(4.6, 0.0));
        assert!(f.is_on_carpet(5.1, 3.6));
        assert!(!f.is_on_carpet(5.3, 0.0));
        assert_eq!(f.half(-0.1), Side::Own);
        assert_eq!(f.half(0.1), Side::Opponent);
        assert_eq!(f.ball_status(4.5, 0.0, r), BallStatus::InPlay);
        assert_eq!(f.ball_status(4.6, 0.0, r), BallStatus::Goal(Side::Opponent));
        assert_eq!(f.ball_status(-4.6, 0.5, r), BallStatus::Goal(Side::Own));
        assert_eq!(f.ball_status(4.6, 0.9, r), BallStatus::OutOverGoalLine(Side::Opponent));
        assert_eq!(f.ball_status(0.0, -3.1, r), BallStatus::OutOverSideLine(Lateral::Right));
        assert_eq!(f.ball_status(0.0, 3.07, r), BallStatus::InPlay);
        assert_eq!(f.is_in_goal(4.8, 0.2), Some(Side::Opponent));
        assert_eq!(f.is_in_goal(-4.8, -0.7), Some(Side::Own));
        assert_eq!(f.is_in_goal(4.8, 0.8), None);
        assert_eq!(f.is_in_goal(4.5, 0.0), None);
        let area = f.penalty_area(Side::Own);
        assert!(area.contains(Point::new(-3.0, 1.9)) && !area.contains(Point::new(-2.8, 0.0)));
        assert!(f.goal_area(Side::Opponent).is_some_and(|a| approx(a.min.x, 3.9)));
        assert_eq!(paper().goal_area(Side::Own), None);
    }

    #[test]
    fn invalid_values_name_the_file_and_the_field() {
        let cases = [
            (
                "field_length = 9.0",
                "field_length = -3.0",
                "fields/x.toml: field_length must be > 0, got -3",
            ),
            (
                "line_width = 0.05",
                "line_width = nan",
                "fields/x.toml: line_width must be > 0, got NaN",
            ),
            ("goal_depth = 0.5", "goal_depth = inf", "goal_depth must be > 0, got inf"),
            (
                "border_strip_width = 0.7",
                "border_strip_width = -0.1",
                "border_strip_width must be >= 0",
            ),
            (
                "penalty_area = { length = 1.65, width = 4.0 }",
                "penalty_area = { length = 1.65, width = 6.5 }",
                "penalty_area.width must be < 6 (field_width), got 6.5",
            ),
            (
                "penalty_area = { length = 1.65, width = 4.0 }",
                "penalty_area = { length = 5, width = 4.0 }",
                "penalty_area.length must be < 4.5 (half the field_length), got 5",
            ),
            (
                "goal_area = { length = 0.6, width = 2.2 }",
                "goal_area = { length = 2.0, width = 2.2 }",
                "goal_area.length must be < 1.65 (penalty_area.length), got 2",
            ),
            (
                "penalty_mark_distance = 1.3",
                "penalty_mark_distance = 4.5",
                "penalty_mark_distance must be < 4.5",
            ),
            (
                "center_circle_diameter = 1.5",
                "center_circle_diameter = 7",
                "center_circle_diameter must be < 6",
            ),
            (
                "goal_inner_width = 1.5",
                "goal_inner_width = 2.3",
                "goal_inner_width must be < 2.2 (goal_area.width), got 2.3",
            ),
            (
                "goal_depth = 0.5",
                "goal_depth = 0.8",
                "goal_depth must be <= 0.7 (border_strip_width), got 0.8",
            ),
            ("name = \"SPL\"", "name = \"\"", "name must be non-empty"),
        ];
        for (from, to, expected) in cases {
            assert!(SPL_TOML.contains(from), "{from}");
            let message = error_of(&SPL_TOML.replacen(from, to, 1));
            assert!(message.contains(expected), "{message:?} does not contain {expected:?}");
            assert!(message.starts_with("fields/x.toml: "), "{message}");
        }
    }

    #[test]
    fn invalid_beacons_are_rejected() {
        let cases = [
            ("y = 2.4", "y = 1.0", "beacons[0].x, y must be outside the field lines, got (0, 1)"),
            ("y = 2.4", "y = 3.0", "beacons[0].y must be within ±2.7 (the carpet), got 3"),
            ("diameter = 0.2", "diameter = 0", "beacons[0].diameter must be > 0, got 0"),
            (
                "name = \"right\"",
                "name = \"left\"",
                "beacons[1].name must be non-empty and unique, got left",
            ),
            (
                "colours = [\"yellow\", \"white\", \"yellow\"]",
                "colours = []",
                "beacons[1].colours must be non-empty",
            ),
        ];
        for (from, to, expected) in cases {
            assert!(PAPER2010_TOML.contains(from), "{from}");
            let message = error_of(&PAPER2010_TOML.replacen(from, to, 1));
            assert!(message.contains(expected), "{message:?} does not contain {expected:?}");
        }
    }

    #[test]
    fn syntax_errors_and_unknown_keys_name_the_file() {
        let message = error_of(&SPL_TOML.replacen("goal_height", "goal_hieght", 1));
        assert!(message.starts_with("fields/x.toml: "), "{message}");
        assert!(message.contains("goal_hieght"), "{message}");
        let message = error_of("field_length = ");
        assert!(message.starts_with("fields/x.toml: "), "{message}");
        let message = error_of(&SPL_TOML.replacen("\"white\" }", "\"mauve\" }", 1));
        assert!(message.contains("mauve"), "{message}");
    }

    #[test]
    fn load_reads_files_and_reports_missing_ones() {
        let dir = std::env::temp_dir().join(format!("strata-spl-field-{}", std::process::id()));
        let write = std::fs::create_dir_all(&dir).and_then(|()| {
            std::fs::write(dir.join("good.toml"), SPL_TOML)?;
            std::fs::write(dir.join("bad.toml"), SPL_TOML.replacen("9.0", "-3.0", 1))
        });
        assert!(write.is_ok(), "{write:?}");
        assert!(Field::load(dir.join("good.toml")).is_ok());
        let bad = Field::load(dir.join("bad.toml")).map(|_| ()).map_err(|e| e.to_string());
        let expected =
            format!("{}: field_length must be > 0, got -3", dir.join("bad.toml").display());
        assert_eq!(bad, Err(expected));
        let missing = Field::load(dir.join("missing.toml")).map(|_| ()).map_err(|e| e.to_string());
        assert!(missing.is_err_and(|m| m.contains("missing.toml")));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn dimensions_round_trip_through_toml() {
        for f in [spl(), paper()] {
            let text = toml::to_string(f.dimensions());
            let Ok(text) = text else { panic!("{text:?}") };
            let again = Field::from_toml_str(&text, "round trip").map(|g| g.dimensions().clone());
            assert_eq!(again.ok().as_ref(), Some(f.dimensions()));
        }
    }
}
