//! The planning layer (paper 3.3): multi-robot coordination, decided distributively.
//!
//! - **MAMC** (multi-agent mission coordinator) keeps what each teammate last said and decides
//!   who is available: a teammate that is fallen, penalized, not localized, silent beyond a
//!   timeout, or not accomplishing its mission is freed from its role until it recovers.
//! - **MAMS** (multi-agent mission selector) selects the mission from everything the available
//!   teammates share, re-evaluated on every message; without communication it falls back to the
//!   application's default mission.
//! - **ARS** (agent role selector) assigns the mission's roles to the available robots (this one
//!   included) by their utilities — every robot runs the same deterministic assignment on the
//!   same shared data, so no leader is needed. Teammates' data is as old as their last message
//!   (the budget allows one every few seconds), so a robot holding a single-robot role gives it
//!   up only to a teammate that claims it (or whose data is fresh), and two claimants settle on
//!   the utilities they announced, which both know alike: the lower one (the higher number on
//!   a tie) yields. The first to detect a double claim sends an instant message. A robot's
//!   claim is the one it announced: it takes the first role over from a teammate, or gives it
//!   up to nobody in particular, only when it can say so at once (a role changed unheard leaves
//!   the ball to two robots or to none until the next message, seconds away on the budget).
//! - Communication lives only here: a periodic message, plus an instant message when this
//!   robot's status changes (falls, stands up, loses or finds the ball), its role changes or a
//!   role conflict is detected, always within the message budget; part of the budget is kept
//!   for the urgent ones (a claim or release of the mission's first role, a fall), and the last
//!   part of that for the vital ones (what the whole team must act on together: in soccer, the
//!   referee's signals). The
//!   deliberative layer is told only when the mission, the role or the application's
//!   directive change.

use std::collections::BTreeMap;
use std::fmt::Debug;
use std::hash::Hash;
use std::time::Duration;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use strata_runtime::Time;

use crate::geometry::{Global, Point, Pose};

/// A mission or role name of the application (an enum, typically).
pub trait Label:
    Copy + Debug + PartialEq + Eq + Hash + Ord + Serialize + DeserializeOwned + Send + Sync + 'static
{
}

impl<T> Label for T where
    T: Copy
        + Debug
        + PartialEq
        + Eq
        + Hash
        + Ord
        + Serialize
        + DeserializeOwned
        + Send
        + Sync
        + 'static
{
}

/// One role of a mission.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "R: Label")]
pub struct RoleSpec<R> {
    pub role: R,
    /// How many robots may hold the role at once (`None`: any number).
    pub max_robots: Option<usize>,
    /// A special role is held by a designated robot only (the goalkeeper).
    pub designated: Option<u8>,
}

/// A mission and its roles, in the order they are assigned (most important first).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "M: Label, R: Label")]
pub struct MissionSpec<M, R> {
    pub mission: M,
    pub roles: Vec<RoleSpec<R>>,
}

/// The missions and roles of an application (paper Table 1), as data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "M: Label, R: Label")]
pub struct MissionCatalog<M, R> {
    pub missions: Vec<MissionSpec<M, R>>,
    /// What a robot does when it hears no teammate (the paper: Attack / Striker).
    pub default_mission: M,
    pub default_role: R,
}

impl<M: Label, R: Label> MissionCatalog<M, R> {
    pub fn mission(&self, mission: M) -> Option<&MissionSpec<M, R>> {
        self.missions.iter().find(|m| m.mission == mission)
    }

    fn role_spec(&self, mission: M, role: R) -> Option<&RoleSpec<R>> {
        self.mission(mission)?.roles.iter().find(|r| r.role == role)
    }
}

/// Standing status, the first thing a teammate must know.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StandingStatus {
    #[default]
    Stable,
    Unstable,
    Fallen,
}

/// An object of interest as a robot shares it (the local map of Fig. 2), in the field frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SharedObject {
    pub name: String,
    pub position: Point<Global>,
    /// Position standard deviation, m.
    pub sigma: f64,
    pub confidence: f64,
    /// Seconds since the sender last saw it.
    pub age: f64,
}

/// A signal the sender perceived (the referee's whistle, a gesture) or followed from a
/// teammate, for teammates that missed it: the application's code for it, and how long ago the
/// first robot perceived it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SharedSignal {
    pub code: u8,
    /// s.
    pub age: f64,
}

/// The team message of Fig. 2: internal state, basic communication information, world model.
/// The application turns it into bytes (and may add its own fields in `extra`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "M: Label, R: Label")]
pub struct TeamMessage<M, R> {
    pub sender: u8,
    pub mission: M,
    pub role: R,
    pub status: StandingStatus,
    pub penalized: bool,
    pub localized: bool,
    /// Seconds since the sender last heard any teammate.
    pub since_last_received: f64,
    /// Whether the sender has received anything since its previous message.
    pub data_received: bool,
    /// The sender's own utility for the role it holds (the ARS compares it).
    pub utility: f64,
    /// The sender detected a role conflict and asks the others to re-evaluate.
    pub conflict: bool,
    pub pose: Pose,
    pub pose_confidence: f64,
    pub objects: Vec<SharedObject>,
    /// A signal the sender perceived and its teammates should act on.
    #[serde(default)]
    pub signal: Option<SharedSignal>,
}

/// This robot as the planning layer sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OwnState {
    pub id: u8,
    pub status: StandingStatus,
    pub penalized: bool,
    pub localized: bool,
    pub pose: Pose,
    pub pose_confidence: f64,
    pub objects: Vec<SharedObject>,
}

/// What MAMC keeps about a teammate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "M: Label, R: Label")]
pub struct TeammateRecord<M, R> {
    pub message: TeamMessage<M, R>,
    pub last_heard: Time,
    pub messages: u64,
    /// Why it is unavailable, if it is.
    pub unavailable: Option<String>,
}

