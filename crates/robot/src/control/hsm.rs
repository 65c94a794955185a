//! Hierarchical state machines: the deliberative layer's behaviors are organized as state
//! machines whose structure depends on the robot's role, and each state "can be structured as a
//! single behavior or as a behavior-tree" (paper 3.4). The other engine, the behavior tree, is
//! in [`super::bt`]; see there why we do not use `bonsai-bt` or `statig` (in short: `statig`'s
//! macro-generated machines cannot hold a runtime-built [`Tree`] as a state).
//!
//! States are identified by an application type `S` (usually an enum). Each state has an
//! optional parent, an initial child if it has children, on-enter and on-exit hooks, transitions
//! in priority order, and — if it is a leaf — a body: a behavior closure or a behavior [`Tree`].
//!
//! # Tick semantics
//!
//! These rules are a contract: `tests/tick_semantics.rs` checks each with a table and
//! `docs/tick-semantics.md` states the same. Changing one is a breaking change.
//!
//! The *active configuration* is a chain of states from a top-level state down to a leaf. One
//! [`StateMachine::tick`] does, in order:
//!
//! 1. **Start.** If the machine is not active (first tick, or after [`StateMachine::halt`]), it
//!    enters the initial state (from the top level down to it) and descends through initial
//!    children to a leaf, running on-enter hooks outermost first. This counts as the tick's
//!    transition: no guard is evaluated. Go to 4.
//! 2. **Select a transition.** The transitions of the active states are evaluated from the
//!    OUTERMOST active state to the innermost, and within a state in declaration order; the first
//!    guard that holds fires. Outer first, so that a global condition declared on a parent ("the
//!    robot fell") preempts whatever its children would do. A guard sees the context and the
//!    status the active leaf's body returned on the previous tick.
//! 3. **Take it.** Let `T` be the target and `D` the deepest active state that is a proper
//!    ancestor of `T` (none if `T` is a top-level state): the active states below `D` are exited
//!    innermost first — for each, its behavior tree is halted (if running) and then its on-exit
//!    hook runs — and the states from below `D` down to `T` are entered outermost first, then
//!    initial children down to a leaf, running on-enter hooks. Consequences: a self-transition
//!    exits and re-enters its state; a transition to an active ancestor re-enters that ancestor
//!    and descends to its initial leaf; states above `D` are neither exited nor entered. The
//!    result depends only on the active configuration and the target, not on which state
//!    declared the transition (that only sets its priority).
//! 4. **Tick the body** of the active leaf, in the same tick, so a transition's target acts
//!    immediately. Only the leaf has a body: composite states structure the machine and act
//!    through their hooks (a body on a composite state is a build error, rather than a body
//!    that silently never runs). A leaf without a body returns `Running` (it waits for a
//!    transition). A finished tree body that no transition leaves is started anew on the next
//!    tick.
//!
//! At most one transition fires per tick. A transition whose guard already holds in the new
//! configuration fires on the next tick, not in a chain within this one: a tick has bounded
//! work, and two states whose guards point at each other alternate tick by tick instead of
//! livelocking the layer.
//!
//! [`StateMachine::halt`] exits the whole active configuration as a transition would (trees
//! halted, on-exit hooks innermost first); the next tick starts again at the initial state.
//!
//! The builder rejects, naming the state: duplicate states, unknown parents, cycles in the
//! hierarchy, an initial child that is not a child, a composite state without an initial child,
//! a body on a composite state, an unknown transition target, and a missing or unknown initial
//! state of the machine. In the steady state a tick allocates nothing.
//!
//! # Example
//!
//! ```
//! use strata_robot::control::bt::{Status, Tree, action};
//! use strata_robot::control::hsm::{State, StateMachine};
//! use strata_runtime::Time;
//!
//! #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
//! enum Goalie { Playing, Covering, Clearing, Fallen }
//!
//! struct World { fallen: bool, ball_close: bool }
//!
//! let mut machine = StateMachine::builder()
//!     .initial(Goalie::Playing)
//!     .state(
//!         State::new(Goalie::Playing)
//!             .name("Goalie playing")
//!             .initial_child(Goalie::Covering)
//!             .transition(|w: &World, _| w.fallen, Goalie::Fallen),
//!     )
//!     .state(
//!         State::new(Goalie::Covering)
//!             .name("Goal covering")
//!             .parent(Goalie::Playing)
//!             .tree(Tree::new(action("observe", |_: &mut World, _| Status::Running)))
//!             .transition(|w: &World, _| w.ball_close, Goalie::Clearing),
//!     )
//!     .state(
//!         State::new(Goalie::Clearing)
//!             .parent(Goalie::Playing)
//!             .behavior(|_: &mut World, _| Status::Success)
//!             .transition(|_, status| status == Status::Success, Goalie::Covering),
//!     )
//!     .state(State::new(Goalie::Fallen).transition(|w: &World, _| !w.fallen, Goalie::Playing))
//!     .build()?;
//!
//! let mut world = World { fallen: false, ball_close: false };
//! machine.tick(&mut world, Time::ZERO);
//! assert_eq!(machine.active_path(), "Goalie playing/Goal covering/observe");
//! world.fallen = true;
//! machine.tick(&mut world, Time::from_secs_f64(0.5));
//! assert_eq!(machine.active_leaf(), Some(Goalie::Fallen));
//! # Ok::<(), strata_robot::control::hsm::BuildError<Goalie>>(())
//! ```

