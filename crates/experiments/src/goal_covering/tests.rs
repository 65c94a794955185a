use super::*;

fn sample(t: f64, observe_ball: bool, ball_known: bool, pose_error: f64) -> Sample {
    Sample {
        t,
        observe_ball,
        ball_known,
        pose_error,
        coverage: 0.5,
        ideal_coverage: 0.6,
        covering: ball_known,
        ..Sample::default()
    }
}

#[test]
fn a_ball_unknown_a_quarter_of_the_time_gives_25_percent() {
    let trace: Vec<Sample> =
        (0..100).map(|i| sample(f64::from(i) * 0.02, i % 2 == 0, i % 4 != 0, 0.1)).collect();
    let m = metrics(&trace, &Recover::default());
    assert_eq!(m.samples, 100);
    assert!((m.ball_unknown - 0.25).abs() < 1e-12, "{m:?}");
    assert!((m.observe_ball - 0.5).abs() < 1e-12);
    assert!((m.coverage - 0.5).abs() < 1e-12 && (m.ideal_coverage - 0.6).abs() < 1e-12);
    assert!((m.covering_behavior - 0.75).abs() < 1e-12);
    // Alternating every sample: 99 switches in 1.98 s.
    assert!((m.gaze_switches_per_min - 99.0 / (1.98 / 60.0)).abs() < 1e-6);
}

#[test]
fn pose_error_statistics_skip_samples_without_an_estimate() {
    let mut trace: Vec<Sample> =
        (1..=20).map(|i| sample(f64::from(i), true, true, f64::from(i) / 100.0)).collect();
    trace.push(sample(21.0, true, true, f64::NAN));
    let m = metrics(&trace, &Recover::default());
    assert!((m.pose_error_mean - 0.105).abs() < 1e-12, "{m:?}");
    // 95th percentile of 0.01..0.20: position 18.05 -> 0.1905.
    assert!((m.pose_error_p95 - 0.1905).abs() < 1e-9, "{m:?}");
}

#[test]
fn the_built_in_scenario_is_valid_and_its_trajectories_stay_out_of_the_penalty_area() {
    let mut scenario: Scenario =
        super::super::parse_scenario(DEFAULT_SCENARIO, "built-in").expect("parses");
    scenario.validate(&Check { source_name: "built-in" }, None).expect("valid");
    let field = TeamField::new(strata_spl::Field::preset(&scenario.field).expect("preset"), 1.0);
    assert_eq!(scenario.paths.len(), scenario.trajectories.len());
    assert_eq!(scenario.speed_bands, vec![[0.2, 0.2]]);
    for t in scenario.paths.iter().map(|p| &p.trajectory) {
        for [x, y] in &t.waypoints {
            let p = Point::new(*x, *y);
            assert!(field.is_inside(p, 0.0), "{}: {p:?}", t.name);
            assert!(!field.in_own_penalty_area(p, 0.1), "{}: {p:?}", t.name);
        }
    }
    assert_eq!(scenario.paper.len(), 3);
}

fn head(selected: &str, goals: &[(&str, &[&str])]) -> MuxReport {
    use strata_robot::control::reactive::GoalReport;
    let goals: Vec<GoalReport> = goals
        .iter()
        .map(|(goal, objects)| GoalReport {
            goal: (*goal).into(),
            objects: objects.iter().map(|o| (*o).to_owned()).collect(),
            deliberative: 0.5,
            reactive: 0.5,
            final_score: 0.5,
            applicable: true,
        })
        .collect();
    MuxReport { goals: goals.into(), selected_goal: Some(selected.into()), ..MuxReport::default() }
}

