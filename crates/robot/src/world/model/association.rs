//! Data association: which object filter each observation of an image belongs to (gating,
//! global nearest neighbour, ambiguity), and the tracks that rejected observations start.

use nalgebra::{Matrix2, Vector2};
use strata_runtime::Time;

use super::{FrameGain, Track, WorldModel, map_prediction_at};
use crate::percept::Observation;
use crate::world::math::RangeBearing;
use crate::world::object::{GainedInformation, MotionModel, ObjectFilter, innovation_at};
use crate::world::odometry_error::Lag;
use crate::world::pose::PoseFilter;
use crate::world::state::ObjectCategory;

/// A rejected observation kept for a while: several consistent ones restart a track.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pending {
    pub(super) position: Vector2<f64>,
    pub(super) stamp: Time,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Assignment {
    Open,
    Taken,
    /// Fits several instances of this group about equally well.
    Ambiguous(usize),
}

/// A position estimate (robot frame) and its covariance.
pub(super) type Gaussian2 = (Vector2<f64>, Matrix2<f64>);

/// One observation of an image, ready for association: the group that accepts it, and the
/// measured point with its noise in the robot frame. Converted from range and bearing once per
/// image: gating, the update, a new track and the pose filter all use the same conversion
/// (each costs a sine and cosine of the bearing).
#[derive(Clone, Copy, Debug)]
pub(super) struct Measured {
    pub(super) group: usize,
    pub(super) position: Vector2<f64>,
    pub(super) noise: Matrix2<f64>,
}

impl Measured {
    pub(super) fn gained(&self) -> GainedInformation {
        GainedInformation { position: self.position, covariance: self.noise }
    }
}

impl WorldModel {
    pub(super) fn measurement(&self, obs: &Observation) -> Option<RangeBearing> {
        let camera = &self.config.camera;
        let (range_sigma, bearing_sigma) = camera.sigmas(obs.range);
        let usable = |s: f64| s.is_finite() && s > 0.0;
        let z = if camera.use_percept_sigmas && usable(obs.range_sigma) && usable(obs.bearing_sigma)
        {
            RangeBearing {
                range: obs.range,
                bearing: obs.bearing,
                range_sigma: obs.range_sigma,
                bearing_sigma: obs.bearing_sigma,
            }
        } else {
            RangeBearing { range: obs.range, bearing: obs.bearing, range_sigma, bearing_sigma }
        };
        z.is_valid().then_some(z)
    }

    /// What association compares an observation with: the filter's position estimate, or
    /// where the pose and the map put an untracked landmark instance.
    fn association_prior(
        &self,
        slot: usize,
        pose: Option<&(PoseFilter, (f64, f64))>,
    ) -> Option<(Vector2<f64>, Matrix2<f64>)> {
        let slot = &self.slots[slot];
        match &slot.track {
            Some(track) => {
                Some((track.filter.position_vector(), track.filter.position_covariance()))
            }
            None => {
                let (pose, heading) = pose?;
                Some(map_prediction_at(pose, *heading, slot.map_position?))
            }
        }
    }

    /// Associates one image's observations with the object filters (global nearest neighbour:
    /// each filter takes at most one observation per image, best fits first, so a false
    /// positive next to the real object does not also correct it), then corrects them.
    pub(super) fn associate_frame(&mut self, observations: &[Observation], now: Time) {
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.measurements.clear();
        scratch.pairs.clear();
        scratch.lines.clear();
        // Nothing changes until every candidate pair is scored: each filter's prior (or map
        // prediction) is worked out once per image, each observation converted once.
        scratch.priors.clear();
        scratch.priors.resize(self.slots.len(), None);
        let pose = self.pose_usable().map(|p| (p.clone(), p.heading_sin_cos()));
        for (i, obs) in observations.iter().enumerate() {
            self.diagnostics.observations += 1;
            if self.take_line(obs, &mut scratch.lines) {
                scratch.measurements.push(None);
                continue;
            }
            let z = self.measurement(obs);
            let group = self.groups.iter().position(|g| g.accepts(obs));
            let (Some(z), Some(group)) = (z, group) else {
                self.diagnostics.ignored += 1;
                scratch.measurements.push(None);
                continue;
            };
            let (measured, noise) = (z.cartesian(), z.cartesian_noise());
            scratch.measurements.push(Some(Measured { group, position: measured, noise }));
            for g in self.groups.iter().filter(|g| g.accepts(obs)) {
                for slot in g.slots.clone() {
                    let prior = *scratch.priors[slot]
                        .get_or_insert_with(|| self.association_prior(slot, pose.as_ref()));
                    if let Some((position, covariance)) = prior
                        && let Some(innovation) =
                            innovation_at(position, &covariance, measured, &noise)
                        && innovation.nis <= self.gate
                    {
                        scratch.pairs.push((innovation.cost(), i, slot));
                    }
                }
            }
        }
        scratch.pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        scratch.observation_done.clear();
        scratch.observation_done.resize(observations.len(), Assignment::Open);
        scratch.slot_taken.clear();
        scratch.slot_taken.resize(self.slots.len(), false);
        let margin = self.config.association.ambiguity_margin;
        for k in 0..scratch.pairs.len() {
            let (cost, i, slot) = scratch.pairs[k];
            if scratch.observation_done[i] != Assignment::Open || scratch.slot_taken[slot] {
                continue;
            }
            let second = scratch
                .pairs
                .iter()
                .filter(|&&(_, j, s)| j == i && s != slot && !scratch.slot_taken[s])
                .map(|p| p.0)
                .fold(f64::INFINITY, f64::min);
            if second - cost < margin {
                scratch.observation_done[i] = Assignment::Ambiguous(self.slots[slot].group);
                continue;
            }
            scratch.observation_done[i] = Assignment::Taken;
            scratch.slot_taken[slot] = true;
            if let Some(m) = scratch.measurements[i] {
                self.associate(slot, &m, now);
            }
        }
        for (i, m) in scratch.measurements.iter().enumerate() {
            let Some(m) = m else { continue };
            match scratch.observation_done[i] {
                Assignment::Taken => {}
                Assignment::Ambiguous(g) => {
                    self.diagnostics.ambiguous += 1;
                    self.reject(g, m, now);
                }
                Assignment::Open => self.reject(m.group, m, now),
            }
        }
        self.scratch = scratch;
    }

