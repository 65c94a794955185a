//! The referee and the GameController it emulates: game states (Initial, Ready, Set, Playing,
//! Finished), kick-offs, goals, two halves, ball-out set plays (kick-in, goal kick, corner kick)
//! with the ball placed as the rules place it, the leaving-the-field penalty, the team message
//! budget, and the control packets (`RGme` v18, from the `spl` crate's encoder).
//!
//! The referee decides; the world acts on its decisions (moves the ball and robots, penalizes)
//! and records them as events. It looks at the world only through [`RefereeView`].

use serde::{Deserialize, Serialize};
use strata_robot::{Field as FieldFrame, Point};
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
    }

    /// Counts a team message. Returns whether it is within the budget; outside Ready, Set and
    /// Playing messages are not counted (as the GameController does).
    pub fn count_message(&mut self, team: usize, legal: bool) -> bool {
        if !matches!(self.state, GameState::Ready | GameState::Set | GameState::Playing) {
            return true;
        }
        if self.budget[team] == 0 || !legal {
            self.illegal_communication[team] = true;
            self.score[team] = 0;
            false
        } else {
            self.budget[team] -= 1;
            true
        }
    }

    /// Advances the referee by `dt` and appends its decisions.
    pub fn update(&mut self, dt: f64, view: &RefereeView<'_>, out: &mut Vec<Decision>) {
        self.state_time += dt;
        let auto = self.config.auto;
        match self.state {
            GameState::Initial if auto && self.state_time >= self.config.initial_duration => {
                if self.kicking_team.is_none() {
                    self.kicking_team = Some(self.config.kick_off_team);
                }
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
                    if !self.illegal_communication[team] {
                        self.score[team] = self.score[team].saturating_add(1);
                    }
                    out.push(Decision::Goal { team });
                    if auto {
                        self.kicking_team = Some(1 - team);
                        self.last_touch = None;
                        self.enter(GameState::Ready, out);
                        return;
                    }
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

    /// The control packet, with each robot's penalty from `player`.
    pub fn control_data(
        &mut self,
        teams: &[crate::config::TeamConfig; 2],
        players_per_team: u8,
        player: impl Fn(usize, u8) -> RobotInfo,
    ) -> GameControlData {
        let packet_number = self.packet_number;
        self.packet_number = self.packet_number.wrapping_add(1);
        let secondary = match self.state {
            GameState::Ready => self.config.ready_duration - self.state_time,
            GameState::Playing if self.set_play != SetPlay::None => {
                self.config.set_play_duration - self.set_play_time
            }
            GameState::Finished if self.first_half && !self.game_over => {
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
            slot.score = self.score[t];
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
            state: self.state,
            set_play: self.set_play,
            first_half: self.first_half,
            kicking_team: self.kicking_team.map(|t| teams[t].number),
            secs_remaining: seconds_i16(self.clock),
            secondary_time: seconds_i16(secondary.max(0.0)),
            teams: info,
        }
    }
}

/// Whole seconds for a packet, rounded up (a clock showing 0 has run out).
fn seconds_i16(seconds: f64) -> i16 {
    seconds.ceil().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}
