//! Each object's confidence in [0, 1]: its existence (raised by detections, lowered by negative
//! information), the time since it was seen and its covariance.

use super::WorldModel;
use crate::percept::ViewCone;
use crate::world::math::{BearingBound, polar, sigma_radius};
use crate::world::state::ObjectId;

/// Objects closer than this are not expected to be seen (below the camera), m.
const MIN_VISIBLE_RANGE: f64 = 0.2;

pub(super) fn bayes_detect(e: f64, pd: f64, pf: f64) -> f64 {
    e * pd / (e * pd + (1.0 - e) * pf)
}

fn bayes_miss(e: f64, pd: f64) -> f64 {
    e * (1.0 - pd) / (e * (1.0 - pd) + (1.0 - e))
}

impl WorldModel {
    /// Objects predicted well inside the view that were not seen: less likely to be there,
    /// and a little less certain where they are.
    pub(super) fn negative_information(&mut self, view: &ViewCone) {
        let k = self.config.confidence;
        let bearing_bound = BearingBound::new(view, k.view_margin);
        for slot in &mut self.slots {
            let Some(track) = &mut slot.track else { continue };
            if track.updated {
                continue;
            }
            // Too close, beyond the camera's range or outside its bearings whatever the
            // uncertainty (the tests below only get stricter): no need for the bearing's
            // trigonometry.
            let position = track.filter.position_vector();
            let range = position.norm();
            let nearest = MIN_VISIBLE_RANGE.max(view.near);
            if range < nearest
                || range > view.range
                || bearing_bound.certainly_outside(position, range)
            {
                continue;
            }
            let (z, h) = polar(position);
            let s = h * track.filter.position_covariance() * h.transpose();
            let (sr, sb) = (s[(0, 0)].max(0.0).sqrt(), s[(1, 1)].max(0.0).sqrt());
            if z.x < nearest || z.x + 2.0 * sr > view.range {
                continue;
            }
            let margin = k.view_margin + 2.0 * sb;
            if !view.contains_polar(track.filter.position().range(), z.y, margin) {
                continue;
            }
            track.existence = bayes_miss(track.existence, k.detection_probability)
                .clamp(k.min_existence, k.max_existence);
            track.filter.inflate(k.miss_inflation);
        }
    }

    /// Confidence of an object filter, in [0, 1]:
    /// `existence * 2^(-age / half_life) / (1 + (sigma / sigma_half)^2)`.
    pub(super) fn confidence(&self, slot: usize) -> f64 {
        let Some(track) = &self.slots[slot].track else { return 0.0 };
        let c = self.groups[self.slots[slot].group].confidence;
        let now = self.time.unwrap_or(track.last_seen);
        let age = (now - track.last_seen).as_secs_f64();
        let sigma = sigma_radius(&track.filter.position_covariance());
        // An object seen in this very frame has not aged: exp(-0) is exactly 1, without the
        // call (most of the filters a frame updates are asked right after).
        let decay =
            if age == 0.0 { 1.0 } else { (-age / c.half_life * std::f64::consts::LN_2).exp() };
        let value = track.existence * decay / (1.0 + (sigma / c.sigma_half).powi(2));
        if value.is_finite() { value.clamp(0.0, 1.0) } else { 0.0 }
    }

    /// [`WorldModel::confidence`], from the end of the frame when nothing changed since.
    pub(super) fn frame_confidence(&self, slot: usize) -> f64 {
        if !self.confidences_current {
            return self.confidence(slot);
        }
        let c = self.confidences[slot];
        debug_assert_eq!(c.to_bits(), self.confidence(slot).to_bits(), "slot {slot}");
        c
    }

    /// Something that a confidence depends on may change: the end-of-frame confidences are
    /// no longer those of the model.
    pub(super) fn confidence_changes(&mut self) {
        self.confidences_current = false;
    }

    /// The confidence of an object, in [0, 1] (0 when not tracked).
    pub fn object_confidence(&self, id: ObjectId) -> f64 {
        if id.index() < self.slots.len() { self.confidence(id.index()) } else { 0.0 }
    }
}
