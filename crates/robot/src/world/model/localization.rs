//! The robot's pose: its correction with what the landmark filters gained, kidnap detection
//! and relabelling, and recovery when lost.

use nalgebra::{Matrix3, Vector3};
use strata_runtime::Time;

use super::{FrameGain, Slot, Track, WorldModel};
use crate::geometry::Odometry;
use crate::platform::{FootContact, InertialData};
use crate::world::config::{PoseFeed, PosePrior, SymmetryHint};
use crate::world::object::GainedInformation;
use crate::world::pose::PoseFilter;
use crate::world::recovery::{
    MapInstance, RecoveryInput, RecoveryOutcome, Relocation, Sighting, recover,
};
use crate::world::state::LostReason;

/// How long after a kidnap recovery tries the `Relocations` hints, s.
const RELOCATION_WINDOW: f64 = 10.0;

#[derive(Clone, Debug, Default)]
pub(super) struct KidnapDetector {
    consecutive: usize,
    slots: Vec<usize>,
    /// When the current run of disagreements started.
    since: Option<Time>,
    /// The odometry since then: where the robot went after it may have been moved.
    moved: Odometry,
}

impl KidnapDetector {
    pub(super) fn accept(&mut self) {
        self.consecutive = 0;
        self.slots.clear();
        self.since = None;
        self.moved = Odometry::ZERO;
    }

    pub(super) fn reject(&mut self, slot: usize, now: Time) {
        self.consecutive += 1;
        self.since.get_or_insert(now);
        if !self.slots.contains(&slot) {
            self.slots.push(slot);
        }
    }

    pub(super) fn travel(&mut self, odometry: Odometry) {
        if self.since.is_some() {
            self.moved = self.moved.then(odometry);
        }
    }

    pub(super) fn triggered(&self, needed: usize, one_landmark: bool) -> bool {
        self.consecutive >= needed && (self.slots.len() >= 2 || one_landmark)
    }
}

impl WorldModel {
    pub(super) fn check_lift(&mut self, contact: &FootContact) {
        let Some(threshold) = self.config.pose.kidnap_on_lift else { return };
        if !contact.on_ground(threshold) {
            self.lifted = true;
        } else if self.lifted {
            self.lifted = false;
            self.declare_kidnapped();
        }
    }

    /// A fall and the stand-up after it move the robot by what no odometry measured: once the
    /// torso is upright again, the pose and every tracked object (kept in the robot's frame)
    /// grow uncertain by `pose.fall_sigma`.
    pub(super) fn check_fall(&mut self, inertial: &InertialData) {
        let Some(threshold) = self.config.pose.fall_tilt else { return };
        let [roll, pitch] = inertial.body_angles;
        let tilt = roll.abs().max(pitch.abs());
        if !tilt.is_finite() {
            return;
        }
        if tilt > threshold {
            self.fallen = true;
        } else if self.fallen && tilt < threshold / 2.0 {
            self.fallen = false;
            let [sx, sy, st] = self.config.pose.fall_sigma;
            self.unmeasured_motion(&Matrix3::from_diagonal(&Vector3::new(
                sx * sx,
                sy * sy,
                st * st,
            )));
        }
    }

    /// Motion with no measured increment and error covariance `q` (robot frame).
    fn unmeasured_motion(&mut self, q: &Matrix3<f64>) {
        if let Some(pose) = &mut self.pose {
            pose.predict(&Odometry::ZERO, q);
        }
        for slot in &mut self.slots {
            if let Some(track) = &mut slot.track {
                track.filter.predict_odometry_with(&Odometry::ZERO, (0.0, 1.0), q);
            }
        }
    }

    /// What the pose filter is corrected with for a landmark filter corrected in this frame
    /// (`pose.feed`).
    fn pose_measurement(&self, gain: &FrameGain) -> GainedInformation {
        match self.config.pose.feed {
            PoseFeed::Gained => gain.gained,
            PoseFeed::Estimates => match &self.slots[gain.slot].track {
                Some(track) => GainedInformation {
                    position: track.filter.position_vector(),
                    covariance: track.filter.position_covariance(),
                },
                None => gain.gained,
            },
        }
    }

