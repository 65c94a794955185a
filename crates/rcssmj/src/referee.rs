//! The server's referee as a GameController: each game-state perceptor (`GS`: play mode,
//! scores, team names) becomes the control packet an SPL GameController would send, so the
//! soccer application follows the game on this platform exactly as on a field.
//!
//! Play modes map to the SPL's states and set plays:
//!
//! | rcssservermj | GameController |
//! |---|---|
//! | `BeforeKickOff` | Ready, the left team kicking off (as `strata match` starts each half) |
//! | `Goal_Left/Right` | Ready, the team that conceded kicking off |
//! | `KickOff_Left/Right` | Playing, that team kicking off |
//! | `PlayOn` | Playing |
//! | `KickIn_*` | Playing, set play kick-in |
//! | `corner_kick_*` | Playing, set play corner kick |
//! | `goal_kick_*` | Playing, set play goal kick |
//! | `free_kick_*`, `direct_free_kick_*`, `offside_*` | Playing, set play pushing free kick |
//! | `penalty_kick_*`, `penalty_shoot_*` | Playing, set play penalty kick |
//! | `GameOver` | Finished |
//!
//! The server's left team defends the goal at negative x in both halves (the teams change ends
//! by connecting in the other order). A GameController lists first the team that attacks +x in
//! the first half and -x in the second, so the left team is listed first in the first half and
//! second in the second.

use std::sync::{Arc, Mutex, PoisonError};

use strata_robot::geometry::Pose;
use strata_robot::platform::{ExternalLink, LinkError, ReceivedPacket};
use strata_robot::world::PosePrior;
use strata_runtime::Time;
use strata_spl::FieldDimensions;
use strata_spl::gamecontroller::{GameControlData, GameState, SetPlay, TeamInfo};

use crate::protocol::{FieldSide, GameStatePerceptor, PlayMode};

/// What the packets say that the server does not: its rule book's half length, which gives
/// the half and the seconds left from the play time, and a message budget (the server counts
/// no team messages, but the robots pace theirs by the budget as on an SPL field).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefereeRules {
    /// Length of a half in the server's rule book, play seconds (the `ssim` rules': 300).
    pub half_time: f64,
    /// Team messages per team and game.
    pub message_budget: u16,
    /// Play seconds after which the referee gives the ball free when a kick-off was not taken
    /// (rcsssmj 0.2.1's `kick_off_time`: 15).
    pub kick_off_time: f64,
}

impl Default for RefereeRules {
    fn default() -> Self {
        RefereeRules { half_time: 300.0, message_budget: 1200, kick_off_time: 15.0 }
    }
}

/// The team numbers the packets use: ours, and the one that stands for the other team.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TeamNumbers {
    pub own: u8,
    pub opponent: u8,
}

impl TeamNumbers {
    /// `own` and a different number for the opponent.
    pub fn new(own: u8) -> TeamNumbers {
        TeamNumbers { own, opponent: if own == 1 { 2 } else { 1 } }
    }
}

/// The control packet for a game state, or `None` while our team is on neither side (the
/// server lists a team once one of its robots has joined).
pub fn control_data(
    game: &GameStatePerceptor,
    team_name: &str,
    numbers: TeamNumbers,
    players_per_team: u8,
    rules: RefereeRules,
) -> Option<GameControlData> {
    let side = game.side_of(team_name)?;
    let (left, right) = match side {
        FieldSide::Left => (numbers.own, numbers.opponent),
        FieldSide::Right => (numbers.opponent, numbers.own),
    };
    let team_of = |s: FieldSide| match s {
        FieldSide::Left => left,
        FieldSide::Right => right,
    };
    let (state, set_play, kicking) = match game.play_mode {
        None => (GameState::Ready, SetPlay::None, None),
        Some(PlayMode::BeforeKickOff) => (GameState::Ready, SetPlay::None, Some(FieldSide::Left)),
        Some(PlayMode::GoalLeft) => (GameState::Ready, SetPlay::None, Some(FieldSide::Right)),
        Some(PlayMode::GoalRight) => (GameState::Ready, SetPlay::None, Some(FieldSide::Left)),
        Some(PlayMode::GameOver) => (GameState::Finished, SetPlay::None, None),
        Some(PlayMode::PlayOn) => (GameState::Playing, SetPlay::None, None),
        Some(mode) => {
            let (set_play, side) = set_play_of(mode);
            (GameState::Playing, set_play, Some(side))
        }
    };
    let team = |number: u8, score: u32| TeamInfo {
        team_number: number,
        score: u8::try_from(score).unwrap_or(u8::MAX),
        message_budget: rules.message_budget,
        ..TeamInfo::default()
    };
    // The server's play time runs on through the halves: the first ends at one half time, the
    // second at two.
    let half_time = rules.half_time.max(1.0);
    let first_half = game.play_time < half_time;
    let half_end = if first_half { half_time } else { 2.0 * half_time };
    let secs_remaining = (half_end - game.play_time).round().clamp(-32768.0, 32767.0) as i16;
    let (left_team, right_team) = (team(left, game.score_left), team(right, game.score_right));
    Some(GameControlData {
        players_per_team,
        state,
        set_play,
        first_half,
        kicking_team: kicking.map(team_of),
        secs_remaining,
        teams: if first_half { [left_team, right_team] } else { [right_team, left_team] },
        ..GameControlData::default()
    })
}

