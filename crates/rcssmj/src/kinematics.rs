//! Where the T1's camera is: the neck chain of the server's robot model (torso, head yaw joint,
//! head pitch joint, camera site), and the torso's tilt from its orientation.
//!
//! Frames are right-handed, x forward, y left, z up. The server reports detections in the
//! camera site's frame, which the model gives the head-pitch link's axes; so a point seen at
//! polar (distance, azimuth, elevation) is a vector in that link, and this module carries it
//! down the chain to the *ground frame*: the torso's position projected on the ground, its
//! heading as x, z vertical. Perception needs exactly that: range and bearing on the ground.

/// A 3-vector, metres.
pub type Vec3 = [f64; 3];

/// The neck of the T1 model shipped with rcssservermj 0.2.1 (`resources/robots/T1/robot.xml`:
/// bodies `H1`, `H2` and site `camera`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeckGeometry {
    /// The head yaw joint (body `H1`) in the torso frame.
    pub yaw_joint: Vec3,
    /// The head pitch joint (body `H2`) in the yaw link.
    pub pitch_joint: Vec3,
    /// The camera site in the pitch link.
    pub camera: Vec3,
}

impl NeckGeometry {
    pub const T1: NeckGeometry = NeckGeometry {
        yaw_joint: [0.0625, 0.0, 0.243],
        pitch_joint: [0.0, 0.0, 0.06185],
        camera: [0.05, 0.0, 0.12],
    };
}

/// A unit quaternion (w, x, y, z): the torso's orientation in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quaternion {
    pub w: f64,
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Quaternion {
    pub const IDENTITY: Quaternion = Quaternion { w: 1.0, x: 0.0, y: 0.0, z: 0.0 };

    /// Normalized, or `None` for a zero or non-finite quaternion (which names no rotation).
    pub fn normalized(self) -> Option<Quaternion> {
        let n = (self.w * self.w + self.x * self.x + self.y * self.y + self.z * self.z).sqrt();
        (n.is_finite() && n > 1e-9).then(|| Quaternion {
            w: self.w / n,
            x: self.x / n,
            y: self.y / n,
            z: self.z / n,
        })
    }

    /// Rotates `v` from the body frame into the world frame.
    pub fn rotate(&self, v: Vec3) -> Vec3 {
        let Quaternion { w, x, y, z } = *self;
        // v + 2 q_v x (q_v x v + w v)
        let t =
            [2.0 * (y * v[2] - z * v[1]), 2.0 * (z * v[0] - x * v[2]), 2.0 * (x * v[1] - y * v[0])];
        [
            v[0] + w * t[0] + (y * t[2] - z * t[1]),
            v[1] + w * t[1] + (z * t[0] - x * t[2]),
            v[2] + w * t[2] + (x * t[1] - y * t[0]),
        ]
    }

    /// Rotates `v` from the world frame into the body frame.
    pub fn rotate_inverse(&self, v: Vec3) -> Vec3 {
        Quaternion { w: self.w, x: -self.x, y: -self.y, z: -self.z }.rotate(v)
    }

    /// The heading: the angle of the body's x axis projected on the ground, rad.
    pub fn yaw(&self) -> f64 {
        let forward = self.rotate([1.0, 0.0, 0.0]);
        forward[1].atan2(forward[0])
    }

    /// Roll and pitch of the body against gravity, rad (pitch > 0 leaning forward, roll > 0
    /// leaning right, as `InertialData::body_angles`).
    pub fn roll_pitch(&self) -> [f64; 2] {
        // Gravity's direction seen from the body: upright (0, 0, -1).
        let g = self.rotate_inverse([0.0, 0.0, -1.0]);
        let pitch = g[0].atan2(-g[2]);
        let roll = (-g[1]).atan2((g[0] * g[0] + g[2] * g[2]).sqrt());
        [roll, pitch]
    }

    /// The angle of the rotation that takes this orientation to `other`, rad in [0, pi].
    pub fn angle_to(&self, other: &Quaternion) -> f64 {
        let dot = self.w * other.w + self.x * other.x + self.y * other.y + self.z * other.z;
        2.0 * dot.abs().min(1.0).acos()
    }

    /// The torso's tilt alone: this orientation with its heading taken out, so that it maps the
    /// torso frame into the ground frame.
    pub fn without_yaw(&self) -> Quaternion {
        let half = -0.5 * self.yaw();
        let (s, c) = half.sin_cos();
        // (cos, 0, 0, sin) * self: a rotation about the world's vertical by -yaw first.
        let Quaternion { w, x, y, z } = *self;
        Quaternion { w: c * w - s * z, x: c * x - s * y, y: c * y + s * x, z: c * z + s * w }
    }
}

