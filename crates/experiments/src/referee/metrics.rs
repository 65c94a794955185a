//! Metric functions: pure, on the events of a game and each robot's believed states, and the
//! results and summaries they make.

use std::collections::BTreeMap;

use serde::Serialize;
use strata_robot::geometry::Pose;
use strata_sim::{Event, EventKind, GameState, RobotId};
use strata_soccer::behaviors::kickoff_pose;
use strata_soccer::field::TeamField;

use crate::stats::Distribution;

/// Events of one instant: the whistle is recorded in the same simulator step as the state.
pub(super) const SAME_INSTANT: f64 = 1e-6;

/// Each robot's believed game state (its planning layer's decision) at each change: (package
/// stamp s, state), in time order.
pub type Beliefs = BTreeMap<RobotId, Vec<(f64, GameState)>>;

/// The true game states, (time s, state) at each change, from a game's events.
pub fn state_timeline(events: &[Event]) -> Vec<(f64, GameState)> {
    events
        .iter()
        .filter_map(|e| match e.kind {
            EventKind::GameState { state, .. } => Some((e.time.as_secs_f64(), state)),
            _ => None,
        })
        .collect()
}

/// The state of a timeline (true or believed) at `t`: the last change at or before it.
pub fn state_at(timeline: &[(f64, GameState)], t: f64) -> Option<GameState> {
    timeline.iter().take_while(|(at, _)| *at <= t).last().map(|(_, s)| *s)
}

/// A true Ready phase: from Ready to Set.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReadyPhase {
    pub start: f64,
    pub end: f64,
    /// It came from Standby, so the referee gestured (the first Ready of each half with
    /// GameController3's timing).
    pub gesture: bool,
    /// It came from Playing: a goal. The packets keep showing Playing for a while (15 s with
    /// GameController3's timing) and there is no gesture.
    pub after_goal: bool,
}

/// Every Ready phase that ended in Set (one the game or the run ended in is not judged).
pub fn ready_phases(timeline: &[(f64, GameState)]) -> Vec<ReadyPhase> {
    timeline
        .windows(2)
        .enumerate()
        .filter(|(_, w)| w[0].1 == GameState::Ready && w[1].1 == GameState::Set)
        .map(|(i, w)| {
            let before = i.checked_sub(1).map(|b| timeline[b].1);
            ReadyPhase {
                start: w[0].0,
                end: w[1].0,
                gesture: before == Some(GameState::Standby),
                after_goal: before == Some(GameState::Playing),
            }
        })
        .collect()
}

/// A kick-off: the true Set -> Playing, and the referee's whistle with it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct KickOffWhistle {
    pub time: f64,
    /// Whether the referee whistled (signals on); without, `time` is the state change.
    pub whistle: bool,
    /// The robots that heard it.
    pub heard: Vec<RobotId>,
}

/// The kick-offs of a game: each Playing that follows Set, with the whistle of the same
/// instant (goal whistles come with a Ready and are not kick-offs).
pub fn kick_off_whistles(events: &[Event]) -> Vec<KickOffWhistle> {
    let mut previous = None;
    let mut kick_offs = Vec::new();
    for event in events {
        let EventKind::GameState { state, .. } = event.kind else { continue };
        if previous == Some(GameState::Set) && state == GameState::Playing {
            let time = event.time.as_secs_f64();
            let heard = events.iter().find_map(|e| match &e.kind {
                EventKind::Whistle { robots }
                    if (e.time.as_secs_f64() - time).abs() <= SAME_INSTANT =>
                {
                    Some(robots.clone())
                }
                _ => None,
            });
            kick_offs.push(KickOffWhistle {
                time,
                whistle: heard.is_some(),
                heard: heard.unwrap_or_default(),
            });
        }
        previous = Some(state);
    }
    kick_offs
}

