//! The figures: per rate, Fig. 4 and 5, the ball confidence, the Pareto picture.

use super::*;

/// The bar charts per rate and method: ball unknown, observe ball, pose error, coverage.
pub(super) fn plot_per_rate(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    conditions: &[Condition],
) -> Result<(String, String, String, String)> {
    let groups: Vec<String> = scenario.deliberative_hz.iter().map(|h| hz_label(*h)).collect();
    let series = |f: &dyn Fn(&Condition) -> Estimate, scale: f64| -> Vec<(String, Vec<Estimate>)> {
        scenario
            .methods
            .iter()
            .map(|m| {
                let values = scenario
                    .deliberative_hz
                    .iter()
                    .map(|hz| {
                        conditions
                            .iter()
                            .find(|c| c.method == m.name && (c.deliberative_hz - hz).abs() < 1e-9)
                            .map(|c| {
                                let e = f(c);
                                Estimate { mean: e.mean * scale, ci95: e.ci95 * scale, n: e.n }
                            })
                            .unwrap_or_default()
                    })
                    .collect();
                (m.name.clone(), values)
            })
            .collect()
    };
    let paper = |f: &dyn Fn(&PaperRow) -> f64| -> Vec<Option<f64>> {
        scenario
            .deliberative_hz
            .iter()
            .map(|hz| scenario.paper_row(*hz).map(|r| 100.0 * f(r)))
            .collect()
    };
    let unknown_png = ctx.plot(
        &Bars {
            title: "Ball position unknown (Table 5, column 3)".into(),
            y_label: "% of time".into(),
            groups: groups.clone(),
            series: series(&|c| c.ball_unknown, 100.0),
            reference: Some(("paper (Table 5)".into(), paper(&|r| r.ball_unknown))),
            targets: Some(("target".into(), paper(&|r| r.target_ball_unknown))),
        },
        "ball_unknown",
    )?;
    let observe_png = ctx.plot(
        &Bars {
            title: "Robot decides to observe the ball (Table 5, column 2)".into(),
            y_label: "% of time".into(),
            groups: groups.clone(),
            series: series(&|c| c.observe_ball, 100.0),
            reference: Some(("paper (Table 5)".into(), paper(&|r| r.observe_ball))),
            targets: None,
        },
        "observe_ball",
    )?;
    let pose_png = ctx.plot(
        &Bars {
            title: "Self-localization error (mean)".into(),
            y_label: "cm".into(),
            groups: groups.clone(),
            series: series(&|c| c.pose_error_mean, 100.0),
            reference: None,
            targets: Some((
                "target".into(),
                scenario
                    .deliberative_hz
                    .iter()
                    .map(|_| Some(100.0 * scenario.target_pose_error))
                    .collect(),
            )),
        },
        "pose_error",
    )?;
    let coverage_png = ctx.plot(
        &Bars {
            title: "Goal covered by the keeper (fraction of the goal's angle seen from the ball)"
                .into(),
            y_label: "%".into(),
            groups: groups.clone(),
            series: series(&|c| c.coverage, 100.0),
            reference: None,
            targets: None,
        },
        "coverage",
    )?;
    Ok((unknown_png, observe_png, pose_png, coverage_png))
}