fn set_play_of(mode: PlayMode) -> (SetPlay, FieldSide) {
    use FieldSide::{Left, Right};
    match mode {
        PlayMode::KickOffLeft => (SetPlay::None, Left),
        PlayMode::KickOffRight => (SetPlay::None, Right),
        PlayMode::KickInLeft => (SetPlay::KickIn, Left),
        PlayMode::KickInRight => (SetPlay::KickIn, Right),
        PlayMode::CornerKickLeft => (SetPlay::CornerKick, Left),
        PlayMode::CornerKickRight => (SetPlay::CornerKick, Right),
        PlayMode::GoalKickLeft => (SetPlay::GoalKick, Left),
        PlayMode::GoalKickRight => (SetPlay::GoalKick, Right),
        PlayMode::FreeKickLeft | PlayMode::DirectFreeKickLeft | PlayMode::OffsideLeft => {
            (SetPlay::PushingFreeKick, Left)
        }
        PlayMode::FreeKickRight | PlayMode::DirectFreeKickRight | PlayMode::OffsideRight => {
            (SetPlay::PushingFreeKick, Right)
        }
        PlayMode::PenaltyKickLeft | PlayMode::PenaltyShootLeft => (SetPlay::PenaltyKick, Left),
        PlayMode::PenaltyKickRight | PlayMode::PenaltyShootRight => (SetPlay::PenaltyKick, Right),
        // Handled by the caller; listed so a new play mode is a compile error here.
        PlayMode::BeforeKickOff
        | PlayMode::PlayOn
        | PlayMode::GameOver
        | PlayMode::GoalLeft
        | PlayMode::GoalRight => (SetPlay::None, Left),
    }
}

/// How far apart rcsssmj 0.2.1's referee tries the spots it puts a penalized robot on, m.
const PENALTY_SPOT_STEP: f64 = 2.0;

/// Where the server's referee may put a robot of ours without telling it (rcsssmj 0.2.1's
/// `_penalize`: a robot in the way of the other team's set play, one lying too long, ...), in
/// the team's frame: outside the side line at the field border's edge, on the side away from
/// the ball, facing into the field, at the first free x of 2, 4, 6 ... m into its own half.
/// No packet says the robot was moved, so world modeling needs these to find it there
/// (`SymmetryHint::Relocations`).
pub fn penalty_spots(field: &FieldDimensions) -> Vec<PosePrior> {
    let y = field.field_width / 2.0 + field.border_strip_width;
    let half_length = field.field_length / 2.0;
    let mut spots = Vec::new();
    let mut x = -PENALTY_SPOT_STEP;
    while x > -half_length {
        for side in [1.0, -1.0] {
            spots.push(PosePrior {
                pose: Pose::new(x, side * y, -side * std::f64::consts::FRAC_PI_2),
                // The placement is exact, but the robot walks and turns on until its landmarks
                // disagree, which is when world modeling starts carrying the spots along by
                // odometry. Any wider, one landmark would tell neither two spots 2 m apart nor
                // (by the heading) the two side lines apart.
                sigma: [0.35, 0.35, 0.4],
            });
        }
        x -= PENALTY_SPOT_STEP;
    }
    spots
}

/// The newest game state, shared by the platform's connection thread and the link.
pub type SharedGame = Arc<Mutex<Option<GameStatePerceptor>>>;

/// A GameController link whose packets are made from the server's game state: one packet per
/// `receive` when the state changed, and at least every half second (a GameController's rate).
#[derive(Debug)]
pub struct RefereeLink {
    game: SharedGame,
    team_name: String,
    numbers: TeamNumbers,
    players_per_team: u8,
    rules: RefereeRules,
    last: Option<(GameControlData, Time)>,
    packet_number: u8,
    /// The play mode last seen and the play time it was first seen at.
    mode_since: Option<(Option<PlayMode>, f64)>,
}

