//! The referee and the GameController it emulates: game states (Initial, Standby, Ready, Set,
//! Playing, Finished), kick-offs, goals, two halves, ball-out set plays (kick-in, goal kick,
//! corner kick) with the ball placed as the rules place it, the leaving-the-field penalty, the
//! team message budget, and the control packets (`RGme` v18, from the `spl` crate's encoder).
//!
//! The referee decides; the world acts on its decisions (moves the ball and robots, penalizes)
//! and records them as events. It looks at the world only through [`RefereeView`].
//!
//! Like GameController3, the control packets can show a delayed copy of the game (see
//! [`RefereeConfig::delay_after_ready`]): robots must see the referee's Ready gesture and hear
//! the kick-off whistle themselves, so for a while after those (and after a goal) the packets
//! keep showing the game as it was. The world always acts on the true game.

use serde::{Deserialize, Serialize};
use strata_robot::{Global as FieldFrame, Point};
use strata_spl::Field;
use strata_spl::field::{BallStatus, Side};
use strata_spl::gamecontroller::{
    CompetitionPhase, CompetitionType, GameControlData, GamePhase, GameState, RobotInfo, SetPlay,
    TeamInfo,
};

use crate::config::RefereeConfig;

/// What the referee sees of the world.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RefereeView<'a> {
    pub field: &'a Field,
    pub ball: Point<FieldFrame>,
    pub ball_radius: f64,
    /// Positions of the robots on the field (present and not penalized), by slot index.
    pub robots: &'a [Option<Point<FieldFrame>>],
}

/// A decision of the referee for the world to carry out.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Decision {
    /// The game state changed.
    State(GameState),
    /// `team` scored (index).
    Goal { team: usize },
    /// The ball left the field; with the automatic referee a set play was awarded and the ball
    /// must be placed at `place`.
    Out {
        status: BallStatus,
        set_play: SetPlay,
        team: Option<usize>,
        place: Option<Point<FieldFrame>>,
    },
    /// Place the ball (kick-off).
    PlaceBall(Point<FieldFrame>),
    /// Move robots out of illegal kick-off positions.
    PlaceForKickOff,
    /// A new half: robots to the side lines of their own half.
    PlaceForHalf,
    /// The robot in this slot left the field.
    LeftField { slot: usize },
    /// A set play ended.
    SetPlayOver,
}

/// The game as the control packets show it during a delay: what a packet needs of the game
/// before the delayed transition, with that game's own timers running on.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
struct Delayed {
    /// How long the packets show this copy, s.
    duration: f64,
    /// How long they have shown it, s. Counted up like `state_time` so that a delay as long as
    /// the state it hides ends in the same step (45 s of Ready behind 45 s of Standby).
    elapsed: f64,
    state: GameState,
    set_play: SetPlay,
    first_half: bool,
    kicking_team: Option<usize>,
    score: [u8; 2],
    clock: f64,
    set_play_time: f64,
}

/// The referee's state.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Referee {
    config: RefereeConfig,
    pub state: GameState,
    pub set_play: SetPlay,
    pub first_half: bool,
    /// Index of the team taking the kick-off or set play.
    pub kicking_team: Option<usize>,
    /// Time in the current state, s.
    pub state_time: f64,
    /// Seconds left in the half.
    pub clock: f64,
    pub score: [u8; 2],
    pub budget: [u16; 2],
    /// A team that sent an illegal message or exceeded its budget scores no more (GameController 3).
    pub illegal_communication: [bool; 2],
    /// +1 when the team attacks the goal at +x.
    pub attack_sign: [f64; 2],
    /// The team that last touched the ball.
    pub last_touch: Option<usize>,
    pub game_over: bool,
    packet_number: u8,
    set_play_time: f64,
    set_play_ball: Option<Point<FieldFrame>>,
    last_ball_status: BallStatus,
    /// What the control packets show instead of the true game, while a delay runs.
    delayed: Option<Delayed>,
}

impl Referee {
    pub fn new(config: &RefereeConfig) -> Referee {
        Referee {
            config: config.clone(),
            state: GameState::Initial,
            set_play: SetPlay::None,
            first_half: true,
            kicking_team: Some(config.kick_off_team),
            state_time: 0.0,
            clock: config.half_duration,
            score: [0; 2],
            budget: [config.message_budget; 2],
            illegal_communication: [false; 2],
            attack_sign: [1.0, -1.0],
            last_touch: None,
            game_over: false,
            packet_number: 0,
            set_play_time: 0.0,
            set_play_ball: None,
            last_ball_status: BallStatus::InPlay,
            delayed: None,
        }
    }

