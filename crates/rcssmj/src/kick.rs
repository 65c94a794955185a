//! The T1's kicks, numbered as the soccer application and the 2D simulator number theirs:
//! `Kick(0)` a strong kick straight ahead, `Kick(1)` a softer one (a pass). The sideways kicks
//! (`Kick(2)`, `Kick(3)` there) are not in this catalogue: the platform refuses them.
//!
//! Each kick is a *walk-through kick*: Booster's walking policy keeps the balance, the kick
//! orders it a short burst of fast walking through the ball, then stands. The burst starts
//! harder than an ordinary walk (a larger smoothing step), so the feet reach the ball at
//! speed, and always at the gait's first step (phase zero, the left leg swinging first), so
//! the same foot meets the ball at the same moment every time: ordered while walking, a kick
//! stands first. A swing of one leg can be laid on the policy's targets during that leg's
//! swing ([`Swing`]): the forward kick straightens the right knee harder as the right foot
//! swings through the ball.
//!
//! The platform does not know where the ball is: the motion is the same wherever it is, and
//! the soccer application's approach puts the robot behind the ball. The kicks were tuned from
//! a ball 0.20 m ahead of the torso on its centre line, from standing; the approach orders
//! them walking slowly with the ball 0.36-0.40 m ahead (crates/soccer/bodies/booster-t1.toml
//! says why). crates/rcssmj/tests/kick.rs measures both and has a bench for other placements.

use serde::{Deserialize, Serialize};

use crate::joints::LEG_COUNT;
use crate::policy::WalkCommand;

/// One kick of the catalogue.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KickSpec {
    /// What the catalogue calls it.
    pub name: String,
    /// The burst's walk: forward m/s.
    pub forward: f64,
    /// ... and leftward m/s (lines the kicking foot up with a ball in the middle).
    #[serde(default)]
    pub sideways: f64,
    /// ... and turning rad/s, counter-clockwise (aims the kicking foot).
    #[serde(default)]
    pub turn: f64,
    /// How fast the burst's command rises and falls, m/s per 20 ms cycle (the deployment's
    /// ordinary walk: 0.02).
    pub smoothing_step: f64,
    /// How long the burst is ordered, s.
    pub burst: f64,
    /// From the end of the burst until the body stands still again, s.
    pub settle: f64,
    /// Ordered while walking, the kick first stands this long, s, so that its burst starts
    /// from both feet on the ground at the gait's first step, as from standing.
    pub stop: f64,
    /// A leg swing on top of the policy's targets, if any.
    pub swing: Option<Swing>,
}

impl KickSpec {
    /// The whole motion from standing, s: burst and settling (from a walk, `stop` more).
    pub fn duration(&self) -> f64 {
        self.burst + self.settle
    }

    /// Checks every value; the error names the kick and the field.
    pub fn validate(&self) -> Result<(), String> {
        let name = &self.name;
        let positive = [
            ("smoothing_step", self.smoothing_step),
            ("burst", self.burst),
            ("settle", self.settle),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("kick {name:?}: {field} must be > 0, got {value}"));
            }
        }
        if !(self.stop.is_finite() && self.stop >= 0.0) {
            return Err(format!("kick {name:?}: stop must be >= 0, got {}", self.stop));
        }
        let walk = [self.forward, self.sideways, self.turn];
        if !walk.iter().all(|v| v.is_finite()) {
            return Err(format!(
                "kick {name:?}: forward, sideways and turn must be numbers, got {walk:?}"
            ));
        }
        if let Some(swing) = &self.swing {
            swing.validate().map_err(|e| format!("kick {name:?}: swing: {e}"))?;
        }
        Ok(())
    }
}

/// Which leg swings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KickLeg {
    Left,
    Right,
}

impl KickLeg {
    /// The leg's first joint among the policy's twelve (hip pitch).
    fn first_joint(self) -> usize {
        match self {
            KickLeg::Left => 0,
            KickLeg::Right => LEG_COUNT / 2,
        }
    }
}

/// A swing of one leg laid on the walking policy's targets: the first time the gait phase (the
/// policy's, 0 to 1 per gait cycle; a kick from standing starts at 0, the left leg swinging
/// first) enters the window `[start, end)` at least `after` seconds into the burst, the leg's
/// pitch joints get these offsets until it leaves the window, rising and falling as a half
/// sine over it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Swing {
    pub leg: KickLeg,
    /// s into the burst before the swing may start.
    pub after: f64,
    /// The gait-phase window.
    pub start: f64,
    pub end: f64,
    /// Peak offsets, rad: hip pitch (negative swings the leg forward), knee (negative
    /// straightens it), ankle pitch.
    pub hip: f64,
    pub knee: f64,
    pub ankle: f64,
}

