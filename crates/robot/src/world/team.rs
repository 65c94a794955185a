//! Multi-agent world modeling (MAWM, paper 3.3): teammates' estimates of the mobile objects of
//! interest fused with this robot's own, with a Kalman (inverse-covariance) fusion in the field
//! frame as in the approach the paper cites. Each estimate is weighted by its covariance, its
//! age and the sender's confidence in its own pose; estimates are fused only if they agree
//! (Mahalanobis gate), so a teammate's wild estimate cannot pull the team's estimate away.

use std::collections::BTreeMap;

use nalgebra::{Matrix2, Vector2};
use serde::{Deserialize, Serialize};
use strata_runtime::Time;

use super::config::TeamConfig;
use super::math::{all_finite, chi2_2dof_quantile, nis, symmetrize2};
use super::state::ObjectId;
use crate::geometry::{Global, Point, Pose, Vector};
use crate::platform::ObjectClass;

/// One mobile object as a teammate estimates it, in the field frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SharedObject {
    pub class: ObjectClass,
    pub variant: Option<u16>,
    pub position: Point<Global>,
    pub velocity: Option<Vector<Global>>,
    /// Field-frame covariance, including the sender's pose uncertainty.
    pub covariance: Matrix2<f64>,
    /// The sender's confidence in the object, in [0, 1].
    pub confidence: f64,
    /// Seconds between the sender's last observation of the object and `stamp`.
    pub age: f64,
}

/// A teammate's shared estimates: the message the planning layer hands to world modeling.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeammateEstimate {
    pub member: u8,
    /// When the estimate was made, on this robot's clock (the planning layer converts).
    pub stamp: Time,
    pub pose: Pose,
    pub pose_covariance: nalgebra::Matrix3<f64>,
    /// The sender's confidence in its own pose, in [0, 1].
    pub pose_confidence: f64,
    pub objects: Vec<SharedObject>,
}

/// A teammate message world modeling refuses.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("estimate from teammate {member}: `{field}` {problem}")]
pub struct TeamError {
    pub member: u8,
    pub field: String,
    pub problem: String,
}

fn covariance_ok(m: &Matrix2<f64>) -> bool {
    all_finite(m)
        && m[(0, 0)] >= 0.0
        && m[(1, 1)] >= 0.0
        && (m[(0, 1)] - m[(1, 0)]).abs() <= 1e-6 * (1.0 + m[(0, 0)] + m[(1, 1)])
        && m.determinant() >= -1e-12
}

impl TeammateEstimate {
    /// Checks every number: teammates' data comes from outside the process.
    pub fn validate(&self) -> Result<(), TeamError> {
        let bad = |field: String, problem: &str| TeamError {
            member: self.member,
            field,
            problem: problem.to_owned(),
        };
        if !self.pose.is_finite() || !all_finite(&self.pose_covariance) {
            return Err(bad("pose".into(), "must be finite"));
        }
        if !(0.0..=1.0).contains(&self.pose_confidence) {
            return Err(bad("pose_confidence".into(), "must lie in [0, 1]"));
        }
        for (i, o) in self.objects.iter().enumerate() {
            if !o.position.is_finite()
                || o.velocity.is_some_and(|v| !v.x.is_finite() || !v.y.is_finite())
            {
                return Err(bad(format!("objects[{i}].position"), "must be finite"));
            }
            if !covariance_ok(&o.covariance) {
                return Err(bad(
                    format!("objects[{i}].covariance"),
                    "must be a finite symmetric positive semi-definite matrix",
                ));
            }
            if !(0.0..=1.0).contains(&o.confidence) {
                return Err(bad(format!("objects[{i}].confidence"), "must lie in [0, 1]"));
            }
            if !(o.age.is_finite() && o.age >= 0.0) {
                return Err(bad(format!("objects[{i}].age"), "must be finite and >= 0"));
            }
        }
        Ok(())
    }
}

/// The team's estimate of one mobile object of interest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeamObject {
    /// The object filter of this robot it corresponds to.
    pub id: ObjectId,
    pub name: super::state::ObjectName,
    pub class: ObjectClass,
    pub position: Point<Global>,
    pub velocity: Option<Vector<Global>>,
    pub covariance: Matrix2<f64>,
    /// Whether this robot's own estimate is part of the fusion.
    pub includes_own: bool,
    /// Teammates whose estimates were fused.
    pub teammates: Vec<u8>,
    /// Teammates whose estimates disagreed and were left out.
    pub rejected: Vec<u8>,
}

