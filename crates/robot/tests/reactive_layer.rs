//! The reactive layer, tabulated: multiplexer selection, stage-1 splitting, score combination,
//! deactivation, inhibition across resource groups, and the fall reflex.

use serde::{Deserialize, Serialize};
use strata_robot::command::{
    BodyCommand, BodyMotion, HeadCommand, HeadMotion, MotionCommands, ResourceGroup,
    WholeBodyCommand,
};
use strata_robot::control::reactive::{
    ActivationPolicy, ActivationShortcuts, FallDetectorConfig, Multiplexer, MultiplexerConfig,
    PrimitiveBehavior, ReactiveInput, ReactiveLayer, Stability,
};
use strata_robot::control::scores::{Goal, GoalScore, NoGoal, ScoreCombination, ScoreVector};
use strata_robot::geometry::Velocity;
use strata_robot::percept::Percepts;
use strata_robot::platform::{HeadAngles, MotionName, SpecialMotion};
use strata_runtime::Time;

/// A toy world: how confident the robot is about each object, and their bearings.
#[derive(Clone, Debug, Default)]
struct World {
    confidence: Vec<(&'static str, f64, f64)>,
    target_close: bool,
}

impl World {
    fn object(&self, name: &str) -> Option<(f64, f64)> {
        self.confidence.iter().find(|(n, _, _)| *n == name).map(|(_, c, b)| (*c, *b))
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
enum HeadGoal {
    Observe(String),
    /// Two objects in one gaze if they fit.
    ObserveBoth(String, String),
}

strata_robot::primitive_ids! {
    enum HeadPrimitive {
        Track => "track",
        Search => "search",
    }
}

impl Goal for HeadGoal {
    type Primitive = HeadPrimitive;

    fn label(&self) -> String {
        match self {
            HeadGoal::Observe(o) => format!("observe {o}"),
            HeadGoal::ObserveBoth(a, b) => format!("observe {a}+{b}"),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
enum BodyGoal {
    Approach,
    GoToAndKick,
}

strata_robot::primitive_ids! {
    enum BodyPrimitive {
        Walk => "walk",
        Kick => "kick",
    }
}

impl Goal for BodyGoal {
    type Primitive = BodyPrimitive;

    fn label(&self) -> String {
        format!("{self:?}").to_lowercase()
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
enum WholeGoal {
    Fall,
    Celebrate,
}

strata_robot::primitive_ids! {
    enum WholePrimitive {
        Fall => "fall",
        Celebrate => "celebrate",
    }
}

impl Goal for WholeGoal {
    type Primitive = WholePrimitive;

    fn label(&self) -> String {
        format!("{self:?}").to_lowercase()
    }
}

const FOV: f64 = 1.0;

struct HeadPolicy;
impl ActivationPolicy<HeadGoal, World> for HeadPolicy {
    fn split(
        &self,
        goal: &GoalScore<HeadGoal>,
        input: &ReactiveInput<'_, World>,
    ) -> Option<Vec<GoalScore<HeadGoal>>> {
        match &goal.goal {
            HeadGoal::ObserveBoth(a, b) => {
                let world = input.world.expect("world");
                let (Some((_, ba)), Some((_, bb))) = (world.object(a), world.object(b)) else {
                    return Some(vec![]);
                };
                if (ba - bb).abs() < FOV * 0.8 {
                    None
                } else {
                    // Not in one gaze: two goals, each with the deliberative score.
                    Some(vec![
                        GoalScore::new(HeadGoal::Observe(a.clone()), goal.deliberative)
                            .about(a.clone()),
                        GoalScore::new(HeadGoal::Observe(b.clone()), goal.deliberative)
                            .about(b.clone()),
                    ])
                }
            }
            HeadGoal::Observe(_) => None,
        }
    }

    fn reactive_score(&self, goal: &GoalScore<HeadGoal>, input: &ReactiveInput<'_, World>) -> f64 {
        let world = input.world.expect("world");
        // The less confident, the more worth observing.
        goal.objects
            .iter()
            .filter_map(|o| world.object(o))
            .map(|(c, _)| 1.0 - c)
            .fold(0.0, f64::max)
    }

    fn primitives_for(
        &self,
        goal: &HeadGoal,
        input: &ReactiveInput<'_, World>,
    ) -> &'static [HeadPrimitive] {
        let world = input.world.expect("world");
        let known = match goal {
            HeadGoal::Observe(o) => world.object(o).is_some_and(|(c, _)| c > 0.3),
            HeadGoal::ObserveBoth(..) => true,
        };
        if known {
            &[HeadPrimitive::Track, HeadPrimitive::Search]
        } else {
            &[HeadPrimitive::Search]
        }
    }
}

impl ActivationShortcuts<HeadGoal, World> for HeadPolicy {
    fn reuse_key(&self, _: &ReactiveInput<'_, World>) -> Option<u64> {
        Some(0)
    }
}

struct Look(HeadPrimitive);
impl PrimitiveBehavior<HeadGoal, HeadCommand, World> for Look {
    fn id(&self) -> HeadPrimitive {
        self.0
    }
    fn step(&mut self, _: &HeadGoal, _: &ReactiveInput<'_, World>) -> Option<HeadCommand> {
        let yaw = if self.0 == HeadPrimitive::Track { 0.1 } else { 1.0 };
        Some(HeadCommand::NonQueue(HeadMotion {
            target: HeadAngles { yaw, pitch: 0.0 },
            max_speed: 2.0,
        }))
    }
}

struct BodyPolicy;
impl ActivationPolicy<BodyGoal, World> for BodyPolicy {
    fn reactive_score(&self, _: &GoalScore<BodyGoal>, _: &ReactiveInput<'_, World>) -> f64 {
        0.5
    }
    fn primitives_for(
        &self,
        goal: &BodyGoal,
        input: &ReactiveInput<'_, World>,
    ) -> &'static [BodyPrimitive] {
        match goal {
            BodyGoal::Approach => &[BodyPrimitive::Walk],
            // Kick vs go-to from percepts; the kick id would be a deliberative parameter.
            BodyGoal::GoToAndKick if input.world.is_some_and(|w| w.target_close) => {
                &[BodyPrimitive::Kick, BodyPrimitive::Walk]
            }
            BodyGoal::GoToAndKick => &[BodyPrimitive::Walk],
        }
    }
}

impl ActivationShortcuts<BodyGoal, World> for BodyPolicy {
    fn reuse_key(&self, _: &ReactiveInput<'_, World>) -> Option<u64> {
        Some(0)
    }
}

struct Walk;
impl PrimitiveBehavior<BodyGoal, BodyCommand, World> for Walk {
    fn id(&self) -> BodyPrimitive {
        BodyPrimitive::Walk
    }
    fn step(&mut self, _: &BodyGoal, _: &ReactiveInput<'_, World>) -> Option<BodyCommand> {
        Some(BodyCommand::NonQueue(BodyMotion::Walk {
            velocity: Velocity::new(0.2, 0.0, 0.0),
            duration: 0.5,
        }))
    }
}

/// This application's motions beside the robot crate's own: a kick leaves the head free.
const KICK: SpecialMotion = SpecialMotion::new(MotionName::from_static("kick"), 0, false);
const CELEBRATE: SpecialMotion = SpecialMotion::new(MotionName::from_static("celebrate"), 9, true);

struct Kick;
impl PrimitiveBehavior<BodyGoal, BodyCommand, World> for Kick {
    fn id(&self) -> BodyPrimitive {
        BodyPrimitive::Kick
    }
    fn step(&mut self, _: &BodyGoal, _: &ReactiveInput<'_, World>) -> Option<BodyCommand> {
        Some(BodyCommand::Special(KICK))
    }
}

struct WholePolicy;
impl ActivationPolicy<WholeGoal, World> for WholePolicy {
    fn reactive_score(&self, goal: &GoalScore<WholeGoal>, input: &ReactiveInput<'_, World>) -> f64 {
        match goal.goal {
            WholeGoal::Fall if !input.stability.is_stable() => 1.0,
            _ => 0.0,
        }
    }
    fn primitives_for(
        &self,
        goal: &WholeGoal,
        input: &ReactiveInput<'_, World>,
    ) -> &'static [WholePrimitive] {
        match goal {
            WholeGoal::Fall if matches!(input.stability, Stability::Unstable(_)) => {
                &[WholePrimitive::Fall]
            }
            WholeGoal::Fall => &[],
            WholeGoal::Celebrate => &[WholePrimitive::Celebrate],
        }
    }
}

struct Sequence(WholePrimitive, SpecialMotion);
impl PrimitiveBehavior<WholeGoal, WholeBodyCommand, World> for Sequence {
    fn id(&self) -> WholePrimitive {
        self.0
    }
    fn step(&mut self, _: &WholeGoal, _: &ReactiveInput<'_, World>) -> Option<WholeBodyCommand> {
        Some(WholeBodyCommand::Special { motion: self.1 })
    }
}

type Layer = ReactiveLayer<HeadGoal, BodyGoal, WholeGoal, World>;

fn layer(combination: ScoreCombination) -> Layer {
    let config = MultiplexerConfig { combination, hysteresis: 0.0 };
    let head =
        Multiplexer::with_shortcuts(ResourceGroup::Head, config.clone(), Box::new(HeadPolicy))
            .with_primitive(Box::new(Look(HeadPrimitive::Track)))
            .with_primitive(Box::new(Look(HeadPrimitive::Search)));
    let body =
        Multiplexer::with_shortcuts(ResourceGroup::Body, config.clone(), Box::new(BodyPolicy))
            .with_primitive(Box::new(Walk))
            .with_primitive(Box::new(Kick));
    let whole = Multiplexer::new(ResourceGroup::HeadAndBody, config, Box::new(WholePolicy))
        .with_primitive(Box::new(Sequence(WholePrimitive::Fall, SpecialMotion::fall(0))))
        .with_primitive(Box::new(Sequence(WholePrimitive::Celebrate, CELEBRATE)))
        .with_reflexes(ScoreVector::single(WholeGoal::Fall));
    ReactiveLayer::new(head, body, whole, FallDetectorConfig::default())
}

fn observe(o: &str, sd: f64) -> GoalScore<HeadGoal> {
    GoalScore::new(HeadGoal::Observe(o.into()), sd).about(o)
}

fn upright() -> Percepts {
    let mut p = Percepts::default();
    p.inertial.accelerometer = [0.0, 0.0, 9.81];
    p
}

fn tipping() -> Percepts {
    let mut p = upright();
    p.inertial.body_angles = [0.0, 0.4];
    p.inertial.gyroscope = [0.0, 2.0, 0.0];
    p
}

struct Row {
    name: &'static str,
    head: Vec<GoalScore<HeadGoal>>,
    world: World,
    combination: ScoreCombination,
    selected: Option<&'static str>,
    primitive: Option<&'static str>,
    /// (goal, S_r, final) for every scored goal.
    scores: Vec<(&'static str, f64, f64)>,
}

#[test]
fn head_multiplexer_table() {
    let world =
        |c: &[(&'static str, f64, f64)]| World { confidence: c.to_vec(), target_close: false };
    let rows = vec![
        Row {
            name: "the reactive score lifts an uncertain object above a higher S_d",
            head: vec![observe("ball", 0.6), observe("beacon", 0.5)],
            world: world(&[("ball", 0.9, 0.0), ("beacon", 0.1, 0.5)]),
            combination: ScoreCombination::Average,
            selected: Some("observe beacon"),
            primitive: Some("search"),
            scores: vec![("observe ball", 0.1, 0.35), ("observe beacon", 0.9, 0.7)],
        },
        Row {
            name: "without reactive rescaling the deliberative order stands",
            head: vec![observe("ball", 0.6), observe("beacon", 0.5)],
            world: world(&[("ball", 0.9, 0.0), ("beacon", 0.1, 0.5)]),
            combination: ScoreCombination::DeliberativeOnly,
            selected: Some("observe ball"),
            primitive: Some("track"),
            scores: vec![("observe ball", 0.1, 0.6), ("observe beacon", 0.9, 0.5)],
        },
        Row {
            name: "two objects that fit in one gaze stay one goal",
            head: vec![
                GoalScore::new(HeadGoal::ObserveBoth("ball".into(), "post".into()), 0.8)
                    .about("ball")
                    .about("post"),
            ],
            world: world(&[("ball", 0.5, 0.1), ("post", 0.4, 0.4)]),
            combination: ScoreCombination::Average,
            selected: Some("observe ball+post"),
            primitive: Some("track"),
            scores: vec![("observe ball+post", 0.6, 0.7)],
        },
        Row {
            name: "two objects that do not fit in one gaze are split (stage 1)",
            head: vec![
                GoalScore::new(HeadGoal::ObserveBoth("ball".into(), "post".into()), 0.8)
                    .about("ball")
                    .about("post"),
            ],
            world: world(&[("ball", 0.5, -1.0), ("post", 0.2, 1.0)]),
            combination: ScoreCombination::Average,
            selected: Some("observe post"),
            primitive: Some("search"),
            scores: vec![("observe ball", 0.5, 0.65), ("observe post", 0.8, 0.8)],
        },
        Row {
            name: "an empty score vector selects nothing",
            head: vec![],
            world: World::default(),
            combination: ScoreCombination::Average,
            selected: None,
            primitive: None,
            scores: vec![],
        },
    ];
    for row in rows {
        let mut layer = layer(row.combination);
        layer.head.set_scores(
            ScoreVector { goals: row.head.clone() },
            &Default::default(),
            Time::ZERO,
        );
        let report = layer.step(Time::from_nanos(1), &upright(), Some(&row.world));
        assert_eq!(report.head.selected_goal.as_deref(), row.selected, "{}", row.name);
        assert_eq!(report.head.primitive.as_deref(), row.primitive, "{}", row.name);
        let scored: Vec<(String, f64, f64)> = report
            .head
            .goals
            .iter()
            .map(|g| (g.goal.to_string(), g.reactive, g.final_score))
            .collect();
        assert_eq!(scored.len(), row.scores.len(), "{}: {scored:?}", row.name);
        for ((goal, sr, s), (eg, esr, es)) in scored.iter().zip(&row.scores) {
            assert_eq!(goal, eg, "{}", row.name);
            assert!(
                (sr - esr).abs() < 1e-9 && (s - es).abs() < 1e-9,
                "{}: {goal} S_r {sr} S {s}",
                row.name
            );
        }
        // S_d is never changed by the reactive layer.
        assert_eq!(layer.head.scores().goals, row.head, "{}", row.name);
        match (&report.commands, row.selected) {
            (MotionCommands::PerResource { head: Some(_), .. }, Some(_)) => {}
            (MotionCommands::PerResource { head: None, .. }, None) => {}
            (other, _) => panic!("{}: unexpected commands {other:?}", row.name),
        }
    }
}

#[test]
fn kick_or_walk_is_chosen_from_percepts_and_the_deliberative_layer_can_deactivate_the_kick() {
    let mut layer = layer(ScoreCombination::Average);
    let world = World { confidence: vec![], target_close: true };
    layer.body.set_scores(
        ScoreVector::single(BodyGoal::GoToAndKick),
        &Default::default(),
        Time::ZERO,
    );
    let report = layer.step(Time::ZERO, &upright(), Some(&world));
    assert_eq!(report.body.primitive.as_deref(), Some("kick"));
    assert!(matches!(
        report.commands,
        MotionCommands::PerResource { body: Some(BodyCommand::Special(KICK)), .. }
    ));
    let far = World { confidence: vec![], target_close: false };
    let report = layer.step(Time::ZERO, &upright(), Some(&far));
    assert_eq!(report.body.primitive.as_deref(), Some("walk"));
    // Dribbling wanted: the deliberative layer deactivates the kick.
    let deactivated = ["kick".to_owned()].into_iter().collect();
    layer.body.set_scores(ScoreVector::single(BodyGoal::GoToAndKick), &deactivated, Time::ZERO);
    let report = layer.step(Time::ZERO, &upright(), Some(&world));
    assert_eq!(report.body.primitive.as_deref(), Some("walk"));
}

#[test]
fn a_fall_inhibits_head_and_body_within_one_reactive_cycle() {
    let mut layer = layer(ScoreCombination::Average);
    let world = World { confidence: vec![("ball", 0.2, 0.0)], target_close: false };
    layer.head.set_scores(
        ScoreVector { goals: vec![observe("ball", 1.0)] },
        &Default::default(),
        Time::ZERO,
    );
    layer.body.set_scores(ScoreVector::single(BodyGoal::Approach), &Default::default(), Time::ZERO);
    let report = layer.step(Time::ZERO, &upright(), Some(&world));
    assert!(matches!(
        report.commands,
        MotionCommands::PerResource { head: Some(_), body: Some(_) }
    ));
    assert!(!report.whole_body.goals[0].applicable, "no fall goal while stable");
    // The very next percept shows the robot tipping: the reflex fires, no deliberation needed.
    let report = layer.step(Time::from_nanos(12), &tipping(), Some(&world));
    assert_eq!(report.stability, Stability::Unstable(strata_robot::platform::FallDirection::Front));
    assert_eq!(
        report.commands,
        MotionCommands::WholeBody {
            command: WholeBodyCommand::Special { motion: SpecialMotion::fall(0) }
        }
    );
    assert_eq!(report.head.inhibited_by, Some(ResourceGroup::HeadAndBody));
    assert_eq!(report.body.inhibited_by, Some(ResourceGroup::HeadAndBody));
    assert!(report.active_path().starts_with("head+body: fall > fall"), "{}", report.active_path());
}

#[test]
fn a_head_and_body_goal_yields_to_higher_scored_separate_goals() {
    let mut layer = layer(ScoreCombination::Average);
    let world = World { confidence: vec![("ball", 0.0, 0.0)], target_close: false };
    layer.whole_body.set_scores(
        ScoreVector { goals: vec![GoalScore::new(WholeGoal::Celebrate, 0.2)] },
        &Default::default(),
        Time::ZERO,
    );
    layer.head.set_scores(
        ScoreVector { goals: vec![observe("ball", 0.9)] },
        &Default::default(),
        Time::ZERO,
    );
    let report = layer.step(Time::ZERO, &upright(), Some(&world));
    assert_eq!(report.head.selected_goal.as_deref(), Some("observe ball"));
    assert_eq!(report.whole_body.selected_goal, None);
    // Raise the whole-body goal above both: it takes both resources.
    layer.whole_body.set_scores(
        ScoreVector { goals: vec![GoalScore::new(WholeGoal::Celebrate, 1.0)] },
        &Default::default(),
        Time::ZERO,
    );
    layer.head.set_scores(
        ScoreVector { goals: vec![observe("ball", 0.1)] },
        &Default::default(),
        Time::ZERO,
    );
    // Head: (0.1 + 0.2) / 2 = 0.15 against the whole-body goal's (1.0 + 0.0) / 2 = 0.5.
    let world = World { confidence: vec![("ball", 0.8, 0.0)], target_close: false };
    let report = layer.step(Time::ZERO, &upright(), Some(&world));
    assert_eq!(report.whole_body.selected_goal.as_deref(), Some("celebrate"));
    assert_eq!(report.head.inhibited_by, Some(ResourceGroup::HeadAndBody));
}

#[test]
fn hysteresis_keeps_the_current_goal_when_scores_are_close() {
    let config = MultiplexerConfig { combination: ScoreCombination::Average, hysteresis: 0.05 };
    let mut mux: Multiplexer<HeadGoal, HeadCommand, World> =
        Multiplexer::new(ResourceGroup::Head, config, Box::new(HeadPolicy))
            .with_primitive(Box::new(Look(HeadPrimitive::Track)))
            .with_primitive(Box::new(Look(HeadPrimitive::Search)));
    mux.set_scores(
        ScoreVector { goals: vec![observe("a", 0.5), observe("b", 0.5)] },
        &Default::default(),
        Time::ZERO,
    );
    let percepts = upright();
    let actuation = Default::default();
    let world = World { confidence: vec![("a", 0.5, 0.0), ("b", 0.52, 0.0)], target_close: false };
    let input = ReactiveInput {
        now: Time::ZERO,
        percepts: &percepts,
        world: Some(&world),
        actuation: &actuation,
        stability: Stability::Stable,
    };
    let first = mux.evaluate(&input).expect("a selection");
    let _ = mux.execute(&first, &input);
    assert_eq!(mux.selected(&first).map(|g| &g.goal), Some(&HeadGoal::Observe("a".into())));
    // b becomes slightly more uncertain than a: within the hysteresis, a is kept.
    let world = World { confidence: vec![("a", 0.5, 0.0), ("b", 0.46, 0.0)], target_close: false };
    let input = ReactiveInput { world: Some(&world), ..input };
    let kept = mux.evaluate(&input).expect("selection");
    assert_eq!(mux.selected(&kept).map(|g| &g.goal), Some(&HeadGoal::Observe("a".into())));
    // Well beyond it, b wins.
    let world = World { confidence: vec![("a", 0.5, 0.0), ("b", 0.3, 0.0)], target_close: false };
    let input = ReactiveInput { world: Some(&world), ..input };
    let switched = mux.evaluate(&input).expect("selection");
    assert_eq!(mux.selected(&switched).map(|g| &g.goal), Some(&HeadGoal::Observe("b".into())));
}

/// A world-only policy that counts how often the multiplexer asks it.
struct Counted(HeadPolicy, std::sync::Arc<std::sync::atomic::AtomicUsize>);
impl ActivationPolicy<HeadGoal, World> for Counted {
    fn split(
        &self,
        goal: &GoalScore<HeadGoal>,
        input: &ReactiveInput<'_, World>,
    ) -> Option<Vec<GoalScore<HeadGoal>>> {
        self.0.split(goal, input)
    }
    fn reactive_score(&self, goal: &GoalScore<HeadGoal>, input: &ReactiveInput<'_, World>) -> f64 {
        self.1.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.0.reactive_score(goal, input)
    }
    fn primitives_for(
        &self,
        goal: &HeadGoal,
        input: &ReactiveInput<'_, World>,
    ) -> &'static [HeadPrimitive] {
        self.0.primitives_for(goal, input)
    }
}

impl ActivationShortcuts<HeadGoal, World> for Counted {
    fn reuse_key(&self, _: &ReactiveInput<'_, World>) -> Option<u64> {
        Some(0)
    }
}

/// Cycles numbered by world-state revision reuse a world-only policy's answers while the world
/// state and the score vector stay, and decide exactly as cycles that ask every time: same
/// reports, same commands, through world changes, new score vectors, splits, hysteresis, a
/// fall and a deactivated primitive.
#[test]
fn cycles_on_one_world_state_decide_as_cycles_that_ask_every_time() {
    let config = MultiplexerConfig { combination: ScoreCombination::Average, hysteresis: 0.05 };
    let counted = |asked: &std::sync::Arc<std::sync::atomic::AtomicUsize>| {
        Multiplexer::with_shortcuts(
            ResourceGroup::Head,
            config.clone(),
            Box::new(Counted(HeadPolicy, asked.clone())),
        )
        .with_primitive(Box::new(Look(HeadPrimitive::Track)))
        .with_primitive(Box::new(Look(HeadPrimitive::Search)))
    };
    let asked_plain = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let asked_revised = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let mut plain = layer(ScoreCombination::Average);
    plain.head = counted(&asked_plain);
    let mut revised = layer(ScoreCombination::Average);
    revised.head = counted(&asked_revised);
    let worlds = [
        World { confidence: vec![("ball", 0.5, 0.1), ("post", 0.4, 0.4)], target_close: false },
        World { confidence: vec![("ball", 0.5, -1.0), ("post", 0.2, 1.0)], target_close: true },
        World { confidence: vec![("ball", 0.52, -1.0), ("post", 0.5, 1.0)], target_close: true },
        World { confidence: vec![("ball", 0.1, 0.0), ("post", 0.9, 0.2)], target_close: false },
    ];
    let vectors = [
        vec![observe("ball", 0.5), observe("post", 0.5)],
        vec![
            GoalScore::new(HeadGoal::ObserveBoth("ball".into(), "post".into()), 0.8)
                .about("ball")
                .about("post"),
            observe("ball", 0.3),
        ],
    ];
    for step in 0..48usize {
        // A new world state every third cycle, a new score vector every eleventh.
        let revision = (step / 3) as u64;
        let world = &worlds[(step / 3) % worlds.len()];
        if step % 11 == 0 {
            let head = ScoreVector { goals: vectors[(step / 11) % vectors.len()].clone() };
            let deactivated = if step == 33 {
                ["kick".to_owned()].into_iter().collect()
            } else {
                Default::default()
            };
            for layer in [&mut plain, &mut revised] {
                layer.head.set_scores(head.clone(), &Default::default(), Time::ZERO);
                layer.body.set_scores(
                    ScoreVector::single(BodyGoal::GoToAndKick),
                    &deactivated,
                    Time::ZERO,
                );
            }
        }
        let percepts = if step == 20 { tipping() } else { upright() };
        let now = Time::from_nanos(step as u64);
        let expected = plain.step(now, &percepts, Some(world));
        let got = revised.step_on_revision(now, &percepts, Some(world), revision);
        assert_eq!(got, expected, "cycle {step}");
    }
    // A new world state every third cycle: about a third of the questions.
    let plain = asked_plain.load(std::sync::atomic::Ordering::Relaxed);
    let revised = asked_revised.load(std::sync::atomic::Ordering::Relaxed);
    assert!(revised > 0 && 2 * revised < plain, "asked {revised} times, not {plain}");
}

/// A policy's shortcuts are behind its contract: a multiplexer that takes them
/// (`with_shortcuts`) selects and commands exactly as one that asks the contract every cycle
/// (`new`), even on cycles numbered by revision, where only the first may reuse answers.
#[test]
fn shortcuts_give_the_contracts_answers() {
    let config = MultiplexerConfig { combination: ScoreCombination::Average, hysteresis: 0.05 };
    let asked_contract = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let asked_shortcuts = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let mut contract = layer(ScoreCombination::Average);
    contract.head = Multiplexer::new(
        ResourceGroup::Head,
        config.clone(),
        Box::new(Counted(HeadPolicy, asked_contract.clone())),
    )
    .with_primitive(Box::new(Look(HeadPrimitive::Track)))
    .with_primitive(Box::new(Look(HeadPrimitive::Search)));
    contract.body = Multiplexer::new(ResourceGroup::Body, config.clone(), Box::new(BodyPolicy))
        .with_primitive(Box::new(Walk))
        .with_primitive(Box::new(Kick));
    let mut shortcuts = layer(ScoreCombination::Average);
    shortcuts.head = Multiplexer::with_shortcuts(
        ResourceGroup::Head,
        config,
        Box::new(Counted(HeadPolicy, asked_shortcuts.clone())),
    )
    .with_primitive(Box::new(Look(HeadPrimitive::Track)))
    .with_primitive(Box::new(Look(HeadPrimitive::Search)));
    let worlds = [
        World { confidence: vec![("ball", 0.5, 0.1), ("post", 0.4, 0.4)], target_close: false },
        World { confidence: vec![("ball", 0.1, 0.0), ("post", 0.9, 0.2)], target_close: true },
    ];
    let goals = ScoreVector {
        goals: vec![
            GoalScore::new(HeadGoal::ObserveBoth("ball".into(), "post".into()), 0.8)
                .about("ball")
                .about("post"),
            observe("ball", 0.3),
        ],
    };
    for layer in [&mut contract, &mut shortcuts] {
        layer.head.set_scores(goals.clone(), &Default::default(), Time::ZERO);
        layer.body.set_scores(
            ScoreVector::single(BodyGoal::GoToAndKick),
            &Default::default(),
            Time::ZERO,
        );
    }
    for step in 0..24usize {
        let revision = (step / 4) as u64;
        let world = &worlds[(step / 4) % worlds.len()];
        let percepts = if step == 10 { tipping() } else { upright() };
        let now = Time::from_nanos(step as u64);
        let expected = contract.step_on_revision(now, &percepts, Some(world), revision);
        let got = shortcuts.step_on_revision(now, &percepts, Some(world), revision);
        assert_eq!(got, expected, "cycle {step}");
    }
    let contract = asked_contract.load(std::sync::atomic::Ordering::Relaxed);
    let shortcuts = asked_shortcuts.load(std::sync::atomic::Ordering::Relaxed);
    assert!(shortcuts > 0 && shortcuts < contract, "asked {shortcuts} times, not {contract}");
}

/// A selection is executed only by the assessment it was made from.
#[test]
fn a_selection_from_an_earlier_assessment_executes_nothing() {
    let mut layer = layer(ScoreCombination::Average);
    layer.head.set_scores(
        ScoreVector { goals: vec![observe("ball", 0.9)] },
        &Default::default(),
        Time::ZERO,
    );
    let world = World { confidence: vec![("ball", 0.5, 0.0)], target_close: false };
    let percepts = upright();
    let actuation = Default::default();
    let input = ReactiveInput {
        now: Time::ZERO,
        percepts: &percepts,
        world: Some(&world),
        actuation: &actuation,
        stability: Stability::Stable,
    };
    let old = layer.head.evaluate(&input).expect("a selection");
    let new = layer.head.evaluate(&input).expect("a selection");
    assert!(layer.head.selected(&old).is_none());
    assert!(layer.head.execute(&old, &input).is_none());
    assert!(layer.head.execute(&new, &input).is_some());
}

/// A robot that drives its body only: its head and head+body multiplexers are unused (goal
/// type `NoGoal`, no policy, no primitives), never select and never command; the body's does.
#[test]
fn a_layer_runs_only_the_multiplexers_an_application_uses() {
    let config = MultiplexerConfig { combination: ScoreCombination::Average, hysteresis: 0.0 };
    let mut layer: ReactiveLayer<NoGoal, BodyGoal, NoGoal, World> =
        ReactiveLayer::empty(FallDetectorConfig::default()).with_body(
            Multiplexer::new(ResourceGroup::Body, config, Box::new(BodyPolicy))
                .with_primitive(Box::new(Walk))
                .with_primitive(Box::new(Kick)),
        );
    layer.body.set_scores(
        ScoreVector::single(BodyGoal::GoToAndKick),
        &Default::default(),
        Time::ZERO,
    );
    let world = World { confidence: vec![("ball", 0.5, 0.0)], target_close: false };
    for step in 0..3u64 {
        let percepts = if step == 2 { tipping() } else { upright() };
        let report = layer.step(Time::from_nanos(step), &percepts, Some(&world));
        assert!(report.head.selected_goal.is_none() && report.head.primitive.is_none());
        assert!(report.whole_body.selected_goal.is_none());
        assert_eq!(report.body.primitive.as_deref(), Some("walk"), "cycle {step}");
        assert!(
            matches!(report.commands, MotionCommands::PerResource { head: None, body: Some(_) }),
            "cycle {step}: {:?}",
            report.commands
        );
    }
}

/// A primitive the policy names but nobody registered leaves the goals only it pursues
/// inapplicable; the multiplexer and the layer say which primitives they lack.
#[test]
fn a_layer_lists_the_primitives_it_lacks() {
    let config = MultiplexerConfig { combination: ScoreCombination::Average, hysteresis: 0.0 };
    let mut layer = layer(ScoreCombination::Average);
    assert_eq!(layer.unregistered(), []);
    layer.body = Multiplexer::new(ResourceGroup::Body, config.clone(), Box::new(BodyPolicy))
        .with_primitive(Box::new(Kick));
    assert_eq!(layer.body.unregistered().collect::<Vec<_>>(), [BodyPrimitive::Walk]);
    assert_eq!(layer.unregistered(), [(ResourceGroup::Body, "walk")]);
    layer.body.set_scores(ScoreVector::single(BodyGoal::Approach), &Default::default(), Time::ZERO);
    let world = World::default();
    let report = layer.step(Time::ZERO, &upright(), Some(&world));
    assert!(!report.body.goals[0].applicable && report.body.selected_goal.is_none());
    // The unused multiplexers of a layer that drives its body only lack nothing.
    let body_only: ReactiveLayer<NoGoal, BodyGoal, NoGoal, World> =
        ReactiveLayer::empty(FallDetectorConfig::default()).with_body(
            Multiplexer::new(ResourceGroup::Body, config, Box::new(BodyPolicy))
                .with_primitive(Box::new(Walk))
                .with_primitive(Box::new(Kick)),
        );
    assert_eq!(body_only.unregistered(), []);
}
