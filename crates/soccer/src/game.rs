//! The GameController, from the robot's side: what the referee's packets tell the
//! deliberative layer (the game state), the planning layer (penalties, the message budget) and
//! world modeling (where the robot was placed), and the return packet the robot sends back.
//! The same bytes arrive from a real GameController over UDP and from the simulator's referee.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use strata_robot::control::planning::{MessageBudget, OwnState, SharedSignal, StandingStatus};
use strata_robot::control::planning_module::ExternalDevice;
use strata_robot::geometry::{Global as FieldFrame, Point, Pose};
use strata_robot::percept::{Signal, SignalKind};
use strata_robot::platform::ObjectClass;
use strata_robot::world::{PosePrior, SymmetryHint, WorldCommand, WorldState};
use strata_runtime::Time;
use strata_spl::gamecontroller::{
    GameControlData, GamePhase, GameState, Penalty, ReturnData, SetPlay,
};
use strata_spl::{Gesture, ObjectKind};

use crate::field::TeamField;
use crate::world_config::BALL;

/// The team-message code of the referee's Ready gesture (seen in Standby).
pub const SIGNAL_READY: u8 = 1;
/// The team-message code of the whistle (heard in Set: the kick-off; in Playing: a goal).
pub const SIGNAL_WHISTLE: u8 = 2;

/// How a robot follows the referee's own signals. Under the SPL rules robots must see the
/// Ready gesture and hear the whistle themselves: GameController3 keeps sending Standby for
/// 45 s after the gesture, Set for 15 s after the kick-off whistle and Playing for 15 s after
/// a goal's (docs/spl-protocols.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SignalConfig {
    /// Act on the signals. Off: the packets alone decide the game state.
    pub enabled: bool,
    /// Whistles the detector is less sure of than this are ignored, in [0, 1].
    pub whistle_confidence: f64,
    /// How many robots of the team (this one included) must report a whistle within
    /// `whistle_window` before they act on it. A detector fires now and then with no whistle;
    /// two at once hardly ever do, while a true whistle is heard by nearly all. 1: every
    /// robot acts on its own detections. A robot that hears nothing from its teammates waits
    /// for the packets.
    pub whistle_quorum: u8,
    /// The time within which the quorum's reports must fall, s.
    pub whistle_window: f64,
    /// How long a whistle the packets have not confirmed is believed, s. GameController3 shows
    /// Set for 15 s after a true one; a whistle still unconfirmed after this was false, and the
    /// robot goes back to Set (the rules penalize its motion in Set meanwhile).
    pub whistle_trust: f64,
    /// The same for the Ready gesture, s: GameController3 shows Standby for 45 s after it.
    pub gesture_trust: f64,
    /// A signal a teammate reports is followed only if perceived less than this long ago, s
    /// (older, it belongs to an earlier phase).
    pub teammate_max_age: f64,
    /// The kick-off's free-ball time after the whistle, s: what the GameController's secondary
    /// time will say once its packets catch up.
    pub kick_off_time: f64,
}

impl Default for SignalConfig {
    fn default() -> Self {
        SignalConfig {
            enabled: true,
            whistle_confidence: 0.5,
            whistle_quorum: 2,
            whistle_window: 1.0,
            whistle_trust: 20.0,
            gesture_trust: 50.0,
            teammate_max_age: 3.0,
            kick_off_time: 10.0,
        }
    }
}

impl SignalConfig {
    /// The first field that is out of range, and why.
    pub fn invalid(&self) -> Option<(&'static str, String)> {
        let c = self.whistle_confidence;
        if !(c.is_finite() && (0.0..=1.0).contains(&c)) {
            return Some(("signals.whistle_confidence", format!("must be in [0, 1], got {c}")));
        }
        if self.whistle_quorum == 0 {
            return Some(("signals.whistle_quorum", "must be at least 1 robot, got 0".into()));
        }
        for (field, v) in [
            ("signals.whistle_window", self.whistle_window),
            ("signals.whistle_trust", self.whistle_trust),
            ("signals.gesture_trust", self.gesture_trust),
            ("signals.teammate_max_age", self.teammate_max_age),
            ("signals.kick_off_time", self.kick_off_time),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Some((field, format!("must be >= 0 s, got {v}")));
            }
        }
        None
    }
}

/// What a referee signal the robot acts on ended, ahead of the packets.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Ahead {
    /// Standby, by the Ready gesture.
    Standby,
    /// Set, by the kick-off whistle.
    Set,
    /// Playing, by a goal's whistle: Ready for the kick-off of `kicking`.
    Goal { kicking: Kicking },
}

impl Ahead {
    /// The state the packets show until they catch up.
    fn awaited(self) -> GameState {
        match self {
            Ahead::Standby => GameState::Standby,
            Ahead::Set => GameState::Set,
            Ahead::Goal { .. } => GameState::Playing,
        }
    }

    fn code(self) -> u8 {
        if self == Ahead::Standby { SIGNAL_READY } else { SIGNAL_WHISTLE }
    }
}

/// How long after the packets turn to Playing a whistle is still the kick-off's, s: the
/// whistle, its reports and the packet's change come within a second of each other.
const KICK_OFF_WHISTLE_MARGIN: f64 = 3.0;