    /// The pose filter's correction: the landmark filters' estimates as observations (by
    /// default only what each gained in this frame, so no observation counts twice).
    pub(super) fn correct_pose(&mut self, now: Time) {
        if self.pose_usable().is_none() {
            return;
        }
        let mut gains = std::mem::take(&mut self.frame_gains);
        for gain in &mut gains {
            gain.gained = self.pose_measurement(gain);
        }
        for gain in &gains {
            let Some(map) = self.slots[gain.slot].map_position else { continue };
            let Some(pose) = self.pose.as_ref() else { break };
            let fits =
                pose.landmark_innovation(map, &gain.gained).is_some_and(|i| i.nis <= self.gate);
            if fits {
                if let Some(pose) = self.pose.as_mut()
                    && pose.update_landmark(map, &gain.gained).is_some()
                {
                    self.last_pose_correction = Some(now);
                }
                self.kidnap.accept();
                continue;
            }
            // The track may carry the wrong label (started while lost, or ambiguous): another
            // free instance of the same landmark that fits takes it over.
            if let Some(other) = self.relabel_candidate(gain, now) {
                swap_tracks(&mut self.slots, gain.slot, other);
                self.diagnostics.relabels += 1;
                if let (Some(map), Some(pose)) =
                    (self.slots[other].map_position, self.pose.as_mut())
                    && pose.update_landmark(map, &gain.gained).is_some()
                {
                    self.last_pose_correction = Some(now);
                }
                self.kidnap.accept();
                continue;
            }
            self.diagnostics.pose_rejections += 1;
            self.kidnap.reject(gain.slot, now);
        }
        self.frame_gains = gains;
        if self.kidnap_triggered() {
            self.declare_disagreement();
        }
    }

    pub(super) fn kidnap_triggered(&self) -> bool {
        let pose = &self.config.pose;
        self.kidnap.triggered(pose.kidnap_rejections, pose.kidnap_from_one_landmark)
    }