/// A candidate for role assignment: this robot or an available teammate.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate<'a> {
    pub id: u8,
    pub pose: Pose,
    pub objects: &'a [SharedObject],
}

/// A robot competing for the mission's roles, as this robot sees it.
struct Contender<'a, R> {
    candidate: Candidate<'a>,
    /// The role it holds now: this robot's current one, a teammate's last announced one.
    holding: Option<R>,
    /// How old the data about it is, s.
    age: f64,
    /// A teammate's announced utility for the role it holds (unused for this robot).
    announced_utility: f64,
}

/// The application's part of planning.
pub trait PlanningPolicy: Send {
    type Mission: Label;
    type Role: Label;

    fn catalog(&self) -> &MissionCatalog<Self::Mission, Self::Role>;

    /// MAMS: the mission for the team, from this robot and its available teammates. `held` is
    /// this robot's mission and role while they still stand as its claim (not after it was
    /// out): teammates know it as announced, and a mission led by whoever holds a role must
    /// count this robot among the holders, or two holders each follow the other.
    fn select_mission(
        &self,
        own: &OwnState,
        held: Option<(Self::Mission, Self::Role)>,
        teammates: &[&TeammateRecord<Self::Mission, Self::Role>],
    ) -> Self::Mission;

    /// ARS: how well `candidate` would perform `role` (higher is better).
    fn role_utility(
        &self,
        candidate: &Candidate<'_>,
        role: Self::Role,
        mission: Self::Mission,
    ) -> f64;

    /// MAMC's "is it accomplishing its mission" check, beyond status and silence.
    fn accomplishing(
        &self,
        _teammate: &TeammateRecord<Self::Mission, Self::Role>,
        _now: Time,
    ) -> bool {
        true
    }

    /// Whether this robot's own shared state changed enough to warrant an instant message
    /// (beyond standing status, which always does): e.g. it lost or found the ball.
    fn instant_worthy(&self, _previous: &OwnState, _current: &OwnState) -> bool {
        false
    }

    /// How much a teammate's utility for the role it claims has likely grown in the `age`
    /// seconds since its message: it has been working at the role meanwhile. This robot's own
    /// candidacy is measured on fresh data, a teammate's on its last message; without this
    /// credit, a teammate closing in on the ball would look as far as it was when it spoke, and
    /// two robots would each find themselves best.
    fn claim_progress(&self, _role: Self::Role, _age: f64) -> f64 {
        0.0
    }

    /// Whether holding `held` is a claim to `role`: roles that are the same job under another
    /// mission (the robot going to the ball, attacking or defending) keep their claim when the
    /// mission changes.
    fn same_claim(&self, held: Self::Role, role: Self::Role) -> bool {
        held == role
    }
}

/// The one mission and the one role of a robot that works alone.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize,
)]
pub enum Solo {
    #[default]
    Alone,
}

/// The planning policy of a robot without teammates: one mission, one role, always its own
/// (MAMS and ARS have nothing to choose between).
#[derive(Clone, Debug)]
pub struct Alone {
    catalog: MissionCatalog<Solo, Solo>,
}

impl Default for Alone {
    fn default() -> Alone {
        let solo = MissionSpec {
            mission: Solo::Alone,
            roles: vec![RoleSpec { role: Solo::Alone, max_robots: Some(1), designated: None }],
        };
        Alone {
            catalog: MissionCatalog {
                missions: vec![solo],
                default_mission: Solo::Alone,
                default_role: Solo::Alone,
            },
        }
    }
}

impl PlanningPolicy for Alone {
    type Mission = Solo;
    type Role = Solo;

    fn catalog(&self) -> &MissionCatalog<Solo, Solo> {
        &self.catalog
    }

    fn select_mission(
        &self,
        _own: &OwnState,
        _held: Option<(Solo, Solo)>,
        _teammates: &[&TeammateRecord<Solo, Solo>],
    ) -> Solo {
        Solo::Alone
    }

    fn role_utility(&self, _candidate: &Candidate<'_>, _role: Solo, _mission: Solo) -> f64 {
        0.0
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanningConfig {
    /// Period of the regular team message, s.
    pub message_interval: f64,
    /// A teammate silent for longer is unavailable, s.
    pub teammate_timeout: f64,
    /// Minimum spacing between any two messages (instant ones included), s.
    pub min_message_spacing: f64,
    /// Messages that may go out back to back when the budget has been saved up (a fall, a new
    /// role): the burst of the budget's token bucket.
    pub message_burst: f64,
    /// Utility bonus of the robot currently holding a role: another must be better by this
    /// much to take it over, so that two nearly equal robots do not swap roles back and forth
    /// on stale data. Every handover leaves the team with two or no robots in the role until
    /// both have heard of it, so handovers must be worth it.
    pub role_hysteresis: f64,
    /// A teammate is silent only after this many of the intervals its message budget allows
    /// (and never before `teammate_timeout`): when the budget spaces messages by more than
    /// the timeout, a fixed timeout would declare every teammate silent between two of its
    /// messages, and the team would fall back to all strikers.
    pub silence_intervals: f64,
    /// Tokens of the message budget kept for urgent messages (a claim or release of the
    /// mission's first role, a fall, a conflict over that role): ordinary messages wait until
    /// the bucket holds more than this.
    pub urgent_reserve: f64,
    /// A robot holding a single-robot role hands it to a teammate that has not claimed it
    /// only on that teammate's data younger than this, s.
    pub release_age: f64,
}

impl Default for PlanningConfig {
    fn default() -> Self {
        PlanningConfig {
            message_interval: 4.0,
            teammate_timeout: 6.0,
            min_message_spacing: 0.5,
            message_burst: 3.0,
            role_hysteresis: 3.0,
            silence_intervals: 2.5,
            urgent_reserve: 1.0,
            release_age: 1.0,
        }
    }
}

/// How many messages may still be sent, and until when: the application keeps it up to date
/// (in soccer, from the GameController's message budget). A robot spends at most its share of
/// what remains, evenly over the remaining time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MessageBudget {
    /// Messages left for this robot's team.
    pub team_remaining: u32,
    /// Robots of the team sharing it.
    pub robots: u32,
    /// Time left in the game, s.
    pub time_left: f64,
    /// Messages of each robot's share kept back for urgent and vital messages.
    pub reserve: u32,
    /// Messages of each robot's share, within `reserve`, kept back for vital messages.
    #[serde(default)]
    pub vital_reserve: u32,
}

/// How much of the message budget a message may use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub enum Urgency {
    /// Waits behind the reserve (periodic messages, news teammates can live without for a
    /// while: a role further down the mission, the ball found).
    #[default]
    Ordinary,
    /// May use the reserve, but not its vital part: a claim or release of the mission's first
    /// role, a robot that cannot play or can again.
    Urgent,
    /// May use the whole reserve: what the whole team must act on together and at once (in
    /// soccer, the referee's signals). Late in a game falls and claims have spent the rest.
    Vital,
}