/// A referee signal the robot acts on before the packets show it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Followed {
    ahead: Ahead,
    /// When the first robot perceived it.
    since: Time,
}

/// What the robot made of the referee's signals, for experiments and diagnostics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignalStats {
    /// Signals this robot perceived and followed (whistles: when its own report made the
    /// quorum).
    pub perceived: u64,
    /// Signals followed on a teammate's word.
    pub from_teammates: u64,
    /// Whistles the packets never confirmed (the robot went back to Set).
    pub false_whistles: u64,
    /// Gestures the packets never confirmed.
    pub false_gestures: u64,
}

/// Who takes the next kick-off or set play.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kicking {
    Us,
    Them,
    #[default]
    Nobody,
}

/// What the deliberative layer needs of the game.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GameDirective {
    pub state: GameState,
    pub set_play: SetPlay,
    pub kicking: Kicking,
    pub penalized: bool,
    pub first_half: bool,
    pub penalty_shootout: bool,
    pub secs_remaining: i16,
    pub secondary_time: i16,
    /// Goals for this team and the other.
    pub score: [u8; 2],
    /// Whether any GameController packet has arrived.
    pub connected: bool,
}

impl Default for GameDirective {
    /// Before the first packet, a robot plays: a robot without a GameController (a test
    /// field, the paper's experiments) must not stand still forever.
    fn default() -> Self {
        GameDirective {
            state: GameState::Playing,
            set_play: SetPlay::None,
            kicking: Kicking::Nobody,
            penalized: false,
            first_half: true,
            penalty_shootout: false,
            secs_remaining: 600,
            secondary_time: 0,
            score: [0, 0],
            connected: false,
        }
    }
}

/// The GameController as the planning layer sees it.
#[derive(Debug, Clone)]
pub struct GameControllerReferee {
    team_number: u8,
    player: u8,
    field: TeamField,
    directive: GameDirective,
    last: Option<GameControlData>,
    budget: Option<MessageBudget>,
    half_duration: f64,
    pending_commands: Vec<WorldCommand>,
    last_status: Option<Time>,
    /// When the ball was last seen and where on the field: the world model forgets a ball it
    /// has not seen for a while, but the return packet's ball age is the time since it was
    /// last seen, whatever the world model still holds.
    ball_seen: Option<(Time, Point<FieldFrame>)>,
    status_interval: f64,
    signals: SignalConfig,
    followed: Option<Followed>,
    /// Whistles reported within the window, by player (this robot's included), with when they
    /// were heard.
    whistles: Vec<(u8, Time)>,
    /// When this robot last heard a whistle itself: its messages report it while it counts.
    heard: Option<Time>,
    /// When the packets' state last changed (as received).
    state_since: Time,
    /// A signal perceived since the planning module last asked: teammates hear of it at once.
    signal_news: bool,
    now: Time,
    pub signal_stats: SignalStats,
    pub packets: u64,
    pub rejected: u64,
}

/// Messages of each robot's share kept for instant messages.
const MESSAGE_RESERVE: u32 = 10;

/// Messages of each robot's share, within the reserve, kept for the referee's signals: late in a
/// game falls and claims spend the rest, and a whistle the team cannot share is a kick-off
/// its robots start only when the packets catch up, 15 s late. Two whistle reports per kick-off
/// make the quorum; a team of seven keeps 14 messages, a few kick-offs' worth.
const VITAL_RESERVE: u32 = 2;

/// The time left the message budget is paced over once the GameController's clock has run out
/// outside the first half, s.
const CLOCK_OUT_PACING_SECS: f64 = 60.0;

impl GameControllerReferee {
    pub fn new(
        team_number: u8,
        player: u8,
        field: TeamField,
        half_duration: f64,
        signals: SignalConfig,
    ) -> GameControllerReferee {
        GameControllerReferee {
            team_number,
            player,
            field,
            directive: GameDirective::default(),
            last: None,
            budget: None,
            half_duration,
            pending_commands: Vec::new(),
            last_status: None,
            ball_seen: None,
            status_interval: 1.0,
            signals,
            followed: None,
            whistles: Vec::new(),
            heard: None,
            state_since: Time::ZERO,
            signal_news: false,
            now: Time::ZERO,
            signal_stats: SignalStats::default(),
            packets: 0,
            rejected: 0,
        }
    }

    /// Whether the packets show a state a signal could end, and nothing is followed yet.
    fn may_follow(&self) -> bool {
        let d = &self.directive;
        self.signals.enabled && d.connected && !d.penalized && self.followed.is_none()
    }

    /// Follows a signal perceived at `since` (by this robot, or a teammate), if the packets
    /// show the state it ends and nothing is followed yet.
    fn follow(&mut self, ahead: Ahead, since: Time) -> bool {
        if !self.may_follow() || self.directive.state != ahead.awaited() {
            return false;
        }
        self.followed = Some(Followed { ahead, since });
        true
    }

