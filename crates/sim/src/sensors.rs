//! The proprioceptive sensors: inertial unit (accelerometer, gyroscope, body angles), head joint
//! encoders and foot pressure, sampled at the sensor rate with noise.
//!
//! Conventions (torso frame, x forward, y left, z up): the accelerometer reads the specific
//! force, about (0, 0, +9.81) upright; pitch is positive leaning forward, roll positive leaning
//! right. Leaning forward by `p` gives a_x = -g sin p; leaning right by `r` gives
//! a_y = g sin r. A fall shows as a growing angle and rate, a drop of the measured gravity while
//! the body falls freely, and a spike at the impact.

use strata_robot::platform::{FootContact, HeadAngles, InertialData};

use crate::body::{Activity, Body, SpecialKind};
use crate::config::RobotConfig;
use crate::noise::ImuNoise;
use crate::random::Stream;
use crate::util::sin_cos;

/// Standard gravity, m/s^2.
pub const GRAVITY: f64 = 9.81;

/// One inertial sample of `body`; consumes the impact spike.
pub(crate) fn inertial(body: &mut Body, noise: &ImuNoise, rng: &mut Stream) -> InertialData {
    let (sr, cr) = sin_cos(body.roll);
    let (sp, cp) = sin_cos(body.pitch);
    let g = GRAVITY * body.accel_scale;
    let mut accelerometer = [-g * sp, g * sr * cp, g * cr * cp];
    if body.impact > 0.0 {
        // The impact pushes against the side the robot landed on.
        accelerometer[0] -= body.impact * sp;
        accelerometer[1] += body.impact * sr;
        accelerometer[2] += body.impact * 0.5;
        body.impact = 0.0;
    }
    let a = noise.accel_sigma;
    let w = noise.gyro_sigma;
    let angle = noise.angle_sigma;
    InertialData {
        accelerometer: [
            accelerometer[0] + rng.gauss(a),
            accelerometer[1] + rng.gauss(a),
            accelerometer[2] + rng.gauss(a),
        ],
        gyroscope: [
            body.gyro[0] + rng.gauss(w),
            body.gyro[1] + rng.gauss(w),
            body.gyro[2] + rng.gauss(w),
        ],
        body_angles: [body.roll + rng.gauss(angle), body.pitch + rng.gauss(angle)],
    }
}

/// The head joint encoders.
pub(crate) fn encoders(body: &Body, noise: &ImuNoise, rng: &mut Stream) -> HeadAngles {
    HeadAngles {
        yaw: body.head.yaw + rng.gauss(noise.joint_sigma),
        pitch: body.head.pitch + rng.gauss(noise.joint_sigma),
    }
}

/// Foot pressure: the weight shifts between the feet while walking, rests on the support foot
/// during a kick, fades while falling and is gone lying down or lifted.
pub(crate) fn foot_contact(
    body: &Body,
    lifted: bool,
    config: &RobotConfig,
    noise: &ImuNoise,
    rng: &mut Stream,
) -> FootContact {
    let m = config.mass;
    let (left, right) = if lifted {
        (0.0, 0.0)
    } else {
        match body.activity {
            Activity::Standing => (m / 2.0, m / 2.0),
            Activity::Walking { .. } => {
                let shift = 0.45 * body.gait.sin;
                (m * (0.5 + shift), m * (0.5 - shift))
            }
            Activity::Special(run) => match run.kind {
                SpecialKind::Kick { .. } => (m, 0.0),
                SpecialKind::StandUp { .. } => {
                    let up = ((run.elapsed / run.duration - 0.6) / 0.4).clamp(0.0, 1.0)
                        * (1.0 - body.pitch.abs().max(body.roll.abs()) / 1.5).max(0.0);
                    (m / 2.0 * up, m / 2.0 * up)
                }
                SpecialKind::ProtectiveFall { .. } | SpecialKind::Dive { .. } => {
                    let up = (1.0 - body.pitch.abs().max(body.roll.abs()) / 1.0).max(0.0);
                    (m / 2.0 * up, m / 2.0 * up)
                }
            },
            Activity::Falling { .. } => {
                let up = (1.0 - body.pitch.abs().max(body.roll.abs()) / 1.0).max(0.0);
                (m / 2.0 * up, m / 2.0 * up)
            }
            Activity::Fallen { .. } => (0.0, 0.0),
        }
    };
    let s = noise.foot_sigma;
    FootContact { left: (left + rng.gauss(s)).max(0.0), right: (right + rng.gauss(s)).max(0.0) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::{NoiseLevel, NoiseParams};
    use strata_robot::Pose;
    use strata_robot::platform::FallDirection;

    #[test]
    fn upright_reads_gravity_and_a_fall_shows_in_every_signal() {
        let config = RobotConfig::default();
        let noise = NoiseParams::preset(NoiseLevel::None);
        let mut rng = Stream::new(1, "imu");
        let mut body = Body::new(Pose::default());
        let upright = inertial(&mut body, &noise.imu, &mut rng);
        assert_eq!(upright.accelerometer, [0.0, 0.0, GRAVITY]);
        let feet = foot_contact(&body, false, &config, &noise.imu, &mut rng);
        assert!((feet.left + feet.right - config.mass).abs() < 1e-12);

        body.start_fall(FallDirection::Right);
        let mut landed_sample = None;
        let mut previous_roll = 0.0;
        for step in 0..80 {
            let events = body.update(0.012, &config, &noise, &mut rng);
            let sample = inertial(&mut body, &noise.imu, &mut rng);
            assert!(sample.body_angles[0] >= previous_roll, "roll grows monotonically");
            previous_roll = sample.body_angles[0];
            if events.landed.is_some() {
                landed_sample = Some((step, sample));
            }
        }
        let (_, at_impact) = landed_sample.expect("the robot landed");
        let magnitude = at_impact.accelerometer.iter().map(|a| a * a).sum::<f64>().sqrt();
        assert!(magnitude > 1.5 * GRAVITY, "impact spike: {magnitude}");
        let lying = inertial(&mut body, &noise.imu, &mut rng);
        assert!(lying.accelerometer[1] > 9.0, "lying on the right side: {:?}", lying);
        let feet = foot_contact(&body, false, &config, &noise.imu, &mut rng);
        assert_eq!((feet.left, feet.right), (0.0, 0.0));
    }
}