impl MessageBudget {
    pub fn unlimited() -> MessageBudget {
        MessageBudget {
            team_remaining: u32::MAX,
            robots: 1,
            time_left: f64::INFINITY,
            reserve: 0,
            vital_reserve: 0,
        }
    }

    fn own_share(&self) -> f64 {
        f64::from(self.team_remaining) / f64::from(self.robots.max(1))
    }

    /// The smallest average interval between messages that lasts the game.
    pub fn sustainable_interval(&self) -> f64 {
        let rate = self.sustainable_rate();
        if rate <= 0.0 { f64::INFINITY } else { 1.0 / rate }
    }

    /// Messages per second this robot can send on average and still have its share last the
    /// game.
    pub fn sustainable_rate(&self) -> f64 {
        let usable = self.own_share();
        if usable <= 0.0 {
            0.0
        } else if self.time_left.is_infinite() || self.time_left <= 0.0 {
            f64::INFINITY
        } else {
            usable / self.time_left
        }
    }

    pub fn can_send(&self, urgency: Urgency) -> bool {
        let kept = match urgency {
            Urgency::Ordinary => self.reserve,
            Urgency::Urgent => self.vital_reserve.min(self.reserve),
            Urgency::Vital => 0,
        };
        self.own_share() >= 1.0 + f64::from(kept)
    }

    pub fn spend(&mut self) {
        self.team_remaining = self.team_remaining.saturating_sub(1);
    }
}

/// What the planning layer tells the deliberative layer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(bound = "M: Label, R: Label")]
pub struct Assignment<M, R> {
    pub mission: M,
    pub role: R,
    /// No teammate is available: the default mission is in force.
    pub alone: bool,
}

/// Why a message is due.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MessageKind {
    Periodic,
    Instant,
}

/// The planning layer's state: MAMC records, the current assignment, message scheduling.
#[derive(Debug)]
pub struct Planner<P: PlanningPolicy> {
    policy: P,
    config: PlanningConfig,
    teammates: BTreeMap<u8, TeammateRecord<P::Mission, P::Role>>,
    assignment: Assignment<P::Mission, P::Role>,
    own: Option<OwnState>,
    own_utility: f64,
    /// This robot was out (fallen, penalized) since its last assignment: its old role is no
    /// claim any more (teammates have taken it over meanwhile).
    relinquished: bool,
    /// The role, utility and time of this robot's last message: what teammates know of its
    /// claim.
    announced: Option<(P::Mission, P::Role, f64, Time)>,
    last_sent: Option<Time>,
    /// Token bucket of the message budget: refilled at the sustainable rate.
    tokens: f64,
    last_refill: Option<Time>,
    last_received: Option<Time>,
    received_since_sent: bool,
    instant_pending: bool,
    /// How much of the reserve the pending instant message may use: more when it changes who
    /// holds the mission's first role (or whether this robot can play at all).
    urgency: Urgency,
    conflict_pending: bool,
    pub budget: MessageBudget,
    pub stats: PlanningStats,
}

/// Counters of the planning layer, for reports.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanningStats {
    pub sent_periodic: u64,
    pub sent_instant: u64,
    pub received: u64,
    pub rejected: u64,
    pub role_changes: u64,
    pub conflicts_detected: u64,
    /// Messages skipped because the budget did not allow them.
    pub withheld: u64,
}

impl<P: PlanningPolicy> Planner<P> {
    pub fn new(policy: P, config: PlanningConfig) -> Planner<P> {
        let catalog = policy.catalog();
        let assignment = Assignment {
            mission: catalog.default_mission,
            role: catalog.default_role,
            alone: true,
        };
        Planner {
            policy,
            config,
            teammates: BTreeMap::new(),
            assignment,
            own: None,
            own_utility: 0.0,
            relinquished: false,
            announced: None,
            last_sent: None,
            tokens: 0.0,
            last_refill: None,
            last_received: None,
            received_since_sent: false,
            instant_pending: false,
            urgency: Urgency::Ordinary,
            conflict_pending: false,
            budget: MessageBudget::unlimited(),
            stats: PlanningStats::default(),
        }
    }

    pub fn policy(&self) -> &P {
        &self.policy
    }

    pub fn policy_mut(&mut self) -> &mut P {
        &mut self.policy
    }

    pub fn assignment(&self) -> &Assignment<P::Mission, P::Role> {
        &self.assignment
    }

    pub fn teammates(&self) -> impl Iterator<Item = &TeammateRecord<P::Mission, P::Role>> {
        self.teammates.values()
    }

