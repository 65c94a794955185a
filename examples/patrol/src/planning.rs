//! The planning layer's patrol knowledge (paper 3.2–3.3): the missions and roles (the patrol's
//! Table 1), which mission the team pursues (MAMS: the operator's alarm decides), how well each
//! robot would fill each role (ARS: the responder is the robot with the shortest walk to the
//! alarm, on the floor plan's roadmap), and the team message codec.
//!
//! | mission | roles |
//! |---|---|
//! | Patrol: walk the beats, inspect the points of interest | Patroller (any number) |
//! | Respond: go to the alarm and watch what is there | Responder (one robot), Patroller (the others keep their beats) |

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use strata_robot::control::planning::{
    Candidate, MissionCatalog, MissionSpec, OwnState, PlanningPolicy, RoleSpec, SharedObject,
    StandingStatus, TeamMessage, TeammateRecord,
};
use strata_robot::control::planning_module::TeamCodec;
use strata_robot::geometry::{Point, Pose};

use crate::building::FloorPlan;
use crate::console::{AlarmBoard, read_board};
use crate::world_config::INTRUDER;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mission {
    Patrol,
    Respond,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Patroller,
    Responder,
}

/// The missions and roles, as data.
pub fn catalog() -> MissionCatalog<Mission, Role> {
    let role = |role, max_robots| RoleSpec { role, max_robots, designated: None };
    MissionCatalog {
        missions: vec![
            MissionSpec { mission: Mission::Patrol, roles: vec![role(Role::Patroller, None)] },
            MissionSpec {
                mission: Mission::Respond,
                roles: vec![role(Role::Responder, Some(1)), role(Role::Patroller, None)],
            },
        ],
        // Without teammates a robot patrols; its deliberative layer still answers an alarm on
        // its own (a robot that loses the network loses no ability of its own).
        default_mission: Mission::Patrol,
        default_role: Role::Patroller,
    }
}

/// The patrol's planning policy.
#[derive(Debug)]
pub struct PatrolPlanning {
    catalog: MissionCatalog<Mission, Role>,
    plan: Arc<FloorPlan>,
    board: AlarmBoard,
}

impl PatrolPlanning {
    pub fn new(plan: Arc<FloorPlan>, board: AlarmBoard) -> PatrolPlanning {
        PatrolPlanning { catalog: catalog(), plan, board }
    }
}

impl PlanningPolicy for PatrolPlanning {
    type Mission = Mission;
    type Role = Role;

    fn catalog(&self) -> &MissionCatalog<Mission, Role> {
        &self.catalog
    }

    fn select_mission(
        &self,
        _own: &OwnState,
        _held: Option<(Mission, Role)>,
        _teammates: &[&TeammateRecord<Mission, Role>],
    ) -> Mission {
        if read_board(&self.board).is_some() { Mission::Respond } else { Mission::Patrol }
    }

    fn role_utility(&self, candidate: &Candidate<'_>, role: Role, _mission: Mission) -> f64 {
        match (role, read_board(&self.board)) {
            // Every robot measures every candidate on the same plan from the same shared
            // poses: they agree on who is nearest without a leader.
            (Role::Responder, Some(alarm)) => {
                -self.plan.path_length(candidate.pose.position(), alarm.point).min(1e3)
            }
            _ => 0.0,
        }
    }

    fn instant_worthy(&self, previous: &OwnState, current: &OwnState) -> bool {
        // Sighting an intruder (or losing it) is news for the team now, not in two seconds.
        let sees = |s: &OwnState| s.objects.iter().any(|o| o.name == INTRUDER && o.age < 1.0);
        sees(previous) != sees(current)
    }
}