impl Swing {
    fn validate(&self) -> Result<(), String> {
        let window = (0.0..=1.0).contains(&self.start)
            && (0.0..=1.0).contains(&self.end)
            && self.start < self.end;
        if !window {
            return Err(format!(
                "the phase window [{}, {}) must lie within [0, 1] and not be empty",
                self.start, self.end
            ));
        }
        let values = [self.after, self.hip, self.knee, self.ankle];
        if !values.iter().all(|v| v.is_finite()) || self.after < 0.0 {
            return Err(format!("after must be >= 0 and the offsets numbers, got {values:?}"));
        }
        Ok(())
    }

    /// The offsets at gait phase `phase` while the swing runs, else zero.
    fn offsets(&self, phase: f64) -> [f64; LEG_COUNT] {
        let mut offsets = [0.0; LEG_COUNT];
        if (self.start..self.end).contains(&phase) {
            let shape =
                (std::f64::consts::PI * (phase - self.start) / (self.end - self.start)).sin();
            let first = self.leg.first_joint();
            // The policy's leg order: hip pitch, hip roll, hip yaw, knee, ankle pitch, roll.
            offsets[first] = shape * self.hip;
            offsets[first + 3] = shape * self.knee;
            offsets[first + 4] = shape * self.ankle;
        }
        offsets
    }
}

/// The kicks the T1 makes, by sequence number. Tuned against rcssservermj from a ball 0.20 m
/// ahead of the torso, 0.05 m either side of its centre line, from standing;
/// crates/rcssmj/tests/kick.rs measures them. The right foot meets the
/// ball. Both walk a little to the left, or a ball just left of the centre line passes between
/// the legs, and turn a little to the right, which takes back some of the angle to the left at
/// which the inside of the right foot sends the ball.
pub fn catalogue() -> Vec<KickSpec> {
    vec![
        KickSpec {
            name: "forward: a walk-through kick with a right-leg knee snap".to_owned(),
            forward: 0.6,
            sideways: 0.1,
            turn: -0.5,
            smoothing_step: 0.05,
            burst: 1.2,
            settle: 1.0,
            stop: 0.6,
            // The right leg's first swing (phase 0.6 to 0.95 from a standing start) meets the
            // ball; straightening its knee harder throws the foot through it. More than 0.5
            // rad made the robot stumble and fall in trials.
            swing: Some(Swing {
                leg: KickLeg::Right,
                after: 0.0,
                start: 0.65,
                end: 0.9,
                hip: 0.0,
                knee: -0.5,
                ankle: 0.0,
            }),
        },
        KickSpec {
            name: "pass: a walk-through kick".to_owned(),
            forward: 0.4,
            sideways: 0.1,
            turn: -0.3,
            smoothing_step: 0.04,
            burst: 1.0,
            settle: 0.8,
            stop: 0.6,
            swing: None,
        },
    ]
}

/// Where the swing of a running kick is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum SwingStage {
    /// Waiting for the phase to enter its window.
    Waiting,
    /// In its window.
    Running,
    Done,
}

/// A kick in progress.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KickRun {
    /// The sequence number.
    pub sequence: u8,
    /// s since the kick started.
    pub elapsed: f64,
    /// s of standing before the burst (the spec's `stop` from a walk, else 0).
    lead: f64,
    burst_started: bool,
    swing: SwingStage,
    last_phase: Option<f64>,
}

/// What a kick asks of one cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KickCycle {
    /// The walk to order the policy this cycle.
    pub command: WalkCommand,
    /// The command's smoothing step this cycle.
    pub smoothing_step: f64,
    /// The burst starts this cycle: its first step is the gait's first (phase zero).
    pub restart_gait: bool,
    /// Offsets to add to the policy's leg targets, rad, in the policy's order.
    pub offsets: [f64; LEG_COUNT],
}

impl KickRun {
    /// A kick ordered while standing, or while walking (`walking`: it stops first).
    pub fn new(sequence: u8, spec: &KickSpec, walking: bool) -> KickRun {
        KickRun {
            sequence,
            elapsed: 0.0,
            lead: if walking { spec.stop } else { 0.0 },
            burst_started: false,
            swing: SwingStage::Waiting,
            last_phase: None,
        }
    }

    /// This run's whole duration, s.
    pub fn duration(&self, spec: &KickSpec) -> f64 {
        self.lead + spec.duration()
    }

    /// This cycle of the kick, at the policy's gait phase `phase` (before this cycle's step);
    /// then advances the kick by `cycle` seconds.
    pub fn step(&mut self, spec: &KickSpec, phase: f64, cycle: f64) -> KickCycle {
        // Time into the burst (negative while stopping first).
        let t = self.elapsed - self.lead;
        let bursting = t >= -1e-9 && t < spec.burst;
        let restart_gait = bursting && !self.burst_started;
        self.burst_started |= bursting;
        let command = if bursting {
            WalkCommand { vx: spec.forward, vy: spec.sideways, yaw_rate: spec.turn }
        } else {
            WalkCommand::STAND
        };
        // The phase the policy steps with: a restarted gait's.
        let phase = if restart_gait { 0.0 } else { phase };
        let mut offsets = [0.0; LEG_COUNT];
        if let Some(swing) = &spec.swing {
            let window = swing.start..swing.end;
            let entering = window.contains(&phase)
                && self.last_phase.is_none_or(|last| !window.contains(&last));
            match self.swing {
                SwingStage::Waiting if bursting && t >= swing.after - 1e-9 && entering => {
                    self.swing = SwingStage::Running;
                }
                SwingStage::Running if !window.contains(&phase) => {
                    self.swing = SwingStage::Done;
                }
                _ => {}
            }
            if self.swing == SwingStage::Running {
                offsets = swing.offsets(phase);
            }
        }
        self.last_phase = Some(phase);
        self.elapsed += cycle;
        KickCycle { command, smoothing_step: spec.smoothing_step, restart_gait, offsets }
    }