    /// A message arrived from a teammate (already decoded by the application).
    pub fn receive(&mut self, now: Time, message: TeamMessage<P::Mission, P::Role>) {
        let own_id = self.own.as_ref().map(|o| o.id);
        if own_id == Some(message.sender) {
            // Our own broadcast echoed back (loopback networks do this).
            return;
        }
        self.stats.received += 1;
        self.last_received = Some(now);
        self.received_since_sent = true;
        let record = self.teammates.entry(message.sender).or_insert_with(|| TeammateRecord {
            message: message.clone(),
            last_heard: now,
            messages: 0,
            unavailable: None,
        });
        record.message = message;
        record.last_heard = now;
        record.messages += 1;
    }

    pub fn reject(&mut self) {
        self.stats.rejected += 1;
    }

    /// MAMC: marks teammates available or not.
    fn coordinate(&mut self, now: Time) {
        let paced = self.budget.sustainable_interval() * self.config.silence_intervals;
        // Once the budget is down to its reserve, teammates speak only of falls and claims:
        // their silence is the rule's, not a lost link, and their last word stands.
        let muted = !self.budget.can_send(Urgency::Ordinary);
        let timeout = if muted {
            f64::INFINITY
        } else if paced.is_finite() {
            self.config.teammate_timeout.max(paced)
        } else {
            self.config.teammate_timeout
        };
        for record in self.teammates.values_mut() {
            let m = &record.message;
            record.unavailable = if (now - record.last_heard).as_secs_f64() > timeout {
                Some(format!("silent for {:.1} s", (now - record.last_heard).as_secs_f64()))
            } else if m.penalized {
                Some("penalized".to_owned())
            } else if m.status != StandingStatus::Stable {
                Some(format!("{:?}", m.status).to_lowercase())
            } else if !m.localized {
                Some("not localized".to_owned())
            } else {
                None
            };
        }
        let not_accomplishing: Vec<u8> = self
            .teammates
            .values()
            .filter(|r| r.unavailable.is_none() && !self.policy.accomplishing(r, now))
            .map(|r| r.message.sender)
            .collect();
        for id in not_accomplishing {
            if let Some(r) = self.teammates.get_mut(&id) {
                r.unavailable = Some("not accomplishing its mission".to_owned());
            }
        }
    }

    /// Re-evaluates mission and role. Returns the new assignment when it changed.
    pub fn evaluate(
        &mut self,
        now: Time,
        own: OwnState,
    ) -> Option<Assignment<P::Mission, P::Role>> {
        if let Some(previous) = &self.own
            && (previous.status != own.status
                || previous.penalized != own.penalized
                || self.policy.instant_worthy(previous, &own))
        {
            self.instant_pending = true;
            // Teammates must learn at once that this robot can or cannot play; how it lies
            // while it cannot is no matter to them.
            let playing = |s: &OwnState| s.status == StandingStatus::Stable && !s.penalized;
            if playing(previous) != playing(&own) {
                self.urgency = self.urgency.max(Urgency::Urgent);
            }
        }
        self.own = Some(own.clone());
        self.coordinate(now);
        let available: Vec<&TeammateRecord<P::Mission, P::Role>> =
            self.teammates.values().filter(|r| r.unavailable.is_none()).collect();
        let catalog = self.policy.catalog();
        let alone = available.is_empty();
        let out = own.penalized || own.status != StandingStatus::Stable;
        if out {
            self.relinquished = true;
            // What it announced before is no claim any more either.
            self.announced = None;
        }
        let (mission, role, utility) = if out {
            // An unavailable robot keeps its assignment; teammates free its role.
            (self.assignment.mission, self.assignment.role, 0.0)
        } else if let Some((mission, role)) = self.designated_role(own.id) {
            // A designated robot (the goalkeeper) has its role's own mission, whatever the
            // field players' mission is.
            (mission, role, 1.0)
        } else if alone {
            // Its true utility all the same: teammates that hear it again weigh its claim.
            let candidate = Candidate { id: own.id, pose: own.pose, objects: &own.objects };
            let utility =
                self.policy.role_utility(&candidate, catalog.default_role, catalog.default_mission);
            (catalog.default_mission, catalog.default_role, utility)
        } else {
            let held =
                (!self.relinquished).then_some((self.assignment.mission, self.assignment.role));
            let mission = self.policy.select_mission(&own, held, &available);
            let (role, utility) = self.assign_role(now, mission, &own, &available);
            (mission, role, utility)
        };
        // A claim to the mission's first role, taken or given up, holds for the team only once
        // teammates hear of it: a robot taking it over unheard makes two going to the ball
        // (the holder keeps it), a holder giving it up unheard leaves the ball to nobody
        // (everyone still counts on it). With no message possible now (the budget's tokens, the
        // spacing), the claim teammates last heard stands until one is; but giving it up to a
        // teammate that announced its own claim needs no word (both settle on what they
        // announced, and this robot takes it back if that says so), nor does taking it when
        // no teammate claims it, and once the budget is spent for the game there is no
        // waiting for a message.
        let (mission, role, utility) = if !out
            && !alone
            && Self::leads(catalog, mission, role) != self.heard_claiming()
            && self.budget.can_send(Urgency::Urgent)
            && !self.can_announce(now)
        {
            let teammate_claims =
                available.iter().any(|r| Self::leads(catalog, r.message.mission, r.message.role));
            let unheard_ok = if self.heard_claiming() { teammate_claims } else { !teammate_claims };
            if unheard_ok {
                (mission, role, utility)
            } else {
                let (mission, role) = (self.assignment.mission, self.assignment.role);
                let candidate = Candidate { id: own.id, pose: own.pose, objects: &own.objects };
                (mission, role, self.policy.role_utility(&candidate, role, mission))
            }
        } else {
            (mission, role, utility)
        };
        self.own_utility = utility;
        // A conflict: someone available claims our single-robot role.
        if let Some(spec) = catalog.role_spec(mission, role)
            && spec.max_robots == Some(1)
            && available.iter().any(|r| r.message.mission == mission && r.message.role == role)
            && !self.conflict_pending
        {
            self.stats.conflicts_detected += 1;
            self.conflict_pending = true;
            self.instant_pending = true;
            // The budget cannot settle every conflict at once: the first role's can.
            if Self::leads(catalog, mission, role) {
                self.urgency = self.urgency.max(Urgency::Urgent);
            }
        }
        if !out {
            // Back in: the role just computed, without the old claim, is the claim from now on.
            self.relinquished = false;
        }
        let next = Assignment { mission, role, alone };
        if next != self.assignment {
            if next.role != self.assignment.role {
                self.stats.role_changes += 1;
                // A claim or a release of the first role is what teammates must hear first.
                if Self::leads(catalog, next.mission, next.role)
                    || Self::leads(catalog, self.assignment.mission, self.assignment.role)
                {
                    self.urgency = self.urgency.max(Urgency::Urgent);
                }
            }
            self.assignment = next.clone();
            // Teammates must learn the new role soon, not at the next period.
            self.instant_pending = true;
            return Some(next);
        }
        None
    }

