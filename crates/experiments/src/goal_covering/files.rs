//! The output directory: CSVs, figures and the report.

use super::*;

/// Writes every output file: the raw data, the figures and the report.
#[allow(clippy::too_many_arguments)]
pub(super) fn write_outputs(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
    conditions: &[Condition],
    bands: &[BandCondition],
    targets: &[Target],
    runs: usize,
) -> Result<()> {
    write_runs_csv(scenario, ctx, jobs, results)?;
    write_timeseries_csv(scenario, ctx, jobs, results)?;
    let (unknown_png, observe_png, pose_png, coverage_png) =
        plot_per_rate(scenario, ctx, conditions)?;
    let fig5 = plot_fig5(scenario, ctx, jobs, results)?;
    let confidence_plots = plot_confidence(scenario, ctx, jobs, results)?;
    let fig4 = plot_fig4(scenario, ctx, jobs, results)?;
    let pareto = plot_pareto(scenario, ctx, conditions)?;
    let figures = Figures {
        unknown_png,
        observe_png,
        pose_png,
        coverage_png,
        pareto,
        fig5,
        confidence_plots,
        fig4,
    };
    write_report(scenario, ctx, conditions, bands, targets, runs, figures)
}

/// The figures the report shows, as [`Ctx::plot`] names them.
pub(super) struct Figures {
    pub(super) unknown_png: String,
    pub(super) observe_png: String,
    pub(super) pose_png: String,
    pub(super) coverage_png: String,
    pub(super) pareto: Vec<(f64, String)>,
    pub(super) fig5: Vec<(f64, String)>,
    pub(super) confidence_plots: Vec<String>,
    pub(super) fig4: String,
}

/// The index of the reference method (the first when it is not among the methods).
pub(super) fn reference_index(scenario: &Scenario) -> usize {
    scenario.methods.iter().position(|m| m.name == scenario.reference).unwrap_or(0)
}

/// `runs.csv`: one row per run with every metric.
pub(super) fn write_runs_csv(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<()> {
    let rows: Vec<Vec<String>> = jobs
        .iter()
        .zip(results)
        .map(|(j, r)| {
            let m = &r.metrics;
            vec![
                scenario.methods[j.method].name.clone(),
                num(scenario.deliberative_hz[j.rate]),
                scenario.paths[j.trajectory].trajectory.name.clone(),
                num(scenario.paths[j.trajectory].speed),
                j.run.to_string(),
                j.seed.to_string(),
                m.samples.to_string(),
                num(m.observe_ball),
                num(m.joint_gaze),
                num(m.ball_unknown),
                num(m.pose_error_mean),
                num(m.pose_error_p95),
                num(m.ball_error_mean),
                num(m.coverage),
                num(m.ideal_coverage),
                num(m.gaze_switches_per_min),
                num(m.covering_behavior),
                m.direction_changes.to_string(),
                num(m.recover_time_mean),
                num(m.not_recovered),
                num(r.reactive_hz),
                num(r.deliberative_hz),
            ]
        })
        .collect();
    let runs_csv = ctx.path("runs.csv");
    write_csv(
        &runs_csv,
        &[
            "method",
            "deliberative_hz",
            "trajectory",
            "ball_speed",
            "run",
            "seed",
            "samples",
            "observe_ball",
            "joint_gaze",
            "ball_unknown",
            "pose_error_mean_m",
            "pose_error_p95_m",
            "ball_error_mean_m",
            "coverage",
            "ideal_coverage",
            "gaze_switches_per_min",
            "covering_behavior",
            "direction_changes",
            "recover_time_mean_s",
            "not_recovered",
            "reactive_hz",
            "deliberative_hz_measured",
        ],
        &rows,
    )
}

/// `timeseries.csv`: every traced sample, with the head multiplexer's scores per object.
pub(super) fn write_timeseries_csv(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<()> {
    let mut ts_rows = Vec::new();
    for (j, r) in jobs.iter().zip(results) {
        let Some(trace) = &r.trace else { continue };
        for s in trace {
            let mut row = vec![
                scenario.methods[j.method].name.clone(),
                num(scenario.deliberative_hz[j.rate]),
                scenario.paths[j.trajectory].trajectory.name.clone(),
                format!("{:.3}", s.t),
                u8::from(s.observe_ball).to_string(),
                u8::from(s.joint_gaze).to_string(),
                u8::from(s.ball_known).to_string(),
                num(s.ball_confidence),
                num(s.pose_error),
                num(s.coverage),
                num(s.keeper.0),
                num(s.keeper.1),
                num(s.keeper_heading),
                num(s.ball.0),
                num(s.ball.1),
                num(s.head.0),
                num(s.head.1),
            ];
            row.push(s.behavior.clone());
            row.push(s.reactive_path.clone());
            row.push(
                s.scores
                    .iter()
                    .map(|(o, d, r, f)| format!("{o}:{d:.3}/{r:.3}/{f:.3}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            );
            ts_rows.push(row);
        }
    }
    let ts_csv = ctx.path("timeseries.csv");
    write_csv(
        &ts_csv,
        &[
            "method",
            "deliberative_hz",
            "trajectory",
            "t",
            "observe_ball",
            "joint_gaze",
            "ball_known",
            "ball_confidence",
            "pose_error_m",
            "coverage",
            "keeper_x",
            "keeper_y",
            "keeper_theta",
            "ball_x",
            "ball_y",
            "head_yaw",
            "head_pitch",
            "behavior_path",
            "reactive_path",
            "head_scores (object:S_d/S_r/final)",
        ],
        &ts_rows,
    )
}