/// Fig. 5: the reference method's scores and ball confidence over time, per rate.
pub(super) fn plot_fig5(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<Vec<(f64, String)>> {
    let reference_index = reference_index(scenario);
    let mut fig5 = Vec::new();
    for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
        let Some(trace) = jobs
            .iter()
            .zip(results)
            .find(|(j, _)| {
                j.method == reference_index && j.rate == r && j.trajectory == 0 && j.run == 0
            })
            .and_then(|(_, res)| res.trace.as_ref())
        else {
            continue;
        };
        let objects = plotted_objects(trace);
        let score_series = |pick: &dyn Fn(&ObjectScores) -> f64| -> Vec<Series> {
            objects
                .iter()
                .enumerate()
                .map(|(i, object)| Series {
                    name: object.clone(),
                    points: trace
                        .iter()
                        .filter_map(|s| {
                            s.scores.iter().find(|x| &x.0 == object).map(|x| (s.t, pick(x)))
                        })
                        .collect(),
                    colour: i,
                })
                .collect()
        };
        let stack = Stack {
            title: format!(
                "Goal covering, deliberative layer at {hz} Hz, reactive at {} Hz ({}, trajectory `{}`)",
                scenario.reactive_hz, scenario.reference, scenario.paths[0].trajectory.name
            ),
            x_label: "t (s)".into(),
            panels: vec![
                Panel {
                    title: "Final score for gaze direction selection".into(),
                    y_label: "score".into(),
                    y_range: Some((0.0, 1.05)),
                    series: score_series(&|x| x.3),
                },
                Panel {
                    title: "Evolution of the ball confidence".into(),
                    y_label: "confidence".into(),
                    y_range: Some((0.0, 1.05)),
                    series: vec![Series {
                        name: "ball".into(),
                        points: trace.iter().map(|s| (s.t, s.ball_confidence)).collect(),
                        colour: 0,
                    }],
                },
                Panel {
                    title: "Score calculated by the deliberative layer".into(),
                    y_label: "S_d".into(),
                    y_range: Some((0.0, 1.05)),
                    series: score_series(&|x| x.1),
                },
                Panel {
                    title: "Score calculated by the reactive layer".into(),
                    y_label: "S_r".into(),
                    y_range: Some((0.0, 1.05)),
                    series: score_series(&|x| x.2),
                },
            ],
        };
        let stem = format!("fig5_{}hz", hz).replace('.', "_");
        fig5.push((*hz, ctx.plot(&stack, &stem)?));
    }
    Ok(fig5)
}