    /// Whether teammates count on this robot for its mission's first role: what it last
    /// announced, whatever it has done since.
    fn heard_claiming(&self) -> bool {
        self.announced
            .is_some_and(|(mission, role, _, _)| Self::leads(self.policy.catalog(), mission, role))
    }

    /// Whether an urgent message could go out now (the reserve is its).
    fn can_announce(&self, now: Time) -> bool {
        let burst = self.config.message_burst.max(1.0);
        let rate = self.budget.sustainable_rate();
        let tokens = match self.last_refill {
            None => burst,
            Some(_) if rate.is_infinite() => burst,
            Some(t) => (self.tokens + rate * (now - t).as_secs_f64()).min(burst),
        };
        let spacing = self.config.min_message_spacing.max(0.0);
        tokens >= 1.0
            && self.budget.can_send(Urgency::Urgent)
            && self.last_sent.is_none_or(|t| (now - t).as_secs_f64() >= spacing)
    }

    /// Whether `role` is the first role of `mission` (the one its roles are assigned around).
    fn leads(
        catalog: &MissionCatalog<P::Mission, P::Role>,
        mission: P::Mission,
        role: P::Role,
    ) -> bool {
        catalog.mission(mission).and_then(|m| m.roles.first()).is_some_and(|r| r.role == role)
    }

    fn designated_role(&self, id: u8) -> Option<(P::Mission, P::Role)> {
        self.policy.catalog().missions.iter().find_map(|m| {
            m.roles.iter().find(|r| r.designated == Some(id)).map(|r| (m.mission, r.role))
        })
    }

    /// ARS: the deterministic assignment every robot computes on the same data.
    fn assign_role(
        &self,
        now: Time,
        mission: P::Mission,
        own: &OwnState,
        available: &[&TeammateRecord<P::Mission, P::Role>],
    ) -> (P::Role, f64) {
        let catalog = self.policy.catalog();
        let Some(spec) = catalog.mission(mission) else {
            return (catalog.default_role, 0.0);
        };
        // This robot first (index 0), then the teammates not bound to a designated role (the
        // goalkeeper is no candidate for others).
        let mut contenders = vec![Contender {
            candidate: Candidate { id: own.id, pose: own.pose, objects: &own.objects },
            // Unless it was out meanwhile.
            holding: (!self.relinquished).then_some(self.assignment.role),
            age: 0.0,
            announced_utility: 0.0,
        }];
        contenders.extend(
            available.iter().filter(|r| self.designated_role(r.message.sender).is_none()).map(
                |r| Contender {
                    candidate: Candidate {
                        id: r.message.sender,
                        pose: r.message.pose,
                        objects: &r.message.objects,
                    },
                    holding: Some(r.message.role),
                    age: (now - r.last_heard).as_secs_f64(),
                    announced_utility: r.message.utility,
                },
            ),
        );
        let id = |i: usize| contenders[i].candidate.id;
        let mut unassigned: Vec<usize> = (0..contenders.len()).collect();
        let mut fallback = None;
        for role_spec in spec.roles.iter().filter(|r| r.designated.is_none()) {
            // This robot's claim is also the one it announced: teammates count on it until it
            // says otherwise (it may have given the role up unheard), and settling two claims
            // on it keeps everyone's answer alike.
            let announced_claim = self
                .announced
                .filter(|(_, held, _, _)| self.policy.same_claim(*held, role_spec.role));
            let holds = |i: usize| {
                contenders[i]
                    .holding
                    .is_some_and(|held| self.policy.same_claim(held, role_spec.role))
                    || (i == 0 && announced_claim.is_some())
            };
            // (candidate, utility as ranked, the candidate's own utility for the role)
            let mut ranked: Vec<(usize, f64, f64)> = unassigned
                .iter()
                .map(|&i| {
                    let utility =
                        self.policy.role_utility(&contenders[i].candidate, role_spec.role, mission);
                    let bonus = if holds(i) {
                        self.config.role_hysteresis
                            + self.policy.claim_progress(role_spec.role, contenders[i].age)
                    } else {
                        0.0
                    };
                    (i, utility + bonus, utility)
                })
                .collect();
            // Two announced claims to a single-robot role are settled on what both claimants
            // know alike, the utilities they announced (aged alike): each measuring itself on
            // fresh data and the other on its last message, both could keep the role, or both
            // yield it. The losing claims leave the ranking.
            if role_spec.max_robots == Some(1)
                && let Some((_, _, announced_utility, announced_at)) = announced_claim
            {
                let aged = |utility: f64, age: f64| {
                    utility + self.policy.claim_progress(role_spec.role, age.max(0.0))
                };
                let claims: Vec<(usize, f64)> = ranked
                    .iter()
                    .filter(|(i, _, _)| holds(*i))
                    .map(|&(i, _, _)| {
                        let claim = if i == 0 {
                            aged(announced_utility, (now - announced_at).as_secs_f64())
                        } else {
                            aged(contenders[i].announced_utility, contenders[i].age)
                        };
                        (i, claim)
                    })
                    .collect();
                if let Some(&(winner, _)) =
                    claims.iter().max_by(|a, b| a.1.total_cmp(&b.1).then(id(b.0).cmp(&id(a.0))))
                {
                    ranked.retain(|(i, _, _)| *i == winner || !holds(*i));
                }
            }
            // Higher utility first; on a tie, the lower robot number.
            ranked.sort_by(|a, b| b.1.total_cmp(&a.1).then(id(a.0).cmp(&id(b.0))));
            let take = role_spec.max_robots.unwrap_or(ranked.len()).min(ranked.len());
            for &(i, _, utility) in &ranked[..take] {
                if id(i) == own.id {
                    return (role_spec.role, utility);
                }
            }
            // A single-robot role is released only to a teammate that has announced its claim,
            // or whose data is fresh and who will take it: the teammate that looks better on
            // this robot's older data may, on its own, not find itself best, and the role would
            // be nobody's. A fresh teammate weighs this robot as announced, with the holder's
            // bonus and credit for the walking since: it takes the role only if it beats that.
            let to_beat = announced_claim.map(|(_, _, utility, at)| {
                utility
                    + self.config.role_hysteresis
                    + self.policy.claim_progress(role_spec.role, (now - at).as_secs_f64().max(0.0))
            });
            let takes_over = |i: usize, utility: f64| {
                holds(i)
                    || (contenders[i].age < self.config.release_age
                        && to_beat.is_none_or(|claim| utility > claim))
            };
            if role_spec.max_robots == Some(1)
                && holds(0)
                && !ranked[..take].iter().any(|&(i, _, utility)| takes_over(i, utility))
                && let Some(&(_, _, utility)) = ranked.iter().find(|(i, _, _)| *i == 0)
            {
                return (role_spec.role, utility);
            }
            let taken: Vec<usize> = ranked[..take].iter().map(|(i, _, _)| *i).collect();
            unassigned.retain(|i| !taken.contains(i));
            fallback.get_or_insert(role_spec.role);
        }
        (fallback.unwrap_or(catalog.default_role), 0.0)
    }

