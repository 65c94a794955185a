//! The head camera: it reports the markers inside its field of view and range that no wall
//! hides, each with a chance of being missed, with noisy range and bearing relative to the
//! optical axis.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use strata_robot::geometry::{Pose, normalize_angle};
use strata_robot::platform::Detection;

use crate::config::CameraConfig;
use crate::world::World;

/// Noise never reports an object closer than this, m.
const MIN_REPORTED_RANGE: f64 = 0.05;

/// What a camera on a body at `pose`, its head turned by `yaw`, reports of `world`. The draws
/// follow the markers' order, so one seed gives one image.
pub(crate) fn detections(
    config: &CameraConfig,
    pose: Pose,
    yaw: f64,
    world: &World,
    rng: &mut ChaCha8Rng,
) -> Vec<Detection> {
    let mut out = Vec::new();
    for marker in world.markers() {
        let Some(position) = marker.position else { continue };
        let relative = pose.to_robot(position);
        let range = relative.range();
        let bearing = normalize_angle(relative.bearing() - yaw);
        // The miss is drawn last, for visible markers only: what cannot be seen costs no draw.
        if !(config.min_range..=config.range).contains(&range)
            || bearing.abs() > config.fov / 2.0
            || !world.line_of_sight(pose.position(), position)
            || rng.random::<f64>() > config.detection_probability
        {
            continue;
        }
        let range_sigma = config.range_sigma + config.range_sigma_per_metre * range;
        let range_noise: f64 = rng.sample(StandardNormal);
        let bearing_noise: f64 = rng.sample(StandardNormal);
        out.push(Detection {
            class: marker.class,
            variant: marker.variant,
            range: (range + range_sigma * range_noise).max(MIN_REPORTED_RANGE),
            bearing: bearing + config.bearing_sigma * bearing_noise,
            orientation: None,
        });
    }
    out
}