    /// Counts a whistle `player` heard at `at`; once `whistle_quorum` robots heard one within
    /// `whistle_window`, follows it from the first of them: in Set the kick-off, in Playing a
    /// goal. Returns whether it now follows.
    fn count_whistle(&mut self, player: u8, at: Time) -> bool {
        let state = self.directive.state;
        // Reports of the whistle it follows are still counted: they tell whether its own
        // report is needed (`take_signal_news`).
        let following = self.followed.is_some_and(|f| f.ahead != Ahead::Standby);
        if !(self.may_follow() || following)
            || !matches!(state, GameState::Set | GameState::Playing)
        {
            return false;
        }
        // A whistle heard as the packets turned to Playing is the kick-off's they show (without
        // GameController3's delay), not a goal's.
        let settled = self.state_since + Duration::from_secs_f64(KICK_OFF_WHISTLE_MARGIN);
        if state == GameState::Playing && at < settled {
            return false;
        }
        let window = self.signals.whistle_window;
        // Reports from either side of `at` (a teammate's arrives after this robot heard its own).
        let apart = |a: Time, b: Time| (a.max(b) - a.min(b)).as_secs_f64();
        self.whistles.retain(|(p, t)| *p != player && apart(at, *t) <= window);
        self.whistles.push((player, at));
        if following || self.whistles.len() < usize::from(self.signals.whistle_quorum) {
            return false;
        }
        let since = self.whistles.iter().map(|(_, t)| *t).min().unwrap_or(at);
        let ahead = if state == GameState::Set {
            Ahead::Set
        } else {
            // The team whose goal the ball went into kicks off: ours if the ball was last
            // seen in our half (team frame: own goal at -x).
            let kicking = match self.ball_seen {
                Some((_, ball)) if ball.x > 0.0 => Kicking::Them,
                Some(_) => Kicking::Us,
                None => Kicking::Nobody,
            };
            Ahead::Goal { kicking }
        };
        self.follow(ahead, since)
    }

    /// Keeps when and where the ball was last seen: the world model forgets it.
    fn remember_ball(&mut self, world: Option<&WorldState>) {
        if let Some(b) = world.and_then(|w| w.object(BALL))
            && let Some(seen) = b.last_seen
            && self.ball_seen.is_none_or(|(t, _)| seen >= t)
        {
            self.ball_seen = Some((seen, b.global_position));
        }
    }

    fn side_line_priors(&self, x: f64) -> Vec<PosePrior> {
        [1.0, -1.0]
            .into_iter()
            .map(|side| PosePrior {
                pose: Pose::new(
                    x,
                    side * self.field.half_width,
                    -side * std::f64::consts::FRAC_PI_2,
                ),
                sigma: [0.4, 0.15, 0.3],
            })
            .collect()
    }

    fn apply(&mut self, data: GameControlData) {
        let ours = data.teams.iter().position(|t| t.team_number == self.team_number);
        let Some(ours) = ours else {
            // Packets for another game: ignore, as a real robot on a shared network must.
            return;
        };
        let team = data.teams[ours];
        let them = data.teams[1 - ours];
        let penalized = team.player(self.player).is_some_and(|p| p.penalty != Penalty::None);
        let previous = self.directive.clone();
        self.directive = GameDirective {
            state: data.state,
            set_play: data.set_play,
            kicking: match data.kicking_team {
                Some(n) if n == self.team_number => Kicking::Us,
                Some(_) => Kicking::Them,
                None => Kicking::Nobody,
            },
            penalized,
            first_half: data.first_half,
            penalty_shootout: data.game_phase == GamePhase::PenaltyShoot,
            secs_remaining: data.secs_remaining,
            secondary_time: data.secondary_time,
            score: [team.score, them.score],
            connected: true,
        };
        // Where the referee puts a robot tells world modeling where it is.
        if previous.connected && previous.penalized && !penalized {
            let x = -self.field.half_length + self.field.field.dimensions().penalty_mark_distance;
            self.pending_commands.push(WorldCommand::SetHints {
                hints: vec![SymmetryHint::NearPoses { poses: self.side_line_priors(x) }],
            });
        }
        if (!previous.connected || previous.state != GameState::Initial)
            && data.state == GameState::Initial
        {
            let x = -self.field.half_length / 2.0;
            self.pending_commands.push(WorldCommand::SetHints {
                hints: vec![SymmetryHint::NearPoses { poses: self.side_line_priors(x) }],
            });
        }
        let players = data.players_per_team.max(1);
        let half = self.half_duration.max(1.0);
        let time_left = if data.first_half {
            f64::from(data.secs_remaining.max(0)) + half
        } else if data.secs_remaining > 0 {
            f64::from(data.secs_remaining)
        } else {
            // The clock at zero or below does not end the play (a half the referee has not
            // ended yet, stoppage, a penalty shoot-out): pacing over no time at all would lift
            // the rate limit and let the team spend its whole budget at once.
            CLOCK_OUT_PACING_SECS
        };
        self.budget = Some(MessageBudget {
            team_remaining: u32::from(team.message_budget),
            robots: u32::from(players),
            time_left,
            // Kept for instant messages, per robot: a whistle's reports and a fall must get
            // through when pacing over the clock (which stops through Ready and Set) has
            // spent the rest.
            reserve: MESSAGE_RESERVE,
            vital_reserve: VITAL_RESERVE,
        });
        self.last = Some(data);
    }
}

impl ExternalDevice for GameControllerReferee {
    type Directive = GameDirective;

