//! How long a T1 walked, from the server's ground truth: falls are counted per minute of
//! walking, so a robot that stood still for a run does not make its condition look safer.
//!
//! The simulation's time is cut into windows of about a second. A window counts as walking when
//! the torso stayed upright in every sample and either moved at least `speed` on average over
//! it or turned at least `turning` (turning in place is stepping too): a T1 standing or treading
//! in place sways its torso by a few centimetres and degrees, well below 0.1 m/s and 0.2 rad/s.

use strata_rcssmj::falls::FALL_ONSET_TILT;

/// The windows' length, s of simulation.
const WINDOW: f64 = 1.0;

/// A move between two samples this long is the trainer placing the robot, not a step.
const TELEPORT: f64 = 1.0;

/// The walking time of one robot, fed with its ground truth as the monitor streams it.
#[derive(Clone, Debug)]
pub struct WalkTracker {
    /// Average torso speed over a window from which the robot walks, m/s.
    speed: f64,
    /// Average turning rate over a window from which the robot walks, rad/s.
    turning: f64,
    /// Totals, s of simulation.
    walking: f64,
    upright: f64,
    observed: f64,
    /// Ground-truth path of the torso, m.
    path: f64,
    window: Option<Window>,
    last: Option<(f64, [f64; 2])>,
}

#[derive(Clone, Copy, Debug)]
struct Window {
    start: f64,
    from: [f64; 2],
    heading: f64,
    upright: bool,
}

impl WalkTracker {
    pub fn new(speed: f64, turning: f64) -> WalkTracker {
        WalkTracker {
            speed,
            turning,
            walking: 0.0,
            upright: 0.0,
            observed: 0.0,
            path: 0.0,
            window: None,
            last: None,
        }
    }

    /// A sample at simulation time `t`: the torso's `position` (m, world frame) and
    /// `orientation` (`[w, x, y, z]`). Samples at a time not after the last are ignored.
    pub fn sample(&mut self, t: f64, position: [f64; 3], orientation: [f64; 4]) {
        if self.last.is_some_and(|(last, _)| t <= last) {
            return;
        }
        let at = [position[0], position[1]];
        let upright = tilt_of(orientation) < FALL_ONSET_TILT;
        let heading = heading_of(orientation);
        if let Some((_, previous)) = self.last {
            let step = distance(previous, at);
            if step >= TELEPORT {
                // Placed elsewhere: the window that spans it measures nothing.
                self.window = None;
            } else {
                self.path += step;
            }
        }
        self.last = Some((t, at));
        let Some(window) = self.window.as_mut() else {
            self.window = Some(Window { start: t, from: at, heading, upright });
            return;
        };
        window.upright &= upright;
        let span = t - window.start;
        if span >= WINDOW {
            self.observed += span;
            if window.upright {
                self.upright += span;
                let turned = angle_between(window.heading, heading);
                if distance(window.from, at) >= self.speed * span || turned >= self.turning * span {
                    self.walking += span;
                }
            }
            self.window = Some(Window { start: t, from: at, heading, upright });
        }
    }

    /// Seconds of simulation in which the robot walked.
    pub fn walking_s(&self) -> f64 {
        self.walking
    }

    /// Seconds of simulation in which the robot stood or walked (never past the fall onset).
    pub fn upright_s(&self) -> f64 {
        self.upright
    }

    /// Seconds of simulation the samples covered (in whole windows).
    pub fn observed_s(&self) -> f64 {
        self.observed
    }

    /// The torso's path over the ground, m.
    pub fn path_m(&self) -> f64 {
        self.path
    }
}

/// The angle between the torso's z axis and the world's vertical, rad.
pub fn tilt_of([_, x, y, _]: [f64; 4]) -> f64 {
    (1.0 - 2.0 * (x * x + y * y)).clamp(-1.0, 1.0).acos()
}

/// The torso's heading about the world's vertical, rad.
fn heading_of([w, x, y, z]: [f64; 4]) -> f64 {
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

/// The absolute difference of two headings, in [0, pi].
fn angle_between(a: f64, b: f64) -> f64 {
    let d = (b - a).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    const UPRIGHT: [f64; 4] = [1.0, 0.0, 0.0, 0.0];

    /// Tilted `angle` rad about the y axis.
    fn tilted(angle: f64) -> [f64; 4] {
        [(angle / 2.0).cos(), 0.0, (angle / 2.0).sin(), 0.0]
    }

    /// Feeds 40 ms samples from `t0` for `seconds`, the torso at `x(t)`.
    fn feed(
        w: &mut WalkTracker,
        t0: f64,
        seconds: f64,
        x: impl Fn(f64) -> f64,
        q: impl Fn(f64) -> [f64; 4],
    ) {
        let steps = (seconds / 0.04).round() as usize;
        for i in 0..=steps {
            let t = t0 + i as f64 * 0.04;
            w.sample(t, [x(t), 0.0, 0.65], q(t));
        }
    }

    #[test]
    fn walking_at_walking_speed_counts_and_treading_in_place_does_not() {
        let mut w = WalkTracker::new(0.1, 0.2);
        // 10 s at 0.4 m/s, then 10 s swaying 3 cm in place.
        feed(&mut w, 0.0, 10.0, |t| 0.4 * t, |_| UPRIGHT);
        feed(&mut w, 10.04, 10.0, |t| 4.0 + 0.03 * (t * 6.0).sin(), |_| UPRIGHT);
        assert!((w.walking_s() - 10.0).abs() < 1.1, "{}", w.walking_s());
        assert!((w.upright_s() - w.observed_s()).abs() < 1e-9);
        assert!(w.observed_s() > 18.5, "{}", w.observed_s());
        assert!(w.path_m() > 4.0, "{}", w.path_m());
    }

    #[test]
    fn a_fallen_robot_is_neither_upright_nor_walking_even_when_it_slides() {
        let mut w = WalkTracker::new(0.1, 0.2);
        feed(&mut w, 0.0, 5.0, |t| 0.5 * t, |_| tilted(1.4));
        assert_eq!(w.walking_s(), 0.0);
        assert_eq!(w.upright_s(), 0.0);
        assert!(w.observed_s() > 4.0);
        assert!((tilt_of(tilted(0.3)) - 0.3).abs() < 1e-9);
    }

    #[test]
    fn a_placement_by_the_trainer_is_no_walk_and_old_samples_are_ignored() {
        let mut w = WalkTracker::new(0.1, 0.2);
        feed(&mut w, 0.0, 3.0, |_| 0.0, |_| UPRIGHT);
        // Moved 5 m at once, then standing.
        feed(&mut w, 3.04, 3.0, |_| 5.0, |_| UPRIGHT);
        w.sample(1.0, [100.0, 0.0, 0.65], UPRIGHT);
        assert_eq!(w.walking_s(), 0.0);
        assert!(w.path_m() < 1e-9, "{}", w.path_m());
    }

    #[test]
    fn turning_in_place_is_walking_too() {
        let mut w = WalkTracker::new(0.1, 0.2);
        // 5 s turning at 0.5 rad/s about the vertical, across the +-pi seam, torso still.
        let yaw = |t: f64| 2.5 + 0.5 * t;
        feed(&mut w, 0.0, 5.0, |_| 0.0, |t| [(yaw(t) / 2.0).cos(), 0.0, 0.0, (yaw(t) / 2.0).sin()]);
        assert!((w.walking_s() - 5.0).abs() < 0.1, "{}", w.walking_s());
        assert!((angle_between(3.0, -3.0) - (std::f64::consts::TAU - 6.0)).abs() < 1e-12);
    }
}