/// How long after the whistle at `whistle` a robot's decision showed Playing: 0 when it
/// already did (a false start, counted as such on its own), `None` when it did not before
/// `until` (the next change of the true state, or the end of the run).
pub fn start_delay(changes: &[(f64, GameState)], whistle: f64, until: f64) -> Option<f64> {
    if state_at(changes, whistle) == Some(GameState::Playing) {
        return Some(0.0);
    }
    changes
        .iter()
        .find(|(t, s)| *t > whistle && *t < until && *s == GameState::Playing)
        .map(|(t, _)| t - whistle)
}

/// A robot's decision going to Playing while the true game was in Set, with no true whistle
/// in the `window` before.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FalseStart {
    pub robot: RobotId,
    pub time: f64,
    /// Until its decision left Playing or the true whistle came, s.
    pub duration: f64,
    /// Its own detector fired falsely in the window before; otherwise a teammate's false
    /// whistle reached it in a team message.
    pub own_whistle: bool,
}

/// The false starts of a game, from the robots' believed states, the true states, the true
/// kick-off whistles and the false whistle detections (time, robot).
pub fn false_starts(
    beliefs: &Beliefs,
    timeline: &[(f64, GameState)],
    whistles: &[f64],
    detections: &[(f64, RobotId)],
    window: f64,
) -> Vec<FalseStart> {
    let mut found = Vec::new();
    for (robot, changes) in beliefs {
        for (i, (t, state)) in changes.iter().enumerate() {
            let entered =
                *state == GameState::Playing && (i == 0 || changes[i - 1].1 != GameState::Playing);
            if !entered || state_at(timeline, *t) != Some(GameState::Set) {
                continue;
            }
            if whistles.iter().any(|w| *w <= *t && *t - *w <= window) {
                continue;
            }
            let left = changes[i + 1..].first().map_or(f64::INFINITY, |(at, _)| *at);
            let whistle = whistles.iter().copied().find(|w| *w > *t).unwrap_or(f64::INFINITY);
            let end = left.min(whistle);
            found.push(FalseStart {
                robot: *robot,
                time: *t,
                duration: if end.is_finite() { end - t } else { f64::NAN },
                own_whistle: detections
                    .iter()
                    .any(|(at, r)| r == robot && *at <= *t && *t - *at <= window),
            });
        }
    }
    found.sort_by(|a, b| a.time.total_cmp(&b.time).then(a.robot.cmp(&b.robot)));
    found
}

/// The false whistle detections of a game: (time, robot).
pub fn false_whistles(events: &[Event]) -> Vec<(f64, RobotId)> {
    events
        .iter()
        .filter_map(|e| match e.kind {
            EventKind::FalseWhistle { robot } => Some((e.time.as_secs_f64(), robot)),
            _ => None,
        })
        .collect()
}

/// Of false whistle detections, those while the true game was in Set (where a robot acting on
/// one moves before the kick-off).
pub fn in_set(detections: &[(f64, RobotId)], timeline: &[(f64, GameState)]) -> usize {
    detections.iter().filter(|(t, _)| state_at(timeline, *t) == Some(GameState::Set)).count()
}

/// Whether a robot fell, and whether it was penalized, in [start, end).
pub fn incidents(events: &[Event], robot: RobotId, start: f64, end: f64) -> (bool, bool) {
    let during = events.iter().filter(|e| {
        let t = e.time.as_secs_f64();
        t >= start && t < end
    });
    let (mut fell, mut penalized) = (false, false);
    for event in during {
        match event.kind {
            EventKind::Fall { robot: r, .. } if r == robot => fell = true,
            EventKind::Penalty { robot: r, .. } if r == robot => penalized = true,
            _ => {}
        }
    }
    (fell, penalized)
}

/// One robot as the experiment looked at it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotSample {
    pub robot: RobotId,
    /// Present and not penalized.
    pub on_field: bool,
    pub fallen: bool,
    /// Its own team's frame (own goal at -x) as of now: after half time the sides changed and
    /// the frame with them, as the robot's own frame does.
    pub team_pose: Pose,
}

