//! The perception module (paper 3.1): turns the platform's sensor frames into percepts for the
//! reactive layer and world modeling. Platform-independent: any platform that delivers a
//! [`SensorFrame`] works.

use serde::{Deserialize, Serialize};
use strata_runtime::{Context, Input, Module, ModuleError, Output, Policy, PortName};

use crate::geometry::normalize_angle;
use crate::percept::{CameraPercepts, Observation, Percepts, Signal, SignalKind, ViewCone};
use crate::platform::{ObjectClass, PlatformInfo, SensorFrame};
use crate::world::CameraNoise;

/// What perception does with the camera's detections besides attaching their noise. The noise
/// itself is the robot's one camera model, [`CameraNoise`] (world modeling's
/// `WorldModelConfig::camera`): perception attaches it to each observation and world modeling
/// predicts observations with it, so the two cannot disagree.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerceptionConfig {
    /// Classes the camera reports that are signals, not objects to track (the referee, whose
    /// variant is its gesture): they go to the planning layer as [`Signal`]s, not to world
    /// modeling.
    pub signal_classes: Vec<ObjectClass>,
}

/// Converts one sensor frame into percepts, each observation with the noise `camera` gives it,
/// and appends the signals the frame carried to `signals`. Detections with non-finite numbers
/// are dropped (and counted by the caller): a filter fed a NaN is lost for good; so is a
/// whistle whose confidence is not a number.
pub fn percepts_from_frame(
    frame: &SensorFrame,
    info: &PlatformInfo,
    config: &PerceptionConfig,
    camera_noise: &CameraNoise,
    signals: &mut Vec<Signal>,
) -> (Percepts, usize) {
    let mut rejected = 0;
    if let Some(confidence) = frame.whistle {
        if confidence.is_finite() {
            signals.push(Signal {
                stamp: frame.stamp,
                kind: SignalKind::Whistle,
                confidence: confidence.clamp(0.0, 1.0),
            });
        } else {
            rejected += 1;
        }
    }
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
                let bearing = normalize_angle(d.bearing + camera.head.yaw);
                if config.signal_classes.contains(&d.class) {
                    let kind = SignalKind::Sight {
                        class: d.class,
                        variant: d.variant,
                        range: d.range,
                        bearing,
                    };
                    signals.push(Signal { stamp: camera.stamp, kind, confidence: 1.0 });
                    return None;
                }
                let (range_sigma, bearing_sigma) = camera_noise.sigmas(d.range);
                Some(Observation {
                    class: d.class,
                    variant: d.variant,
                    range: d.range,
                    bearing,
                    orientation: d.orientation.map(|o| normalize_angle(o + camera.head.yaw)),
                    range_sigma,
                    bearing_sigma,
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

/// The ports of the perception module, declared once for the assembly and for replay.
#[derive(Clone, Copy, Debug)]
pub struct PerceptionPorts {
    /// The platform's sensor frames, every one: a frame may carry a camera image.
    pub frames: Input<SensorFrame>,
    pub percepts: Output<Percepts>,
    pub signals: Output<Signal>,
}

impl PerceptionPorts {
    pub const FRAMES: PortName<SensorFrame> = PortName::new("frames");
    pub const PERCEPTS: PortName<Percepts> = PortName::new("percepts");
    pub const SIGNALS: PortName<Signal> = PortName::new("signals");
    /// Frames waiting for a perception cycle; more means perception falls behind the sensors.
    pub const FRAME_QUEUE: usize = 4;

    /// Declares the ports; perception runs on every sensor frame.
    pub fn declare(p: &mut strata_runtime::Ports<'_>) -> PerceptionPorts {
        let ports = PerceptionPorts {
            frames: p.input(Self::FRAMES, Policy::queue(Self::FRAME_QUEUE)),
            percepts: p.output(Self::PERCEPTS),
            signals: p.output(Self::SIGNALS),
        };
        p.trigger(strata_runtime::Trigger::on_any([ports.frames.into()]));
        ports
    }
}

/// Turns every sensor frame into percepts stamped with the measurement time, and the
/// referee's signals among them into signals.
pub struct PerceptionModule {
    info: PlatformInfo,
    config: PerceptionConfig,
    camera: CameraNoise,
    ports: PerceptionPorts,
    /// Reused for every frame's signals (nearly always none).
    frame_signals: Vec<Signal>,
    rejected_detections: u64,
}

impl std::fmt::Debug for PerceptionModule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PerceptionModule")
            .field("platform", &self.info.name)
            .field("rejected_detections", &self.rejected_detections)
            .finish_non_exhaustive()
    }
}

impl PerceptionModule {
    pub fn new(
        info: PlatformInfo,
        config: PerceptionConfig,
        camera: CameraNoise,
        ports: PerceptionPorts,
    ) -> PerceptionModule {
        PerceptionModule {
            info,
            config,
            camera,
            ports,
            frame_signals: Vec::new(),
            rejected_detections: 0,
        }
    }
}

impl Module for PerceptionModule {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        // One at a time: no list is allocated in the sensor path.
        while let Some(package) = ctx.take(self.ports.frames) {
            let (percepts, rejected) = percepts_from_frame(
                &package.value,
                &self.info,
                &self.config,
                &self.camera,
                &mut self.frame_signals,
            );
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
            ctx.send_stamped(self.ports.percepts, percepts, stamp);
            for signal in self.frame_signals.drain(..) {
                ctx.send_stamped(self.ports.signals, signal, signal.stamp);
            }
        }
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
    fn observations_carry_the_noise_of_the_robots_camera_model() {
        let camera = CameraNoise {
            range_sigma: 0.2,
            range_sigma_per_metre: 0.1,
            bearing_sigma: 0.07,
            use_percept_sigmas: true,
        };
        let frame = SensorFrame {
            stamp: Time::from_nanos(7),
            camera: Some(CameraFrame {
                stamp: Time::from_nanos(5),
                head: HeadAngles::default(),
                footprint: None,
                detections: vec![Detection {
                    class: ObjectClass(1),
                    variant: None,
                    range: 3.0,
                    bearing: 0.0,
                    orientation: None,
                }],
            }),
            ..SensorFrame::default()
        };
        let mut signals = Vec::new();
        let (percepts, _) = percepts_from_frame(
            &frame,
            &info(),
            &PerceptionConfig::default(),
            &camera,
            &mut signals,
        );
        let observation = &percepts.camera.expect("a camera frame").observations[0];
        // The sigmas world modeling predicts for the same range (active vision).
        assert_eq!((observation.range_sigma, observation.bearing_sigma), camera.sigmas(3.0));
        assert!((observation.range_sigma - 0.5).abs() < 1e-12);
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
        let mut signals = Vec::new();
        let (percepts, rejected) = percepts_from_frame(
            &frame,
            &info(),
            &PerceptionConfig::default(),
            &CameraNoise::default(),
            &mut signals,
        );
        assert_eq!(rejected, 1);
        assert!(signals.is_empty());
        let camera = percepts.camera.expect("camera percepts");
        assert_eq!(camera.observations.len(), 1);
        let o = camera.observations[0];
        assert!((o.bearing - 0.7).abs() < 1e-12);
        assert!((o.orientation.unwrap_or_default() - 0.6).abs() < 1e-12);
        assert!((o.range_sigma - (0.05 + 0.16)).abs() < 1e-12);
        assert!((camera.view.direction - 0.5).abs() < 1e-12);
        assert_eq!(percepts.stamp, Time::from_nanos(7));
    }

    #[test]
    fn signal_classes_and_the_whistle_become_signals_not_observations() {
        let referee = ObjectClass(4);
        let frame = SensorFrame {
            stamp: Time::from_nanos(9),
            whistle: Some(1.5),
            camera: Some(CameraFrame {
                stamp: Time::from_nanos(5),
                head: HeadAngles { yaw: -0.5, pitch: 0.2 },
                detections: vec![
                    Detection {
                        class: referee,
                        variant: Some(1),
                        range: 5.0,
                        bearing: 0.25,
                        orientation: None,
                    },
                    Detection {
                        class: ObjectClass(1),
                        variant: None,
                        range: 2.0,
                        bearing: 0.0,
                        orientation: None,
                    },
                ],
                footprint: None,
            }),
            ..SensorFrame::default()
        };
        let config = PerceptionConfig { signal_classes: vec![referee] };
        let mut signals = Vec::new();
        let (percepts, rejected) =
            percepts_from_frame(&frame, &info(), &config, &CameraNoise::default(), &mut signals);
        assert_eq!(rejected, 0);
        assert_eq!(percepts.observations().len(), 1, "the ball only");
        assert_eq!(percepts.observations()[0].class, ObjectClass(1));
        assert_eq!(signals.len(), 2);
        // Clamped to [0, 1], stamped with the frame.
        assert_eq!(
            signals[0],
            Signal { stamp: Time::from_nanos(9), kind: SignalKind::Whistle, confidence: 1.0 }
        );
        let SignalKind::Sight { class, variant, range, bearing } = signals[1].kind else {
            panic!("a sight: {:?}", signals[1]);
        };
        assert_eq!(
            (class, variant, range, signals[1].stamp),
            (referee, Some(1), 5.0, Time::from_nanos(5))
        );
        assert!((bearing + 0.25).abs() < 1e-12, "in the body frame: {bearing}");

        // A whistle that is not a number is dropped and counted.
        let garbled = SensorFrame { whistle: Some(f64::NAN), ..SensorFrame::default() };
        signals.clear();
        let (_, rejected) =
            percepts_from_frame(&garbled, &info(), &config, &CameraNoise::default(), &mut signals);
        assert_eq!((rejected, signals.len()), (1, 0));
    }
}