    /// The team defending the goal on `side` of the field.
    pub fn defender_of(&self, side: Side) -> usize {
        if self.attack_sign[0] == side.sign() { 1 } else { 0 }
    }

    /// Sets the state by hand (experiments, tests, a manual referee).
    pub fn set_state(&mut self, state: GameState, out: &mut Vec<Decision>) {
        if state == self.state {
            return;
        }
        self.enter(state, out);
    }

    fn enter(&mut self, state: GameState, out: &mut Vec<Decision>) {
        match (self.state, state) {
            (GameState::Standby, GameState::Ready) => {
                self.fork(self.copy(), self.config.delay_after_ready);
            }
            (GameState::Set, GameState::Playing) => {
                self.fork(self.copy(), self.config.delay_after_playing);
            }
            // Other transitions are not delayed, and the copy (Standby, Set, or the Playing
            // before a goal) cannot follow them, so GameController3 stops delaying and the
            // robots see the true game at once.
            _ => self.delayed = None,
        }
        self.state = state;
        self.state_time = 0.0;
        if state != GameState::Playing {
            self.set_play = SetPlay::None;
            self.set_play_ball = None;
        }
        out.push(Decision::State(state));
    }

    /// Awards a set play by hand.
    pub fn start_set_play(&mut self, set_play: SetPlay, team: usize, ball: Point<FieldFrame>) {
        self.set_play = set_play;
        self.kicking_team = Some(team);
        self.set_play_time = 0.0;
        self.set_play_ball = Some(ball);
        // Set plays are not delayed: GameController3 applies one to its delayed copy where the
        // copy could take it (Playing), and otherwise stops delaying.
        match self.delayed.as_mut() {
            Some(copy) if copy.state == GameState::Playing => {
                copy.set_play = set_play;
                copy.kicking_team = Some(team);
                copy.set_play_time = 0.0;
            }
            _ => self.delayed = None,
        }
    }

    /// The game as it is now, for packets to show during a delay that starts now.
    fn copy(&self) -> Delayed {
        Delayed {
            duration: 0.0,
            elapsed: 0.0,
            state: self.state,
            set_play: self.set_play,
            first_half: self.first_half,
            kicking_team: self.kicking_team,
            score: self.score,
            clock: self.clock,
            set_play_time: self.set_play_time,
        }
    }

    /// Holds the packets at `copy` for `duration`. Replaces a running delay, as GameController3
    /// forks the true game again; a zero delay just ends the running one.
    fn fork(&mut self, copy: Delayed, duration: f64) {
        self.delayed = (duration > 0.0).then_some(Delayed { duration, elapsed: 0.0, ..copy });
    }

    /// Counts a running delay down and runs the copy's timers by its own state's rules (the
    /// clock and a set play's time only in Playing), as GameController3 seeks its delayed game.
    fn advance_delay(&mut self, dt: f64) {
        let Some(copy) = self.delayed.as_mut() else { return };
        copy.elapsed += dt;
        if copy.elapsed >= copy.duration {
            self.delayed = None;
            return;
        }
        if copy.state == GameState::Playing {
            copy.clock = (copy.clock - dt).max(0.0);
            if copy.set_play != SetPlay::None {
                copy.set_play_time += dt;
                if copy.set_play_time >= self.config.set_play_duration {
                    copy.set_play = SetPlay::None;
                }
            }
        }
    }

    /// Counts a team message. Returns whether it is within the budget; outside Standby, Ready,
    /// Set and Playing messages are not counted (as GameController3 does).
    pub fn count_message(&mut self, team: usize, legal: bool) -> bool {
        if !matches!(
            self.state,
            GameState::Standby | GameState::Ready | GameState::Set | GameState::Playing
        ) {
            return true;
        }
        if self.budget[team] == 0 || !legal {
            self.illegal_communication[team] = true;
            self.score[team] = 0;
            // A delayed copy is always in a state that counts messages, so GameController3
            // zeroes its score too (and its budget stays equal to the true one).
            if let Some(copy) = self.delayed.as_mut() {
                copy.score[team] = 0;
            }
            false
        } else {
            self.budget[team] -= 1;
            true
        }
    }