impl RefereeLink {
    pub fn new(
        game: SharedGame,
        team_name: &str,
        numbers: TeamNumbers,
        players_per_team: u8,
        rules: RefereeRules,
    ) -> RefereeLink {
        RefereeLink {
            game,
            team_name: team_name.to_owned(),
            numbers,
            players_per_team,
            rules,
            last: None,
            packet_number: 0,
            mode_since: None,
        }
    }
}

impl ExternalLink for RefereeLink {
    fn receive(&mut self, now: Time) -> Result<Vec<ReceivedPacket>, LinkError> {
        let game = self.game.lock().unwrap_or_else(PoisonError::into_inner).clone();
        let Some(game) = game else { return Ok(Vec::new()) };
        let since = match self.mode_since {
            Some((mode, since)) if mode == game.play_mode => since,
            _ => {
                self.mode_since = Some((game.play_mode, game.play_time));
                game.play_time
            }
        };
        let Some(mut data) =
            control_data(&game, &self.team_name, self.numbers, self.players_per_team, self.rules)
        else {
            return Ok(Vec::new());
        };
        if matches!(game.play_mode, Some(PlayMode::KickOffLeft | PlayMode::KickOffRight)) {
            // As an SPL GameController counts down to the free ball after a kick-off: the
            // server gives it free at the kicker's touch (the play mode changes) or when
            // `kick_off_time` has passed. Until then the other team must keep out of the
            // centre circle and the kicking team's others out of the opponent half.
            let left = self.rules.kick_off_time - (game.play_time - since);
            data.secondary_time = left.ceil().clamp(1.0, f64::from(i16::MAX)) as i16;
        }
        let due = match &self.last {
            None => true,
            Some((last, at)) => {
                // The clock ticking is not news; a changed state is.
                let changed = GameControlData { secs_remaining: 0, packet_number: 0, ..*last }
                    != GameControlData { secs_remaining: 0, packet_number: 0, ..data };
                changed || now.saturating_since(*at).as_secs_f64() >= 0.5
            }
        };
        if !due {
            return Ok(Vec::new());
        }
        self.packet_number = self.packet_number.wrapping_add(1);
        let data = GameControlData { packet_number: self.packet_number, ..data };
        self.last = Some((data, now));
        Ok(vec![ReceivedPacket { received: now, bytes: data.encode().to_vec() }])
    }

    /// Return packets have nobody to go to: the server's referee does not read them.
    fn send(&mut self, _now: Time, _payload: &[u8]) -> Result<(), LinkError> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn penalty_spots_are_off_the_side_lines_of_the_own_half_facing_in() {
        let field = strata_spl::Field::preset("rcssservermj").expect("the preset");
        let spots = penalty_spots(field.dimensions());
        // x = -2 ... -26 on both sides of the 55 m x 36 m field with its 3 m border.
        assert_eq!(spots.len(), 26);
        for spot in &spots {
            let p = spot.pose;
            assert!(p.x < 0.0 && p.x > -27.5 && (p.x / 2.0).fract() == 0.0, "{p:?}");
            assert_eq!(p.y.abs(), 21.0, "{p:?}");
            // Facing the centre line's direction into the field: towards y = 0.
            assert!((p.theta.sin() + p.y.signum()).abs() < 1e-12, "{p:?}");
        }
        let first = spots.iter().find(|s| s.pose.y < 0.0).expect("the -y side");
        assert_eq!((first.pose.x, first.pose.y), (-2.0, -21.0));
    }

    fn gs(mode: PlayMode, left: Option<&str>, right: Option<&str>) -> GameStatePerceptor {
        GameStatePerceptor {
            play_time: 12.4,
            play_mode_text: mode.as_str().to_owned(),
            play_mode: Some(mode),
            team_left: left.map(str::to_owned),
            team_right: right.map(str::to_owned),
            score_left: 2,
            score_right: 1,
        }
    }