use std::borrow::Cow;
use std::collections::HashMap;
use std::fmt::{self, Debug};
use std::hash::Hash;

use strata_runtime::Time;
use thiserror::Error;

use super::bt::{Status, Tree};

type Hook<C> = Box<dyn FnMut(&mut C, Time) + Send>;
type Guard<C> = Box<dyn Fn(&C, Status) -> bool + Send>;
type Behavior<C> = Box<dyn FnMut(&mut C, Time) -> Status + Send>;

/// What a leaf state does while it is active.
enum Body<C> {
    /// Nothing: the state waits for a transition.
    Idle,
    Behavior(Behavior<C>),
    Tree(Tree<C>),
}

struct Transition<T, C> {
    guard: Guard<C>,
    target: T,
}

/// The definition of one state, given to [`Builder::state`].
pub struct State<S, C> {
    id: S,
    name: Option<Cow<'static, str>>,
    parent: Option<S>,
    initial: Option<S>,
    on_enter: Option<Hook<C>>,
    on_exit: Option<Hook<C>>,
    body: Body<C>,
    transitions: Vec<Transition<S, C>>,
}

impl<S: Debug, C> State<S, C> {
    /// A top-level leaf state without body, hooks or transitions.
    pub fn new(id: S) -> State<S, C> {
        State {
            id,
            name: None,
            parent: None,
            initial: None,
            on_enter: None,
            on_exit: None,
            body: Body::Idle,
            transitions: Vec::new(),
        }
    }

    /// The name in the active path; defaults to the `Debug` form of the state.
    pub fn name(mut self, name: impl Into<Cow<'static, str>>) -> Self {
        self.name = Some(name.into());
        self
    }

    /// Makes this state a child of `parent`.
    pub fn parent(mut self, parent: S) -> Self {
        self.parent = Some(parent);
        self
    }

    /// The child entered when this (composite) state is entered. Required for a state with
    /// children.
    pub fn initial_child(mut self, child: S) -> Self {
        self.initial = Some(child);
        self
    }

    /// Runs when the state is entered, after its parent's on-enter hook.
    pub fn on_enter(mut self, hook: impl FnMut(&mut C, Time) + Send + 'static) -> Self {
        self.on_enter = Some(Box::new(hook));
        self
    }

    /// Runs when the state is exited, after its children's on-exit hooks and after its tree was
    /// halted.
    pub fn on_exit(mut self, hook: impl FnMut(&mut C, Time) + Send + 'static) -> Self {
        self.on_exit = Some(Box::new(hook));
        self
    }