    /// Advances the referee by `dt` and appends its decisions.
    pub fn update(&mut self, dt: f64, view: &RefereeView<'_>, out: &mut Vec<Decision>) {
        self.state_time += dt;
        self.advance_delay(dt);
        let auto = self.config.auto;
        match self.state {
            GameState::Initial if auto && self.state_time >= self.config.initial_duration => {
                if self.kicking_team.is_none() {
                    self.kicking_team = Some(self.config.kick_off_team);
                }
                let next = if self.config.standby_duration > 0.0 {
                    GameState::Standby
                } else {
                    GameState::Ready
                };
                self.enter(next, out);
            }
            GameState::Standby if auto && self.state_time >= self.config.standby_duration => {
                self.enter(GameState::Ready, out);
            }
            GameState::Ready if auto && self.state_time >= self.config.ready_duration => {
                self.enter(GameState::Set, out);
                out.push(Decision::PlaceBall(Point::new(0.0, 0.0)));
                if self.config.auto_placement {
                    out.push(Decision::PlaceForKickOff);
                }
            }
            GameState::Set if auto && self.state_time >= self.config.set_duration => {
                self.last_ball_status = BallStatus::InPlay;
                self.enter(GameState::Playing, out);
            }
            GameState::Playing => self.play(dt, view, out),
            GameState::Finished
                if auto
                    && self.first_half
                    && !self.game_over
                    && self.state_time >= self.config.half_time_break =>
            {
                self.first_half = false;
                self.clock = self.config.half_duration;
                if self.config.switch_sides_at_half_time {
                    self.attack_sign = [-self.attack_sign[0], -self.attack_sign[1]];
                }
                self.kicking_team = Some(1 - self.config.kick_off_team);
                self.last_touch = None;
                self.enter(GameState::Initial, out);
                out.push(Decision::PlaceBall(Point::new(0.0, 0.0)));
                out.push(Decision::PlaceForHalf);
            }
            _ => {}
        }
    }

    fn play(&mut self, dt: f64, view: &RefereeView<'_>, out: &mut Vec<Decision>) {
        let auto = self.config.auto;
        self.clock = (self.clock - dt).max(0.0);
        if self.set_play != SetPlay::None {
            self.set_play_time += dt;
            let moved = self.set_play_ball.is_some_and(|start| start.distance(view.ball) > 0.1);
            if self.set_play_time >= self.config.set_play_duration || moved {
                self.set_play = SetPlay::None;
                self.set_play_ball = None;
                // A copy in Playing has the true game's set play (forked with it, or given it by
                // `start_set_play`), so it ends with it.
                if let Some(copy) = self.delayed.as_mut()
                    && copy.state == GameState::Playing
                {
                    copy.set_play = SetPlay::None;
                }
                out.push(Decision::SetPlayOver);
            }
        }

        let status = view.field.ball_status(view.ball.x, view.ball.y, view.ball_radius);
        let changed = status != self.last_ball_status;
        self.last_ball_status = status;
        if changed {
            match status {
                BallStatus::InPlay => {}
                BallStatus::Goal(side) => {
                    let team = 1 - self.defender_of(side);
                    let before = self.copy();
                    if !self.illegal_communication[team] {
                        self.score[team] = self.score[team].saturating_add(1);
                    }
                    out.push(Decision::Goal { team });
                    if auto {
                        self.kicking_team = Some(1 - team);
                        self.last_touch = None;
                        self.enter(GameState::Ready, out);
                        self.fork(before, self.config.delay_after_goal);
                        return;
                    }
                    self.fork(before, self.config.delay_after_goal);
                }
                BallStatus::OutOverSideLine(_) | BallStatus::OutOverGoalLine(_) => {
                    let (set_play, team, place) = self.out_decision(status, view);
                    if auto {
                        self.start_set_play(set_play, team, place);
                        self.last_ball_status = BallStatus::InPlay;
                        out.push(Decision::Out {
                            status,
                            set_play,
                            team: Some(team),
                            place: Some(place),
                        });
                    } else {
                        out.push(Decision::Out { status, set_play, team: Some(team), place: None });
                    }
                }
            }
        }

        if auto {
            let field = view.field;
            let d = field.dimensions();
            let limit_x =
                field.half_length() + d.line_width / 2.0 + self.config.leaving_field_margin;
            let limit_y =
                field.half_width() + d.line_width / 2.0 + self.config.leaving_field_margin;
            for (slot, robot) in view.robots.iter().enumerate() {
                if let Some(robot) = robot
                    && (robot.x.abs() > limit_x || robot.y.abs() > limit_y)
                {
                    out.push(Decision::LeftField { slot });
                }
            }
            if self.clock <= 0.0 {
                if !self.first_half {
                    self.game_over = true;
                }
                self.kicking_team = None;
                self.enter(GameState::Finished, out);
            }
        }
    }