    pub(super) fn start_track(
        &mut self,
        slot: usize,
        m: &Measured,
        now: Time,
        model: MotionModel,
        velocity_sigma: f64,
    ) {
        self.slots[slot].track = Some(Track {
            filter: ObjectFilter::from_converted(m.position, m.noise, velocity_sigma, model),
            lag: Lag::default(),
            existence: self.config.confidence.initial_existence,
            last_seen: now,
            updated: true,
        });
    }

    pub(super) fn is_stale(&self, slot: usize, now: Time) -> bool {
        self.slots[slot].track.as_ref().is_none_or(|t| {
            (now - t.last_seen).as_secs_f64() > self.config.association.reinit_window
        })
    }

    fn reject(&mut self, g: usize, m: &Measured, now: Time) {
        self.diagnostics.rejected += 1;
        let position = m.position;
        let group = &self.groups[g];
        let (model, velocity_sigma, category) = (group.model, group.velocity_sigma, group.category);
        // A mobile object or obstacle nobody follows starts at once (a false positive dies of
        // negative information); a free landmark instance waits for consistent observations,
        // which keeps false positives out of recovery.
        if category != ObjectCategory::Landmark
            && let Some(free) = group.slots.clone().find(|&s| self.slots[s].track.is_none())
        {
            self.start_track(free, m, now, model, velocity_sigma);
            self.diagnostics.reinitialized += 1;
            return;
        }
        let radius = self.config.association.reinit_radius;
        let group = &mut self.groups[g];
        group.pending.push(Pending { position, stamp: now });
        let (consistent, since) = group
            .pending
            .iter()
            .filter(|p| (p.position - position).norm() <= radius)
            .fold((0, now), |(n, t), p| (n + 1, t.min(p.stamp)));
        if consistent < self.config.association.reinit_observations {
            return;
        }
        group.pending.retain(|p| (p.position - position).norm() > radius);
        let Some(slot) = self.reinit_slot(g, m, now, since) else {
            if category == ObjectCategory::Landmark && self.pose_usable().is_some() {
                // Consistent observations of a landmark where the map and the pose put none:
                // a persistent false positive, or the robot is not where it believes.
                self.kidnap.reject(usize::MAX - g, now);
                if self.kidnap_triggered() {
                    self.declare_disagreement();
                }
            }
            return;
        };
        self.slots[slot].track = None;
        self.diagnostics.reinitialized += 1;
        self.diagnostics.associated += 1;
        self.start_track(slot, m, now, model, velocity_sigma);
        if category == ObjectCategory::Landmark {
            self.frame_gains.push(FrameGain { slot, gained: m.gained(), prior: None });
        }
    }

    /// Which filter a cluster of consistent rejected observations, the oldest made at `since`,
    /// restarts. A mobile object or obstacle confirmed since then is really elsewhere: the
    /// cluster was clutter.
    fn reinit_slot(&self, g: usize, m: &Measured, now: Time, since: Time) -> Option<usize> {
        let group = &self.groups[g];
        let unconfirmed =
            |s: usize| self.slots[s].track.as_ref().is_none_or(|t| t.last_seen < since);
        match group.category {
            ObjectCategory::Mobile => Some(group.slots.start).filter(|&s| unconfirmed(s)),
            ObjectCategory::Obstacle => group
                .slots
                .clone()
                .filter(|&s| unconfirmed(s))
                .min_by(|&a, &b| self.confidence(a).total_cmp(&self.confidence(b))),
            ObjectCategory::Landmark => {
                let eligible = group.slots.clone().filter(|&s| self.is_stale(s, now));
                if self.pose_usable().is_some() {
                    // The instance the pose and the map make most likely, if any fits.
                    eligible
                        .filter_map(|s| {
                            let (l, cov) = self.map_prediction(s)?;
                            let i = innovation_at(l, &cov, m.position, &m.noise)?;
                            (i.nis <= self.gate).then_some((s, i.cost()))
                        })
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                        .map(|(s, _)| s)
                } else {
                    // Lost: any label will do, recovery relabels the instances.
                    eligible.min_by_key(|&s| {
                        self.slots[s]
                            .track
                            .as_ref()
                            .map_or(0, |t| t.last_seen.as_nanos().saturating_add(1))
                    })
                }
            }
        }
    }
}