    fn receive(&mut self, now: Time, packet: &[u8]) -> Result<(), String> {
        match GameControlData::decode(packet) {
            Ok(data) => {
                self.packets += 1;
                let before = self.directive.state;
                self.apply(data);
                if self.directive.state != before {
                    self.state_since = now;
                }
                Ok(())
            }
            Err(error) => {
                self.rejected += 1;
                Err(error.to_string())
            }
        }
    }

    fn directive(&self) -> GameDirective {
        let mut directive = self.directive.clone();
        let Some(followed) = self.followed else { return directive };
        match followed.ahead {
            Ahead::Standby => directive.state = GameState::Ready,
            Ahead::Set => {
                directive.state = GameState::Playing;
                directive.set_play = SetPlay::None;
                let left = self.signals.kick_off_time - (self.now - followed.since).as_secs_f64();
                directive.secondary_time = left.max(0.0).ceil() as i16;
            }
            Ahead::Goal { kicking } => {
                directive.state = GameState::Ready;
                directive.set_play = SetPlay::None;
                directive.kicking = kicking;
                directive.secondary_time = 0;
            }
        }
        directive
    }

    fn perceive(&mut self, _now: Time, signal: &Signal) {
        match signal.kind {
            SignalKind::Whistle if signal.confidence >= self.signals.whistle_confidence => {
                if !self.may_follow()
                    || !matches!(self.directive.state, GameState::Set | GameState::Playing)
                {
                    return;
                }
                // Teammates count it toward their quorum: tell them at once, followed or not.
                self.heard = Some(signal.stamp);
                self.signal_news = true;
                if self.count_whistle(self.player, signal.stamp) {
                    self.signal_stats.perceived += 1;
                }
            }
            SignalKind::Sight { class, variant, .. }
                if class == ObjectClass(ObjectKind::Referee.code())
                    && variant == Some(Gesture::Ready.code())
                    && self.follow(Ahead::Standby, signal.stamp) =>
            {
                self.signal_stats.perceived += 1;
                self.signal_news = true;
            }
            _ => {}
        }
    }

    fn teammate_signal(&mut self, now: Time, sender: u8, signal: &SharedSignal) {
        if !(signal.age.is_finite() && signal.age <= self.signals.teammate_max_age) {
            return;
        }
        let since = Time::from_secs_f64((now.as_secs_f64() - signal.age).max(0.0));
        // Not news: the teammate told everybody already.
        let followed = match signal.code {
            SIGNAL_READY => self.follow(Ahead::Standby, since),
            SIGNAL_WHISTLE => self.count_whistle(sender, since),
            _ => false,
        };
        if followed {
            self.signal_stats.from_teammates += 1;
        }
    }

    fn shared_signal(&self, now: Time) -> Option<SharedSignal> {
        let age = |since: Time| (now - since).as_secs_f64();
        match (self.followed, self.heard) {
            (Some(f), _) => Some(SharedSignal { code: f.ahead.code(), age: age(f.since) }),
            // Heard but no quorum yet: a report for the teammates' count.
            (None, Some(heard)) if age(heard) <= self.signals.whistle_window => {
                Some(SharedSignal { code: SIGNAL_WHISTLE, age: age(heard) })
            }
            (None, _) => None,
        }
    }

    fn take_signal_news(&mut self) -> bool {
        let news = std::mem::take(&mut self.signal_news);
        // When teammates' reports alone make a quorum, every robot that heard the whistle has
        // its own: this robot's report would only spend the team's message budget.
        let others = self.whistles.iter().filter(|(p, _)| *p != self.player).count();
        let redundant = self.followed.is_some_and(|f| f.ahead != Ahead::Standby)
            && others >= usize::from(self.signals.whistle_quorum);
        news && !redundant
    }

    fn update(&mut self, now: Time, world: Option<&WorldState>) {
        self.now = now;
        self.remember_ball(world);
        let Some(followed) = self.followed else { return };
        let d = &self.directive;
        if d.state != followed.ahead.awaited() || d.penalized {
            // The packets caught up (or moved on): they decide again.
            self.followed = None;
            self.whistles.clear();
            return;
        }
        let (trust, count) = if followed.ahead == Ahead::Standby {
            (self.signals.gesture_trust, &mut self.signal_stats.false_gestures)
        } else {
            (self.signals.whistle_trust, &mut self.signal_stats.false_whistles)
        };
        if (now - followed.since).as_secs_f64() > trust {
            // Never confirmed: a false whistle (or gesture); back to what the packets say.
            *count += 1;
            self.followed = None;
        }
    }

    fn penalized(&self) -> bool {
        self.directive.penalized
    }

    fn budget(&self) -> Option<MessageBudget> {
        self.budget.clone()
    }