/// Who an estimate comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    Own,
    Teammate(u8),
}

/// One estimate entering the fusion, already aged and weighted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusionCandidate {
    pub source: Source,
    pub position: Vector2<f64>,
    pub covariance: Matrix2<f64>,
    pub velocity: Option<Vector2<f64>>,
}

/// The fused estimate and who took part.
#[derive(Clone, Debug, PartialEq)]
pub struct Fused {
    pub position: Vector2<f64>,
    pub covariance: Matrix2<f64>,
    pub velocity: Option<Vector2<f64>>,
    pub members: Vec<Source>,
    pub rejected: Vec<Source>,
}

/// Up to this many candidates, [`fuse`] tabulates which pairs agree.
const SMALL_FUSION: usize = 16;

/// Fuses the largest set of mutually agreeing estimates (each within the gate of the set's
/// seed). Ties prefer the set holding this robot's own estimate (a single teammate cannot
/// overrule it, two agreeing teammates can), then the most informative set.
pub fn fuse(candidates: &[FusionCandidate], gate: f64) -> Option<Fused> {
    let n = candidates.len();
    let agree_pair = |i: usize, j: usize| {
        let (seed, other) = (&candidates[i], &candidates[j]);
        nis(&(seed.position - other.position), &(seed.covariance + other.covariance))
            .is_some_and(|d| d <= gate)
    };
    let information_of =
        |j: usize| candidates[j].covariance.try_inverse().map(|inv| inv.determinant());
    // A team's worth of candidates: each pair is tested once (the test gives the same numbers
    // either way round: the difference only changes sign) and each candidate's information is
    // computed once, not once per seed.
    let small = n <= SMALL_FUSION;
    let mut agreeing = [0u16; SMALL_FUSION];
    let mut informations = [None; SMALL_FUSION];
    if small {
        for i in 0..n {
            informations[i] = information_of(i);
            for j in i + 1..n {
                if agree_pair(i, j) {
                    agreeing[i] |= 1 << j;
                    agreeing[j] |= 1 << i;
                }
            }
        }
    }
    let agree = |i: usize, j: usize| {
        j == i || if small { agreeing[i] & (1 << j) != 0 } else { agree_pair(i, j) }
    };
    // Only the best seed's members are listed (again, at the end): no list per seed.
    let mut best: Option<(usize, bool, f64, usize)> = None;
    for i in 0..n {
        let (mut count, mut own, mut information) = (0, false, -0.0);
        for j in (0..n).filter(|&j| agree(i, j)) {
            count += 1;
            own |= candidates[j].source == Source::Own;
            if let Some(det) = if small { informations[j] } else { information_of(j) } {
                information += det;
            }
        }
        let better = match &best {
            None => true,
            Some((n, o, info, _)) => {
                (count, own) > (*n, *o) || ((count, own) == (*n, *o) && information > *info)
            }
        };
        if better {
            best = Some((count, own, information, i));
        }
    }
    let (_, _, _, seed) = best?;
    let members: Vec<usize> = (0..n).filter(|&j| agree(seed, j)).collect();
    let mut info = Matrix2::zeros();
    let mut info_mean = Vector2::zeros();
    let mut velocity_sum = Vector2::zeros();
    let mut velocity_weight = 0.0;
    for &j in &members {
        let c = &candidates[j];
        let inv = c.covariance.try_inverse()?;
        info += inv;
        info_mean += inv * c.position;
        if let Some(v) = c.velocity {
            let w = inv.trace();
            velocity_sum += v * w;
            velocity_weight += w;
        }
    }
    let covariance = symmetrize2(info.try_inverse()?);
    let position = covariance * info_mean;
    if !all_finite(&covariance) || !all_finite(&position) {
        return None;
    }
    Some(Fused {
        position,
        covariance,
        velocity: (velocity_weight > 0.0).then(|| velocity_sum / velocity_weight),
        rejected: (0..candidates.len())
            .filter(|j| !members.contains(j))
            .map(|j| candidates[j].source)
            .collect(),
        members: members.iter().map(|&j| candidates[j].source).collect(),
    })
}

/// The newest estimate of each teammate, and how to turn them into fusion candidates.
#[derive(Clone, Debug)]
pub struct TeamFusion {
    config: TeamConfig,
    gate: f64,
    teammates: BTreeMap<u8, TeammateEstimate>,
}