/// A point in the camera frame from the server's polar coordinates (distance m, azimuth and
/// elevation rad; azimuth left positive, elevation up positive).
pub fn polar_to_camera(distance: f64, azimuth: f64, elevation: f64) -> Vec3 {
    let (se, ce) = elevation.sin_cos();
    let (sa, ca) = azimuth.sin_cos();
    [distance * ce * ca, distance * ce * sa, distance * se]
}

fn rot_z(angle: f64, v: Vec3) -> Vec3 {
    let (s, c) = angle.sin_cos();
    [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]
}

fn rot_y(angle: f64, v: Vec3) -> Vec3 {
    let (s, c) = angle.sin_cos();
    [c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]]
}

fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Carries points from the camera frame to the ground frame, for one head and torso pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPose {
    neck: NeckGeometry,
    head_yaw: f64,
    head_pitch: f64,
    tilt: Quaternion,
    /// The torso's height above the ground, m.
    torso_height: f64,
}

impl CameraPose {
    /// `head_pitch` is the joint angle (positive looks down: the joint turns about +y);
    /// `orientation` the torso's in the world; `torso_height` where the torso origin is above
    /// the ground (the T1 stands with it at about 0.67 m).
    pub fn new(
        neck: NeckGeometry,
        head_yaw: f64,
        head_pitch: f64,
        orientation: Quaternion,
        torso_height: f64,
    ) -> CameraPose {
        CameraPose { neck, head_yaw, head_pitch, tilt: orientation.without_yaw(), torso_height }
    }

    /// A point of the camera frame in the torso frame.
    pub fn camera_to_torso(&self, p: Vec3) -> Vec3 {
        let in_pitch_link = add(self.neck.camera, p);
        let in_yaw_link = add(self.neck.pitch_joint, rot_y(self.head_pitch, in_pitch_link));
        add(self.neck.yaw_joint, rot_z(self.head_yaw, in_yaw_link))
    }

    /// A point of the camera frame in the ground frame (z: height above the ground).
    pub fn camera_to_ground(&self, p: Vec3) -> Vec3 {
        let level = self.tilt.rotate(self.camera_to_torso(p));
        [level[0], level[1], level[2] + self.torso_height]
    }