/// Ball confidence of every method at each rate (same seed, first trajectory).
pub(super) fn plot_confidence(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<Vec<String>> {
    let mut confidence_plots = Vec::new();
    for (r, hz) in scenario.deliberative_hz.iter().enumerate() {
        let series: Vec<Series> = scenario
            .methods
            .iter()
            .enumerate()
            .filter_map(|(m, method)| {
                let trace = jobs
                    .iter()
                    .zip(results)
                    .find(|(j, _)| j.method == m && j.rate == r && j.trajectory == 0 && j.run == 0)
                    .and_then(|(_, res)| res.trace.as_ref())?;
                Some(Series {
                    name: method.name.clone(),
                    points: trace.iter().map(|s| (s.t, s.ball_confidence)).collect(),
                    colour: m,
                })
            })
            .collect();
        let stack = Stack {
            title: format!("Ball confidence, every method, deliberative layer at {hz} Hz"),
            x_label: "t (s)".into(),
            panels: vec![Panel {
                title: format!("trajectory `{}`, run 0", scenario.paths[0].trajectory.name),
                y_label: "confidence".into(),
                y_range: Some((0.0, 1.05)),
                series,
            }],
        };
        let stem = format!("confidence_{}hz", hz).replace('.', "_");
        confidence_plots.push(ctx.plot(&stack, &stem)?);
    }
    Ok(confidence_plots)
}

/// The trade-off per rate: ball unknown against mean pose error, one point per method with
/// its confidence intervals, goal coverage as the point's size.
pub(super) fn plot_pareto(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    conditions: &[Condition],
) -> Result<Vec<(f64, String)>> {
    let mut figures = Vec::new();
    for hz in &scenario.deliberative_hz {
        let scaled = |e: Estimate| Estimate { mean: e.mean * 100.0, ci95: e.ci95 * 100.0, n: e.n };
        let points = scenario
            .methods
            .iter()
            .enumerate()
            .filter_map(|(m, method)| {
                let c = conditions
                    .iter()
                    .find(|c| c.method == method.name && (c.deliberative_hz - hz).abs() < 1e-9)?;
                Some(TradeoffPoint {
                    name: method.name.clone(),
                    x: scaled(c.ball_unknown),
                    y: scaled(c.pose_error_mean),
                    size: c.coverage.mean,
                    colour: m,
                })
            })
            .collect();
        let figure = Tradeoff {
            title: format!(
                "Ball unknown against pose error at {hz} Hz (size: goal coverage; lower left is better)"
            ),
            x_label: "ball unknown (% of time)".into(),
            y_label: "mean pose error (cm)".into(),
            size_label: "coverage".into(),
            size_unit: (100.0, " %".into()),
            points,
        };
        let stem = format!("pareto_{hz}hz").replace('.', "_");
        figures.push((*hz, ctx.plot(&figure, &stem)?));
    }
    Ok(figures)
}

/// Paths drawn in Fig. 4: more make its legend longer than the field.
pub(super) const FIG4_PATHS: usize = 6;

/// Fig. 4: the trajectories (the first [`FIG4_PATHS`]), and where the keeper went.
pub(super) fn plot_fig4(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<String> {
    let reference_index = reference_index(scenario);
    let field = TeamField::new(
        strata_spl::Field::preset(&scenario.field)
            .or_else(|_| strata_spl::Field::load(&scenario.field))
            .map_err(|e| anyhow!("field {}: {e}", scenario.field))?,
        1.0,
    );
    let mid_rate = scenario.deliberative_hz.len() / 2;
    let mut paths = Vec::new();
    for (t, trajectory) in scenario.paths.iter().map(|p| &p.trajectory).enumerate().take(FIG4_PATHS)
    {
        paths.push(Series {
            name: format!("ball: {}", trajectory.name),
            points: trajectory.waypoints.iter().map(|[x, y]| (*x, *y)).collect(),
            colour: t,
        });
        if let Some(trace) = jobs
            .iter()
            .zip(results)
            .find(|(j, _)| {
                j.method == reference_index && j.rate == mid_rate && j.trajectory == t && j.run == 0
            })
            .and_then(|(_, res)| res.trace.as_ref())
        {
            paths.push(Series {
                name: format!(
                    "keeper ({}, {} Hz)",
                    trajectory.name, scenario.deliberative_hz[mid_rate]
                ),
                points: trace.iter().map(|s| s.keeper).collect(),
                colour: t + 4,
            });
        }
    }
    ctx.plot(
        &FieldPaths {
            title: if scenario.paths.len() > FIG4_PATHS {
                format!(
                    "Ball trajectories (Fig. 4; the first {FIG4_PATHS} of {}) and the keeper's true path",
                    scenario.paths.len()
                )
            } else {
                "Ball trajectories (Fig. 4) and the keeper's true path".into()
            },
            outline: field_outline(&field),
            paths,
            half_extent: (field.half_length + 0.8, field.half_width + 0.8),
        },
        "fig4_trajectories",
    )
}

/// The objects of Fig. 5: the ball and the two landmarks the head multiplexer ranked highest
/// on average (the paper shows the ball and two beacons).
pub(super) fn plotted_objects(trace: &[Sample]) -> Vec<String> {
    let mut totals: BTreeMap<String, (f64, usize)> = BTreeMap::new();
    for s in trace {
        for (object, _, _, final_score) in &s.scores {
            let e = totals.entry(object.clone()).or_default();
            e.0 += final_score;
            e.1 += 1;
        }
    }
    let mut landmarks: Vec<(String, f64)> = totals
        .into_iter()
        .filter(|(o, _)| o != BALL)
        .map(|(o, (sum, n))| (o, sum / trace.len().max(n).max(1) as f64))
        .collect();
    landmarks.sort_by(|a, b| b.1.total_cmp(&a.1));
    std::iter::once(BALL.to_owned()).chain(landmarks.into_iter().take(2).map(|(o, _)| o)).collect()
}

/// The field's lines and goals as polylines (team frame).
pub(super) fn field_outline(field: &TeamField) -> Vec<Vec<(f64, f64)>> {
    let (hl, hw) = (field.half_length, field.half_width);
    let (pl, pw) = (field.penalty_area_length, field.penalty_area_half_width);
    let gw = field.goal_half_width;
    let depth = field.field.dimensions().goal_depth;
    let r = field.center_circle_radius;
    let mut lines = vec![
        vec![(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw), (-hl, -hw)],
        vec![(0.0, -hw), (0.0, hw)],
        vec![(-hl, -pw), (-hl + pl, -pw), (-hl + pl, pw), (-hl, pw)],
        vec![(hl, -pw), (hl - pl, -pw), (hl - pl, pw), (hl, pw)],
        vec![(-hl, -gw), (-hl - depth, -gw), (-hl - depth, gw), (-hl, gw)],
        vec![(hl, -gw), (hl + depth, -gw), (hl + depth, gw), (hl, gw)],
    ];
    lines.push(
        (0..=48)
            .map(|i| {
                let a = f64::from(i) / 48.0 * std::f64::consts::TAU;
                (r * a.cos(), r * a.sin())
            })
            .collect(),
    );
    lines
}
