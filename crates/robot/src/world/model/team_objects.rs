//! Team fusion (MAWM, paper 3.3): teammates' estimates fused with this robot's into team
//! objects, and the cues they give pose recovery.

use nalgebra::Vector2;
use strata_runtime::Time;

use super::{WorldModel, global_estimate};
use crate::geometry::{Point, Vector};
use crate::world::recovery::TeamCue;
use crate::world::state::{ObjectCategory, ObjectId};
use crate::world::team::{FusionCandidate, Source, TeamError, TeamObject, TeammateEstimate, fuse};

impl WorldModel {
    /// Mobile objects this robot tracks that the teammates also report, for recovery.
    pub(super) fn team_cues(&self, now: Time) -> Vec<TeamCue> {
        let mut cues = Vec::new();
        for group in self.groups.iter().filter(|g| g.category == ObjectCategory::Mobile) {
            let slot = group.slots.start;
            let Some(track) = &self.slots[slot].track else { continue };
            if self.frame_confidence(slot) < self.config.confidence.unknown_threshold {
                continue;
            }
            let candidates = self.team.candidates(now, group.class, group.variant, group.friction);
            if let Some(f) = fuse(&candidates, self.team.gate()) {
                cues.push(TeamCue {
                    own_position: track.filter.position_vector(),
                    own_covariance: track.filter.position_covariance(),
                    team_position: f.position,
                    team_covariance: f.covariance,
                });
            }
        }
        cues
    }

    pub(super) fn fuse_team(&mut self, now: Time) {
        self.team_objects.clear();
        if self.team.teammates().next().is_none() {
            return;
        }
        let pose = self.pose_usable().map(|p| (p.pose(), p.covariance()));
        let mut candidates = std::mem::take(&mut self.scratch.candidates);
        for group in &self.groups {
            if group.category != ObjectCategory::Mobile {
                continue;
            }
            let slot = group.slots.start;
            self.team.candidates_into(
                now,
                group.class,
                group.variant,
                group.friction,
                &mut candidates,
            );
            if let (Some((pose, pose_cov)), Some(track)) = (pose, &self.slots[slot].track)
                && self.frame_confidence(slot) >= self.config.confidence.unknown_threshold
            {
                let (position, covariance) = global_estimate(
                    &pose,
                    &pose_cov,
                    track.filter.position_vector(),
                    &track.filter.position_covariance(),
                );
                let v = track.filter.velocity();
                let fv = pose.vector_to_global(v);
                candidates.push(FusionCandidate {
                    source: Source::Own,
                    position,
                    covariance,
                    velocity: Some(Vector2::new(fv.x, fv.y)),
                });
            }
            let Some(f) = fuse(&candidates, self.team.gate()) else { continue };
            let teammates = |sources: &[Source]| {
                sources
                    .iter()
                    .filter_map(|s| match s {
                        Source::Teammate(p) => Some(*p),
                        Source::Own => None,
                    })
                    .collect::<Vec<u8>>()
            };
            self.team_objects.push(TeamObject {
                id: ObjectId(u16::try_from(slot).unwrap_or(u16::MAX)),
                name: group.name.clone(),
                class: group.class,
                position: Point::new(f.position.x, f.position.y),
                velocity: f.velocity.map(|v| Vector::new(v.x, v.y)),
                covariance: f.covariance,
                includes_own: f.members.contains(&Source::Own),
                teammates: teammates(&f.members),
                rejected: teammates(&f.rejected),
            });
        }
        self.scratch.candidates = candidates;
    }

    /// Stores a teammate's estimate for team fusion (MAWM); malformed ones are refused.
    pub fn add_teammate_estimate(&mut self, estimate: TeammateEstimate) -> Result<(), TeamError> {
        let result = self.team.insert(estimate);
        if result.is_err() {
            self.diagnostics.team_rejected += 1;
        }
        result
    }
}