/// How one robot ended a Ready phase.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RobotReady {
    pub robot: RobotId,
    /// From its kick-off position, m.
    pub distance: f64,
    pub reached: bool,
    /// Lying or falling at the end.
    pub fallen: bool,
    /// From its kick-off position when its decision first showed Ready (when it set off), or
    /// at the phase's start if it never did, m.
    pub start_distance: Option<f64>,
    /// It fell during the phase.
    pub fell: bool,
    /// It was penalized during the phase (and back on the field by its end).
    pub penalized: bool,
    /// When its decision first showed Ready in the phase, s after the phase began (`None`: it
    /// never believed Ready, so it never went to its position).
    pub believed_ready: Option<f64>,
}

/// A robot's distance from its kick-off position, m (team frame).
pub fn kick_off_distance(
    field: &TeamField,
    kicking_team: Option<usize>,
    robot: RobotId,
    team_pose: Pose,
) -> f64 {
    let kicking = kicking_team == Some(robot.team);
    let target = kickoff_pose(field, robot.player, kicking, false);
    team_pose.position().distance(target.position())
}

/// A robot's last sample before Set against its kick-off position (`None`: not on the field).
pub fn ready_check(
    field: &TeamField,
    kicking_team: Option<usize>,
    sample: &RobotSample,
    tolerance: f64,
) -> Option<RobotReady> {
    if !sample.on_field {
        return None;
    }
    let distance = kick_off_distance(field, kicking_team, sample.robot, sample.team_pose);
    Some(RobotReady {
        robot: sample.robot,
        distance,
        reached: distance <= tolerance,
        fallen: sample.fallen,
        start_distance: None,
        fell: false,
        penalized: false,
        believed_ready: None,
    })
}

/// When a robot's decision first showed `state` in [start, end), s after `start`.
pub fn first_belief(
    changes: &[(f64, GameState)],
    state: GameState,
    start: f64,
    end: f64,
) -> Option<f64> {
    if state_at(changes, start) == Some(state) {
        return Some(0.0);
    }
    changes.iter().find(|(t, s)| *t >= start && *t < end && *s == state).map(|(t, _)| t - start)
}

/// `ok` of `all`, as a fraction (NaN for none).
pub fn rate(ok: usize, all: usize) -> f64 {
    if all == 0 { f64::NAN } else { ok as f64 / all as f64 }
}

/// Fractions of `values` in the bins `[edges[i], edges[i + 1])`, and a last bin for values at
/// or above the last edge or missing (`None`).
pub fn histogram(values: &[Option<f64>], edges: &[f64]) -> Vec<f64> {
    let mut counts = vec![0usize; edges.len()];
    for value in values {
        let bin = match value {
            Some(v) => edges.windows(2).position(|w| *v >= w[0] && *v < w[1]),
            None => None,
        };
        let last = edges.len().saturating_sub(1);
        counts[bin.unwrap_or(last)] += 1;
    }
    counts.iter().map(|c| rate(*c, values.len())).collect()
}

/// One Ready phase of a game, judged.
#[derive(Clone, Debug, Serialize)]
pub struct ReadyResult {
    pub phase: ReadyPhase,
    pub first_half: bool,
    pub kicking_team: Option<usize>,
    /// The robots on the field at its end.
    pub robots: Vec<RobotReady>,
}

impl ReadyResult {
    pub fn all_reached(&self) -> bool {
        self.robots.iter().all(|r| r.reached)
    }
}

/// One robot at a kick-off.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RobotStart {
    pub robot: RobotId,
    pub heard: bool,
    pub delay: Option<f64>,
}

/// One kick-off of a game.
#[derive(Clone, Debug, Serialize)]
pub struct KickOffResult {
    pub kick_off: KickOffWhistle,
    pub first_half: bool,
    pub kicking_team: Option<usize>,
    /// The robots on the field at the whistle.
    pub robots: Vec<RobotStart>,
}