#[test]
fn observe_ball_is_the_ball_alone_and_a_joint_gaze_is_counted_apart() {
    let goals: &[(&str, &[&str])] = &[
        ("observe ball", &[BALL]),
        ("observe ball+left", &[BALL, "left"]),
        ("observe left", &["left"]),
    ];
    assert_eq!(gaze(&head("observe ball", goals)), Gaze::Ball);
    assert_eq!(gaze(&head("observe ball+left", goals)), Gaze::BallWithOthers);
    assert_eq!(gaze(&head("observe left", goals)), Gaze::Other);
    // The baselines' plain goal names no object.
    assert_eq!(gaze(&head("observe ball", &[("observe ball", &[])])), Gaze::Ball);
    assert_eq!(gaze(&head("scan", &[("scan", &[])])), Gaze::Other);
    assert_eq!(gaze(&MuxReport::default()), Gaze::Other);

    // A quarter of the time the ball alone, a quarter jointly with a landmark.
    let trace: Vec<Sample> = (0..100)
        .map(|i| {
            let g = [Gaze::Ball, Gaze::BallWithOthers, Gaze::Other, Gaze::Other][i % 4];
            Sample {
                t: i as f64 * 0.02,
                observe_ball: g == Gaze::Ball,
                joint_gaze: g == Gaze::BallWithOthers,
                ..sample(i as f64 * 0.02, false, true, 0.1)
            }
        })
        .collect();
    let m = metrics(&trace, &Recover::default());
    assert!((m.observe_ball - 0.25).abs() < 1e-12, "{m:?}");
    assert!((m.joint_gaze - 0.25).abs() < 1e-12, "{m:?}");
    // Ball alone to joint is no switch away from the ball; joint to other and other to ball
    // are: 49 switches in 1.98 s.
    assert!((m.gaze_switches_per_min - 49.0 / (1.98 / 60.0)).abs() < 1e-6, "{m:?}");
}

/// The ball along +x until `turn_at`, then along +y, at 0.2 m/s, sampled every 0.02 s; the
/// keeper covers as well as the ideal pose from `covered_from` on.
fn turning_trace(turn_at: f64, covered_from: f64, end: f64) -> Vec<Sample> {
    (0..=(end / 0.02).round() as usize)
        .map(|i| {
            let t = i as f64 * 0.02;
            let ball =
                if t <= turn_at { (0.2 * t, 0.0) } else { (0.2 * turn_at, 0.2 * (t - turn_at)) };
            Sample {
                t,
                ball,
                coverage: if t >= covered_from - 1e-9 { 0.58 } else { 0.3 },
                ideal_coverage: 0.6,
                ..Sample::default()
            }
        })
        .collect()
}

#[test]
fn the_time_to_re_cover_runs_from_the_turn_until_the_keeper_covers_for_the_hold_time() {
    let recover = Recover { turn: 40.0, tolerance: 0.05, hold: 0.5 };
    let times = recover_times(&turning_trace(1.0, 1.6, 4.0), &recover);
    assert_eq!(times.len(), 1, "{times:?}");
    let time = times[0].expect("re-covered");
    // The turn shows in the displacement ending at the first sample after t = 1.
    assert!((time - 0.58).abs() < 1e-9, "{time}");
    // Covered, but not for the hold time before the trace ends: not re-covered.
    assert_eq!(recover_times(&turning_trace(1.0, 3.8, 4.0), &recover), vec![None]);
    let m = metrics(&turning_trace(1.0, 3.8, 4.0), &recover);
    assert_eq!((m.direction_changes, m.not_recovered), (1, 1.0));
    assert!(m.recover_time_mean.is_nan());
    // A turn smaller than the threshold is no change of direction.
    let shallow = Recover { turn: 95.0, ..recover };
    assert!(recover_times(&turning_trace(1.0, 1.6, 4.0), &shallow).is_empty());
}

#[test]
fn a_gradual_curve_changes_direction_once_per_turn_threshold() {
    // A quarter circle of radius 1 m at 0.2 m/s: 90 degrees of turning.
    let trace: Vec<Sample> = (0..=400)
        .map(|i| {
            let t = f64::from(i) * 0.02;
            let a = (0.2 * t).min(std::f64::consts::FRAC_PI_2);
            Sample {
                t,
                ball: (a.sin(), 1.0 - a.cos()),
                coverage: 0.6,
                ideal_coverage: 0.6,
                ..Sample::default()
            }
        })
        .collect();
    let times = recover_times(&trace, &Recover { turn: 40.0, tolerance: 0.05, hold: 0.5 });
    // At 40 and 80 degrees; covered all along, so at once.
    assert_eq!(times, vec![Some(0.0), Some(0.0)]);
}

fn random_section() -> RandomPaths {
    RandomPaths {
        paths: 30,
        seed: 7,
        speed: [0.1, 0.5],
        segments: [2, 4],
        min_segment: 0.5,
        region: [[-2.2, -1.7], [0.0, 1.7]],
        speed_bands: 4,
    }
}

fn paper_field() -> TeamField {
    TeamField::new(strata_spl::Field::preset("paper2010").expect("preset"), 1.0)
}