    /// Makes the state's body a single behavior, ticked while the state is the active leaf.
    /// Replaces any previous body.
    pub fn behavior(
        mut self,
        behavior: impl FnMut(&mut C, Time) -> Status + Send + 'static,
    ) -> Self {
        self.body = Body::Behavior(Box::new(behavior));
        self
    }

    /// Makes the state's body a behavior tree, ticked while the state is the active leaf and
    /// halted when the state is exited. Replaces any previous body.
    pub fn tree(mut self, tree: Tree<C>) -> Self {
        self.body = Body::Tree(tree);
        self
    }

    /// Adds a transition to `target`, taken when `guard` holds while this state is active. The
    /// guard sees the context and the status the active leaf's body returned on the previous
    /// tick. Transitions of one state have priority in the order they are added.
    pub fn transition(
        mut self,
        guard: impl Fn(&C, Status) -> bool + Send + 'static,
        target: S,
    ) -> Self {
        self.transitions.push(Transition { guard: Box::new(guard), target });
        self
    }
}

impl<S: Debug, C> Debug for State<S, C> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("State")
            .field("id", &self.id)
            .field("name", &self.name)
            .field("parent", &self.parent)
            .field("initial", &self.initial)
            .field("transitions", &self.transitions.iter().map(|t| &t.target).collect::<Vec<_>>())
            .finish_non_exhaustive()
    }
}

/// Why a state machine could not be built. Each names the offending state.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum BuildError<S: Debug> {
    /// Two definitions of one state.
    #[error("state {0:?} is defined twice")]
    DuplicateState(S),
    #[error("state {state:?} has parent {parent:?}, which is not defined")]
    UnknownParent { state: S, parent: S },
    /// A state on a cycle of parents (a state that is its own parent included).
    #[error("state {0:?} is its own ancestor (a cycle in the hierarchy)")]
    HierarchyCycle(S),
    /// The initial child is not defined, or not a direct child of the state.
    #[error("state {state:?} has initial child {initial:?}, which is not one of its children")]
    InitialNotChild { state: S, initial: S },
    #[error("state {0:?} has children but no initial child")]
    MissingInitialChild(S),
    /// Only leaf states have bodies: a composite state's body would never run.
    #[error("state {0:?} has children and a body; only leaf states have bodies")]
    BodyOnComposite(S),
    #[error("state {state:?} has a transition to {target:?}, which is not defined")]
    UnknownTarget { state: S, target: S },
    #[error("the machine has no initial state")]
    NoInitialState,
    #[error("the machine's initial state {0:?} is not defined")]
    UnknownInitialState(S),
}

/// Collects state definitions; [`Builder::build`] validates them.
pub struct Builder<S, C> {
    states: Vec<State<S, C>>,
    initial: Option<S>,
}