    /// The set play, the team awarded it and where the ball goes, for a ball out.
    fn out_decision(
        &self,
        status: BallStatus,
        view: &RefereeView<'_>,
    ) -> (SetPlay, usize, Point<FieldFrame>) {
        let field = view.field;
        let d = field.dimensions();
        let (hl, hw) = (field.half_length(), field.half_width());
        let ball = view.ball;
        let toward = |y: f64| if y >= 0.0 { 1.0 } else { -1.0 };
        match status {
            BallStatus::OutOverGoalLine(side) => {
                let defender = self.defender_of(side);
                let last = self.last_touch.unwrap_or(1 - defender);
                if last == defender {
                    // The defenders put it out: a corner kick for the attackers.
                    let place = Point::new(side.sign() * hl, toward(ball.y) * hw);
                    (SetPlay::CornerKick, 1 - defender, place)
                } else {
                    // The attackers put it out: a goal kick from the goal area's front corner.
                    let area = d.goal_area.unwrap_or(d.penalty_area);
                    let place = Point::new(
                        side.sign() * (hl - area.length),
                        toward(ball.y) * area.width / 2.0,
                    );
                    (SetPlay::GoalKick, defender, place)
                }
            }
            _ => {
                // Over a side line: a kick-in for the other team where it left the field.
                let last = self.last_touch.unwrap_or_else(|| self.defender_of(field.half(ball.x)));
                let place = Point::new(ball.x.clamp(-hl, hl), toward(ball.y) * hw);
                (SetPlay::KickIn, 1 - last, place)
            }
        }
    }

    /// The control packet, with each robot's penalty from `player`. During a delay it shows the
    /// delayed copy of the game; the budget is the true one, which the copy's always equals.
    pub fn control_data(
        &mut self,
        teams: &[crate::config::TeamConfig; 2],
        players_per_team: u8,
        player: impl Fn(usize, u8) -> RobotInfo,
    ) -> GameControlData {
        let packet_number = self.packet_number;
        self.packet_number = self.packet_number.wrapping_add(1);
        let shown = self.delayed.unwrap_or_else(|| self.copy());
        // A copy is never in Ready or Finished, so `state_time` there is the shown game's.
        let secondary = match shown.state {
            GameState::Ready => self.config.ready_duration - self.state_time,
            GameState::Playing if shown.set_play != SetPlay::None => {
                self.config.set_play_duration - shown.set_play_time
            }
            GameState::Finished if shown.first_half && !self.game_over => {
                self.config.half_time_break - self.state_time
            }
            _ => 0.0,
        };
        let mut info = [TeamInfo::default(); 2];
        for (t, team) in teams.iter().enumerate() {
            let slot = &mut info[t];
            slot.team_number = team.number;
            slot.field_player_colour = team.field_player_colour;
            slot.goalkeeper_colour = team.goalkeeper_colour;
            slot.goalkeeper = team.goalkeeper;
            slot.score = shown.score[t];
            slot.message_budget = self.budget[t];
            for p in 1..=players_per_team {
                if let Some(robot) = slot.players.get_mut(usize::from(p) - 1) {
                    *robot = player(t, p);
                }
            }
        }
        GameControlData {
            packet_number,
            players_per_team,
            competition_phase: CompetitionPhase::RoundRobin,
            competition_type: CompetitionType::Normal,
            game_phase: GamePhase::Normal,
            state: shown.state,
            set_play: shown.set_play,
            first_half: shown.first_half,
            kicking_team: shown.kicking_team.map(|t| teams[t].number),
            secs_remaining: seconds_i16(shown.clock),
            secondary_time: seconds_i16(secondary.max(0.0)),
            teams: info,
        }
    }
}