#[test]
fn random_paths_are_the_same_for_a_seed_and_respect_the_section() {
    let field = paper_field();
    let random = random_section();
    let a = random_paths(&random, &field).expect("drawn");
    let b = random_paths(&random, &field).expect("drawn");
    let as_data = |p: &[BallPath]| {
        p.iter().map(|p| (p.trajectory.waypoints.clone(), p.speed)).collect::<Vec<_>>()
    };
    assert_eq!(as_data(&a), as_data(&b));
    let other = random_paths(&RandomPaths { seed: 8, ..random_section() }, &field).expect("drawn");
    assert_ne!(as_data(&a), as_data(&other));
    assert_eq!(a.len(), 30);
    let [[x0, y0], [x1, y1]] = random.region;
    for path in &a {
        assert!(path.random);
        assert!((0.1..=0.5).contains(&path.speed), "{}: {}", path.trajectory.name, path.speed);
        let w = &path.trajectory.waypoints;
        assert!((3..=5).contains(&w.len()), "{}: {} waypoints", path.trajectory.name, w.len());
        for [x, y] in w {
            assert!((x0..=x1).contains(x) && (y0..=y1).contains(y), "{x}, {y}");
        }
        for s in w.windows(2) {
            let (a, b) = (Point::new(s[0][0], s[0][1]), Point::new(s[1][0], s[1][1]));
            assert!(a.distance(b) >= 0.5, "{}: {a:?} {b:?}", path.trajectory.name);
            for k in 0..=100 {
                let p = a.lerp(b, f64::from(k) / 100.0);
                assert!(!field.in_own_penalty_area(p, 0.05), "{}: {p:?}", path.trajectory.name);
            }
        }
    }
    // The speeds spread over the range.
    let slowest = a.iter().map(|p| p.speed).fold(f64::INFINITY, f64::min);
    let fastest = a.iter().map(|p| p.speed).fold(0.0, f64::max);
    assert!(slowest < 0.2 && fastest > 0.4, "{slowest}..{fastest}");
    // A region inside the penalty area has no segment to offer: refused, not looped on.
    let inside = RandomPaths { region: [[-3.0, -0.5], [-2.5, 0.5]], ..random_section() };
    assert!(random_paths(&inside, &field).is_err());
}

fn validated(text: &str) -> Result<Scenario, ScenarioError> {
    let mut scenario: Scenario = super::super::parse_scenario(text, "bad.toml")?;
    scenario.validate(&Check { source_name: "bad.toml" }, None)?;
    Ok(scenario)
}

const RANDOM_SCENARIO: &str = include_str!("../../scenarios/goal-covering-random.toml");

#[test]
fn the_shipped_random_scenario_draws_its_paths_into_four_speed_bands() {
    let scenario = validated(RANDOM_SCENARIO).expect("valid");
    assert_eq!(scenario.paths.len(), 40);
    assert!(scenario.trajectories.is_empty() && scenario.ball_speed.is_none());
    assert_eq!(scenario.speed_bands.len(), 4);
    for path in &scenario.paths {
        assert!(scenario.speed_band(path.speed).is_some(), "{}", path.speed);
    }
    let again = validated(RANDOM_SCENARIO).expect("valid");
    assert_eq!(
        scenario.paths.iter().map(|p| p.speed).collect::<Vec<_>>(),
        again.paths.iter().map(|p| p.speed).collect::<Vec<_>>()
    );
}

