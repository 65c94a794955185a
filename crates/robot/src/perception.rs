//! The perception module (paper 3.1): turns the platform's sensor frames into percepts for the
//! reactive layer and world modeling. Platform-independent: any platform that delivers a
//! [`SensorFrame`] works.

use serde::{Deserialize, Serialize};
use strata_runtime::{Context, Module, ModuleError, Output};

use crate::geometry::normalize_angle;
use crate::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use crate::platform::{PlatformError, PlatformInfo, SensorFrame, SharedPlatform, lock_platform};

/// The measurement noise perception attributes to each observation (what world modeling
/// uses as R). Range noise grows with distance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerceptionConfig {
    /// Range standard deviation at zero distance, m.
    pub range_sigma: f64,
    /// Additional range standard deviation per metre of distance.
    pub range_sigma_per_metre: f64,
    /// Bearing standard deviation, rad.
    pub bearing_sigma: f64,
}

impl Default for PerceptionConfig {
    fn default() -> Self {
        PerceptionConfig { range_sigma: 0.05, range_sigma_per_metre: 0.08, bearing_sigma: 0.035 }
    }
}

/// Converts one sensor frame into percepts. Detections with non-finite numbers are dropped
/// (and counted by the caller): a filter fed a NaN is lost for good.
pub fn percepts_from_frame(
    frame: &SensorFrame,
    info: &PlatformInfo,
    config: &PerceptionConfig,
) -> (Percepts, usize) {
    let mut rejected = 0;
    let camera = frame.camera.as_ref().map(|camera| {
        let observations = camera
            .detections
            .iter()
            .filter_map(|d| {
                let valid = d.range.is_finite()
                    && d.range >= 0.0
                    && d.bearing.is_finite()
                    && d.orientation.is_none_or(f64::is_finite);
                if !valid {
                    rejected += 1;
                    return None;
                }
                // Bearings come relative to the camera axis; the body frame adds the head yaw
                // at the time the image was taken, not the current one.
                Some(Observation {
                    class: d.class,
                    variant: d.variant,
                    range: d.range,
                    bearing: normalize_angle(d.bearing + camera.head.yaw),
                    orientation: d.orientation.map(|o| normalize_angle(o + camera.head.yaw)),
                    range_sigma: config.range_sigma + config.range_sigma_per_metre * d.range,
                    bearing_sigma: config.bearing_sigma,
                })
            })
            .collect();
        CameraPercepts {
            stamp: camera.stamp,
            view: ViewCone {
                direction: camera.head.yaw,
                fov: info.camera_fov,
                range: camera.footprint.map_or(info.camera_range, |f| f.far.min(info.camera_range)),
                near: camera.footprint.map_or(0.0, |f| f.near),
            },
            observations,
        }
    });
    let percepts = Percepts {
        stamp: frame.stamp,
        inertial: frame.inertial,
        head: frame.head,
        foot_contact: frame.foot_contact,
        buttons: frame.buttons,
        camera,
        placed: frame.placed,
    };
    (percepts, rejected)
}

/// Reads the platform every cycle and publishes percepts stamped with the measurement time.
pub struct PerceptionModule {
    platform: SharedPlatform,
    info: PlatformInfo,
    config: PerceptionConfig,
    percepts: Output<Percepts>,
    rejected_detections: u64,
    malformed_frames: u64,
}

impl std::fmt::Debug for PerceptionModule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PerceptionModule")
            .field("platform", &self.info.name)
            .field("malformed_frames", &self.malformed_frames)
            .finish_non_exhaustive()
    }
}

impl PerceptionModule {
    pub fn new(
        platform: SharedPlatform,
        config: PerceptionConfig,
        percepts: Output<Percepts>,
    ) -> PerceptionModule {
        let info = lock_platform(&platform).info();
        PerceptionModule {
            platform,
            info,
            config,
            percepts,
            rejected_detections: 0,
            malformed_frames: 0,
        }
    }
}

impl Module for PerceptionModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let frame = match lock_platform(&self.platform).read_sensors(now) {
            Ok(Some(frame)) => frame,
            Ok(None) => return Ok(()),
            // One garbled frame costs one cycle, not the robot.
            Err(PlatformError::Malformed(reason)) => {
                self.malformed_frames += 1;
                tracing::warn!(module = ctx.module_name(), %reason, total = self.malformed_frames, "malformed sensor frame skipped");
                return Ok(());
            }
            Err(error) => return Err(Box::new(error)),
        };
        let (percepts, rejected) = percepts_from_frame(&frame, &self.info, &self.config);
        if rejected > 0 {
            self.rejected_detections += rejected as u64;
            tracing::warn!(
                module = ctx.module_name(),
                rejected,
                total = self.rejected_detections,
                "detections with non-finite values dropped"
            );
        }
        let stamp = percepts.stamp;
        ctx.send_stamped(self.percepts, percepts, stamp);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::{CameraFrame, Detection, HeadAngles, ObjectClass};
    use std::time::Duration;
    use strata_runtime::Time;

    fn info() -> PlatformInfo {
        PlatformInfo {
            name: "test".into(),
            sensor_period: Duration::from_millis(12),
            camera_fov: 1.06,
            camera_range: 6.0,
            head_yaw_limits: (-2.0, 2.0),
            head_pitch_limits: (-0.6, 0.5),
            max_head_speed: 4.0,
            max_velocity: crate::geometry::Velocity::new(0.3, 0.15, 1.0),
            motions: Vec::new(),
            can_walk: true,
        }
    }

    #[test]
    fn bearings_move_to_the_body_frame_with_the_head_yaw_at_capture() {
        let detection = |bearing: f64, range: f64| Detection {
            class: ObjectClass(1),
            variant: None,
            range,
            bearing,
            orientation: Some(0.1),
        };
        let frame = SensorFrame {
            stamp: Time::from_nanos(7),
            head: HeadAngles { yaw: 0.0, pitch: 0.0 },
            camera: Some(CameraFrame {
                stamp: Time::from_nanos(5),
                head: HeadAngles { yaw: 0.5, pitch: 0.2 },
                detections: vec![detection(0.2, 2.0), detection(f64::NAN, 1.0)],
                footprint: None,
            }),
            ..SensorFrame::default()
        };
        let (percepts, rejected) =
            percepts_from_frame(&frame, &info(), &PerceptionConfig::default());
        assert_eq!(rejected, 1);
        let camera = percepts.camera.expect("camera percepts");
        assert_eq!(camera.observations.len(), 1);
        let o = camera.observations[0];
        assert!((o.bearing - 0.7).abs() < 1e-12);
        assert!((o.orientation.unwrap_or_default() - 0.6).abs() < 1e-12);
        assert!((o.range_sigma - (0.05 + 0.16)).abs() < 1e-12);
        assert!((camera.view.direction - 0.5).abs() < 1e-12);
        assert_eq!(percepts.stamp, Time::from_nanos(7));
    }
}
