//! Missions and roles of robot soccer (paper Table 1).

use serde::{Deserialize, Serialize};
use strata_robot::control::planning::{MissionCatalog, MissionSpec, RoleSpec};

/// A high-level task of the team (Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mission {
    /// The goalkeeper prevents the opponents from scoring.
    DefendTheGoal,
    /// Field players trying to score.
    Attack,
    /// Field players preventing the opponents from scoring.
    Defend,
}

/// A robot's part in a mission (Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// Only one robot, the goalkeeper, may hold it.
    Goalie,
    /// The attacker nearest to the ball: dribbles and kicks to the goal or a partner.
    Striker,
    /// Supports the striker from a nearby position.
    StrikerCover,
    /// Waits for a pass in a free position.
    PassReceiver,
    /// The defender nearest to the ball.
    ActiveDefender,
    /// A defender taking its defensive position.
    DefenderGoingToPosition,
}

impl Mission {
    pub const ALL: [Mission; 3] = [Mission::DefendTheGoal, Mission::Attack, Mission::Defend];

    pub fn code(self) -> u8 {
        self as u8
    }

    pub fn from_code(code: u8) -> Option<Mission> {
        Mission::ALL.get(usize::from(code)).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            Mission::DefendTheGoal => "defend the goal",
            Mission::Attack => "attack",
            Mission::Defend => "defend",
        }
    }
}

impl Role {
    pub const ALL: [Role; 6] = [
        Role::Goalie,
        Role::Striker,
        Role::StrikerCover,
        Role::PassReceiver,
        Role::ActiveDefender,
        Role::DefenderGoingToPosition,
    ];

    pub fn code(self) -> u8 {
        self as u8
    }

    pub fn from_code(code: u8) -> Option<Role> {
        Role::ALL.get(usize::from(code)).copied()
    }

    pub fn name(self) -> &'static str {
        match self {
            Role::Goalie => "goalie",
            Role::Striker => "striker",
            Role::StrikerCover => "striker cover",
            Role::PassReceiver => "pass receiver",
            Role::ActiveDefender => "active defender",
            Role::DefenderGoingToPosition => "defender going to position",
        }
    }
}

/// The goalkeeper's player number (SPL convention).
pub const GOALKEEPER_NUMBER: u8 = 1;

/// Table 1 as data. Field players without communication attack as strikers (paper 3.3).
pub fn catalog() -> MissionCatalog<Mission, Role> {
    MissionCatalog {
        missions: vec![
            MissionSpec {
                mission: Mission::DefendTheGoal,
                roles: vec![RoleSpec {
                    role: Role::Goalie,
                    max_robots: Some(1),
                    designated: Some(GOALKEEPER_NUMBER),
                }],
            },
            MissionSpec {
                mission: Mission::Attack,
                roles: vec![
                    RoleSpec { role: Role::Striker, max_robots: Some(1), designated: None },
                    RoleSpec { role: Role::StrikerCover, max_robots: Some(1), designated: None },
                    RoleSpec { role: Role::PassReceiver, max_robots: None, designated: None },
                ],
            },
            MissionSpec {
                mission: Mission::Defend,
                roles: vec![
                    RoleSpec { role: Role::ActiveDefender, max_robots: Some(1), designated: None },
                    RoleSpec {
                        role: Role::DefenderGoingToPosition,
                        max_robots: None,
                        designated: None,
                    },
                ],
            },
        ],
        default_mission: Mission::Attack,
        default_role: Role::Striker,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip() {
        for m in Mission::ALL {
            assert_eq!(Mission::from_code(m.code()), Some(m));
        }
        for r in Role::ALL {
            assert_eq!(Role::from_code(r.code()), Some(r));
        }
        assert_eq!(Role::from_code(6), None);
    }

    #[test]
    fn only_the_goalkeeper_may_be_goalie() {
        let c = catalog();
        let goalie = &c.mission(Mission::DefendTheGoal).expect("mission").roles[0];
        assert_eq!(goalie.designated, Some(GOALKEEPER_NUMBER));
        assert_eq!((c.default_mission, c.default_role), (Mission::Attack, Role::Striker));
    }
}
