//! The painted field lines as observations of the pose: each line seen in an image is
//! associated with the map line it fits best (gated, unambiguous, the observed point on the
//! painted segment) and corrects the pose filter's distance to that line and heading.

use strata_runtime::Time;

use super::WorldModel;
use crate::percept::Observation;
use crate::world::pose::{LineObservation, MeasuredLine};

impl WorldModel {
    /// Keeps a line observation in `lines_seen` for [`WorldModel::correct_with_lines`]; `true` for
    /// an observation that is one (association leaves it alone).
    pub(super) fn take_line(
        &mut self,
        obs: &Observation,
        lines_seen: &mut Vec<MeasuredLine>,
    ) -> bool {
        let lines = &self.config.lines;
        if !lines.accepts(obs.class) {
            return false;
        }
        let direction = obs.orientation.filter(|o| o.is_finite());
        let z = self.measurement(obs);
        match (z, direction) {
            (Some(z), Some(direction)) if z.range <= lines.max_range => {
                let observation = LineObservation {
                    point: z.cartesian(),
                    point_covariance: z.cartesian_noise(),
                    direction,
                    direction_sigma: lines.direction_sigma,
                };
                lines_seen.push(observation.measurement());
            }
            _ => self.diagnostics.ignored += 1,
        }
        true
    }

    /// Corrects the pose with this image's line observations. Lines say nothing while the pose
    /// is lost (every line has many twins), and a line that fits no map line is not taken as
    /// evidence of a kidnap: lines are seen where landmarks are not, and a robot's own feet or
    /// another robot's legs can look like one.
    pub(super) fn correct_with_lines(&mut self, now: Time) {
        let observations = std::mem::take(&mut self.scratch.lines);
        let margin = self.config.association.ambiguity_margin;
        let end_margin = self.config.lines.end_margin;
        for measured in &observations {
            let Some(pose) = self.pose_usable() else { break };
            let mut best: Option<(f64, usize)> = None;
            let mut second = f64::INFINITY;
            for (k, line) in self.map_lines.iter().enumerate() {
                let Some((innovation, along)) =
                    pose.line_innovation_within(line, measured, self.gate)
                else {
                    continue;
                };
                if innovation.nis > self.gate
                    || along < -end_margin
                    || along > line.length + end_margin
                {
                    continue;
                }
                let cost = innovation.cost();
                match best {
                    Some((c, _)) if cost >= c => second = second.min(cost),
                    _ => {
                        if let Some((c, _)) = best {
                            second = second.min(c);
                        }
                        best = Some((cost, k));
                    }
                }
            }
            let Some((cost, k)) = best else {
                self.diagnostics.rejected += 1;
                continue;
            };
            if second - cost < margin {
                self.diagnostics.ambiguous += 1;
                continue;
            }
            let line = self.map_lines[k];
            if let Some(pose) = self.pose.as_mut()
                && pose.update_line_with(&line, measured).is_some()
            {
                self.diagnostics.associated += 1;
                self.diagnostics.line_corrections += 1;
                self.last_pose_correction = Some(now);
            }
        }
        self.scratch.lines = observations;
    }
}