    /// Whether the kick has ended (the body stands again).
    pub fn finished(&self, spec: &KickSpec) -> bool {
        self.elapsed >= self.duration(spec) - 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CYCLE: f64 = 0.02;

    #[test]
    fn the_catalogue_is_valid_and_numbered_as_the_soccer_kicks() {
        let kicks = catalogue();
        assert_eq!(kicks.len(), 2);
        assert!(kicks[0].name.starts_with("forward"));
        assert!(kicks[1].name.starts_with("pass"));
        assert!(kicks[1].forward < kicks[0].forward, "a pass is softer");
        for kick in &kicks {
            kick.validate().expect("valid");
        }
    }

    #[test]
    fn a_kick_bursts_forward_then_stands_until_its_duration() {
        let spec = &catalogue()[0];
        let mut run = KickRun::new(0, spec, false);
        let first = run.step(spec, 0.0, CYCLE);
        assert_eq!(first.command.vx, spec.forward);
        assert_eq!(first.smoothing_step, spec.smoothing_step);
        assert!(first.restart_gait, "the burst starts the gait afresh");
        let cycles = (spec.duration() / CYCLE).round() as usize;
        let mut standing = 0;
        for _ in 1..cycles {
            assert!(!run.finished(spec));
            let cycle = run.step(spec, 0.0, CYCLE);
            assert!(!cycle.restart_gait);
            if cycle.command == WalkCommand::STAND {
                standing += 1;
            }
        }
        assert!(run.finished(spec));
        assert_eq!(standing, (spec.settle / CYCLE).round() as usize);
    }

    #[test]
    fn a_kick_ordered_while_walking_stands_first() {
        let spec = &catalogue()[1];
        let mut run = KickRun::new(1, spec, true);
        assert!((run.duration(spec) - spec.stop - spec.duration()).abs() < 1e-9);
        let stop = (spec.stop / CYCLE).round() as usize;
        for _ in 0..stop {
            let cycle = run.step(spec, 0.3, CYCLE);
            assert_eq!(cycle.command, WalkCommand::STAND);
            assert!(!cycle.restart_gait);
        }
        let burst = run.step(spec, 0.3, CYCLE);
        assert!(burst.restart_gait && burst.command.vx == spec.forward);
    }

    #[test]
    fn a_swing_runs_once_in_the_first_window_after_its_delay() {
        let swing = Swing {
            leg: KickLeg::Right,
            after: 0.5,
            start: 0.2,
            end: 0.4,
            hip: -0.5,
            knee: -0.3,
            ankle: 0.1,
        };
        let spec = KickSpec { swing: Some(swing), burst: 5.0, ..catalogue()[0].clone() };
        spec.validate().expect("valid");
        let mut run = KickRun::new(0, &spec, false);
        let mut peak: f64 = 0.0;
        let mut active_cycles = 0;
        // Three gait cycles of 50 steps; the first window (steps 10 to 19) is too early.
        for step in 0..150 {
            let phase = (step % 50) as f64 / 50.0;
            let cycle = run.step(&spec, phase, CYCLE);
            let hip = cycle.offsets[LEG_COUNT / 2];
            assert_eq!(cycle.offsets[0], 0.0, "the left leg is not touched");
            if hip != 0.0 {
                assert!((60..70).contains(&step), "swing at step {step}");
                active_cycles += 1;
                peak = peak.min(hip);
                assert!((cycle.offsets[LEG_COUNT / 2 + 3] / hip - 0.6).abs() < 1e-9);
            }
        }
        assert_eq!(active_cycles, 9, "phases 0.22 to 0.38 (0.2 itself is zero)");
        assert!((peak + 0.5).abs() < 0.01, "peak {peak}");
    }

    #[test]
    fn invalid_kicks_are_refused_by_name() {
        let mut spec = catalogue()[0].clone();
        spec.burst = f64::NAN;
        assert!(spec.validate().err().unwrap_or_default().contains("burst"));
        let mut spec = catalogue()[0].clone();
        spec.swing = Some(Swing {
            leg: KickLeg::Left,
            after: 0.0,
            start: 0.5,
            end: 0.2,
            hip: 0.0,
            knee: 0.0,
            ankle: 0.0,
        });
        assert!(spec.validate().err().unwrap_or_default().contains("window"));
    }
}