    /// Whether a message is due now, and of which kind, given the budget.
    ///
    /// Every message, instant ones included, takes a token from a bucket refilled at the rate
    /// that makes this robot's share of the budget last the game: a burst of instant messages
    /// (a fall, a role change) is allowed from what was saved, never beyond.
    /// Asks for a message at once (within the budget and the spacing): something the robot
    /// perceived that teammates should act on now, with as much of the reserve as `urgency`
    /// allows.
    pub fn request_instant(&mut self, urgency: Urgency) {
        self.instant_pending = true;
        self.urgency = self.urgency.max(urgency);
    }

    pub fn message_due(&mut self, now: Time) -> Option<MessageKind> {
        let burst = self.config.message_burst.max(1.0);
        let rate = self.budget.sustainable_rate();
        self.tokens = match self.last_refill {
            None => burst,
            Some(t) if rate.is_infinite() => {
                let _ = t;
                burst
            }
            Some(t) => (self.tokens + rate * (now - t).as_secs_f64()).min(burst),
        };
        self.last_refill = Some(now);
        let spacing = Duration::from_secs_f64(self.config.min_message_spacing.max(0.0));
        if self.last_sent.is_some_and(|t| now - t < spacing) {
            return None;
        }
        let interval = self.config.message_interval;
        let periodic_due = self.last_sent.is_none_or(|t| (now - t).as_secs_f64() >= interval);
        let kind = if self.instant_pending {
            MessageKind::Instant
        } else if periodic_due {
            MessageKind::Periodic
        } else {
            return None;
        };
        let reserve = if self.urgency > Urgency::Ordinary {
            0.0
        } else {
            self.config.urgent_reserve.max(0.0)
        };
        // The team's reserve is for urgent messages too.
        if self.tokens < 1.0 + reserve || !self.budget.can_send(self.urgency) {
            self.stats.withheld += 1;
            // An instant message that cannot go now is merged into the next one that can.
            return None;
        }
        Some(kind)
    }