impl TeamFusion {
    pub fn new(config: TeamConfig) -> TeamFusion {
        TeamFusion {
            gate: chi2_2dof_quantile(config.gate_probability),
            config,
            teammates: BTreeMap::new(),
        }
    }

    pub fn gate(&self) -> f64 {
        self.gate
    }

    /// Stores a teammate's estimate (replacing an older one from the same member).
    pub fn insert(&mut self, estimate: TeammateEstimate) -> Result<(), TeamError> {
        estimate.validate()?;
        match self.teammates.get(&estimate.member) {
            Some(old) if old.stamp > estimate.stamp => {}
            _ => {
                self.teammates.insert(estimate.member, estimate);
            }
        }
        Ok(())
    }

    /// Forgets estimates older than the configured age.
    pub fn prune(&mut self, now: Time) {
        let max_age = self.config.max_age;
        self.teammates.retain(|_, e| (now - e.stamp).as_secs_f64() <= max_age);
    }

    pub fn teammates(&self) -> impl Iterator<Item = &TeammateEstimate> {
        self.teammates.values()
    }

    /// The teammates' estimates of objects of `class` (matching `variant` when given), aged
    /// to `now` and weighted. A teammate reporting several such objects contributes the one
    /// it is most confident in.
    pub fn candidates(
        &self,
        now: Time,
        class: ObjectClass,
        variant: Option<u16>,
        friction: f64,
    ) -> Vec<FusionCandidate> {
        let mut out = Vec::new();
        self.candidates_into(now, class, variant, friction, &mut out);
        out
    }

    /// As [`TeamFusion::candidates`], into `out` (cleared first; no allocation once warm).
    pub fn candidates_into(
        &self,
        now: Time,
        class: ObjectClass,
        variant: Option<u16>,
        friction: f64,
        out: &mut Vec<FusionCandidate>,
    ) {
        out.clear();
        for e in self.teammates.values() {
            let Some(o) = e
                .objects
                .iter()
                .filter(|o| o.class == class && (variant.is_none() || o.variant == variant))
                .max_by(|a, b| a.confidence.total_cmp(&b.confidence))
            else {
                continue;
            };
            let age = (now - e.stamp).as_secs_f64() + o.age;
            if age > self.config.max_age {
                continue;
            }
            // The sender saw the object `age` seconds ago; it kept rolling since.
            let mut position = Vector2::new(o.position.x, o.position.y);
            let velocity = o.velocity.map(|v| Vector2::new(v.x, v.y));
            if let Some(v) = velocity {
                let s = v.norm();
                let travel = if friction > 0.0 && s > 0.0 {
                    let t = age.min(s / friction);
                    s * t - friction * t * t / 2.0
                } else {
                    s * age
                };
                if s > 0.0 {
                    position += v / s * travel;
                }
            }
            let weight = (e.pose_confidence * o.confidence).max(self.config.min_weight);
            let covariance =
                (o.covariance + Matrix2::identity() * (self.config.position_noise * age)) / weight;
            out.push(FusionCandidate {
                source: Source::Teammate(e.member),
                position,
                covariance: symmetrize2(covariance),
                velocity,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn candidate(source: Source, x: f64, y: f64, var: f64) -> FusionCandidate {
        FusionCandidate {
            source,
            position: Vector2::new(x, y),
            covariance: Matrix2::identity() * var,
            velocity: None,
        }
    }

    #[test]
    fn two_equal_estimates_average_and_halve_the_covariance() {
        let fused = fuse(
            &[
                candidate(Source::Own, 1.0, 0.0, 0.04),
                candidate(Source::Teammate(2), 1.2, 0.0, 0.04),
            ],
            9.21,
        )
        .expect("fusable");
        assert_relative_eq!(fused.position, Vector2::new(1.1, 0.0), epsilon = 1e-12);
        assert_relative_eq!(fused.covariance, Matrix2::identity() * 0.02, epsilon = 1e-12);
        assert!(fused.rejected.is_empty());
    }

    #[test]
    fn a_single_confident_teammate_cannot_overrule_the_own_estimate() {
        let fused = fuse(
            &[
                candidate(Source::Own, 1.0, 0.0, 0.04),
                candidate(Source::Teammate(3), -3.0, 2.0, 0.0001),
            ],
            9.21,
        )
        .expect("fusable");
        assert_relative_eq!(fused.position, Vector2::new(1.0, 0.0), epsilon = 1e-12);
        assert_eq!(fused.rejected, vec![Source::Teammate(3)]);
    }
}