    fn relabel_candidate(&self, gain: &FrameGain, now: Time) -> Option<usize> {
        let pose = self.pose.as_ref()?;
        let group = &self.groups[self.slots[gain.slot].group];
        group
            .slots
            .clone()
            .filter(|&s| s != gain.slot && self.is_stale(s, now))
            .filter_map(|s| {
                let i = pose.landmark_innovation(self.slots[s].map_position?, &gain.gained)?;
                (i.nis <= self.gate).then_some((s, i.cost()))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(s, _)| s)
    }

    pub(super) fn declare_kidnapped(&mut self) {
        let now = self.time.unwrap_or(Time::ZERO);
        // The robot was carried: landmark tracks not confirmed since the landmarks started
        // to disagree (or within the last moment, when told) are wrong.
        let window = std::time::Duration::from_secs_f64(self.config.association.reinit_window);
        let since = self.kidnap.since.unwrap_or(Time::from_nanos(
            now.as_nanos().saturating_sub(u64::try_from(window.as_nanos()).unwrap_or(u64::MAX)),
        ));
        let moved = self.kidnap.moved;
        self.kidnapped(now, moved, |slot| {
            slot.map_position.is_some() && slot.track.as_ref().is_some_and(|t| t.last_seen < since)
        });
    }

    /// A kidnap declared because the landmarks disagree with the pose.
    pub(super) fn declare_disagreement(&mut self) {
        self.declare_kidnapped();
        self.disagreed = true;
    }

    /// The platform saw the robot put somewhere just now (`Percepts::placed`): a kidnap whose
    /// moment is known. The robot is at a `Relocations` pose as they stand (no odometry since),
    /// and every estimate relative to it made before (landmarks, mobile objects, obstacles,
    /// observations waiting for a track) is from where it was.
    pub(super) fn declare_placed(&mut self) {
        let now = self.time.unwrap_or(Time::ZERO);
        self.kidnapped(now, Odometry::ZERO, |_| true);
        for group in &mut self.groups {
            group.pending.clear();
        }
    }

    /// Loses the pose to a kidnap at `now`, the robot having moved by `moved` since it was put
    /// where the relocation hints say; drops the tracks `stale` picks.
    fn kidnapped(&mut self, now: Time, moved: Odometry, stale: impl Fn(&Slot) -> bool) {
        self.confidence_changes();
        self.lost = Some(LostReason::Kidnapped);
        self.disagreed = false;
        self.diagnostics.kidnaps += 1;
        self.relocated = Some((now, moved));
        self.kidnap.accept();
        for slot in &mut self.slots {
            if stale(slot) {
                slot.track = None;
            }
        }
    }

    pub(super) fn try_recover(&mut self, now: Time) {
        let max_age = self.config.pose.recovery_max_age;
        let mut sightings = Vec::new();
        let mut map = Vec::new();
        for (i, slot) in self.slots.iter().enumerate() {
            let Some(position) = slot.map_position else { continue };
            map.push(MapInstance { group: slot.group, slot: i, position });
            if let Some(t) = &slot.track
                && (now - t.last_seen).as_secs_f64() <= max_age
            {
                sightings.push(Sighting {
                    group: slot.group,
                    slot: i,
                    position: t.filter.position_vector(),
                    covariance: t.filter.position_covariance(),
                });
            }
        }
        let relocations = self.relocations(now);
        // As `recover` counts: a relocation stands in for one landmark.
        let min = self.config.pose.recovery_min_landmarks;
        let needed = if relocations.is_empty() { min } else { min.saturating_sub(1).max(1) };
        if sightings.len() < needed {
            return;
        }
        let prior = match (self.lost, &self.pose, self.config.pose.disagreement_prior) {
            (Some(LostReason::Uncertain), Some(p), _) => Some((p.pose(), p.covariance())),
            (Some(LostReason::Kidnapped), Some(p), Some(sigma)) if self.disagreed => {
                let grown = PosePrior { pose: p.pose(), sigma }.covariance();
                Some((p.pose(), p.covariance() + grown))
            }
            _ => None,
        };
        let team = self.team_cues(now);
        let input = RecoveryInput {
            sightings: &sightings,
            map: &map,
            bounds: self.config.pose.bounds,
            hints: &self.hints,
            prior,
            relocations: &relocations,
            team: &team,
            gate: self.gate,
            min_landmarks: self.config.pose.recovery_min_landmarks,
            margin: self.config.pose.recovery_margin,
            max_sigma: self.config.pose.recovery_max_sigma,
            max_hypotheses: self.config.pose.recovery_max_hypotheses,
        };
        let h = match recover(&input) {
            RecoveryOutcome::Found(h) => h,
            RecoveryOutcome::Ambiguous { best, competitor } => {
                tracing::debug!(
                    best = ?best.pose,
                    competitor = ?competitor.pose,
                    "pose recovery ambiguous: waiting for more landmarks or a hint"
                );
                return;
            }
            RecoveryOutcome::Insufficient => return,
        };
        // Relabel: each sighting's track moves to the map instance it was matched with.
        self.confidence_changes();
        let mut moved: Vec<(usize, Option<Track>)> = Vec::new();
        for &(i, to) in &h.assignment {
            let from = sightings[i].slot;
            moved.push((to, self.slots[from].track.take()));
            if from != to {
                self.diagnostics.relabels += 1;
            }
        }
        for (to, track) in moved {
            self.slots[to].track = track;
        }
        self.pose = Some(PoseFilter::new(h.pose, h.covariance));
        self.lost = None;
        self.relocated = None;
        self.kidnap.accept();
        self.last_pose_correction = Some(now);
        self.diagnostics.recoveries += 1;
    }

    /// Where the `Relocations` hints put the robot now: each pose moved by the odometry since
    /// the robot may have been put there, its uncertainty grown by that odometry's. Only
    /// shortly after a kidnap: lost for another reason the robot was not just put somewhere,
    /// and lost for long it may have been moved again, or turned so much that where it faced
    /// when put there tells nothing (with one landmark, the heading is what tells the two side
    /// lines apart).
    fn relocations(&self, now: Time) -> Vec<Relocation> {
        let Some((since, moved)) = self.relocated else { return Vec::new() };
        if (now - since).as_secs_f64() > RELOCATION_WINDOW {
            return Vec::new();
        }
        let q = self.config.odometry.covariance(&moved);
        self.hints
            .iter()
            .filter_map(|hint| match hint {
                SymmetryHint::Relocations { poses } => Some(poses),
                _ => None,
            })
            .flatten()
            .map(|prior| {
                let mut filter = PoseFilter::new(prior.pose, prior.covariance());
                filter.predict(&moved, &q);
                Relocation { pose: filter.pose(), covariance: filter.covariance() }
            })
            .collect()
    }
}

fn swap_tracks(slots: &mut [Slot], a: usize, b: usize) {
    let ta = slots[a].track.take();
    slots[a].track = slots[b].track.take();
    slots[b].track = ta;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_landmark_disagreeing_is_a_kidnap_only_when_allowed() {
        let mut detector = KidnapDetector::default();
        for k in 0..5 {
            detector.reject(7, Time::from_secs_f64(f64::from(k)));
        }
        assert!(!detector.triggered(5, false), "one source: maybe a false positive");
        assert!(detector.triggered(5, true));
        assert!(!detector.triggered(6, true));
        detector.reject(3, Time::from_secs_f64(5.0));
        assert!(detector.triggered(5, false), "two sources");
        detector.accept();
        assert!(!detector.triggered(1, true));
    }

    #[test]
    fn the_robots_motion_is_followed_from_the_first_disagreement() {
        let mut detector = KidnapDetector::default();
        let step = Odometry { dx: 0.1, dy: 0.0, dtheta: std::f64::consts::FRAC_PI_2 };
        detector.travel(step);
        assert_eq!(detector.moved, Odometry::ZERO, "nothing disagreed yet");
        detector.reject(1, Time::ZERO);
        detector.travel(step);
        detector.travel(step);
        assert_eq!(detector.moved, step.then(step));
        assert!((detector.moved.dy - 0.1).abs() < 1e-12, "{:?}", detector.moved);
        detector.accept();
        assert_eq!(detector.moved, Odometry::ZERO);
    }
}