/// Why a team message was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CodecError {
    #[error("message of {0} bytes is too short")]
    Truncated(usize),
    #[error("not a patrol team message")]
    Header,
    #[error("unknown {what} code {code}")]
    Code { what: &'static str, code: u8 },
    #[error("{0} is not a finite number")]
    NotFinite(&'static str),
    #[error("{0} trailing bytes")]
    Trailing(usize),
}

/// The Fig. 2 message in 29 bytes (45 with the intruder): internal state (mission, role, status, flags),
/// basic communication information, the pose and the shared objects (the intruder).
#[derive(Debug, Clone, Copy, Default)]
pub struct PatrolCodec;

/// The objects a patrol robot may share, by code.
const SHARED: [&str; 1] = [INTRUDER];

const MAGIC: [u8; 3] = [b'P', b'T', 1];
const FIXED: usize = 3 + 6 + 2 + 4 + 12 + 1 + 1;
const OBJECT: usize = 1 + 8 + 4 + 1 + 2;

fn f32s(out: &mut Vec<u8>, v: f64) {
    out.extend((v as f32).to_le_bytes());
}

/// Seconds in tenths, saturating (65535: never or longer than 1.8 hours).
fn tenths(v: f64) -> u16 {
    if v.is_finite() { (v * 10.0).round().clamp(0.0, 65535.0) as u16 } else { u16::MAX }
}

fn from_tenths(v: u16) -> f64 {
    if v == u16::MAX { f64::INFINITY } else { f64::from(v) / 10.0 }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], CodecError> {
        let chunk =
            self.bytes.get(self.at..self.at + N).ok_or(CodecError::Truncated(self.bytes.len()))?;
        self.at += N;
        let mut out = [0; N];
        out.copy_from_slice(chunk);
        Ok(out)
    }

    fn u8(&mut self) -> Result<u8, CodecError> {
        Ok(self.take::<1>()?[0])
    }

    fn f32(&mut self, what: &'static str) -> Result<f64, CodecError> {
        let v = f64::from(f32::from_le_bytes(self.take()?));
        if v.is_finite() { Ok(v) } else { Err(CodecError::NotFinite(what)) }
    }

    fn u16(&mut self) -> Result<u16, CodecError> {
        Ok(u16::from_le_bytes(self.take()?))
    }
}