    /// The camera's optical axis projected on the ground: its direction from the torso's
    /// heading, rad.
    pub fn gaze_direction(&self) -> f64 {
        let origin = self.camera_to_ground([0.0; 3]);
        let ahead = self.camera_to_ground([1.0, 0.0, 0.0]);
        (ahead[1] - origin[1]).atan2(ahead[0] - origin[0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4};

    fn close(a: Vec3, b: Vec3) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
    }

    fn about_z(angle: f64) -> Quaternion {
        Quaternion { w: (angle / 2.0).cos(), x: 0.0, y: 0.0, z: (angle / 2.0).sin() }
    }

    fn about_y(angle: f64) -> Quaternion {
        Quaternion { w: (angle / 2.0).cos(), x: 0.0, y: (angle / 2.0).sin(), z: 0.0 }
    }

    #[test]
    fn polar_coordinates_follow_the_servers_convention() {
        // azimuth = atan2(y, x), elevation = asin(z / d), left and up positive.
        assert!(close(polar_to_camera(2.0, 0.0, 0.0), [2.0, 0.0, 0.0]));
        assert!(close(polar_to_camera(2.0, FRAC_PI_2, 0.0), [0.0, 2.0, 0.0]));
        assert!(close(polar_to_camera(2.0, 0.0, -FRAC_PI_2), [0.0, 0.0, -2.0]));
    }

    #[test]
    fn yaw_and_tilt_come_apart() {
        let q = about_z(1.0);
        assert!((q.yaw() - 1.0).abs() < 1e-12);
        assert!(close(q.without_yaw().rotate([1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]));
        // Leaning forward by 0.3 while facing 2 rad: pitch 0.3, heading 2.
        let lean = Quaternion {
            w: about_z(2.0).w * about_y(0.3).w,
            x: -about_z(2.0).z * about_y(0.3).y,
            y: about_z(2.0).w * about_y(0.3).y,
            z: about_z(2.0).z * about_y(0.3).w,
        };
        assert!((lean.yaw() - 2.0).abs() < 1e-9);
        let [roll, pitch] = lean.roll_pitch();
        assert!(roll.abs() < 1e-9 && (pitch - 0.3).abs() < 1e-9, "{roll} {pitch}");
        let rolled = Quaternion { w: (0.2f64).cos(), x: (0.2f64).sin(), y: 0.0, z: 0.0 };
        let [roll, pitch] = rolled.roll_pitch();
        assert!((roll - 0.4).abs() < 1e-9 && pitch.abs() < 1e-9, "{roll} {pitch}");
        let tilt = lean.without_yaw();
        assert!((tilt.yaw()).abs() < 1e-9);
        assert!((tilt.roll_pitch()[1] - 0.3).abs() < 1e-9);
    }

    #[test]
    fn a_point_ahead_of_a_level_camera_is_ahead_on_the_ground() {
        let pose = CameraPose::new(NeckGeometry::T1, 0.0, 0.0, Quaternion::IDENTITY, 0.67);
        let g = pose.camera_to_ground(polar_to_camera(3.0, 0.0, 0.0));
        assert!((g[0] - (3.0 + 0.0625 + 0.05)).abs() < 1e-9);
        assert!(g[1].abs() < 1e-12);
        assert!((g[2] - (0.67 + 0.243 + 0.06185 + 0.12)).abs() < 1e-9);
    }

    #[test]
    fn head_yaw_turns_the_view_to_the_left() {
        let pose = CameraPose::new(NeckGeometry::T1, FRAC_PI_2, 0.0, Quaternion::IDENTITY, 0.67);
        let g = pose.camera_to_ground(polar_to_camera(2.0, 0.0, 0.0));
        assert!((g[0] - 0.0625).abs() < 1e-9 && (g[1] - 2.05).abs() < 1e-9, "{g:?}");
        assert!((pose.gaze_direction() - FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn head_pitch_looks_down_and_a_leaning_torso_adds_to_it() {
        // Pitched down 45 degrees, a point 1 m along the axis is lower than the camera.
        let pose = CameraPose::new(NeckGeometry::T1, 0.0, FRAC_PI_4, Quaternion::IDENTITY, 0.67);
        let camera = pose.camera_to_ground([0.0; 3]);
        let seen = pose.camera_to_ground([1.0, 0.0, 0.0]);
        assert!((camera[2] - seen[2] - FRAC_PI_4.sin()).abs() < 1e-9);
        // The same gaze from a level head on a torso leaning forward 45 degrees.
        let leaning = CameraPose::new(NeckGeometry::T1, 0.0, 0.0, about_y(FRAC_PI_4), 0.67);
        let a = leaning.camera_to_ground([1.0, 0.0, 0.0]);
        let b = leaning.camera_to_ground([0.0; 3]);
        assert!((b[2] - a[2] - FRAC_PI_4.sin()).abs() < 1e-9);
        // A torso turned on the field does not change the ground frame (heading is x).
        let turned = CameraPose::new(NeckGeometry::T1, 0.0, 0.0, about_z(1.2), 0.67);
        assert!(close(
            turned.camera_to_ground([1.0, 0.0, 0.0]),
            CameraPose::new(NeckGeometry::T1, 0.0, 0.0, Quaternion::IDENTITY, 0.67)
                .camera_to_ground([1.0, 0.0, 0.0])
        ));
    }
}