impl<S, C> Builder<S, C>
where
    S: Copy + Eq + Hash + Debug,
{
    /// Adds a state.
    pub fn state(mut self, state: State<S, C>) -> Self {
        self.states.push(state);
        self
    }

    /// The state the machine starts in (any state; if composite, the machine descends through
    /// initial children).
    pub fn initial(mut self, state: S) -> Self {
        self.initial = Some(state);
        self
    }

    /// Validates the definitions. Checks run in the order of [`BuildError`]'s variants, each
    /// over the states in the order they were added; the first problem found is returned.
    pub fn build(self) -> Result<StateMachine<S, C>, BuildError<S>> {
        let mut index = HashMap::with_capacity(self.states.len());
        for (i, state) in self.states.iter().enumerate() {
            if index.insert(state.id, i).is_some() {
                return Err(BuildError::DuplicateState(state.id));
            }
        }
        let mut parents = Vec::with_capacity(self.states.len());
        for state in &self.states {
            parents.push(match state.parent {
                None => None,
                Some(parent) => match index.get(&parent) {
                    Some(&p) => Some(p),
                    None => return Err(BuildError::UnknownParent { state: state.id, parent }),
                },
            });
        }
        // Every cycle contains a state that reaches itself within n parent steps, so checking
        // each state in order finds one on the cycle.
        let n = self.states.len();
        for (i, state) in self.states.iter().enumerate() {
            let mut current = parents[i];
            for _ in 0..n {
                match current {
                    Some(p) if p == i => return Err(BuildError::HierarchyCycle(state.id)),
                    Some(p) => current = parents[p],
                    None => break,
                }
            }
        }
        let mut has_children = vec![false; n];
        for parent in parents.iter().flatten() {
            has_children[*parent] = true;
        }
        let mut initials = Vec::with_capacity(n);
        for (i, state) in self.states.iter().enumerate() {
            initials.push(match state.initial {
                Some(initial) => match index.get(&initial) {
                    Some(&c) if parents[c] == Some(i) => Some(c),
                    _ => return Err(BuildError::InitialNotChild { state: state.id, initial }),
                },
                None if has_children[i] => return Err(BuildError::MissingInitialChild(state.id)),
                None => None,
            });
        }
        for (i, state) in self.states.iter().enumerate() {
            if has_children[i] && !matches!(state.body, Body::Idle) {
                return Err(BuildError::BodyOnComposite(state.id));
            }
        }
        for state in &self.states {
            for transition in &state.transitions {
                if !index.contains_key(&transition.target) {
                    return Err(BuildError::UnknownTarget {
                        state: state.id,
                        target: transition.target,
                    });
                }
            }
        }
        let initial = self.initial.ok_or(BuildError::NoInitialState)?;
        let initial = *index.get(&initial).ok_or(BuildError::UnknownInitialState(initial))?;

        let depth_of = |mut i: usize| {
            let mut depth = 1;
            while let Some(p) = parents[i] {
                depth += 1;
                i = p;
            }
            depth
        };
        let max_depth = (0..n).map(depth_of).max().unwrap_or(0);

        let states = self
            .states
            .into_iter()
            .enumerate()
            .map(|(i, state)| StateData {
                name: state.name.unwrap_or_else(|| Cow::Owned(format!("{:?}", state.id))),
                id: state.id,
                parent: parents[i],
                initial: initials[i],
                on_enter: state.on_enter,
                on_exit: state.on_exit,
                body: state.body,
                transitions: state
                    .transitions
                    .into_iter()
                    .map(|t| Transition { guard: t.guard, target: index[&t.target] })
                    .collect(),
                entered_at: None,
            })
            .collect();
        Ok(StateMachine {
            states,
            index,
            initial,
            active: Vec::with_capacity(max_depth),
            scratch: Vec::with_capacity(max_depth),
            last_status: None,
        })
    }
}

impl<S: Debug, C> Debug for Builder<S, C> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Builder")
            .field("states", &self.states)
            .field("initial", &self.initial)
            .finish()
    }
}

struct StateData<S, C> {
    id: S,
    name: Cow<'static, str>,
    parent: Option<usize>,
    initial: Option<usize>,
    on_enter: Option<Hook<C>>,
    on_exit: Option<Hook<C>>,
    body: Body<C>,
    /// Targets resolved to indices at build time, so a tick never hashes.
    transitions: Vec<Transition<usize, C>>,
    entered_at: Option<Time>,
}

/// A transition that fired.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Fired<S> {
    /// The state that declared the transition.
    pub source: S,
    /// The state the transition led to (the active leaf may be one of its descendants).
    pub target: S,
}

/// What one tick did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TickResult<S> {
    /// The machine entered its initial configuration in this tick.
    pub started: bool,
    /// The transition taken in this tick, if any.
    pub fired: Option<Fired<S>>,
    /// What the active leaf's body returned.
    pub status: Status,
}

