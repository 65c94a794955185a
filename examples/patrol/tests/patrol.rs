//! The patrol application on the unchanged architecture: two robots for three simulated minutes
//! on the lockstep host, with a fixed seed, checked for what they did — not for how fast.

use patrol::goals::GazeKind;
use patrol::planning::{Mission, Role};
use patrol::run::robot_name;
use patrol::{Outcome, PatrolRun};

const SEED: u64 = 7;
const MINUTES: f64 = 3.0;

fn demo() -> Outcome {
    PatrolRun::demo(SEED).and_then(|run| run.run_lockstep(MINUTES * 60.0)).expect("the patrol runs")
}

#[test]
fn two_robots_patrol_their_beats_inspect_and_answer_the_operator() {
    let outcome = demo();
    let summary = outcome.summary();

    // The beats are walked in order: every time a robot's deliberative layer moves on from a
    // waypoint it is the next one of the beat, and the robot really is there.
    for robot in 0..2 {
        let visits = outcome.visits(robot);
        let stops = outcome.plan.beats[robot].len();
        assert!(visits.len() > stops, "robot {robot} did not complete a lap:\n{summary}");
        for pair in visits.windows(2) {
            assert_eq!(pair[1].waypoint, (pair[0].waypoint + 1) % stops, "robot {robot}: {pair:?}");
        }
        for visit in &visits {
            assert!(visit.miss < 0.45, "robot {robot} was not at its waypoint: {visit:?}");
        }
    }

    // Every point of interest was inspected: the robots' estimates, as reported to the
    // console, converged on the true positions — also where the plan is wrong by 25-30 cm.
    for (k, best) in outcome.best_reports().into_iter().enumerate() {
        let (report, error) =
            best.unwrap_or_else(|| panic!("point {k} never reported:\n{summary}"));
        assert!(error < 0.12, "point {k}: {report:?} is {error:.2} m off");
        assert!(report.report.sigma < 0.1, "point {k}: {report:?}");
        let nominal = outcome.plan.points_of_interest[k].nominal;
        let truth = outcome.truth.points_of_interest[k];
        if nominal.distance(truth) > 0.2 {
            assert!(
                report.report.position.distance(nominal) > 0.15,
                "point {k}: the estimate found the displacement, it did not repeat the plan"
            );
        }
    }

    // The alarm: exactly one robot responds, chosen by the planning layer — the one with the
    // shorter walk round the walls (the north wing's) — reaches the spot and sees the
    // intruder; the console then clears the alarm and both go back to patrolling.
    let [alarm] = outcome.truth.alarms.as_slice() else { panic!("one alarm:\n{summary}") };
    let (on_site_player, _) = alarm.on_site.expect("somebody reached the alarm");
    let cleared = alarm.cleared.expect("the alarm was cleared");
    assert_eq!(on_site_player, 1);
    let mut t = alarm.raised + 1.0;
    while t < cleared {
        assert_eq!(outcome.responders_at(t), vec![1], "responders at {t:.1} s:\n{summary}");
        t += 0.5;
    }
    for player in [1, 2] {
        let log = &outcome.observations.robots[&robot_name(player)];
        assert!(
            log.assignments
                .iter()
                .any(|(t, mission, _, _)| *t >= alarm.raised && *mission == Mission::Respond),
            "patrol/{player} heard the alarm"
        );
        assert_eq!(log.role_at(cleared + 2.0), Some(Role::Patroller));
    }
    // Meanwhile the other robot kept walking its beat in the south wing.
    let south = &outcome.observations.robots[&robot_name(2)];
    let state_at = |t: f64| south.paths.iter().take_while(|(s, _)| *s <= t).last().map(|(_, p)| p);
    let mut t = alarm.raised;
    while t < cleared {
        let path = state_at(t).expect("a behavior path");
        assert!(path.starts_with("Patrolling/"), "patrol/2 at {t:.1} s: {path}");
        t += 0.5;
    }
    let window: Vec<_> = outcome.truth.trajectories[1]
        .iter()
        .filter(|(t, _)| *t > alarm.raised && *t < cleared)
        .map(|(_, pose)| pose.position())
        .collect();
    let walked: f64 = window.windows(2).map(|w| w[0].distance(w[1])).sum();
    assert!(walked > 3.0, "patrol/2 walked {walked:.1} m during the alarm");
    assert!(window.iter().all(|p| p.y < 0.0), "patrol/2 left the south wing");

    // Active vision shared the head: while inspecting, each robot looked at the point of
    // interest at some moments and at landmarks (to localize) at others — the reactive
    // report's selected goals say so.
    for player in [1, 2] {
        let log = &outcome.observations.robots[&robot_name(player)];
        assert!(log.gaze_cycles("Inspect", GazeKind::Inspecting) > 0, "{summary}");
        assert!(log.gaze_cycles("Inspect", GazeKind::Localizing) > 0, "{summary}");
        // While walking, only localization is worth a look.
        assert!(log.gaze_cycles("Patrol", GazeKind::Localizing) > 0, "{summary}");
    }

    // The slip: the head+body reflexes protected the robot and got it up, and it went back to
    // its beat.
    assert_eq!(outcome.truth.falls.len(), 1, "{summary}");
    assert_eq!(outcome.truth.stand_ups.len(), 1, "{summary}");
    let log = &outcome.observations.robots[&robot_name(2)];
    assert!(log.reflexes.get("fall").is_some_and(|n| *n > 0), "{:?}", log.reflexes);
    assert!(log.reflexes.get("stand-up").is_some_and(|n| *n > 0), "{:?}", log.reflexes);
    let recovered =
        log.paths.iter().position(|(_, p)| p.starts_with("Recovering")).expect("recovering");
    assert!(log.paths[recovered + 1].1.starts_with("Patrolling/Return"), "{:?}", log.paths);
}

#[test]
fn the_same_seed_gives_the_same_patrol() {
    let run = || PatrolRun::demo(SEED).and_then(|run| run.run_lockstep(20.0)).expect("runs");
    let (a, b) = (run(), run());
    assert_eq!(a.truth, b.truth);
    assert_eq!(a.observations, b.observations);
}

#[test]
fn the_same_robots_run_on_the_threaded_host() {
    // A thread per module, real time: the same graph, briefly.
    let outcome = PatrolRun::demo(SEED).and_then(|run| run.run_threaded(2.0)).expect("runs");
    assert!(outcome.duration > 0.0);
    for player in [1, 2] {
        let name = robot_name(player);
        let reactive = outcome.stats.module(&format!("{name}/reactive")).expect("reactive stats");
        assert!(reactive.cycles > 0);
        let log = &outcome.observations.robots[&name];
        assert!(
            log.paths.iter().any(|(_, p)| p.starts_with("Patrolling/Patrol")),
            "{:?}",
            log.paths
        );
        assert!(!log.assignments.is_empty());
        assert!(log.gaze.values().sum::<u64>() > 0);
    }
}
