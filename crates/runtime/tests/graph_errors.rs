//! Every kind of wiring mistake is reported when the graph is built, naming modules and ports.

use std::time::Duration;

use strata_runtime::{
    Context, GraphBuilder, GraphError, Input, Module, ModuleError, Output, Policy, Trigger,
};

struct Idle;
impl Module for Idle {
    fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
        Ok(())
    }
}

fn source(graph: &mut GraphBuilder, name: &str) -> Output<u32> {
    graph.add(name, |p| {
        p.trigger(Trigger::every(Duration::from_millis(10)));
        (Idle, p.output::<u32>("value"))
    })
}

fn sink(graph: &mut GraphBuilder, name: &str) -> Input<u32> {
    graph.add(name, |p| {
        let input = p.input::<u32>("value", Policy::Latest);
        p.trigger(Trigger::on_any([input.into()]));
        (Idle, input)
    })
}

fn errors(graph: GraphBuilder) -> Vec<GraphError> {
    match graph.build() {
        Ok(_) => panic!("the graph should have been rejected"),
        Err(e) => {
            // The combined message lists every problem.
            let text = e.to_string();
            for error in &e.0 {
                assert!(text.contains(&error.to_string()));
            }
            e.0
        }
    }
}

#[test]
fn a_valid_graph_builds() {
    let mut graph = GraphBuilder::new();
    let out = source(&mut graph, "camera");
    let input = sink(&mut graph, "vision");
    graph.connect(out, input);
    let graph = graph.build().expect("valid");
    let description = graph.describe();
    assert_eq!(description.connections.len(), 1);
    assert_eq!(description.connections[0].from, "camera.value");
    assert_eq!(description.connections[0].to, "vision.value");
}

#[test]
fn an_input_without_writer_is_named() {
    let mut graph = GraphBuilder::new();
    sink(&mut graph, "world");
    let e = errors(graph);
    assert_eq!(e.len(), 1);
    assert!(
        matches!(&e[0], GraphError::InputWithoutWriter { input, .. } if input == "world.value")
    );
    assert!(e[0].to_string().contains("`world.value`"));
}

#[test]
fn an_optional_or_external_input_may_have_no_writer() {
    let mut graph = GraphBuilder::new();
    graph.add("planning", |p| {
        let team = p.optional_input::<u32>("team", Policy::queue(4));
        p.trigger(Trigger::every(Duration::from_millis(100)));
        (Idle, team)
    });
    let fed = sink(&mut graph, "replayed");
    graph.external(fed);
    assert!(graph.build().is_ok());
}

#[test]
fn two_writers_on_one_input_are_named() {
    let mut graph = GraphBuilder::new();
    let a = source(&mut graph, "left_camera");
    let b = source(&mut graph, "right_camera");
    let input = sink(&mut graph, "vision");
    graph.connect(a, input);
    graph.connect(b, input);
    let e = errors(graph);
    assert_eq!(e.len(), 1);
    let text = e[0].to_string();
    assert!(text.contains("vision.value"), "{text}");
    assert!(text.contains("left_camera.value") && text.contains("right_camera.value"), "{text}");
}

#[test]
fn a_type_mismatch_is_named_with_both_types() {
    let mut graph = GraphBuilder::new();
    graph.add("odometry", |p| {
        p.trigger(Trigger::every(Duration::from_millis(10)));
        (Idle, p.output::<f64>("value"))
    });
    sink(&mut graph, "world");
    graph.connect_by_name("odometry", "value", "world", "value").expect("ports exist");
    let e = errors(graph);
    let mismatch =
        e.iter().find(|e| matches!(e, GraphError::TypeMismatch { .. })).expect("mismatch");
    let text = mismatch.to_string();
    assert!(text.contains("odometry.value") && text.contains("world.value"), "{text}");
    assert!(text.contains("f64") && text.contains("u32"), "{text}");
}

