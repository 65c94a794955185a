//! How a world state is written (logs, JSON) and read back.
//!
//! A world state is published thirty times a second per robot and logged every time: forty
//! objects, each in two frames with covariances, names and map positions. Most of that is
//! either fixed (names, classes, the map: the [`WorldLayout`], written once as a [`Shared`]
//! value) or follows from the rest (an object's field-frame estimate from its robot-frame one
//! and the pose; an untracked landmark's estimate from the map and the pose). So a world state
//! is written as what the world model decided — the pose, each object's confidence and filter
//! estimate — and the rest is worked out again when it is read, by the function the model
//! published it with ([`derive`]), to the same bits.

use nalgebra::{Matrix2, Vector2, Vector3};
use serde::ser::SerializeSeq;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use strata_runtime::{Shared, Time};

use super::published::{PoseFrame, Track, derive};
use super::state::{
    MapAccuracy, ObjectEstimate, OdometryErrorEstimate, PoseEstimate, WorldDiagnostics,
    WorldLayout, WorldState,
};
use super::team::TeamObject;
use crate::geometry::{Point, Robot, Vector};

/// An object as written: its confidence and, when a filter follows it, the filter's estimate.
#[derive(Serialize, Deserialize)]
#[serde(rename = "ObjectEstimate")]
struct ObjectRecord {
    confidence: f64,
    track: Option<TrackRecord>,
}

/// A filter's estimate, robot frame.
#[derive(Serialize, Deserialize)]
#[serde(rename = "Track")]
struct TrackRecord {
    position: Point<Robot>,
    covariance: Matrix2<f64>,
    last_seen: Time,
    /// Mobile objects and obstacles.
    velocity: Option<VelocityRecord>,
}

#[derive(Serialize, Deserialize)]
#[serde(rename = "Velocity")]
struct VelocityRecord {
    velocity: Vector<Robot>,
    covariance: Matrix2<f64>,
}

/// The objects of a state, written one record each without collecting them first.
struct ObjectRecords<'a>(&'a [ObjectEstimate]);

impl Serialize for ObjectRecords<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.0.len()))?;
        for o in self.0 {
            let track = match (o.tracked, o.last_seen) {
                (true, Some(last_seen)) => Some(TrackRecord {
                    position: o.position,
                    covariance: o.covariance,
                    last_seen,
                    velocity: o
                        .velocity
                        .zip(o.velocity_covariance)
                        .map(|(velocity, covariance)| VelocityRecord { velocity, covariance }),
                }),
                _ => None,
            };
            seq.serialize_element(&ObjectRecord { confidence: o.confidence, track })?;
        }
        seq.end()
    }
}

/// A world state as written (borrowed from the state).
#[derive(Serialize)]
#[serde(rename = "WorldState")]
struct StateOut<'a> {
    stamp: Time,
    pose: &'a PoseEstimate,
    filter_heading: Option<f64>,
    layout: &'a Shared<WorldLayout>,
    objects: ObjectRecords<'a>,
    map_accuracy: Option<MapAccuracy>,
    odometry_error: &'a OdometryErrorEstimate,
    team: &'a [TeamObject],
    diagnostics: &'a WorldDiagnostics,
}

/// A world state as read; field for field [`StateOut`].
#[derive(Deserialize)]
#[serde(rename = "WorldState")]
struct StateIn {
    stamp: Time,
    pose: PoseEstimate,
    filter_heading: Option<f64>,
    layout: Shared<WorldLayout>,
    objects: Vec<ObjectRecord>,
    map_accuracy: Option<MapAccuracy>,
    odometry_error: OdometryErrorEstimate,
    team: Vec<TeamObject>,
    diagnostics: WorldDiagnostics,
}

impl Serialize for WorldState {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        StateOut {
            stamp: self.stamp,
            pose: &self.pose,
            filter_heading: self.filter_heading,
            layout: &self.layout,
            objects: ObjectRecords(&self.objects),
            map_accuracy: self.map_accuracy,
            odometry_error: &self.odometry_error,
            team: &self.team,
            diagnostics: &self.diagnostics,
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for WorldState {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<WorldState, D::Error> {
        let state = StateIn::deserialize(deserializer)?;
        let layout = &state.layout;
        if state.objects.len() != layout.objects.len() {
            return Err(serde::de::Error::custom(format!(
                "a world state with {} objects for a layout of {}",
                state.objects.len(),
                layout.objects.len()
            )));
        }
        let pose = state.pose.pose;
        let frame = PoseFrame {
            pose,
            pose_cov: state.pose.covariance,
            heading: pose.theta.sin_cos(),
            map_frame: state
                .filter_heading
                .map(|theta| (Vector3::new(pose.x, pose.y, theta), theta.sin_cos())),
            threshold: layout.unknown_threshold,
        };
        let mut unknown = None;
        let objects = state
            .objects
            .iter()
            .zip(&layout.objects)
            .enumerate()
            .map(|(i, (record, info))| {
                let track = record.track.as_ref().map(|t| Track {
                    position: Vector2::new(t.position.x, t.position.y),
                    covariance: t.covariance,
                    velocity: t.velocity.as_ref().map(|v| (v.velocity, v.covariance)),
                    last_seen: t.last_seen,
                });
                derive(&frame, info.map_position, record.confidence, track, &mut unknown)
                    .object(i, info)
            })
            .collect();
        Ok(WorldState {
            stamp: state.stamp,
            pose: state.pose,
            objects,
            map_accuracy: state.map_accuracy,
            odometry_error: state.odometry_error,
            team: state.team,
            camera: layout.camera,
            detection_probability: layout.detection_probability,
            view_margin: layout.view_margin,
            unknown_threshold: layout.unknown_threshold,
            diagnostics: state.diagnostics,
            index: layout.index().clone(),
            filter_heading: state.filter_heading,
            layout: state.layout,
        })
    }
}