/// Whole seconds for a packet, rounded up (a clock showing 0 has run out).
fn seconds_i16(seconds: f64) -> i16 {
    seconds.ceil().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::SimConfig;

    /// A referee and the field it watches; steps of 1 s keep every sum of times exact.
    struct Game {
        referee: Referee,
        field: Field,
        ball: Point<FieldFrame>,
    }

    impl Game {
        fn new(config: RefereeConfig) -> Game {
            Game {
                referee: Referee::new(&config),
                field: Field::preset("spl").expect("the spl preset"),
                ball: Point::new(0.0, 0.0),
            }
        }

        fn step(&mut self) -> Vec<Decision> {
            let view =
                RefereeView { field: &self.field, ball: self.ball, ball_radius: 0.05, robots: &[] };
            let mut out = Vec::new();
            self.referee.update(1.0, &view, &mut out);
            out
        }

        fn set(&mut self, state: GameState) {
            self.referee.set_state(state, &mut Vec::new());
        }

        fn packet(&mut self) -> GameControlData {
            let teams = self.referee.config.teams.clone();
            self.referee.control_data(&teams, 7, |_, _| RobotInfo::default())
        }

        /// Puts the ball in the goal team 0 attacks.
        fn score_for_team_0(&mut self) {
            self.ball = Point::new(self.field.half_length() + 0.2, 0.0);
        }
    }

    fn scores(packet: &GameControlData) -> [u8; 2] {
        [packet.teams[0].score, packet.teams[1].score]
    }

    fn delays(ready: f64, playing: f64, goal: f64) -> RefereeConfig {
        RefereeConfig {
            delay_after_ready: ready,
            delay_after_playing: playing,
            delay_after_goal: goal,
            ..RefereeConfig::default()
        }
    }

    #[test]
    fn by_default_packets_show_every_state_at_once() {
        let mut game = Game::new(RefereeConfig::default());
        let mut seen = Vec::new();
        for _ in 0..60 {
            game.step();
            let packet = game.packet();
            assert_eq!(packet.state, game.referee.state);
            if seen.last() != Some(&packet.state) {
                seen.push(packet.state);
            }
        }
        // No Standby without `standby_duration`.
        assert_eq!(
            seen,
            [GameState::Initial, GameState::Ready, GameState::Set, GameState::Playing]
        );
        game.score_for_team_0();
        game.step();
        let packet = game.packet();
        assert_eq!((packet.state, scores(&packet)), (GameState::Ready, [1, 0]));
        assert!(game.referee.delayed.is_none());
    }

    #[test]
    fn the_kick_off_whistle_reaches_the_packets_after_delay_after_playing() {
        let mut game = Game::new(delays(0.0, 15.0, 0.0));
        game.set(GameState::Set);
        game.set(GameState::Playing);
        assert_eq!(game.packet().state, GameState::Set);
        for second in 1..=15 {
            game.step();
            assert_eq!(game.referee.state, GameState::Playing, "the world plays at once");
            let packet = game.packet();
            if second < 15 {
                assert_eq!(packet.state, GameState::Set, "after {second} s");
                // Set's clock stands still in the copy while the true one runs.
                assert_eq!(packet.secs_remaining, 600);
            } else {
                assert_eq!(packet.state, GameState::Playing, "after {second} s");
                assert_eq!(packet.secs_remaining, 585);
            }
        }
    }

    #[test]
    fn a_goal_keeps_the_old_score_and_playing_in_packets_for_delay_after_goal() {
        let mut game = Game::new(delays(0.0, 0.0, 15.0));
        game.set(GameState::Playing);
        game.step();
        game.score_for_team_0();
        let decisions = game.step();
        assert!(decisions.contains(&Decision::Goal { team: 0 }));
        assert_eq!((game.referee.state, game.referee.score), (GameState::Ready, [1, 0]));
        let packet = game.packet();
        assert_eq!((packet.state, scores(&packet)), (GameState::Playing, [0, 0]));
        assert_eq!(packet.kicking_team, Some(10), "the old kicking team");
        for second in 1..=15 {
            game.step();
            let packet = game.packet();
            if second < 15 {
                assert_eq!((packet.state, scores(&packet)), (GameState::Playing, [0, 0]));
                // The copy's clock runs on in its Playing (598 s at the goal).
                assert_eq!(packet.secs_remaining, 598 - second);
            } else {
                assert_eq!((packet.state, scores(&packet)), (GameState::Ready, [1, 0]));
                assert_eq!(packet.secondary_time, 30, "45 s of Ready, 15 s gone");
                assert_eq!(packet.kicking_team, Some(20));
                assert_eq!(packet.secs_remaining, 598);
            }
        }
    }

    #[test]
    fn a_goal_during_the_playing_delay_starts_its_own_delay_from_the_true_playing() {
        let mut game = Game::new(delays(0.0, 15.0, 15.0));
        game.set(GameState::Set);
        game.set(GameState::Playing);
        for _ in 0..5 {
            game.step();
        }
        assert_eq!(game.packet().state, GameState::Set);
        game.score_for_team_0();
        game.step();
        for second in 1..=15 {
            let packet = game.packet();
            assert_eq!((packet.state, scores(&packet)), (GameState::Playing, [0, 0]), "{second}");
            game.step();
        }
        let packet = game.packet();
        assert_eq!((packet.state, scores(&packet)), (GameState::Ready, [1, 0]));
    }

    #[test]
    fn a_ball_out_during_the_playing_delay_shows_playing_and_the_set_play_at_once() {
        let mut game = Game::new(delays(0.0, 15.0, 0.0));
        game.set(GameState::Set);
        game.set(GameState::Playing);
        game.step();
        game.ball = Point::new(1.0, game.field.half_width() + 0.3);
        game.step();
        let packet = game.packet();
        assert_eq!((packet.state, packet.set_play), (GameState::Playing, SetPlay::KickIn));
    }

    #[test]
    fn the_ready_gesture_is_delayed_and_set_ends_the_delay_at_once() {
        let mut game = Game::new(RefereeConfig { standby_duration: 3.0, ..delays(10.0, 0.0, 0.0) });
        // Initial 2 s, Standby 3 s: Ready at 5 s, shown from 15 s.
        for second in 1..=16 {
            game.step();
            let packet = game.packet();
            let expected = match second {
                0..2 => GameState::Initial,
                2..15 => GameState::Standby,
                _ => GameState::Ready,
            };
            assert_eq!(packet.state, expected, "after {second} s");
            if second >= 5 {
                assert_eq!(game.referee.state, GameState::Ready);
            }
            if second == 15 {
                assert_eq!(packet.secondary_time, 35);
            }
        }

        let mut game = Game::new(RefereeConfig { standby_duration: 3.0, ..delays(45.0, 0.0, 0.0) });
        for _ in 0..8 {
            game.step();
        }
        assert_eq!(
            (game.referee.state, game.packet().state),
            (GameState::Ready, GameState::Standby)
        );
        game.set(GameState::Set);
        assert_eq!(game.packet().state, GameState::Set);
    }

    #[test]
    fn with_champions_cup_delays_robots_never_receive_ready() {
        let mut game =
            Game::new(RefereeConfig { standby_duration: 3.0, ..delays(45.0, 15.0, 15.0) });
        let mut seen = Vec::new();
        for _ in 0..80 {
            game.step();
            let state = game.packet().state;
            if seen.last() != Some(&state) {
                seen.push(state);
            }
        }
        assert_eq!(
            seen,
            [GameState::Initial, GameState::Standby, GameState::Set, GameState::Playing]
        );
    }

    #[test]
    fn illegal_communication_zeroes_the_delayed_score_too() {
        let mut game = Game::new(delays(0.0, 0.0, 15.0));
        game.set(GameState::Playing);
        game.referee.score = [2, 0];
        game.score_for_team_0();
        game.step();
        assert_eq!(scores(&game.packet()), [2, 0]);
        assert!(!game.referee.count_message(0, false));
        assert_eq!(scores(&game.packet()), [0, 0]);
    }

    #[test]
    fn delays_and_standby_must_be_finite_and_not_negative() {
        for key in
            ["delay_after_ready", "delay_after_playing", "delay_after_goal", "standby_duration"]
        {
            for value in ["-1.0", "nan", "inf"] {
                let text = format!("[referee]\n{key} = {value}\n");
                let error = SimConfig::from_toml_str(&text, "x.toml").expect_err(&text);
                assert!(error.to_string().contains(&format!("`referee.{key}`")), "{error}");
            }
            let text = format!("[referee]\n{key} = 15.0\n");
            SimConfig::from_toml_str(&text, "x.toml").expect(&text);
        }
    }
}