#[test]
fn a_bad_random_or_recover_value_names_the_file_and_the_field() {
    let bad = |from: &str, to: &str, field: &str| {
        assert!(RANDOM_SCENARIO.contains(from), "{from}");
        let error = validated(&RANDOM_SCENARIO.replace(from, to)).map(|_| ()).expect_err(to);
        let text = error.to_string();
        assert!(text.contains("bad.toml") && text.contains(&format!("`{field}`")), "{text}");
    };
    bad("speed = [0.1, 0.5]", "speed = [0.5, 0.1]", "random.speed");
    bad("speed = [0.1, 0.5]", "speed = [0.0, 0.5]", "random.speed[0]");
    bad("speed = [0.1, 0.5]", "speed = [0.1]", "random.speed");
    bad("paths = 40", "paths = 0", "random.paths");
    bad("segments = [2, 4]", "segments = [3, 2]", "random.segments");
    bad("min_segment = 0.5", "min_segment = -1.0", "random.min_segment");
    bad("[[-2.2, -1.7], [0.0, 1.7]]", "[[-2.2, -1.7], [0.0, 2.7]]", "random.region");
    bad("[[-2.2, -1.7], [0.0, 1.7]]", "[[-2.2, -1.7], [-2.2, 1.7]]", "random.region");
    bad("[[-2.2, -1.7], [0.0, 1.7]]", "[[-3.0, -0.5], [-2.5, 0.5]]", "random.region");
    bad("speed_bands = 4", "speed_bands = 0", "random.speed_bands");
    bad("turn = 40.0", "turn = 180.0", "recover.turn");
    bad("tolerance = 0.05", "tolerance = 1.5", "recover.tolerance");
    // Fixed trajectories need the speed they are run at.
    bad(
        "[random]",
        "[[trajectories]]\nname = \"t\"\nwaypoints = [[-1.8, 0.2], [-1.8, -0.2]]\n\n[random]",
        "ball_speed",
    );
    // Neither fixed trajectories nor random paths.
    let start = RANDOM_SCENARIO.find("[random]").expect("section");
    let end = RANDOM_SCENARIO.find("# How the time").expect("next section");
    let none = format!("{}{}", &RANDOM_SCENARIO[..start], &RANDOM_SCENARIO[end..]);
    let error = validated(&none).map(|_| ()).expect_err("no paths");
    assert!(error.to_string().contains("`trajectories`"), "{error}");
}

#[test]
fn the_learned_method_loads_the_shipped_policy_and_refuses_a_bad_one() {
    let scenario = validated(RANDOM_SCENARIO).expect("valid");
    let learned = scenario.methods.iter().position(|m| m.name == "learned").expect("learned");
    assert!(scenario.policies[learned].is_some());
    assert_eq!(scenario.policies.iter().filter(|p| p.is_some()).count(), 1);

    let shipped = "policy = \"shipped\"";
    assert!(RANDOM_SCENARIO.contains(shipped));
    let missing = RANDOM_SCENARIO.replace(shipped, "policy = \"no-such-policy.safetensors\"");
    let text = validated(&missing).map(|_| ()).expect_err("no file").to_string();
    assert!(text.contains("`methods[5].policy`") && text.contains("no-such-policy"), "{text}");

    let no_candidates = RANDOM_SCENARIO.replace(
        "team = \"full\"\npolicy = \"shipped\"",
        "team = \"always-ball\"\npolicy = \"shipped\"",
    );
    assert_ne!(no_candidates, RANDOM_SCENARIO);
    let text = validated(&no_candidates).map(|_| ()).expect_err("always-ball").to_string();
    assert!(text.contains("no gaze candidates"), "{text}");
}

fn measured(method: &str, ball_unknown: (f64, f64), pose: (f64, f64), coverage: f64) -> Condition {
    let e = |(mean, ci95): (f64, f64)| Estimate { mean, ci95, n: 60 };
    Condition {
        method: method.into(),
        deliberative_hz: 1.0,
        ball_unknown: e(ball_unknown),
        pose_error_mean: e(pose),
        coverage: e((coverage, 0.01)),
        ..Condition::default()
    }
}

/// A baseline is better on a measure only beyond the reference's interval: a tie the runs
/// cannot tell apart does not fail the reference, a clear lead on both does.
#[test]
fn a_baseline_dominates_only_beyond_the_references_interval_on_both_measures() {
    let reference = measured("value-function", (0.020, 0.007), (0.020, 0.001), 0.68);
    let met = |b: &Condition| -> Vec<bool> {
        comparison_targets("value-function", &reference, b).iter().map(|t| t.met).collect()
    };
    // Lower means, inside the interval: a tie.
    let tie = measured("always-ball", (0.019, 0.007), (0.0199, 0.001), 0.68);
    assert_eq!(met(&tie), [true, true, true, true]);
    // Better pose beyond the interval, ball unknown tied: not better on both.
    let scan = measured("fixed-scan", (0.018, 0.007), (0.013, 0.001), 0.63);
    assert_eq!(met(&scan), [true, false, true, true]);
    // Beyond the interval on both, and more coverage than the reference's interval allows.
    let clear = measured("entropy", (0.005, 0.003), (0.015, 0.001), 0.75);
    assert_eq!(met(&clear), [false, false, false, false]);
    let targets = comparison_targets("value-function", &reference, &clear);
    assert!(targets[2].what.starts_with("entropy better on both"), "{}", targets[2].what);
}