    fn status_packet(
        &mut self,
        now: Time,
        own: &OwnState,
        world: Option<&WorldState>,
    ) -> Option<Vec<u8>> {
        if self.last.is_none()
            || self.last_status.is_some_and(|t| (now - t).as_secs_f64() < self.status_interval)
        {
            return None;
        }
        self.last_status = Some(now);
        self.remember_ball(world);
        let (ball_age, ball_position) = match (world, self.ball_seen) {
            (Some(w), Some((seen, position))) => {
                let relative = own.pose.to_robot(position);
                (
                    (w.stamp - seen).as_secs_f64() as f32,
                    [(relative.x * 1000.0) as f32, (relative.y * 1000.0) as f32],
                )
            }
            _ => (-1.0, [0.0, 0.0]),
        };
        let data = ReturnData {
            player_number: self.player,
            team_number: self.team_number,
            fallen: own.status == StandingStatus::Fallen,
            pose: [
                (own.pose.x * 1000.0) as f32,
                (own.pose.y * 1000.0) as f32,
                own.pose.theta as f32,
            ],
            ball_age,
            ball: ball_position,
        };
        data.encode().ok().map(|bytes| bytes.to_vec())
    }

    fn world_commands(&mut self) -> Vec<WorldCommand> {
        std::mem::take(&mut self.pending_commands)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn referee() -> GameControllerReferee {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        GameControllerReferee::new(5, 2, field, 600.0, SignalConfig::default())
    }

    fn packet(state: GameState, penalized: bool) -> Vec<u8> {
        let mut data = GameControlData {
            state,
            players_per_team: 5,
            kicking_team: Some(9),
            ..Default::default()
        };
        data.teams[0].team_number = 5;
        data.teams[1].team_number = 9;
        data.teams[0].message_budget = 1000;
        if penalized {
            data.teams[0].players[1].penalty = Penalty::Manual;
        }
        data.encode().to_vec()
    }

    #[test]
    fn packets_become_the_directive_budget_and_penalty() {
        let mut r = referee();
        assert!(!r.directive().connected);
        r.receive(Time::ZERO, &packet(GameState::Ready, false)).expect("valid");
        let d = r.directive();
        assert_eq!((d.state, d.kicking, d.connected), (GameState::Ready, Kicking::Them, true));
        let budget = r.budget().expect("budget");
        assert_eq!((budget.team_remaining, budget.robots), (1000, 5));
        r.receive(Time::ZERO, &packet(GameState::Playing, true)).expect("valid");
        assert!(r.penalized());
        r.receive(Time::ZERO, &packet(GameState::Playing, false)).expect("valid");
        assert!(!r.penalized());
        // Back from a penalty: world modeling is told where the robot was placed.
        assert!(matches!(r.world_commands().as_slice(), [WorldCommand::SetHints { .. }]));
    }

    /// A robot at (1, 0) facing +x; the ball at field (3, 1), seen at `seen` (None: the
    /// world model has forgotten it); the state's stamp `at`.
    fn world(at: f64, seen: Option<f64>) -> WorldState {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let mut model =
            strata_robot::world::WorldModel::new(crate::world_config::world_config(&field))
                .expect("valid config");
        let prior = PosePrior { pose: Pose::new(1.0, 0.0, 0.0), sigma: [0.1, 0.1, 0.05] };
        model.command(WorldCommand::SetPose { prior }).expect("pose set");
        let mut world = model.state();
        world.stamp = Time::from_secs_f64(at);
        let mut objects = world.objects.to_vec();
        let ball = objects.iter_mut().find(|o| o.name.as_str() == BALL).expect("a ball");
        ball.known = seen.is_some();
        ball.last_seen = seen.map(Time::from_secs_f64);
        ball.global_position = Point::new(3.0, 1.0);
        ball.position = world.pose.pose.to_robot(ball.global_position);
        world.objects = objects.into();
        world
    }

    fn ball_of(packet: Option<Vec<u8>>) -> (f32, [f32; 2]) {
        let data = ReturnData::decode(&packet.expect("a status packet")).expect("valid");
        (data.ball_age, data.ball)
    }

    #[test]
    fn ball_age_is_the_time_since_the_ball_was_seen_after_the_world_forgets_it() {
        let mut r = referee();
        r.receive(Time::ZERO, &packet(GameState::Playing, false)).expect("valid");
        let own = OwnState {
            id: 2,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            pose: Pose::new(1.0, 0.0, 0.0),
            pose_confidence: 1.0,
            objects: Vec::new(),
        };
        // Never seen: -1, as the return packet defines.
        let (age, _) =
            ball_of(r.status_packet(Time::from_secs_f64(0.5), &own, Some(&world(0.5, None))));
        assert_eq!(age, -1.0);
        let (age, ball) =
            ball_of(r.status_packet(Time::from_secs_f64(2.0), &own, Some(&world(2.0, Some(1.5)))));
        assert_eq!((age, ball), (0.5, [2000.0, 1000.0]));
        // Forgotten by the world model: still the time since it was seen, where it was seen.
        let (age, ball) =
            ball_of(r.status_packet(Time::from_secs_f64(6.0), &own, Some(&world(6.0, None))));
        assert_eq!((age, ball), (4.5, [2000.0, 1000.0]));
    }

    fn secs(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    fn whistle(at: f64, confidence: f64) -> Signal {
        Signal { stamp: secs(at), kind: SignalKind::Whistle, confidence }
    }

    fn gesture(at: f64, gesture: Gesture) -> Signal {
        let kind = SignalKind::Sight {
            class: ObjectClass(ObjectKind::Referee.code()),
            variant: Some(gesture.code()),
            range: 5.0,
            bearing: 0.3,
        };
        Signal { stamp: secs(at), kind, confidence: 1.0 }
    }

    /// One planning cycle at `at`: packets first, then the signals' clock.
    fn cycle(r: &mut GameControllerReferee, at: f64, state: GameState) -> GameDirective {
        r.receive(secs(at), &packet(state, false)).expect("valid");
        r.update(secs(at), None);
        r.directive()
    }

    #[test]
    fn the_ready_gesture_runs_ahead_of_standby_until_the_packets_catch_up() {
        let mut r = referee();
        assert_eq!(cycle(&mut r, 1.0, GameState::Standby).state, GameState::Standby);
        // No gesture, or seen outside Standby: nothing.
        r.perceive(secs(1.1), &gesture(1.1, Gesture::None));
        assert_eq!(cycle(&mut r, 1.2, GameState::Standby).state, GameState::Standby);
        assert!(!r.take_signal_news());

        r.perceive(secs(2.0), &gesture(2.0, Gesture::Ready));
        assert!(r.take_signal_news(), "teammates hear of it at once");
        assert!(!r.take_signal_news(), "once");
        // GameController3 keeps sending Standby for 45 s: the robot is in Ready meanwhile, and
        // says so in its messages.
        for at in [2.1, 20.0, 46.0] {
            assert_eq!(cycle(&mut r, at, GameState::Standby).state, GameState::Ready);
        }
        let shared = r.shared_signal(secs(46.0)).expect("shared");
        assert_eq!(shared.code, SIGNAL_READY);
        assert!((shared.age - 44.0).abs() < 1e-9, "{shared:?}");
        // The packets moved on: they decide again.
        assert_eq!(cycle(&mut r, 47.0, GameState::Set).state, GameState::Set);
        assert_eq!(r.shared_signal(secs(47.0)), None);
        assert_eq!(r.signal_stats.perceived, 1);
        assert_eq!(r.signal_stats.false_gestures, 0);
    }

    /// A teammate's report of a whistle heard `age` s before `at`.
    fn report(r: &mut GameControllerReferee, at: f64, sender: u8, age: f64) {
        r.teammate_signal(secs(at), sender, &SharedSignal { code: SIGNAL_WHISTLE, age });
    }

    #[test]
    fn a_whistle_two_robots_heard_starts_the_kick_off_and_a_false_one_ends_in_set() {
        let mut r = referee();
        assert_eq!(cycle(&mut r, 1.0, GameState::Set).state, GameState::Set);
        // Too unsure to act on, or to tell anybody.
        r.perceive(secs(1.5), &whistle(1.5, 0.3));
        assert_eq!(cycle(&mut r, 1.6, GameState::Set).state, GameState::Set);
        assert!(!r.take_signal_news());

        // Heard alone: told at once, but not acted on before a teammate heard it too.
        r.perceive(secs(2.0), &whistle(2.0, 0.9));
        assert!(r.take_signal_news());
        assert_eq!(r.shared_signal(secs(2.05)).map(|s| s.code), Some(SIGNAL_WHISTLE));
        assert_eq!(cycle(&mut r, 2.05, GameState::Set).state, GameState::Set);
        report(&mut r, 2.1, 3, 0.1);
        let d = cycle(&mut r, 2.1, GameState::Set);
        assert_eq!(
            (d.state, d.set_play, d.secondary_time),
            (GameState::Playing, SetPlay::None, 10)
        );
        // The kick-off's free-ball time counts down from the first to hear it.
        assert_eq!(cycle(&mut r, 5.5, GameState::Set).secondary_time, 7);
        assert_eq!(cycle(&mut r, 14.0, GameState::Set).secondary_time, 0);
        assert_eq!(cycle(&mut r, 21.9, GameState::Set).state, GameState::Playing);
        // 20 s and the packets still say Set: the whistle was false.
        let d = cycle(&mut r, 22.1, GameState::Set);
        assert_eq!(d.state, GameState::Set);
        assert_eq!(r.signal_stats.false_whistles, 1);

        // One robot's false detection: nobody else heard anything, nobody moves.
        r.perceive(secs(25.0), &whistle(25.0, 0.8));
        report(&mut r, 27.0, 4, 0.5);
        assert_eq!(cycle(&mut r, 27.0, GameState::Set).state, GameState::Set, "1.5 s apart");

        // A true whistle: the packets confirm it within the trust.
        r.perceive(secs(30.0), &whistle(30.0, 0.7));
        report(&mut r, 30.1, 5, 0.0);
        assert_eq!(cycle(&mut r, 44.0, GameState::Set).state, GameState::Playing);
        assert_eq!(cycle(&mut r, 45.0, GameState::Playing).state, GameState::Playing);
        assert_eq!(r.shared_signal(secs(45.0)), None, "the packets decide again");
        // Each quorum was made by a teammate's report.
        let stats = r.signal_stats;
        assert_eq!((stats.perceived, stats.from_teammates, stats.false_whistles), (0, 2, 1));
    }

    #[test]
    fn a_goals_whistle_sends_the_team_to_ready_for_the_conceding_teams_kick_off() {
        let mut r = referee();
        cycle(&mut r, 1.0, GameState::Playing);
        // The ball was last seen at (3, 1) of our frame: near their goal.
        r.update(secs(20.0), Some(&world(20.0, Some(19.5))));
        // Just after the packets turned to Playing, a whistle is the kick-off's: no goal.
        r.perceive(secs(2.0), &whistle(2.0, 0.9));
        report(&mut r, 2.1, 3, 0.0);
        assert_eq!(cycle(&mut r, 2.1, GameState::Playing).state, GameState::Playing);

        r.perceive(secs(30.0), &whistle(30.0, 0.9));
        report(&mut r, 30.2, 4, 0.1);
        r.update(secs(30.2), None);
        let d = r.directive();
        assert_eq!((d.state, d.kicking), (GameState::Ready, Kicking::Them), "we scored");
        // GameController3 shows Playing for 15 s after a goal, then Ready.
        assert_eq!(cycle(&mut r, 44.0, GameState::Playing).state, GameState::Ready);
        let d = cycle(&mut r, 45.2, GameState::Ready);
        assert_eq!((d.state, d.kicking), (GameState::Ready, Kicking::Them));
        assert_eq!(r.shared_signal(secs(45.2)), None);
    }

    /// Every robot that heard the whistle needs one teammate's report: once two have come,
    /// a third report would only spend the budget.
    #[test]
    fn a_robot_whose_teammates_already_made_the_quorum_does_not_report_too() {
        let mut r = referee();
        cycle(&mut r, 1.0, GameState::Set);
        r.perceive(secs(2.0), &whistle(2.0, 0.9));
        report(&mut r, 2.03, 3, 0.02);
        report(&mut r, 2.04, 4, 0.03);
        assert_eq!(cycle(&mut r, 2.05, GameState::Set).state, GameState::Playing);
        assert!(!r.take_signal_news(), "two teammates reported it already");
        // It still says so in its next message, for a teammate that missed the whistle.
        assert_eq!(r.shared_signal(secs(2.5)).map(|s| s.code), Some(SIGNAL_WHISTLE));

        let mut r = referee();
        cycle(&mut r, 1.0, GameState::Set);
        r.perceive(secs(2.0), &whistle(2.0, 0.9));
        report(&mut r, 2.03, 3, 0.02);
        assert!(r.take_signal_news(), "the one teammate that reported needs this report");
    }

    #[test]
    fn with_a_quorum_of_one_a_robot_acts_on_its_own_detection() {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let alone = SignalConfig { whistle_quorum: 1, ..SignalConfig::default() };
        let mut r = GameControllerReferee::new(5, 2, field, 600.0, alone);
        cycle(&mut r, 1.0, GameState::Set);
        r.perceive(secs(2.0), &whistle(2.0, 0.6));
        assert_eq!(cycle(&mut r, 2.0, GameState::Set).state, GameState::Playing);
        assert_eq!(r.signal_stats.perceived, 1);
    }

    #[test]
    fn teammates_follow_a_fresh_signal_and_ignore_stale_or_unknown_ones() {
        let mut r = referee();
        cycle(&mut r, 1.0, GameState::Standby);
        r.teammate_signal(secs(2.0), 3, &SharedSignal { code: SIGNAL_READY, age: 3.5 });
        r.teammate_signal(secs(2.0), 3, &SharedSignal { code: 3, age: 0.1 });
        assert_eq!(cycle(&mut r, 2.0, GameState::Standby).state, GameState::Standby);
        r.teammate_signal(secs(3.0), 3, &SharedSignal { code: SIGNAL_READY, age: 0.5 });
        assert!(!r.take_signal_news(), "the teammate told everybody already");
        assert_eq!(cycle(&mut r, 3.0, GameState::Standby).state, GameState::Ready);
        assert_eq!(r.signal_stats.from_teammates, 1);

        let mut r = referee();
        cycle(&mut r, 1.0, GameState::Set);
        // A gesture in Set, a stale whistle, two reports of one robot: none counts.
        r.teammate_signal(secs(2.0), 3, &SharedSignal { code: SIGNAL_READY, age: 0.1 });
        report(&mut r, 2.0, 3, 3.5);
        report(&mut r, 2.0, 4, 0.2);
        report(&mut r, 2.1, 4, 0.1);
        assert_eq!(cycle(&mut r, 2.1, GameState::Set).state, GameState::Set);
        // A second robot's report makes the quorum (a robot's newest report counts).
        report(&mut r, 3.0, 6, 0.9);
        let d = cycle(&mut r, 3.0, GameState::Set);
        assert_eq!((d.state, d.secondary_time), (GameState::Playing, 9));
        let relayed = r.shared_signal(secs(4.0)).expect("relayed");
        assert!((relayed.age - 2.0).abs() < 1e-9, "from the first of the quorum: {relayed:?}");
        assert_eq!(r.signal_stats.from_teammates, 1);
    }

    #[test]
    fn without_signals_or_a_game_controller_the_packets_alone_decide() {
        let field = TeamField::new(strata_spl::Field::preset("spl").expect("preset"), 1.0);
        let off = SignalConfig { enabled: false, ..SignalConfig::default() };
        let mut r = GameControllerReferee::new(5, 2, field, 600.0, off);
        cycle(&mut r, 1.0, GameState::Set);
        r.perceive(secs(2.0), &whistle(2.0, 1.0));
        report(&mut r, 2.0, 3, 0.0);
        assert_eq!(cycle(&mut r, 2.0, GameState::Set).state, GameState::Set);

        // No packet yet: nothing to run ahead of.
        let mut r = referee();
        r.perceive(secs(2.0), &whistle(2.0, 1.0));
        report(&mut r, 2.0, 3, 0.0);
        r.update(secs(2.0), None);
        assert_eq!(r.directive(), GameDirective::default());

        // A penalized robot is off the field: it does not start on a whistle.
        let mut r = referee();
        r.receive(secs(1.0), &packet(GameState::Set, true)).expect("valid");
        r.perceive(secs(2.0), &whistle(2.0, 1.0));
        report(&mut r, 2.0, 3, 0.0);
        r.update(secs(2.0), None);
        assert_eq!(r.directive().state, GameState::Set);
    }

    #[test]
    fn bad_signal_settings_name_the_field() {
        let bad = SignalConfig { whistle_confidence: 1.5, ..SignalConfig::default() };
        assert_eq!(bad.invalid().map(|(f, _)| f), Some("signals.whistle_confidence"));
        let bad = SignalConfig { whistle_trust: f64::NAN, ..SignalConfig::default() };
        assert_eq!(bad.invalid().map(|(f, _)| f), Some("signals.whistle_trust"));
        let bad = SignalConfig { whistle_quorum: 0, ..SignalConfig::default() };
        assert_eq!(bad.invalid().map(|(f, _)| f), Some("signals.whistle_quorum"));
        assert_eq!(SignalConfig::default().invalid(), None);
    }

    #[test]
    fn message_pacing_stays_bounded_when_the_clock_has_run_out() {
        let mut r = referee();
        let mut data = GameControlData::decode(&packet(GameState::Playing, false)).expect("valid");
        data.first_half = false;
        data.secs_remaining = 120;
        r.receive(Time::ZERO, &data.encode()).expect("valid");
        let running = r.budget().expect("budget").sustainable_rate();
        assert!((running - 1000.0 / 5.0 / 120.0).abs() < 1e-9, "{running}");
        // A half's clock at zero or below (the referee has not ended it yet, a penalty
        // shoot-out, stoppage) does not end the play: the robots must not spend their budget
        // as fast as they can.
        for secs in [0, -1, -30, i16::MIN] {
            data.secs_remaining = secs;
            r.receive(Time::ZERO, &data.encode()).expect("valid");
            let rate = r.budget().expect("budget").sustainable_rate();
            // Paced as if a minute were left.
            assert!((rate - 1000.0 / 5.0 / 60.0).abs() < 1e-9, "{secs} s left: {rate} messages/s");
        }
        // In the first half the second is still to come, as before.
        data.first_half = true;
        data.secs_remaining = -5;
        r.receive(Time::ZERO, &data.encode()).expect("valid");
        let first = r.budget().expect("budget").sustainable_rate();
        assert!((first - 1000.0 / 5.0 / 600.0).abs() < 1e-9, "{first}");
    }

    /// Values the robot does not know in fields it does not act on leave the game
    /// followed; a state it does not know leaves the last state it understood.
    #[test]
    fn unknown_values_do_not_make_the_robot_deaf() {
        let mut r = referee();
        let mut bytes = packet(GameState::Ready, false);
        bytes[8] = 9; // competition type
        bytes[18 + 1] = 42; // our field players' colour
        bytes[18 + 10 + 2 * 4] = 12; // player 5's penalty (we are player 2)
        bytes[18 + 50 + 10] = 13; // an opponent's penalty
        r.receive(Time::ZERO, &bytes).expect("followed");
        let d = r.directive();
        assert_eq!((d.state, d.penalized, d.connected), (GameState::Ready, false, true));

        // A set play and a penalty of ours it does not know: a set play, and penalized.
        let mut bytes = packet(GameState::Playing, false);
        bytes[11] = 6;
        bytes[18 + 10 + 2] = 12;
        r.receive(Time::ZERO, &bytes).expect("followed");
        let d = r.directive();
        assert_eq!(
            (d.state, d.set_play, d.penalized),
            (GameState::Playing, SetPlay::Unknown(6), true)
        );

        let mut bytes = packet(GameState::Set, false);
        bytes[10] = 6;
        assert!(r.receive(Time::ZERO, &bytes).is_err());
        assert_eq!((r.rejected, r.packets), (1, 2));
        assert_eq!(r.directive(), d, "the last state understood is kept");
        r.receive(Time::ZERO, &packet(GameState::Set, false)).expect("followed again");
        assert_eq!(r.directive().state, GameState::Set);
    }

    #[test]
    fn garbage_is_rejected_and_counted_and_other_games_ignored() {
        let mut r = referee();
        assert!(r.receive(Time::ZERO, b"RGme but not really").is_err());
        assert_eq!(r.rejected, 1);
        let mut data = GameControlData { state: GameState::Finished, ..Default::default() };
        data.teams[0].team_number = 1;
        data.teams[1].team_number = 2;
        r.receive(Time::ZERO, &data.encode()).expect("valid");
        assert!(!r.directive().connected, "not our game");
    }
}