impl KickOffResult {
    pub fn all_within(&self, within: f64) -> bool {
        self.robots.iter().all(|r| r.delay.is_some_and(|d| d <= within))
    }
}

/// The Ready phases over games.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ReadySummary {
    pub phases: usize,
    /// Phases in which every robot on the field reached its position.
    pub phases_reached: usize,
    pub phase_rate: f64,
    pub robots: usize,
    pub robots_reached: usize,
    pub robot_rate: f64,
    /// Of the robots that missed: lying at the end, fallen during the phase, penalized during
    /// it, never believed Ready.
    pub missed_fallen: usize,
    pub missed_fell: usize,
    pub missed_penalized: usize,
    pub missed_never_ready: usize,
    pub distance: Option<Distribution>,
}

pub fn ready_summary<'a>(phases: impl IntoIterator<Item = &'a ReadyResult>) -> ReadySummary {
    let phases: Vec<&ReadyResult> = phases.into_iter().collect();
    let robots: Vec<&RobotReady> = phases.iter().flat_map(|p| &p.robots).collect();
    let reached = robots.iter().filter(|r| r.reached).count();
    let missed: Vec<&&RobotReady> = robots.iter().filter(|r| !r.reached).collect();
    let phases_reached = phases.iter().filter(|p| p.all_reached()).count();
    let distances: Vec<f64> = robots.iter().map(|r| r.distance).collect();
    ReadySummary {
        phases: phases.len(),
        phases_reached,
        phase_rate: rate(phases_reached, phases.len()),
        robots: robots.len(),
        robots_reached: reached,
        robot_rate: rate(reached, robots.len()),
        missed_fallen: missed.iter().filter(|r| r.fallen).count(),
        missed_fell: missed.iter().filter(|r| r.fell).count(),
        missed_penalized: missed.iter().filter(|r| r.penalized).count(),
        missed_never_ready: missed.iter().filter(|r| r.believed_ready.is_none()).count(),
        distance: (!distances.is_empty()).then(|| Distribution::of(&distances)),
    }
}

/// The kick-offs over games.
#[derive(Clone, Debug, Default, Serialize)]
pub struct KickOffSummary {
    pub kick_offs: usize,
    /// Kick-offs at which every robot on the field started within `start_within`.
    pub all_within: usize,
    pub phase_rate: f64,
    pub robots: usize,
    pub robots_within: usize,
    pub robot_rate: f64,
    /// Delays of the robots that started, s.
    pub delay: Option<Distribution>,
    /// Robots that started only when the packets showed Playing, or never.
    pub not_before_packets: usize,
    /// Robots that did not start before the true state changed again.
    pub never_started: usize,
    /// Robots on the field that heard the whistle themselves.
    pub heard: usize,
}

pub fn kick_off_summary<'a>(
    kick_offs: impl IntoIterator<Item = &'a KickOffResult>,
    within: f64,
    packets_after: f64,
) -> KickOffSummary {
    let kick_offs: Vec<&KickOffResult> = kick_offs.into_iter().collect();
    let robots: Vec<&RobotStart> = kick_offs.iter().flat_map(|k| &k.robots).collect();
    let delays: Vec<f64> = robots.iter().filter_map(|r| r.delay).collect();
    let robots_within = robots.iter().filter(|r| r.delay.is_some_and(|d| d <= within)).count();
    let all_within = kick_offs.iter().filter(|k| k.all_within(within)).count();
    KickOffSummary {
        kick_offs: kick_offs.len(),
        all_within,
        phase_rate: rate(all_within, kick_offs.len()),
        robots: robots.len(),
        robots_within,
        robot_rate: rate(robots_within, robots.len()),
        delay: (!delays.is_empty()).then(|| Distribution::of(&delays)),
        not_before_packets: robots
            .iter()
            .filter(|r| r.delay.is_none_or(|d| packets_after > 0.0 && d >= packets_after))
            .count(),
        never_started: robots.iter().filter(|r| r.delay.is_none()).count(),
        heard: robots.iter().filter(|r| r.heard).count(),
    }
}