/// A hierarchical state machine over a context `C` (see the module documentation).
pub struct StateMachine<S, C> {
    states: Vec<StateData<S, C>>,
    index: HashMap<S, usize>,
    initial: usize,
    /// Indices of the active states, outermost first.
    active: Vec<usize>,
    /// Reused for the target's ancestry so that transitions do not allocate.
    scratch: Vec<usize>,
    last_status: Option<Status>,
}

impl<S, C> StateMachine<S, C>
where
    S: Copy + Eq + Hash + Debug,
{
    /// Starts the definition of a machine.
    pub fn builder() -> Builder<S, C> {
        Builder { states: Vec::new(), initial: None }
    }

    /// One tick: start or take at most one transition, then tick the active leaf's body.
    pub fn tick(&mut self, ctx: &mut C, now: Time) -> TickResult<S> {
        let mut result = TickResult { started: false, fired: None, status: Status::Running };
        if self.active.is_empty() {
            self.enter_configuration(ctx, now, self.initial);
            result.started = true;
        } else if let Some((source, target)) = self.select_transition(ctx) {
            self.enter_configuration(ctx, now, target);
            result.fired =
                Some(Fired { source: self.states[source].id, target: self.states[target].id });
        }
        if let Some(&leaf) = self.active.last() {
            result.status = match &mut self.states[leaf].body {
                Body::Idle => Status::Running,
                Body::Behavior(behavior) => behavior(ctx, now),
                Body::Tree(tree) => tree.tick(ctx, now),
            };
        }
        self.last_status = Some(result.status);
        result
    }

    /// Exits every active state (trees halted, on-exit hooks innermost first). The next tick
    /// starts again at the initial state. Does nothing if the machine is not active.
    pub fn halt(&mut self, ctx: &mut C, now: Time) {
        self.exit_to_depth(ctx, now, 0);
        self.last_status = None;
    }

    /// Whether the machine has started and not been halted.
    pub fn is_active(&self) -> bool {
        !self.active.is_empty()
    }

    /// The active leaf state.
    pub fn active_leaf(&self) -> Option<S> {
        self.active.last().map(|&i| self.states[i].id)
    }

    /// The active states, outermost first.
    pub fn active_states(&self) -> impl Iterator<Item = S> + '_ {
        self.active.iter().map(|&i| self.states[i].id)
    }

    /// Whether `state` is in the active configuration (as the leaf or an ancestor of it).
    pub fn is_in(&self, state: S) -> bool {
        self.index.get(&state).is_some_and(|i| self.active.contains(i))
    }

    /// When `state` was last entered, if it is active.
    pub fn entered_at(&self, state: S) -> Option<Time> {
        self.states[*self.index.get(&state)?].entered_at
    }

    /// What the active leaf's body returned on the last tick.
    pub fn last_status(&self) -> Option<Status> {
        self.last_status
    }

    /// The name of a state in the active path.
    pub fn state_name(&self, state: S) -> Option<&str> {
        Some(&self.states[*self.index.get(&state)?].name)
    }

    /// The behavior tree of `state`, if its body is one.
    pub fn tree(&self, state: S) -> Option<&Tree<C>> {
        match &self.states[*self.index.get(&state)?].body {
            Body::Tree(tree) => Some(tree),
            _ => None,
        }
    }

    /// Writes the active path — the active states' names, outermost first, then the active
    /// path of the leaf's tree, separated by `/` — without allocating. Empty if not active.
    pub fn write_active_path(&self, out: &mut impl fmt::Write) -> fmt::Result {
        for (depth, &i) in self.active.iter().enumerate() {
            if depth > 0 {
                out.write_char('/')?;
            }
            out.write_str(&self.states[i].name)?;
        }
        if let Some(&leaf) = self.active.last()
            && let Body::Tree(tree) = &self.states[leaf].body
        {
            out.write_char('/')?;
            tree.write_active_path(out)?;
        }
        Ok(())
    }

    /// The active path, e.g. `Goalie playing/Goal covering/observe`.
    pub fn active_path(&self) -> String {
        let mut path = String::new();
        // Writing to a String cannot fail.
        let _ = self.write_active_path(&mut path);
        path
    }

    /// The first transition whose guard holds, outermost active state first: (declaring state,
    /// target), as indices.
    fn select_transition(&self, ctx: &C) -> Option<(usize, usize)> {
        let status = self.last_status.unwrap_or(Status::Running);
        self.active.iter().find_map(|&source| {
            self.states[source]
                .transitions
                .iter()
                .find(|t| (t.guard)(ctx, status))
                .map(|t| (source, t.target))
        })
    }

    /// Moves the active configuration to `target` (step 3 of the module documentation; with
    /// nothing active, this is the start).
    fn enter_configuration(&mut self, ctx: &mut C, now: Time, target: usize) {
        let mut path = std::mem::take(&mut self.scratch);
        path.clear();
        let mut state = Some(target);
        while let Some(i) = state {
            path.push(i);
            state = self.states[i].parent;
        }
        path.reverse();
        let shared = self.active.iter().zip(&path).take_while(|(a, b)| a == b).count();
        // The target itself is always exited and entered again: a self-transition re-enters.
        let keep = shared.min(path.len() - 1);
        self.exit_to_depth(ctx, now, keep);
        for &i in &path[keep..] {
            self.enter(ctx, now, i);
        }
        let mut current = target;
        while let Some(child) = self.states[current].initial {
            self.enter(ctx, now, child);
            current = child;
        }
        self.scratch = path;
        self.last_status = None;
    }

    fn enter(&mut self, ctx: &mut C, now: Time, i: usize) {
        self.active.push(i);
        let state = &mut self.states[i];
        state.entered_at = Some(now);
        if let Some(hook) = &mut state.on_enter {
            hook(ctx, now);
        }
    }

    fn exit_to_depth(&mut self, ctx: &mut C, now: Time, depth: usize) {
        while self.active.len() > depth {
            let Some(i) = self.active.pop() else { break };
            let state = &mut self.states[i];
            if let Body::Tree(tree) = &mut state.body {
                tree.halt(ctx);
            }
            if let Some(hook) = &mut state.on_exit {
                hook(ctx, now);
            }
            state.entered_at = None;
        }
    }
}

