//! Decoding what the monitor port streams (RSMP 1.0, every second cycle) into ground truth
//! for tests: the ball and robot poses and the game state.
//!
//! A message is `((RSMP 1 0)((gt 1 0)TIME)((sg 1 0)full|diff (nd …))((gs 1 0)…)((ge 1 0)…))`.
//! The scene graph (`sg`) is a tree of nodes: `(nd TRF (SLT m0 … m15) children…)` carries a
//! body's transform relative to its parent (the 4x4 matrix in column-major order, so the
//! translation is m12 m13 m14), `(nd DSC (ball) …)` and `(nd DSC (agent TEAM N) …)` label the
//! ball's and each robot's root body. A `full` graph has every node; a `diff` has the same tree
//! shape with only the transforms that moved by more than 0.005 in some element, and no labels.
//! The decoder therefore remembers, from the last full graph, where the labelled bodies sit in
//! the tree, and reads their transforms at the same place in each diff. The server sends a full
//! graph every 250 cycles, when a robot joins or leaves, and first to a new monitor.

use crate::protocol::ProtocolError;
use crate::protocol::game::PlayMode;
use crate::protocol::sexp::{self, Sexp};

type ColumnMajor = [f64; 16];

const IDENTITY: ColumnMajor =
    [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// The game state block (`gs`) of a monitor message.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MonitorGame {
    /// Play time, seconds.
    pub play_time: f64,
    /// 1 or 2.
    pub half: u32,
    /// Goals of the left team.
    pub score_left: u32,
    /// Goals of the right team.
    pub score_right: u32,
    /// The play mode, sent as an index into the server's list ([`PlayMode::ALL`]).
    pub play_mode: Option<PlayMode>,
    /// The left team's name (`<LEFT>` before one connected); only full messages carry it, the
    /// decoder keeps the last one.
    pub team_left: Option<String>,
    /// The right team's name, likewise.
    pub team_right: Option<String>,
}

/// Ground truth of one robot.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotTruth {
    /// Team name.
    pub team: String,
    /// Player number.
    pub player: u32,
    /// Position of its root body (the T1's torso, the same point as the `torso_pos`
    /// perceptor) in the world frame, metres, to 0.1 mm (changes under 5 mm may not be sent).
    pub position: [f64; 3],
    /// Orientation of its root body in the world frame, `[w, x, y, z]`.
    pub orientation: [f64; 4],
}

/// What the monitor stream says about the world, as of the last message decoded.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MonitorState {
    /// `gt`: the simulation clock, seconds (the perceptions' `time`, rounded to 0.01).
    pub sim_time: Option<f64>,
    /// `gs`: the game state.
    pub game: Option<MonitorGame>,
    /// The ball's centre in the world frame, metres, once a full scene graph was seen.
    pub ball_position: Option<[f64; 3]>,
    /// Every robot labelled in the last full scene graph.
    pub robots: Vec<RobotTruth>,
}

#[derive(Debug, Clone, PartialEq)]
enum Label {
    Ball,
    Robot { team: String, player: u32 },
}

/// A labelled body: where its transform node sits in the tree (indices among `nd` children,
/// from the root) and the last transform of every node on the way (`None` where a node has no
/// transform of its own).
#[derive(Debug, Clone)]
struct Tracked {
    label: Label,
    path: Vec<usize>,
    locals: Vec<Option<ColumnMajor>>,
}

/// Keeps the state of a monitor stream across full and diff messages.
#[derive(Debug, Clone, Default)]
pub struct MonitorDecoder {
    tracked: Vec<Tracked>,
    state: MonitorState,
}

fn malformed(reason: impl Into<String>) -> ProtocolError {
    ProtocolError::Monitor { reason: reason.into() }
}

fn number(text: &str, what: &str) -> Result<f64, ProtocolError> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(malformed(format!("{what} is {text:?}, not a finite number"))),
    }
}

/// The `nd` lists among a node's items.
fn nd_children<'s, 'a>(items: &'s [Sexp<'a>]) -> impl Iterator<Item = &'s [Sexp<'a>]> {
    items
        .iter()
        .filter_map(Sexp::as_list)
        .filter(|child| child.first().and_then(Sexp::as_atom) == Some("nd"))
}