#[test]
fn a_cycle_of_same_tick_dependencies_is_named() {
    struct Relay;
    impl Module for Relay {
        fn cycle(&mut self, _: &mut Context<'_>) -> Result<(), ModuleError> {
            Ok(())
        }
    }
    fn relay(graph: &mut GraphBuilder, name: &str) -> (Input<u32>, Output<u32>) {
        graph.add(name, |p| {
            let input = p.input::<u32>("in", Policy::Latest);
            let output = p.output::<u32>("out");
            p.trigger(Trigger::on_any([input.into()]));
            (Relay, (input, output))
        })
    }
    let mut graph = GraphBuilder::new();
    let (reactive_in, reactive_out) = relay(&mut graph, "reactive");
    let (actuation_in, actuation_out) = relay(&mut graph, "actuation");
    graph.connect(reactive_out, actuation_in);
    graph.connect(actuation_out, reactive_in);
    let e = errors(graph);
    let text = e.iter().map(ToString::to_string).collect::<Vec<_>>().join("\n");
    assert!(matches!(e[0], GraphError::SameTickCycle { .. }), "{text}");
    assert!(text.contains("reactive.out -> actuation.in"), "{text}");
    assert!(text.contains("actuation.out -> reactive.in"), "{text}");
}

#[test]
fn a_feedback_loop_through_a_non_triggering_input_is_fine() {
    let mut graph = GraphBuilder::new();
    let (commands_in, messages_out) = graph.add("actuation", |p| {
        let commands = p.input::<u32>("commands", Policy::queue(8));
        let messages = p.output::<u32>("messages");
        p.trigger(Trigger::on_any([commands.into()]));
        (Idle, (commands, messages))
    });
    let (messages_in, commands_out) = graph.add("reactive", |p| {
        let percepts = p.input::<u32>("percepts", Policy::Latest);
        let messages = p.input::<u32>("messages", Policy::queue(8));
        let commands = p.output::<u32>("commands");
        p.trigger(Trigger::on_any([percepts.into()]));
        (Idle, ((messages, percepts), commands))
    });
    let camera = source(&mut graph, "perception");
    graph.connect(camera, messages_in.1);
    graph.connect(commands_out, commands_in);
    graph.connect(messages_out, messages_in.0);
    assert!(graph.build().is_ok());
}

#[test]
fn duplicate_names_and_unknown_ports_are_reported() {
    let mut graph = GraphBuilder::new();
    source(&mut graph, "twin");
    source(&mut graph, "twin");
    graph.add("doubled", |p| {
        p.trigger(Trigger::every(Duration::from_millis(1)));
        p.output::<u32>("x");
        p.output::<u32>("x");
        (Idle, ())
    });
    let unknown = graph.connect_by_name("twin", "nope", "doubled", "x").expect_err("no such port");
    assert_eq!(unknown.to_string(), "module `twin` has no output port named `nope`");
    let missing = graph.connect_by_name("ghost", "x", "twin", "x").expect_err("no such module");
    assert_eq!(missing.to_string(), "no module named `ghost`");
    let e = errors(graph);
    assert!(e.contains(&GraphError::DuplicateModule { name: "twin".into() }));
    assert!(e.contains(&GraphError::DuplicatePort { module: "doubled".into(), port: "x".into() }));
}

#[test]
fn a_module_that_can_never_run_or_triggers_on_foreign_inputs_is_reported() {
    let mut graph = GraphBuilder::new();
    graph.add("inert", |p| {
        p.output::<u32>("x");
        (Idle, ())
    });
    let foreign = sink(&mut graph, "owner");
    let out = source(&mut graph, "writer");
    graph.connect(out, foreign);
    graph.add("thief", |p| {
        p.trigger(Trigger::on_any([foreign.into()]));
        (Idle, ())
    });
    let e = errors(graph);
    assert!(e.contains(&GraphError::NeverTriggered { module: "inert".into() }));
    assert!(e.contains(&GraphError::ForeignTriggerInput {
        module: "thief".into(),
        input: "owner.value".into()
    }));
}