    /// The message to send now (call when [`Planner::message_due`] says so); records it as sent.
    pub fn compose(
        &mut self,
        now: Time,
        kind: MessageKind,
    ) -> Option<TeamMessage<P::Mission, P::Role>> {
        let own = self.own.as_ref()?;
        let message = TeamMessage {
            sender: own.id,
            mission: self.assignment.mission,
            role: self.assignment.role,
            status: own.status,
            penalized: own.penalized,
            localized: own.localized,
            since_last_received: self
                .last_received
                .map_or(f64::INFINITY, |t| (now - t).as_secs_f64()),
            data_received: self.received_since_sent,
            utility: self.own_utility,
            conflict: self.conflict_pending,
            pose: own.pose,
            pose_confidence: own.pose_confidence,
            objects: own.objects.clone(),
            signal: None,
        };
        self.last_sent = Some(now);
        // A claim made while unable to play is no claim.
        self.announced = (own.status == StandingStatus::Stable && !own.penalized).then_some((
            self.assignment.mission,
            self.assignment.role,
            self.own_utility,
            now,
        ));
        self.received_since_sent = false;
        self.instant_pending = false;
        self.urgency = Urgency::Ordinary;
        self.conflict_pending = false;
        self.tokens -= 1.0;
        self.budget.spend();
        match kind {
            MessageKind::Periodic => self.stats.sent_periodic += 1,
            MessageKind::Instant => self.stats.sent_instant += 1,
        }
        Some(message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
    enum Mission {
        Attack,
    }

    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
    enum Role {
        Striker,
        StrikerCover,
    }

    /// One mission, a single striker nearest to the ball at x = 1, covers for the rest.
    struct Nearest(MissionCatalog<Mission, Role>);

    impl Nearest {
        fn new() -> Nearest {
            Nearest(MissionCatalog {
                missions: vec![MissionSpec {
                    mission: Mission::Attack,
                    roles: vec![
                        RoleSpec { role: Role::Striker, max_robots: Some(1), designated: None },
                        RoleSpec { role: Role::StrikerCover, max_robots: None, designated: None },
                    ],
                }],
                default_mission: Mission::Attack,
                default_role: Role::Striker,
            })
        }
    }

    impl PlanningPolicy for Nearest {
        type Mission = Mission;
        type Role = Role;

        fn catalog(&self) -> &MissionCatalog<Mission, Role> {
            &self.0
        }

        fn select_mission(
            &self,
            _: &OwnState,
            _: Option<(Mission, Role)>,
            _: &[&TeammateRecord<Mission, Role>],
        ) -> Mission {
            Mission::Attack
        }

        fn role_utility(&self, candidate: &Candidate<'_>, role: Role, _: Mission) -> f64 {
            match role {
                Role::Striker => -candidate.pose.position().distance(Point::new(1.0, 0.0)),
                Role::StrikerCover => 0.0,
            }
        }
    }

    fn own(id: u8, x: f64) -> OwnState {
        OwnState {
            id,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            pose: Pose::new(x, 0.0, 0.0),
            pose_confidence: 0.9,
            objects: Vec::new(),
        }
    }

    fn message(sender: u8, x: f64, role: Role, utility: f64) -> TeamMessage<Mission, Role> {
        TeamMessage {
            sender,
            mission: Mission::Attack,
            role,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            since_last_received: 0.0,
            data_received: true,
            utility,
            conflict: false,
            pose: Pose::new(x, 0.0, 0.0),
            pose_confidence: 0.9,
            objects: Vec::new(),
            signal: None,
        }
    }

    fn t(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    /// Seven robots sharing 1200 messages over 1200 s: one message every 7 s each.
    fn seven_robots_sharing_1200() -> MessageBudget {
        MessageBudget {
            team_remaining: 1200,
            robots: 7,
            time_left: 1200.0,
            reserve: 3,
            vital_reserve: 0,
        }
    }

    fn planner() -> Planner<Nearest> {
        Planner::new(Nearest::new(), PlanningConfig::default())
    }

    #[test]
    fn a_striker_keeps_its_role_until_the_better_teammate_claims_it() {
        let mut p = planner();
        p.receive(t(0.0), message(3, -3.0, Role::StrikerCover, 0.0));
        p.evaluate(t(0.0), own(2, 0.5));
        assert_eq!(p.assignment().role, Role::Striker);
        p.compose(t(0.0), MessageKind::Periodic);
        // Robot 3 has come close to the ball, robot 2 has been pushed away: on two-second-old
        // data, 3 looks better, but 3 may not know it; 2 keeps the role rather than leave it
        // to nobody.
        p.receive(t(1.0), message(3, 0.9, Role::StrikerCover, 0.0));
        p.evaluate(t(3.0), own(2, -3.0));
        assert_eq!(p.assignment().role, Role::Striker);
        // 3 claims it: 2 yields.
        p.receive(t(3.5), message(3, 0.9, Role::Striker, -0.1));
        p.evaluate(t(3.6), own(2, -3.0));
        assert_eq!(p.assignment().role, Role::StrikerCover);
    }

    #[test]
    fn two_claimants_agree_on_who_keeps_the_role_whatever_their_own_fresh_data_says() {
        let (mut a, mut b) = (planner(), planner());
        // Alone, each attacks as striker and says how far it is.
        a.evaluate(t(0.0), own(2, 0.0));
        b.evaluate(t(0.0), own(3, -1.0));
        let from_a = a.compose(t(0.0), MessageKind::Periodic).expect("a message");
        let from_b = b.compose(t(0.0), MessageKind::Periodic).expect("a message");
        assert_eq!((from_a.utility, from_b.utility), (-1.0, -2.0));
        a.receive(t(0.1), from_b);
        b.receive(t(0.1), from_a);
        // Both have walked on; each, fresh, finds itself nearer than the other's last message.
        a.evaluate(t(1.0), own(2, 0.8));
        b.evaluate(t(1.0), own(3, 0.9));
        // The announced claims decide, alike for both.
        assert_eq!(a.assignment().role, Role::Striker);
        assert_eq!(b.assignment().role, Role::StrikerCover);
    }

    #[test]
    fn a_holder_gives_the_role_only_to_a_teammate_that_will_take_it() {
        let mut p = planner();
        p.receive(t(0.0), message(3, -3.0, Role::StrikerCover, 0.0));
        p.evaluate(t(0.0), own(2, 0.0));
        assert_eq!(p.assignment().role, Role::Striker);
        // Robot 2 announces it is 1 m from the ball.
        p.compose(t(0.0), MessageKind::Periodic);
        // Pushed back to 4 m, it hears robot 3 fresh at 0.5 m: better than robot 2 with the
        // holder's bonus. But robot 3 weighs robot 2 as announced (1 m, with the bonus) and
        // does not take the role: robot 2 keeps it rather than leave it to nobody.
        p.receive(t(2.0), message(3, 0.5, Role::StrikerCover, 0.0));
        p.evaluate(t(2.0), own(2, -3.0));
        assert_eq!(p.assignment().role, Role::Striker);
    }

    #[test]
    fn a_takeover_waits_until_it_can_be_announced() {
        let mut p = Planner::new(
            Nearest::new(),
            PlanningConfig { message_burst: 1.0, ..PlanningConfig::default() },
        );
        // Seven robots sharing 1200 messages over 1200 s: a token every 7 s.
        p.budget = seven_robots_sharing_1200();
        p.receive(t(0.0), message(3, -3.0, Role::Striker, -4.0));
        p.evaluate(t(0.0), own(2, -3.5));
        assert_eq!(p.assignment().role, Role::StrikerCover);
        let kind = p.message_due(t(0.0)).expect("the new role goes out");
        p.compose(t(0.0), kind);
        // Robot 2 is now far better than the striker, but has no token to say it takes over:
        // taking it unheard, the striker (which keeps it) and robot 2 would both go.
        p.receive(t(1.0), message(3, -3.0, Role::Striker, -4.0));
        p.evaluate(t(1.0), own(2, 0.9));
        assert_eq!(p.assignment().role, Role::StrikerCover);
        assert_eq!(p.message_due(t(1.0)), None);
        // A token later, it takes over and says so at once.
        p.receive(t(8.0), message(3, -3.0, Role::Striker, -4.0));
        p.evaluate(t(8.0), own(2, 0.9));
        assert_eq!(p.assignment().role, Role::Striker);
        assert_eq!(p.message_due(t(8.0)), Some(MessageKind::Instant));
    }

    #[test]
    fn a_claim_given_up_unheard_is_taken_back_when_the_announced_claims_say_so() {
        let mut p = planner();
        // Robot 5, alone, attacks and announces its claim (9 m from the ball).
        p.evaluate(t(0.0), own(5, -8.0));
        p.compose(t(0.0), MessageKind::Periodic);
        // Robot 3 claims it, nearer: robot 5 yields before it may speak again (the message
        // spacing), which needs no word: robot 3 keeps the role on the same announced claims.
        p.receive(t(0.1), message(3, -7.7, Role::Striker, -8.7));
        p.evaluate(t(0.1), own(5, -8.0));
        assert_eq!(p.assignment().role, Role::StrikerCover);
        // Robot 3's next message announces it much farther (on its own ball estimate), though
        // its pose still looks near on robot 5's: on the announced claims robot 3 yields to
        // robot 5, whose claim teammates still hold, so robot 5 must take the role back.
        p.receive(t(0.3), message(3, -7.0, Role::Striker, -15.5));
        p.evaluate(t(0.3), own(5, -8.0));
        assert_eq!(p.assignment().role, Role::Striker);
    }

    #[test]
    fn teammates_are_silent_only_beyond_what_their_budget_allows() {
        let mut p = planner();
        // Seven robots sharing 1200 messages over 1200 s: one message every 7 s each.
        p.budget = seven_robots_sharing_1200();
        p.receive(t(0.0), message(3, -3.0, Role::StrikerCover, -4.0));
        p.evaluate(t(10.0), own(2, 0.5));
        assert!(!p.assignment().alone, "heard 10 s ago, within the budget's pace");
        p.evaluate(t(20.0), own(2, 0.5));
        assert!(p.assignment().alone, "silent for 20 s");
        // Down to the reserve, teammates may only speak of falls and claims: their last word
        // stands.
        p.budget.team_remaining = 20;
        p.receive(t(21.0), message(3, -3.0, Role::StrikerCover, -4.0));
        p.evaluate(t(80.0), own(2, 0.5));
        assert!(!p.assignment().alone);
    }

    #[test]
    fn ordinary_messages_leave_a_token_for_a_claim() {
        let mut p = Planner::new(
            Nearest::new(),
            PlanningConfig {
                message_interval: 1.0,
                min_message_spacing: 0.0,
                ..PlanningConfig::default()
            },
        );
        p.budget = MessageBudget {
            team_remaining: 10,
            robots: 1,
            time_left: 1000.0,
            reserve: 0,
            vital_reserve: 0,
        };
        p.receive(t(0.0), message(3, -3.0, Role::StrikerCover, -4.0));
        for time in [0.0, 1.0] {
            p.evaluate(t(time), own(2, 0.5));
            let kind = p.message_due(t(time)).expect("a periodic message");
            p.compose(t(time), kind);
        }
        p.evaluate(t(2.0), own(2, 0.5));
        assert_eq!(p.message_due(t(2.0)), None, "the last token is kept");
        // Robot 3 claims the striker role from nearer: the release goes out at once.
        p.receive(t(2.5), message(3, 0.9, Role::Striker, -0.1));
        p.evaluate(t(2.5), own(2, 0.5));
        assert_eq!(p.assignment().role, Role::StrikerCover);
        assert_eq!(p.message_due(t(2.5)), Some(MessageKind::Instant));
    }

    #[test]
    fn the_vital_part_of_the_reserve_outlasts_falls_and_claims() {
        let mut p = planner();
        // Seven robots, two messages each left: the reserve's vital part.
        p.budget = MessageBudget {
            team_remaining: 14,
            robots: 7,
            time_left: 100.0,
            reserve: 10,
            vital_reserve: 2,
        };
        assert!(!p.budget.can_send(Urgency::Ordinary));
        assert!(!p.budget.can_send(Urgency::Urgent));
        assert!(p.budget.can_send(Urgency::Vital));
        p.evaluate(t(0.0), own(2, 0.5));
        p.compose(t(0.0), MessageKind::Periodic);
        p.request_instant(Urgency::Urgent);
        assert_eq!(p.message_due(t(1.0)), None, "a fall waits behind the vital part");
        p.request_instant(Urgency::Vital);
        assert_eq!(p.message_due(t(2.0)), Some(MessageKind::Instant), "a signal goes out");
        // Below one message each, nobody speaks: seven at once would overrun the budget.
        p.budget.team_remaining = 6;
        p.request_instant(Urgency::Vital);
        assert_eq!(p.message_due(t(3.0)), None);
    }
}
