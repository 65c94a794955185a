//! Foxglove's well-known message types, as far as the scene uses them, and their JSON Schemas:
//! this crate's own encoding of the definitions Foxglove publishes
//! (<https://docs.foxglove.dev/docs/visualization/message-schemas/introduction>; the
//! `@foxglove/schemas` package). Field names and types are Foxglove's, so that its app decodes
//! the messages and its 3D panel draws them; `crates/strata/tests/generic_tools.rs` checks every
//! derived message against the package's own JSON Schemas.
//!
//! In JSON (message encoding `json`, schema encoding `jsonschema`), as Foxglove reads these
//! schemas: times and durations are `{sec, nsec}` objects, enumerations their numbers.

use std::sync::OnceLock;

use serde::Serialize;
use serde_json::{Value, json};
use strata_log::RecordSchema;

/// A time: seconds and nanoseconds (`time` in Foxglove's schemas).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Timestamp {
    pub sec: u32,
    pub nsec: u32,
}

impl Timestamp {
    pub fn from_nanos(nanos: u64) -> Timestamp {
        let sec = u32::try_from(nanos / 1_000_000_000).unwrap_or(u32::MAX);
        Timestamp { sec, nsec: (nanos % 1_000_000_000) as u32 }
    }

    pub fn from_secs_f64(secs: f64) -> Timestamp {
        let nanos = if secs.is_finite() && secs > 0.0 { (secs * 1e9).round() as u64 } else { 0 };
        Timestamp::from_nanos(nanos)
    }
}

/// A span of time (`duration`); zero: forever, as a lifetime.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Duration {
    pub sec: i32,
    pub nsec: u32,
}

impl Duration {
    pub fn from_secs_f64(secs: f64) -> Duration {
        let nanos = if secs.is_finite() && secs > 0.0 { (secs * 1e9).round() as u64 } else { 0 };
        Duration {
            sec: i32::try_from(nanos / 1_000_000_000).unwrap_or(i32::MAX),
            nsec: (nanos % 1_000_000_000) as u32,
        }
    }
}