#[cfg(test)]
mod tests {
    use strata_runtime::Time;
    use strata_sim::Penalty;

    use super::*;

    fn event(at: f64, kind: EventKind) -> Event {
        Event { time: Time::from_secs_f64(at), kind }
    }

    fn state(at: f64, state: GameState) -> Event {
        event(at, EventKind::GameState { state, first_half: true })
    }

    fn home(player: u8) -> RobotId {
        RobotId::new(0, player)
    }

    /// Standby at 2 s, the gesture's Ready at 12 s, Set at 57 s, the kick-off whistle at 62 s,
    /// a goal (with its whistle) at 100 s, Ready to Set at 145 s, kick-off at 150 s.
    fn game_events() -> Vec<Event> {
        use GameState::*;
        vec![
            state(2.0, Standby),
            state(12.0, Ready),
            event(30.0, EventKind::FalseWhistle { robot: home(3) }),
            state(57.0, Set),
            event(59.0, EventKind::FalseWhistle { robot: home(4) }),
            state(62.0, Playing),
            event(62.0, EventKind::Whistle { robots: vec![home(1), home(2)] }),
            event(100.0, EventKind::Goal { team: 0, score: [1, 0], scorer: None }),
            event(100.0, EventKind::Whistle { robots: vec![home(1)] }),
            state(100.0, Ready),
            state(145.0, Set),
            state(150.0, Playing),
            event(150.0, EventKind::Whistle { robots: vec![] }),
        ]
    }

    #[test]
    fn ready_phases_and_kick_offs_come_from_the_true_states() {
        let events = game_events();
        let timeline = state_timeline(&events);
        assert_eq!(state_at(&timeline, 1.0), None);
        assert_eq!(state_at(&timeline, 57.0), Some(GameState::Set));
        let phases = ready_phases(&timeline);
        assert_eq!(
            phases,
            vec![
                ReadyPhase { start: 12.0, end: 57.0, gesture: true, after_goal: false },
                ReadyPhase { start: 100.0, end: 145.0, gesture: false, after_goal: true },
            ]
        );
        let kick_offs = kick_off_whistles(&events);
        // The goal's whistle is not a kick-off.
        assert_eq!(kick_offs.len(), 2);
        let near = |a: f64, b: f64| (a - b).abs() < 1e-6;
        assert!(near(kick_offs[0].time, 62.0) && kick_offs[0].whistle, "{kick_offs:?}");
        assert_eq!(kick_offs[0].heard, vec![home(1), home(2)]);
        assert!(near(kick_offs[1].time, 150.0) && kick_offs[1].whistle, "{kick_offs:?}");
        assert!(kick_offs[1].heard.is_empty());
        let detections = false_whistles(&events);
        assert_eq!(detections.len(), 2);
        assert_eq!(detections[1].1, home(4));
        assert_eq!(in_set(&detections, &timeline), 1);
    }

    #[test]
    fn without_signals_a_kick_off_is_the_state_change() {
        let events = vec![state(5.0, GameState::Set), state(10.0, GameState::Playing)];
        let kick_offs = kick_off_whistles(&events);
        assert_eq!(kick_offs.len(), 1);
        assert!((kick_offs[0].time - 10.0).abs() < 1e-6 && !kick_offs[0].whistle);
    }