/// The node's own transform, if it is a `TRF` node.
fn transform(node: &[Sexp<'_>]) -> Result<Option<ColumnMajor>, ProtocolError> {
    if node.get(1).and_then(Sexp::as_atom) != Some("TRF") {
        return Ok(None);
    }
    let slt = node
        .iter()
        .filter_map(Sexp::as_list)
        .find(|l| l.first().and_then(Sexp::as_atom) == Some("SLT"))
        .ok_or_else(|| malformed("a TRF node without SLT"))?;
    if slt.len() != 17 {
        return Err(malformed(format!("SLT with {} values, expected 16", slt.len() - 1)));
    }
    let mut m = [0.0; 16];
    for (slot, value) in m.iter_mut().zip(&slt[1..]) {
        let text = value.as_atom().ok_or_else(|| malformed("SLT holds a list"))?;
        *slot = number(text, "an SLT value")?;
    }
    Ok(Some(m))
}

fn multiply(a: &ColumnMajor, b: &ColumnMajor) -> ColumnMajor {
    let mut out = [0.0; 16];
    for c in 0..4 {
        for r in 0..4 {
            out[c * 4 + r] = (0..4).map(|k| a[k * 4 + r] * b[c * 4 + k]).sum();
        }
    }
    out
}

/// The rotation part of a column-major transform as a unit quaternion `[w, x, y, z]`.
fn quaternion(m: &ColumnMajor) -> [f64; 4] {
    let at = |r: usize, c: usize| m[c * 4 + r];
    let trace = at(0, 0) + at(1, 1) + at(2, 2);
    let q = if trace > 0.0 {
        let s = (trace + 1.0).sqrt() * 2.0;
        [0.25 * s, (at(2, 1) - at(1, 2)) / s, (at(0, 2) - at(2, 0)) / s, (at(1, 0) - at(0, 1)) / s]
    } else if at(0, 0) > at(1, 1) && at(0, 0) > at(2, 2) {
        let s = (1.0 + at(0, 0) - at(1, 1) - at(2, 2)).max(0.0).sqrt() * 2.0;
        [(at(2, 1) - at(1, 2)) / s, 0.25 * s, (at(0, 1) + at(1, 0)) / s, (at(0, 2) + at(2, 0)) / s]
    } else if at(1, 1) > at(2, 2) {
        let s = (1.0 + at(1, 1) - at(0, 0) - at(2, 2)).max(0.0).sqrt() * 2.0;
        [(at(0, 2) - at(2, 0)) / s, (at(0, 1) + at(1, 0)) / s, 0.25 * s, (at(1, 2) + at(2, 1)) / s]
    } else {
        let s = (1.0 + at(2, 2) - at(0, 0) - at(1, 1)).max(0.0).sqrt() * 2.0;
        [(at(1, 0) - at(0, 1)) / s, (at(0, 2) + at(2, 0)) / s, (at(1, 2) + at(2, 1)) / s, 0.25 * s]
    };
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if norm > 0.0 && norm.is_finite() { q.map(|v| v / norm) } else { [1.0, 0.0, 0.0, 0.0] }
}

fn label(node: &[Sexp<'_>]) -> Result<Option<Label>, ProtocolError> {
    if node.get(1).and_then(Sexp::as_atom) != Some("DSC") {
        return Ok(None);
    }
    for description in node.iter().skip(2).filter_map(Sexp::as_list) {
        match description {
            [Sexp::Atom("ball")] => return Ok(Some(Label::Ball)),
            [Sexp::Atom("agent"), Sexp::Atom(team), Sexp::Atom(player)] => {
                let player =
                    player.parse().map_err(|_| malformed(format!("agent number {player:?}")))?;
                return Ok(Some(Label::Robot { team: (*team).to_owned(), player }));
            }
            _ => {}
        }
    }
    Ok(None)
}

/// Walks a full scene graph and records every labelled body.
fn collect(
    node: &[Sexp<'_>],
    path: &mut Vec<usize>,
    locals: &mut Vec<Option<ColumnMajor>>,
    out: &mut Vec<Tracked>,
) -> Result<(), ProtocolError> {
    locals.push(transform(node)?);
    let labelled = label(node)?;
    for (index, child) in nd_children(node).enumerate() {
        path.push(index);
        if let Some(label) = &labelled {
            // The label's first child is the labelled body's own transform node.
            if index == 0 {
                let mut chain = locals.clone();
                chain.push(transform(child)?);
                out.push(Tracked { label: label.clone(), path: path.clone(), locals: chain });
            }
        }
        collect(child, path, locals, out)?;
        path.pop();
    }
    locals.pop();
    Ok(())
}

/// Follows `tracked.path` in a diff graph and takes every transform sent on the way.
fn refresh(root: &[Sexp<'_>], tracked: &mut Tracked) -> Result<(), ProtocolError> {
    let mut node = root;
    for depth in 0..=tracked.path.len() {
        if depth > 0 {
            let index = tracked.path[depth - 1];
            node = nd_children(node).nth(index).ok_or_else(|| {
                malformed("a diff scene graph does not have the shape of the last full one")
            })?;
        }
        if let Some(m) = transform(node)? {
            tracked.locals[depth] = Some(m);
        }
    }
    Ok(())
}

fn world(tracked: &Tracked) -> ColumnMajor {
    tracked.locals.iter().flatten().fold(IDENTITY, |acc, local| multiply(&acc, local))
}

fn field<'a>(items: &[Sexp<'a>], key: &str) -> Option<&'a str> {
    items.iter().filter_map(Sexp::as_list).find_map(|l| match l {
        [Sexp::Atom(k), Sexp::Atom(v)] if *k == key => Some(*v),
        _ => None,
    })
}

fn count(items: &[Sexp<'_>], key: &str) -> Result<u32, ProtocolError> {
    let text = field(items, key).ok_or_else(|| malformed(format!("gs without {key}")))?;
    text.parse().map_err(|_| malformed(format!("gs {key} is {text:?}, not a count")))
}

impl MonitorDecoder {
    /// A decoder that has seen nothing yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The state as of the last message decoded.
    pub fn state(&self) -> &MonitorState {
        &self.state
    }

    /// Decodes one monitor message (a frame's payload) and returns the updated state.
    pub fn decode(&mut self, message: &[u8]) -> Result<&MonitorState, ProtocolError> {
        let top = sexp::parse(message, sexp::MONITOR_MAX_DEPTH)?;
        let Some(blocks) = top.first().and_then(Sexp::as_list) else {
            return Err(malformed("not one list"));
        };
        for block in blocks.iter().filter_map(Sexp::as_list) {
            let Some(kind) = block.first().and_then(Sexp::head) else {
                continue;
            };
            match kind {
                "gt" => {
                    let text = block
                        .get(1)
                        .and_then(Sexp::as_atom)
                        .ok_or_else(|| malformed("gt without a time"))?;
                    self.state.sim_time = Some(number(text, "gt")?);
                }
                "gs" => self.game(&block[1..])?,
                "sg" => self.scene(&block[1..])?,
                _ => {}
            }
        }
        Ok(&self.state)
    }

    fn game(&mut self, items: &[Sexp<'_>]) -> Result<(), ProtocolError> {
        let play_time =
            number(field(items, "time").ok_or_else(|| malformed("gs without time"))?, "gs time")?;
        let previous = self.state.game.take().unwrap_or_default();
        let index = count(items, "play_mode")?;
        self.state.game = Some(MonitorGame {
            play_time,
            half: count(items, "half")?,
            score_left: count(items, "score_left")?,
            score_right: count(items, "score_right")?,
            play_mode: PlayMode::from_index(index as usize),
            team_left: field(items, "team_left").map(str::to_owned).or(previous.team_left),
            team_right: field(items, "team_right").map(str::to_owned).or(previous.team_right),
        });
        Ok(())
    }

    fn scene(&mut self, items: &[Sexp<'_>]) -> Result<(), ProtocolError> {
        let full = match items.first().and_then(Sexp::as_atom) {
            Some("full") => true,
            Some("diff") => false,
            _ => return Err(malformed("sg is neither full nor diff")),
        };
        let root = nd_children(items).next().ok_or_else(|| malformed("sg without a root node"))?;
        if full {
            let mut tracked = Vec::new();
            collect(root, &mut Vec::new(), &mut Vec::new(), &mut tracked)?;
            self.tracked = tracked;
        } else {
            for tracked in &mut self.tracked {
                refresh(root, tracked)?;
            }
        }
        self.state.ball_position = None;
        self.state.robots.clear();
        for tracked in &self.tracked {
            let m = world(tracked);
            let position = [m[12], m[13], m[14]];
            match &tracked.label {
                Label::Ball => self.state.ball_position = Some(position),
                Label::Robot { team, player } => self.state.robots.push(RobotTruth {
                    team: team.clone(),
                    player: *player,
                    position,
                    orientation: quaternion(&m),
                }),
            }
        }
        Ok(())
    }
}