/// `value` to a tenth of a millimetre (or of a ten-thousandth for unitless numbers): the
/// scene is for the eye, and JSON writes the shortest text that reads back as the number, so a
/// rounded coordinate takes a few characters instead of seventeen digits.
pub fn round(value: f64) -> f64 {
    (value * 1e4).round() / 1e4
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Vector3 {
    pub const fn new(x: f64, y: f64, z: f64) -> Vector3 {
        Vector3 { x, y, z }
    }

    /// A vector with its coordinates [rounded](round).
    pub fn rounded(x: f64, y: f64, z: f64) -> Vector3 {
        Vector3 { x: round(x), y: round(y), z: round(z) }
    }
}

/// A point (`foxglove.Point3`).
pub type Point3 = Vector3;

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Quaternion {
    pub const IDENTITY: Quaternion = Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 };

    /// A turn by `angle` about the z axis (yaw, counter-clockwise seen from above).
    /// Its components [rounded](round): within about 2e-4 rad of the angle.
    pub fn about_z(angle: f64) -> Quaternion {
        let (s, c) = (angle / 2.0).sin_cos();
        Quaternion { x: 0.0, y: 0.0, z: round(s), w: round(c) }
    }

    /// A turn by `angle` about the y axis (a head pitching down is a positive turn), its
    /// components [rounded](round).
    pub fn about_y(angle: f64) -> Quaternion {
        let (s, c) = (angle / 2.0).sin_cos();
        Quaternion { x: 0.0, y: round(s), z: 0.0, w: round(c) }
    }

    /// The yaw of a turn about z (the inverse of [`Quaternion::about_z`]).
    pub fn yaw(&self) -> f64 {
        2.0 * self.z.atan2(self.w)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Pose {
    pub position: Vector3,
    pub orientation: Quaternion,
}

impl Pose {
    pub const IDENTITY: Pose =
        Pose { position: Vector3::new(0.0, 0.0, 0.0), orientation: Quaternion::IDENTITY };

    /// At `(x, y, z)`, turned by `yaw` about z ([rounded](round)).
    pub fn planar(x: f64, y: f64, z: f64, yaw: f64) -> Pose {
        Pose { position: Vector3::rounded(x, y, z), orientation: Quaternion::about_z(yaw) }
    }
}

/// Red, green, blue and alpha, each in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Color {
    pub r: f64,
    pub g: f64,
    pub b: f64,
    pub a: f64,
}

impl Color {
    pub const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
        Color { r, g, b, a }
    }

    pub const fn with_alpha(self, a: f64) -> Color {
        Color { a, ..self }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct KeyValuePair {
    pub key: String,
    pub value: String,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ArrowPrimitive {
    pub pose: Pose,
    pub shaft_length: f64,
    pub shaft_diameter: f64,
    pub head_length: f64,
    pub head_diameter: f64,
    pub color: Color,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CubePrimitive {
    pub pose: Pose,
    pub size: Vector3,
    pub color: Color,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SpherePrimitive {
    pub pose: Pose,
    pub size: Vector3,
    pub color: Color,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CylinderPrimitive {
    pub pose: Pose,
    pub size: Vector3,
    pub bottom_scale: f64,
    pub top_scale: f64,
    pub color: Color,
}

/// `foxglove.LineType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineType {
    /// Each point joined to the next.
    Strip = 0,
    /// A strip closed back to the first point.
    Loop = 1,
    /// Pairs of points, each a segment.
    List = 2,
}

impl Serialize for LineType {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u8(*self as u8)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LinePrimitive {
    #[serde(rename = "type")]
    pub kind: LineType,
    pub pose: Pose,
    pub thickness: f64,
    pub scale_invariant: bool,
    pub points: Vec<Point3>,
    pub color: Color,
    pub colors: Vec<Color>,
    pub indices: Vec<u32>,
}

impl LinePrimitive {
    /// Lines of one colour through `points`, `thickness` metres wide.
    pub fn new(kind: LineType, points: Vec<Point3>, thickness: f64, color: Color) -> LinePrimitive {
        LinePrimitive {
            kind,
            pose: Pose::IDENTITY,
            thickness,
            scale_invariant: false,
            points,
            color,
            colors: Vec::new(),
            indices: Vec::new(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TriangleListPrimitive {
    pub pose: Pose,
    pub points: Vec<Point3>,
    pub color: Color,
    pub colors: Vec<Color>,
    pub indices: Vec<u32>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TextPrimitive {
    pub pose: Pose,
    pub billboard: bool,
    pub font_size: f64,
    pub scale_invariant: bool,
    pub color: Color,
    pub text: String,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelPrimitive {
    pub pose: Pose,
    pub scale: Vector3,
    pub color: Color,
    pub override_color: bool,
    pub url: String,
    pub media_type: String,
    /// Base64 (`bytes` in JSON).
    pub data: String,
}

/// One thing drawn in a frame, replacing the entity of the same id.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneEntity {
    pub timestamp: Timestamp,
    pub frame_id: String,
    pub id: String,
    /// How long it is shown without a newer update; zero: until replaced or deleted.
    pub lifetime: Duration,
    pub frame_locked: bool,
    pub metadata: Vec<KeyValuePair>,
    pub arrows: Vec<ArrowPrimitive>,
    pub cubes: Vec<CubePrimitive>,
    pub spheres: Vec<SpherePrimitive>,
    pub cylinders: Vec<CylinderPrimitive>,
    pub lines: Vec<LinePrimitive>,
    pub triangles: Vec<TriangleListPrimitive>,
    pub texts: Vec<TextPrimitive>,
    pub models: Vec<ModelPrimitive>,
}

impl SceneEntity {
    /// An entity without primitives yet.
    pub fn new(timestamp: Timestamp, frame_id: &str, id: &str, lifetime: Duration) -> SceneEntity {
        SceneEntity {
            timestamp,
            frame_id: frame_id.to_owned(),
            id: id.to_owned(),
            lifetime,
            frame_locked: false,
            metadata: Vec::new(),
            arrows: Vec::new(),
            cubes: Vec::new(),
            spheres: Vec::new(),
            cylinders: Vec::new(),
            lines: Vec::new(),
            triangles: Vec::new(),
            texts: Vec::new(),
            models: Vec::new(),
        }
    }

    pub fn meta(&mut self, key: &str, value: impl Into<String>) {
        self.metadata.push(KeyValuePair { key: key.to_owned(), value: value.into() });
    }
}

/// `foxglove.SceneEntityDeletionType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeletionType {
    MatchingId = 0,
    All = 1,
}

impl Serialize for DeletionType {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u8(*self as u8)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneEntityDeletion {
    pub timestamp: Timestamp,
    #[serde(rename = "type")]
    pub kind: DeletionType,
    pub id: String,
}

/// `foxglove.SceneUpdate`: entities to delete, then entities to add or replace.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SceneUpdate {
    pub deletions: Vec<SceneEntityDeletion>,
    pub entities: Vec<SceneEntity>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameTransform {
    pub timestamp: Timestamp,
    pub parent_frame_id: String,
    pub child_frame_id: String,
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `foxglove.FrameTransforms`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameTransforms {
    pub transforms: Vec<FrameTransform>,
}

/// `foxglove.LogLevel`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogLevel {
    Unknown = 0,
    Debug = 1,
    Info = 2,
    Warning = 3,
    Error = 4,
    Fatal = 5,
}

impl Serialize for LogLevel {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_u8(*self as u8)
    }
}

/// `foxglove.Log`: one line of Foxglove's log panel.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Log {
    pub timestamp: Timestamp,
    pub level: LogLevel,
    pub message: String,
    /// Who says it (a robot, `referee`).
    pub name: String,
    pub file: String,
    pub line: u32,
}

// ---- JSON Schemas. ----

/// An object of these fields, every one required.
fn object(title: &str, fields: &[(&str, Value)]) -> Value {
    let properties: serde_json::Map<String, Value> =
        fields.iter().map(|(name, schema)| ((*name).to_owned(), schema.clone())).collect();
    let required: Vec<&str> = fields.iter().map(|(name, _)| *name).collect();
    json!({ "title": title, "type": "object", "properties": properties, "required": required })
}

fn number() -> Value {
    json!({ "type": "number" })
}

fn integer() -> Value {
    json!({ "type": "integer" })
}

fn string() -> Value {
    json!({ "type": "string" })
}

fn boolean() -> Value {
    json!({ "type": "boolean" })
}

fn array(items: Value) -> Value {
    json!({ "type": "array", "items": items })
}

fn enumeration(title: &str, values: &[&str]) -> Value {
    let cases: Vec<Value> =
        values.iter().enumerate().map(|(i, name)| json!({ "title": name, "const": i })).collect();
    json!({ "title": title, "oneOf": cases })
}

fn time() -> Value {
    json!({
        "type": "object",
        "title": "time",
        "properties": {
            "sec": { "type": "integer", "minimum": 0 },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 },
        },
    })
}

fn duration() -> Value {
    json!({
        "type": "object",
        "title": "duration",
        "properties": {
            "sec": { "type": "integer" },
            "nsec": { "type": "integer", "minimum": 0, "maximum": 999_999_999 },
        },
    })
}

fn vector3(title: &str) -> Value {
    object(title, &[("x", number()), ("y", number()), ("z", number())])
}

fn quaternion() -> Value {
    object(
        "foxglove.Quaternion",
        &[("x", number()), ("y", number()), ("z", number()), ("w", number())],
    )
}

fn pose() -> Value {
    object(
        "foxglove.Pose",
        &[("position", vector3("foxglove.Vector3")), ("orientation", quaternion())],
    )
}

fn color() -> Value {
    object("foxglove.Color", &[("r", number()), ("g", number()), ("b", number()), ("a", number())])
}

fn points() -> Value {
    array(vector3("foxglove.Point3"))
}

fn scene_entity() -> Value {
    let key_value = object("foxglove.KeyValuePair", &[("key", string()), ("value", string())]);
    let arrow = object(
        "foxglove.ArrowPrimitive",
        &[
            ("pose", pose()),
            ("shaft_length", number()),
            ("shaft_diameter", number()),
            ("head_length", number()),
            ("head_diameter", number()),
            ("color", color()),
        ],
    );
    let sized = |title: &str| {
        object(
            title,
            &[("pose", pose()), ("size", vector3("foxglove.Vector3")), ("color", color())],
        )
    };
    let cylinder = object(
        "foxglove.CylinderPrimitive",
        &[
            ("pose", pose()),
            ("size", vector3("foxglove.Vector3")),
            ("bottom_scale", number()),
            ("top_scale", number()),
            ("color", color()),
        ],
    );
    let line = object(
        "foxglove.LinePrimitive",
        &[
            ("type", enumeration("foxglove.LineType", &["LINE_STRIP", "LINE_LOOP", "LINE_LIST"])),
            ("pose", pose()),
            ("thickness", number()),
            ("scale_invariant", boolean()),
            ("points", points()),
            ("color", color()),
            ("colors", array(color())),
            ("indices", array(integer())),
        ],
    );
    let triangles = object(
        "foxglove.TriangleListPrimitive",
        &[
            ("pose", pose()),
            ("points", points()),
            ("color", color()),
            ("colors", array(color())),
            ("indices", array(integer())),
        ],
    );
    let text = object(
        "foxglove.TextPrimitive",
        &[
            ("pose", pose()),
            ("billboard", boolean()),
            ("font_size", number()),
            ("scale_invariant", boolean()),
            ("color", color()),
            ("text", string()),
        ],
    );
    let model = object(
        "foxglove.ModelPrimitive",
        &[
            ("pose", pose()),
            ("scale", vector3("foxglove.Vector3")),
            ("color", color()),
            ("override_color", boolean()),
            ("url", string()),
            ("media_type", string()),
            ("data", json!({ "type": "string", "contentEncoding": "base64" })),
        ],
    );
    object(
        "foxglove.SceneEntity",
        &[
            ("timestamp", time()),
            ("frame_id", string()),
            ("id", string()),
            ("lifetime", duration()),
            ("frame_locked", boolean()),
            ("metadata", array(key_value)),
            ("arrows", array(arrow)),
            ("cubes", array(sized("foxglove.CubePrimitive"))),
            ("spheres", array(sized("foxglove.SpherePrimitive"))),
            ("cylinders", array(cylinder)),
            ("lines", array(line)),
            ("triangles", array(triangles)),
            ("texts", array(text)),
            ("models", array(model)),
        ],
    )
}

fn scene_update() -> Value {
    let deletion = object(
        "foxglove.SceneEntityDeletion",
        &[
            ("timestamp", time()),
            ("type", enumeration("foxglove.SceneEntityDeletionType", &["MATCHING_ID", "ALL"])),
            ("id", string()),
        ],
    );
    object(
        "foxglove.SceneUpdate",
        &[("deletions", array(deletion)), ("entities", array(scene_entity()))],
    )
}

fn frame_transforms() -> Value {
    let transform = object(
        "foxglove.FrameTransform",
        &[
            ("timestamp", time()),
            ("parent_frame_id", string()),
            ("child_frame_id", string()),
            ("translation", vector3("foxglove.Vector3")),
            ("rotation", quaternion()),
        ],
    );
    object("foxglove.FrameTransforms", &[("transforms", array(transform))])
}

fn log() -> Value {
    object(
        "foxglove.Log",
        &[
            ("timestamp", time()),
            (
                "level",
                enumeration(
                    "foxglove.LogLevel",
                    &["UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL"],
                ),
            ),
            ("message", string()),
            ("name", string()),
            ("file", string()),
            ("line", json!({ "type": "integer", "minimum": 0 })),
        ],
    )
}

fn schema(
    cell: &'static OnceLock<String>,
    name: &'static str,
    make: fn() -> Value,
) -> RecordSchema {
    let text = cell.get_or_init(|| make().to_string());
    RecordSchema { name, json_schema: text }
}

/// The schema of [`SceneUpdate`] messages.
pub fn scene_update_schema() -> RecordSchema {
    static TEXT: OnceLock<String> = OnceLock::new();
    schema(&TEXT, "foxglove.SceneUpdate", scene_update)
}

/// The schema of [`FrameTransforms`] messages.
pub fn frame_transforms_schema() -> RecordSchema {
    static TEXT: OnceLock<String> = OnceLock::new();
    schema(&TEXT, "foxglove.FrameTransforms", frame_transforms)
}

/// The schema of [`Log`] messages.
pub fn log_schema() -> RecordSchema {
    static TEXT: OnceLock<String> = OnceLock::new();
    schema(&TEXT, "foxglove.Log", log)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fields a schema declares, recursively, as paths.
    fn paths(schema: &Value, prefix: &str, out: &mut Vec<String>) {
        if let Some(properties) = schema["properties"].as_object() {
            for (name, inner) in properties {
                let path = format!("{prefix}.{name}");
                out.push(path.clone());
                paths(inner, &path, out);
            }
        }
        if schema["items"].is_object() {
            paths(&schema["items"], &format!("{prefix}[]"), out);
        }
    }

    /// Every field a message serializes is in its schema, and the other way round.
    fn fields_match(schema: RecordSchema, value: &impl Serialize) {
        let schema: Value = serde_json::from_str(schema.json_schema).expect("JSON");
        let value = serde_json::to_value(value).expect("serializes");
        fn value_paths(value: &Value, prefix: &str, out: &mut Vec<String>) {
            match value {
                Value::Object(map) => {
                    for (name, inner) in map {
                        let path = format!("{prefix}.{name}");
                        out.push(path.clone());
                        value_paths(inner, &path, out);
                    }
                }
                Value::Array(items) => {
                    if let Some(first) = items.first() {
                        value_paths(first, &format!("{prefix}[]"), out);
                    }
                }
                _ => {}
            }
        }
        let (mut declared, mut written) = (Vec::new(), Vec::new());
        paths(&schema, "", &mut declared);
        value_paths(&value, "", &mut written);
        declared.sort();
        written.sort();
        for path in &written {
            assert!(declared.contains(path), "{path} is not in the schema");
        }
        // Every field of a message with one primitive of each kind is written.
        for path in &declared {
            assert!(written.contains(path), "{path} is not written");
        }
    }

    #[test]
    fn messages_write_exactly_the_fields_of_their_schemas() {
        let t = Timestamp::from_secs_f64(1.5);
        assert_eq!(t, Timestamp { sec: 1, nsec: 500_000_000 });
        let c = Color::rgba(1.0, 0.0, 0.0, 1.0);
        let mut entity = SceneEntity::new(t, "field", "e", Duration::from_secs_f64(0.25));
        entity.meta("k", "v");
        entity.arrows.push(ArrowPrimitive {
            pose: Pose::IDENTITY,
            shaft_length: 1.0,
            shaft_diameter: 0.1,
            head_length: 0.2,
            head_diameter: 0.2,
            color: c,
        });
        entity.cubes.push(CubePrimitive {
            pose: Pose::IDENTITY,
            size: Vector3::default(),
            color: c,
        });
        entity.spheres.push(SpherePrimitive {
            pose: Pose::IDENTITY,
            size: Vector3::default(),
            color: c,
        });
        entity.cylinders.push(CylinderPrimitive {
            pose: Pose::IDENTITY,
            size: Vector3::default(),
            bottom_scale: 1.0,
            top_scale: 1.0,
            color: c,
        });
        let mut line = LinePrimitive::new(LineType::List, vec![Vector3::default(); 2], 0.05, c);
        line.colors = vec![c, c];
        line.indices = vec![0, 1];
        entity.lines.push(line);
        entity.triangles.push(TriangleListPrimitive {
            pose: Pose::IDENTITY,
            points: vec![Vector3::default(); 3],
            color: c,
            colors: vec![c],
            indices: vec![0],
        });
        entity.texts.push(TextPrimitive {
            pose: Pose::IDENTITY,
            billboard: true,
            font_size: 12.0,
            scale_invariant: true,
            color: c,
            text: "x".to_owned(),
        });
        entity.models.push(ModelPrimitive {
            pose: Pose::IDENTITY,
            scale: Vector3::new(1.0, 1.0, 1.0),
            color: c,
            override_color: false,
            url: String::new(),
            media_type: String::new(),
            data: String::new(),
        });
        let update = SceneUpdate {
            deletions: vec![SceneEntityDeletion {
                timestamp: t,
                kind: DeletionType::All,
                id: String::new(),
            }],
            entities: vec![entity],
        };
        fields_match(scene_update_schema(), &update);
        let transforms = FrameTransforms {
            transforms: vec![FrameTransform {
                timestamp: t,
                parent_frame_id: "field".to_owned(),
                child_frame_id: "home/1".to_owned(),
                translation: Vector3::default(),
                rotation: Quaternion::IDENTITY,
            }],
        };
        fields_match(frame_transforms_schema(), &transforms);
        let log = Log {
            timestamp: t,
            level: LogLevel::Info,
            message: "goal".to_owned(),
            name: "referee".to_owned(),
            file: String::new(),
            line: 0,
        };
        fields_match(log_schema(), &log);
        let written = serde_json::to_value(&update).expect("serializes");
        assert_eq!(written["deletions"][0]["type"], 1);
        assert_eq!(written["entities"][0]["lines"][0]["type"], 2);
        assert_eq!(serde_json::to_value(&log).expect("serializes")["level"], 2);
    }

    #[test]
    fn quaternions_turn_about_their_axes() {
        let q = Quaternion::about_z(1.0);
        assert!((q.yaw() - 1.0).abs() < 2e-4);
        assert!((q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0).abs() < 2e-4);
        let p = Quaternion::about_y(0.5);
        assert!((2.0 * p.y.atan2(p.w) - 0.5).abs() < 2e-4);
        // Rounded, a coordinate is short in JSON.
        let v = Vector3::rounded(-3.8249999999999997, 1.0 / 3.0, 0.0);
        assert_eq!(serde_json::to_string(&v).expect("JSON"), r#"{"x":-3.825,"y":0.3333,"z":0.0}"#);
    }
}