    #[test]
    fn start_delays_from_decision_changes() {
        use GameState::*;
        let heard = [(1.0, Initial), (57.1, Set), (62.15, Playing)];
        assert!((start_delay(&heard, 62.0, 100.0).unwrap_or(f64::NAN) - 0.15).abs() < 1e-9);
        // Told by the packets 15 s later.
        let packets = [(57.1, Set), (77.05, Playing)];
        assert!((start_delay(&packets, 62.0, 100.0).unwrap_or(f64::NAN) - 15.05).abs() < 1e-9);
        // Already playing (a false start): 0.
        let early = [(57.1, Set), (60.0, Playing)];
        assert_eq!(start_delay(&early, 62.0, 100.0), Some(0.0));
        // Never, before the true state changed again.
        let never = [(57.1, Set), (120.0, Playing)];
        assert_eq!(start_delay(&never, 62.0, 100.0), None);
        assert_eq!(start_delay(&[], 62.0, 100.0), None);
    }

    #[test]
    fn false_starts_are_playing_in_set_without_a_whistle_just_before() {
        use GameState::*;
        let timeline =
            vec![(57.0, Set), (62.0, Playing), (100.0, Ready), (145.0, Set), (150.0, Playing)];
        let whistles = [62.0, 150.0];
        let mut beliefs = Beliefs::new();
        // A false whistle at 59 s: Playing until the true whistle.
        beliefs.insert(home(4), vec![(57.1, Set), (59.0, Playing)]);
        // A false start that the robot drops again at 148 s.
        beliefs
            .insert(home(5), vec![(145.1, Set), (146.0, Playing), (148.0, Set), (150.1, Playing)]);
        // Started by the true whistle: not false.
        beliefs.insert(home(1), vec![(57.1, Set), (62.1, Playing)]);
        // home/4's own detector fired; home/5 followed a teammate's.
        let detections = [(58.9, home(4)), (145.9, home(3))];
        let found = false_starts(&beliefs, &timeline, &whistles, &detections, 1.0);
        assert_eq!(found.len(), 2, "{found:?}");
        assert_eq!((found[0].robot, found[0].time, found[0].own_whistle), (home(4), 59.0, true));
        assert!((found[0].duration - 3.0).abs() < 1e-9);
        assert_eq!((found[1].robot, found[1].time, found[1].own_whistle), (home(5), 146.0, false));
        assert!((found[1].duration - 2.0).abs() < 1e-9);
        // The true state still read Set when the decision changed, but the whistle came within
        // the window before: not false.
        let edge = vec![(57.0, Set), (62.5, Playing)];
        let mut b = Beliefs::new();
        b.insert(home(2), vec![(57.1, Set), (62.2, Playing)]);
        assert!(false_starts(&b, &edge, &[62.0], &[], 1.0).is_empty());
    }

    #[test]
    fn ready_check_against_the_kick_off_positions() {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let target = kickoff_pose(&field, 2, true, false);
        let at = |x: f64, y: f64| Pose::new(x, y, 0.0);
        let sample = |player: u8, pose: Pose, on_field: bool| RobotSample {
            robot: home(player),
            on_field,
            fallen: false,
            team_pose: pose,
        };
        // The kicker of the kicking team, 0.3 m off: reached.
        let r = ready_check(&field, Some(0), &sample(2, at(target.x - 0.3, target.y), true), 0.5)
            .expect("on the field");
        assert!(r.reached && (r.distance - 0.3).abs() < 1e-9, "{r:?}");
        // The same place when the other team kicks off: the defender's place is outside the
        // centre circle, so 0.25 m behind the ball is far from it.
        let r = ready_check(&field, Some(1), &sample(2, at(-0.25, 0.0), true), 0.5)
            .expect("on the field");
        assert!(!r.reached && r.distance > 0.5, "{r:?}");
        // Off the field: not judged.
        assert_eq!(ready_check(&field, Some(0), &sample(3, at(0.0, 0.0), false), 0.5), None);
    }