impl<S: Debug, C> Debug for StateMachine<S, C> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("StateMachine")
            .field("states", &self.states.iter().map(|s| &s.id).collect::<Vec<_>>())
            .field("active", &self.active.iter().map(|&i| &self.states[i].id).collect::<Vec<_>>())
            .field("last_status", &self.last_status)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    enum S {
        A,
        B,
    }

    #[test]
    fn default_names_are_the_debug_form() {
        let mut machine = StateMachine::<S, ()>::builder()
            .initial(S::A)
            .state(State::new(S::A).initial_child(S::B))
            .state(State::new(S::B).parent(S::A))
            .build()
            .expect("valid machine");
        assert_eq!(machine.active_path(), "");
        let result = machine.tick(&mut (), Time::ZERO);
        assert!(result.started);
        assert_eq!(result.status, Status::Running);
        assert_eq!(machine.active_path(), "A/B");
        assert_eq!(machine.state_name(S::B), Some("B"));
        assert_eq!(machine.entered_at(S::A), Some(Time::ZERO));
    }

    #[test]
    fn halt_then_restart() {
        let mut machine = StateMachine::<S, u32>::builder()
            .initial(S::A)
            .state(State::new(S::A).on_exit(|n: &mut u32, _| *n += 1))
            .state(State::new(S::B))
            .build()
            .expect("valid machine");
        let mut exits = 0;
        machine.halt(&mut exits, Time::ZERO);
        assert_eq!(exits, 0);
        machine.tick(&mut exits, Time::ZERO);
        machine.halt(&mut exits, Time::ZERO);
        assert_eq!(exits, 1);
        assert!(!machine.is_active());
        assert!(machine.tick(&mut exits, Time::ZERO).started);
    }
}