    #[test]
    fn play_modes_become_game_states_for_the_right_team() {
        let numbers = TeamNumbers::new(10);
        let before = gs(PlayMode::BeforeKickOff, Some("Us"), None);
        let data = control_data(&before, "Us", numbers, 7, RefereeRules::default())
            .expect("our team is on the left");
        assert_eq!(data.state, GameState::Ready);
        assert_eq!(data.teams[0].team_number, 10);
        assert_eq!(data.teams[0].score, 2);
        // The left team takes the game's kick-off: its kicker walks to the ball.
        assert_eq!(data.kicking_team, Some(10));
        // Listed first in the first half: we attack +x, as the server's left team does.
        assert!(data.first_half);

        let kick_off = gs(PlayMode::KickOffRight, Some("Them"), Some("Us"));
        let data = control_data(&kick_off, "Us", numbers, 7, RefereeRules::default())
            .expect("on the right");
        assert_eq!(data.state, GameState::Playing);
        assert_eq!(data.teams[1].team_number, 10);
        assert_eq!(data.kicking_team, Some(10));

        let corner = gs(PlayMode::CornerKickLeft, Some("Them"), Some("Us"));
        let data =
            control_data(&corner, "Us", numbers, 7, RefereeRules::default()).expect("on the right");
        assert_eq!(
            (data.set_play, data.kicking_team),
            (SetPlay::CornerKick, Some(numbers.opponent))
        );

        assert_eq!(
            control_data(
                &gs(PlayMode::GameOver, Some("Us"), None),
                "Us",
                numbers,
                7,
                RefereeRules::default()
            )
            .map(|d| d.state),
            Some(GameState::Finished)
        );
        assert!(control_data(&before, "Nobody", numbers, 7, RefereeRules::default()).is_none());
    }

    #[test]
    fn the_play_time_gives_the_half_and_the_seconds_left_in_it() {
        let numbers = TeamNumbers::new(1);
        let rules = RefereeRules { message_budget: 500, ..RefereeRules::default() };
        let at = |t: f64| {
            let game =
                GameStatePerceptor { play_time: t, ..gs(PlayMode::PlayOn, Some("Us"), None) };
            control_data(&game, "Us", numbers, 3, rules).expect("our team is on the left")
        };
        let early = at(240.4);
        assert_eq!((early.first_half, early.secs_remaining), (true, 60));
        assert_eq!(early.teams[0].message_budget, 500);
        let second = at(545.0);
        assert_eq!((second.first_half, second.secs_remaining), (false, 55));
        // Still on the left, attacking +x: listed second, as the GameController lists the
        // team attacking +x in the second half.
        assert_eq!(second.teams[1].team_number, 1);
        assert_eq!(second.teams[1].score, 2);
    }

    /// A link for team "Us" (number 3) and the game state it reads.
    fn link_for_us(players_per_team: u8) -> (SharedGame, RefereeLink) {
        let game: SharedGame = Arc::new(Mutex::new(None));
        let link = RefereeLink::new(
            Arc::clone(&game),
            "Us",
            TeamNumbers::new(3),
            players_per_team,
            RefereeRules::default(),
        );
        (game, link)
    }

    #[test]
    fn a_kick_off_counts_down_to_the_free_ball() {
        let (game, mut link) = link_for_us(3);
        let mut at_play_time = |play_time: f64, mode: PlayMode, ms: u64| {
            *game.lock().expect("not poisoned") =
                Some(GameStatePerceptor { play_time, ..gs(mode, Some("Us"), Some("Them")) });
            let sent = link.receive(Time::from_nanos(ms * 1_000_000)).expect("never fails");
            let packet = sent.last().expect("a changed state is sent at once");
            GameControlData::decode(&packet.bytes).expect("a valid packet")
        };
        let start = at_play_time(0.0, PlayMode::KickOffLeft, 0);
        assert_eq!(
            (start.state, start.kicking_team, start.secondary_time),
            (GameState::Playing, Some(3), 15)
        );
        assert_eq!(at_play_time(5.5, PlayMode::KickOffLeft, 5500).secondary_time, 10);
        // The kicker touched the ball: free.
        let free = at_play_time(6.0, PlayMode::PlayOn, 6000);
        assert_eq!((free.kicking_team, free.secondary_time), (None, 0));
        // The next kick-off counts from its own start.
        assert_eq!(at_play_time(40.0, PlayMode::KickOffRight, 40000).secondary_time, 15);
    }

    #[test]
    fn the_link_sends_on_change_and_twice_a_second() {
        let (game, mut link) = link_for_us(5);
        let at = |ms: u64| Time::from_nanos(ms * 1_000_000);
        assert!(link.receive(at(0)).expect("never fails").is_empty());
        *game.lock().expect("not poisoned") = Some(gs(PlayMode::BeforeKickOff, Some("Us"), None));
        let first = link.receive(at(10)).expect("never fails");
        assert_eq!(first.len(), 1);
        let decoded = GameControlData::decode(&first[0].bytes).expect("a valid packet");
        assert_eq!(decoded.state, GameState::Ready);
        assert!(link.receive(at(100)).expect("never fails").is_empty());
        assert_eq!(link.receive(at(600)).expect("never fails").len(), 1);
        *game.lock().expect("not poisoned") = Some(gs(PlayMode::PlayOn, Some("Us"), None));
        assert_eq!(link.receive(at(610)).expect("never fails").len(), 1);
    }
}