    #[test]
    fn phase_and_robot_rates() {
        let robot = |p: u8, reached: bool, fallen: bool, believed: Option<f64>| RobotReady {
            robot: home(p),
            distance: if reached { 0.2 } else { 1.5 },
            reached,
            fallen,
            start_distance: Some(3.0),
            fell: fallen,
            penalized: !reached && !fallen,
            believed_ready: believed,
        };
        let phase = ReadyPhase { start: 0.0, end: 45.0, gesture: true, after_goal: false };
        let phases = [
            ReadyResult {
                phase,
                first_half: true,
                kicking_team: Some(0),
                robots: vec![robot(1, true, false, Some(1.0)), robot(2, true, false, Some(1.0))],
            },
            ReadyResult {
                phase,
                first_half: false,
                kicking_team: Some(1),
                robots: vec![robot(1, true, false, Some(2.0)), robot(2, false, true, Some(2.0))],
            },
            ReadyResult {
                phase,
                first_half: false,
                kicking_team: Some(0),
                robots: vec![robot(1, false, false, None), robot(2, true, false, Some(0.5))],
            },
        ];
        let s = ready_summary(&phases);
        assert_eq!((s.phases, s.phases_reached, s.robots, s.robots_reached), (3, 1, 6, 4));
        assert!((s.phase_rate - 1.0 / 3.0).abs() < 1e-12);
        assert!((s.robot_rate - 4.0 / 6.0).abs() < 1e-12);
        assert_eq!((s.missed_fallen, s.missed_fell, s.missed_penalized), (1, 1, 1));
        assert_eq!(s.missed_never_ready, 1);

        let kick = |delays: &[Option<f64>]| KickOffResult {
            kick_off: KickOffWhistle { time: 62.0, whistle: true, heard: vec![home(1)] },
            first_half: true,
            kicking_team: Some(0),
            robots: delays
                .iter()
                .enumerate()
                .map(|(i, d)| RobotStart { robot: home(i as u8 + 1), heard: i == 0, delay: *d })
                .collect(),
        };
        let kicks = [kick(&[Some(0.1), Some(0.4)]), kick(&[Some(0.2), Some(15.2), None])];
        let k = kick_off_summary(&kicks, 1.0, 15.0);
        assert_eq!((k.kick_offs, k.all_within, k.robots, k.robots_within), (2, 1, 5, 3));
        assert_eq!((k.not_before_packets, k.never_started, k.heard), (2, 1, 2));
        let d = k.delay.expect("delays");
        assert_eq!((d.n, d.max), (4, 15.2));
        assert!((d.median - 0.3).abs() < 1e-12);
        assert!(rate(0, 0).is_nan());
    }

    #[test]
    fn falls_and_penalties_in_a_phase() {
        let fall = |at: f64, robot: RobotId| {
            event(
                at,
                EventKind::Fall {
                    robot,
                    onset: Time::from_secs_f64(at),
                    direction: strata_sim::FallDirection::Front,
                    cause: strata_sim::FallCause::Collision,
                },
            )
        };
        let penalty = |at: f64, robot: RobotId| {
            event(
                at,
                EventKind::Penalty { robot, penalty: Penalty::LeavingTheField, duration: None },
            )
        };
        let events = [fall(10.0, home(2)), penalty(20.0, home(3)), fall(50.0, home(3))];
        assert_eq!(incidents(&events, home(2), 0.0, 45.0), (true, false));
        assert_eq!(incidents(&events, home(3), 0.0, 45.0), (false, true));
        assert_eq!(incidents(&events, home(3), 45.0, 90.0), (true, false));
        assert_eq!(incidents(&events, home(4), 0.0, 90.0), (false, false));
    }

    #[test]
    fn histograms_put_missing_and_large_values_in_the_last_bin() {
        let h = histogram(
            &[Some(0.05), Some(0.15), Some(0.15), Some(20.0), None],
            &[0.0, 0.1, 0.2, 1.0],
        );
        assert_eq!(h, vec![0.2, 0.4, 0.0, 0.4]);
        assert_eq!(histogram(&[], &[0.0, 1.0]).len(), 2);
    }
}
