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

/// Standard gravity, m/s^2.
pub const GRAVITY: f64 = 9.81;

/// One sample of every proprioceptive sensor: inertial unit, head encoders, foot pressure.
/// Consumes the impact spike. All twelve noise values are drawn together.
#[inline(always)]
pub(crate) fn sample(
    body: &mut Body,
    lifted: bool,
    config: &RobotConfig,
    noise: &ImuNoise,
    rng: &mut Stream,
) -> (InertialData, HeadAngles, FootContact) {
    let [sr, cr, sp, cp] = body.tilt_trig();
    let g = GRAVITY * body.accel_scale;
    let mut accelerometer = [-g * sp, g * sr * cp, g * cr * cp];
    if body.impact > 0.0 {
        // The impact pushes against the side the robot landed on.
        accelerometer[0] -= body.impact * sp;
        accelerometer[1] += body.impact * sr;
        accelerometer[2] += body.impact * 0.5;
        body.impact = 0.0;
    }
    let (a, w, s) = (noise.accel_sigma, noise.gyro_sigma, noise.angle_sigma);
    let (j, f) = (noise.joint_sigma, noise.foot_sigma);
    // Deviations are non-negative (the configuration is validated): all zero when they add up
    // to zero, and then nothing is drawn, so the zero-noise mode is exact.
    let n = if a + w + s + j + f > 0.0 {
        let [n0, n1] = rng.gauss_pair(a, a);
        let [n2, n3] = rng.gauss_pair(a, w);
        let [n4, n5] = rng.gauss_pair(w, w);
        let [n6, n7] = rng.gauss_pair(s, s);
        let [n8, n9] = rng.gauss_pair(j, j);
        let [n10, n11] = rng.gauss_pair(f, f);
        [n0, n1, n2, n3, n4, n5, n6, n7, n8, n9, n10, n11]
    } else {
        [0.0; 12]
    };
    let inertial = InertialData {
        accelerometer: [accelerometer[0] + n[0], accelerometer[1] + n[1], accelerometer[2] + n[2]],
        gyroscope: [body.gyro[0] + n[3], body.gyro[1] + n[4], body.gyro[2] + n[5]],
        body_angles: [body.roll + n[6], body.pitch + n[7]],
    };
    let head = HeadAngles { yaw: body.head.yaw + n[8], pitch: body.head.pitch + n[9] };
    let (left, right) = foot_load(body, lifted, config);
    let feet = FootContact { left: (left + n[10]).max(0.0), right: (right + n[11]).max(0.0) };
    (inertial, head, feet)
}

/// Foot pressure (left, right) without noise: the weight shifts between the feet while walking,
/// rests on the support foot during a kick, fades while falling and is gone lying down or
/// lifted.
#[inline(always)]
fn foot_load(body: &Body, lifted: bool, config: &RobotConfig) -> (f64, f64) {
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
    (left, right)
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
        let (upright, _, feet) = sample(&mut body, false, &config, &noise.imu, &mut rng);
        assert_eq!(upright.accelerometer, [0.0, 0.0, GRAVITY]);
        assert!((feet.left + feet.right - config.mass).abs() < 1e-12);

        body.start_fall(FallDirection::Right);
        let mut landed_sample = None;
        let mut previous_roll = 0.0;
        for step in 0..80 {
            let events = body.update(0.012, &config, &noise, &mut rng);
            let (inertial, _, _) = sample(&mut body, false, &config, &noise.imu, &mut rng);
            assert!(inertial.body_angles[0] >= previous_roll, "roll grows monotonically");
            previous_roll = inertial.body_angles[0];
            if events.landed.is_some() {
                landed_sample = Some((step, inertial));
            }
        }
        let (_, at_impact) = landed_sample.expect("the robot landed");
        let magnitude = at_impact.accelerometer.iter().map(|a| a * a).sum::<f64>().sqrt();
        assert!(magnitude > 1.5 * GRAVITY, "impact spike: {magnitude}");
        let (lying, _, feet) = sample(&mut body, false, &config, &noise.imu, &mut rng);
        assert!(lying.accelerometer[1] > 9.0, "lying on the right side: {:?}", lying);
        assert_eq!((feet.left, feet.right), (0.0, 0.0));
    }
}
