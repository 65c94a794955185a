//! The soccer game state the server reports: play modes and field sides.

/// A play mode of rcsssmj 0.2.1 (`rcsssmj/games/soccer/play_mode.py`), in the server's order:
/// the monitor port sends the index into this list, the agent port the text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlayMode {
    /// `BeforeKickOff`: the game has not started; beaming is allowed.
    BeforeKickOff,
    /// `KickOff_Left`.
    KickOffLeft,
    /// `KickOff_Right`.
    KickOffRight,
    /// `PlayOn`: normal play.
    PlayOn,
    /// `KickIn_Left`: the ball left over a touch line, the left team throws in.
    KickInLeft,
    /// `KickIn_Right`.
    KickInRight,
    /// `corner_kick_left`.
    CornerKickLeft,
    /// `corner_kick_right`.
    CornerKickRight,
    /// `goal_kick_left`.
    GoalKickLeft,
    /// `goal_kick_right`.
    GoalKickRight,
    /// `offside_left`: the right team was offside.
    OffsideLeft,
    /// `offside_right`: the left team was offside.
    OffsideRight,
    /// `GameOver`.
    GameOver,
    /// `Goal_Left`: the left team scored; beaming is allowed.
    GoalLeft,
    /// `Goal_Right`: the right team scored; beaming is allowed.
    GoalRight,
    /// `free_kick_left`.
    FreeKickLeft,
    /// `free_kick_right`.
    FreeKickRight,
    /// `direct_free_kick_left`.
    DirectFreeKickLeft,
    /// `direct_free_kick_right`.
    DirectFreeKickRight,
    /// `penalty_kick_left`: from the penalty mark.
    PenaltyKickLeft,
    /// `penalty_kick_right`.
    PenaltyKickRight,
    /// `penalty_shoot_left`: from anywhere, several touches allowed.
    PenaltyShootLeft,
    /// `penalty_shoot_right`.
    PenaltyShootRight,
}

impl PlayMode {
    /// Every play mode, in the server's order (the monitor's `play_mode` index).
    pub const ALL: [PlayMode; 23] = [
        PlayMode::BeforeKickOff,
        PlayMode::KickOffLeft,
        PlayMode::KickOffRight,
        PlayMode::PlayOn,
        PlayMode::KickInLeft,
        PlayMode::KickInRight,
        PlayMode::CornerKickLeft,
        PlayMode::CornerKickRight,
        PlayMode::GoalKickLeft,
        PlayMode::GoalKickRight,
        PlayMode::OffsideLeft,
        PlayMode::OffsideRight,
        PlayMode::GameOver,
        PlayMode::GoalLeft,
        PlayMode::GoalRight,
        PlayMode::FreeKickLeft,
        PlayMode::FreeKickRight,
        PlayMode::DirectFreeKickLeft,
        PlayMode::DirectFreeKickRight,
        PlayMode::PenaltyKickLeft,
        PlayMode::PenaltyKickRight,
        PlayMode::PenaltyShootLeft,
        PlayMode::PenaltyShootRight,
    ];

    /// The server's text for this play mode.
    pub fn as_str(self) -> &'static str {
        match self {
            PlayMode::BeforeKickOff => "BeforeKickOff",
            PlayMode::KickOffLeft => "KickOff_Left",
            PlayMode::KickOffRight => "KickOff_Right",
            PlayMode::PlayOn => "PlayOn",
            PlayMode::KickInLeft => "KickIn_Left",
            PlayMode::KickInRight => "KickIn_Right",
            PlayMode::CornerKickLeft => "corner_kick_left",
            PlayMode::CornerKickRight => "corner_kick_right",
            PlayMode::GoalKickLeft => "goal_kick_left",
            PlayMode::GoalKickRight => "goal_kick_right",
            PlayMode::OffsideLeft => "offside_left",
            PlayMode::OffsideRight => "offside_right",
            PlayMode::GameOver => "GameOver",
            PlayMode::GoalLeft => "Goal_Left",
            PlayMode::GoalRight => "Goal_Right",
            PlayMode::FreeKickLeft => "free_kick_left",
            PlayMode::FreeKickRight => "free_kick_right",
            PlayMode::DirectFreeKickLeft => "direct_free_kick_left",
            PlayMode::DirectFreeKickRight => "direct_free_kick_right",
            PlayMode::PenaltyKickLeft => "penalty_kick_left",
            PlayMode::PenaltyKickRight => "penalty_kick_right",
            PlayMode::PenaltyShootLeft => "penalty_shoot_left",
            PlayMode::PenaltyShootRight => "penalty_shoot_right",
        }
    }

    /// The play mode the server names `text`, if it is one of 0.2.1's.
    pub fn from_server_name(text: &str) -> Option<PlayMode> {
        PlayMode::ALL.into_iter().find(|mode| mode.as_str() == text)
    }

    /// The play mode at `index` in the server's list (the monitor port's encoding).
    pub fn from_index(index: usize) -> Option<PlayMode> {
        PlayMode::ALL.get(index).copied()
    }

    /// Whether agents may beam in this play mode (the referee's `is_beaming_allowed`).
    pub fn allows_beam(self) -> bool {
        matches!(self, PlayMode::BeforeKickOff | PlayMode::GoalLeft | PlayMode::GoalRight)
    }
}

/// A side of the field. The left team defends the goal at negative x.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FieldSide {
    /// The team listed first (`tl`), defending x < 0.
    Left,
    /// The team listed second (`tr`), defending x > 0.
    Right,
}