fn unit(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

impl TeamCodec<Mission, Role> for PatrolCodec {
    fn encode(&self, m: &TeamMessage<Mission, Role>) -> Result<Vec<u8>, String> {
        let mut out = Vec::with_capacity(FIXED + OBJECT);
        out.extend(MAGIC);
        out.push(m.sender);
        out.push(m.mission as u8);
        out.push(m.role as u8);
        out.push(m.status as u8);
        out.push(
            u8::from(m.penalized)
                | (u8::from(m.localized) << 1)
                | (u8::from(m.data_received) << 2)
                | (u8::from(m.conflict) << 3),
        );
        out.push(0); // reserved
        out.extend(tenths(m.since_last_received).to_le_bytes());
        f32s(&mut out, m.utility);
        f32s(&mut out, m.pose.x);
        f32s(&mut out, m.pose.y);
        f32s(&mut out, m.pose.theta);
        out.push(unit(m.pose_confidence));
        let objects: Vec<(u8, &SharedObject)> = m
            .objects
            .iter()
            .filter_map(|o| SHARED.iter().position(|n| *n == o.name).map(|i| (i as u8, o)))
            .collect();
        out.push(objects.len() as u8);
        for (code, o) in objects {
            out.push(code);
            f32s(&mut out, o.position.x);
            f32s(&mut out, o.position.y);
            f32s(&mut out, o.sigma);
            out.push(unit(o.confidence));
            out.extend(tenths(o.age).to_le_bytes());
        }
        Ok(out)
    }

    fn decode(&self, bytes: &[u8]) -> Result<TeamMessage<Mission, Role>, String> {
        decode(bytes).map_err(|e| e.to_string())
    }
}

fn decode(bytes: &[u8]) -> Result<TeamMessage<Mission, Role>, CodecError> {
    if bytes.len() < FIXED {
        return Err(CodecError::Truncated(bytes.len()));
    }
    if bytes[..3] != MAGIC {
        return Err(CodecError::Header);
    }
    let mut r = Reader { bytes, at: 3 };
    let sender = r.u8()?;
    let mission = match r.u8()? {
        0 => Mission::Patrol,
        1 => Mission::Respond,
        code => return Err(CodecError::Code { what: "mission", code }),
    };
    let role = match r.u8()? {
        0 => Role::Patroller,
        1 => Role::Responder,
        code => return Err(CodecError::Code { what: "role", code }),
    };
    let status = match r.u8()? {
        0 => StandingStatus::Stable,
        1 => StandingStatus::Unstable,
        2 => StandingStatus::Fallen,
        code => return Err(CodecError::Code { what: "status", code }),
    };
    let flags = r.u8()?;
    let _reserved = r.u8()?;
    let since_last_received = from_tenths(r.u16()?);
    let utility = r.f32("utility")?;
    let pose = Pose::new(r.f32("pose.x")?, r.f32("pose.y")?, r.f32("pose.theta")?);
    let pose_confidence = f64::from(r.u8()?) / 255.0;
    let count = r.u8()?;
    let mut objects = Vec::with_capacity(usize::from(count));
    for _ in 0..count {
        let code = r.u8()?;
        let name =
            SHARED.get(usize::from(code)).ok_or(CodecError::Code { what: "object", code })?;
        let position = Point::new(r.f32("object.x")?, r.f32("object.y")?);
        let sigma = r.f32("object.sigma")?;
        let confidence = f64::from(r.u8()?) / 255.0;
        let age = from_tenths(r.u16()?);
        objects.push(SharedObject { name: (*name).to_owned(), position, sigma, confidence, age });
    }
    if r.at != bytes.len() {
        return Err(CodecError::Trailing(bytes.len() - r.at));
    }
    Ok(TeamMessage {
        sender,
        mission,
        role,
        status,
        penalized: flags & 1 != 0,
        localized: flags & 2 != 0,
        since_last_received,
        data_received: flags & 4 != 0,
        utility,
        conflict: flags & 8 != 0,
        pose,
        pose_confidence,
        objects,
        // Patrols follow no referee.
        signal: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message() -> TeamMessage<Mission, Role> {
        TeamMessage {
            sender: 2,
            mission: Mission::Respond,
            role: Role::Responder,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            since_last_received: 1.5,
            data_received: true,
            utility: -7.25,
            conflict: false,
            pose: Pose::new(1.5, -2.25, 0.5),
            pose_confidence: 1.0,
            objects: vec![SharedObject {
                name: INTRUDER.into(),
                position: Point::new(-5.25, 3.0),
                sigma: 0.25,
                confidence: 0.0,
                age: 0.5,
            }],
            signal: None,
        }
    }

    #[test]
    fn the_message_round_trips_and_malformed_ones_are_refused() {
        let m = message();
        let bytes = PatrolCodec.encode(&m).expect("encodes");
        assert_eq!(bytes.len(), FIXED + OBJECT);
        let back = PatrolCodec.decode(&bytes).expect("decodes");
        assert_eq!(back.role, Role::Responder);
        assert_eq!(back.objects[0].name, INTRUDER);
        assert!((back.pose.theta - 0.5).abs() < 1e-6 && (back.utility + 7.25).abs() < 1e-6);
        for cut in 0..bytes.len() {
            assert!(PatrolCodec.decode(&bytes[..cut]).is_err(), "truncated at {cut}");
        }
        let mut bad = bytes.clone();
        bad[4] = 9;
        assert_eq!(decode(&bad).map(|_| ()), Err(CodecError::Code { what: "mission", code: 9 }));
        let mut nan = bytes.clone();
        nan[11..15].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(decode(&nan).map(|_| ()), Err(CodecError::NotFinite("utility")));
    }

    #[test]
    fn the_responder_is_the_robot_with_the_shorter_walk_round_the_walls() {
        let plan = Arc::new(FloorPlan::office());
        let board: AlarmBoard = Default::default();
        let policy = PatrolPlanning::new(Arc::clone(&plan), board.clone());
        let own = OwnState {
            id: 1,
            status: StandingStatus::Stable,
            penalized: false,
            localized: true,
            pose: Pose::default(),
            pose_confidence: 1.0,
            objects: Vec::new(),
        };
        assert_eq!(policy.select_mission(&own, None, &[]), Mission::Patrol);
        *board.lock().expect("board") =
            Some(crate::console::Alarm { id: 1, point: Point::new(-4.0, 2.5) });
        assert_eq!(policy.select_mission(&own, None, &[]), Mission::Respond);
        let north = Candidate { id: 1, pose: Pose::new(4.0, 2.0, 0.0), objects: &[] };
        // Closer as the crow flies, but on the other side of the dividing wall.
        let south = Candidate { id: 2, pose: Pose::new(-4.0, -1.0, 0.0), objects: &[] };
        let u = |c: &Candidate<'_>| policy.role_utility(c, Role::Responder, Mission::Respond);
        assert!(u(&north) > u(&south), "{} {}", u(&north), u(&south));
    }
}
