//! The outputs of the rates experiment in physics: `runs.csv` and `robots.csv`, a bar chart per
//! layer (physics beside the 2D simulator and the paper), and `report.md` with each target and
//! whether it was met.

use anyhow::Result;

use super::{RunResult, Scenario, Summary};
use crate::Ctx;
use crate::plot::Bars;
use crate::rates::{LayerSummary, load_label, report_layers};
use crate::report::{Markdown, num, verdict, write_csv};
use crate::stats::Estimate;

const TITLE: &str = "Layer rates in physics: walking T1s in rcssservermj (paper 4.3, Table 6)";

pub(super) fn write_outputs(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    results: &[RunResult],
    s: &Summary,
) -> Result<()> {
    write_layers_csv(scenario, ctx, results)?;
    write_robots_csv(scenario, ctx, results)?;
    let mut figures = Vec::new();
    for layer in ["reactive", "deliberative", "planning"] {
        figures.push((layer, plot_layer(scenario, ctx, s, layer)?));
    }
    write_report(scenario, ctx, s, &figures)
}

fn find<'a>(
    layers: &'a [LayerSummary],
    role: &str,
    layer: &str,
    load: f64,
) -> Option<&'a LayerSummary> {
    layers.iter().find(|l| l.role == role && l.layer == layer && (l.load_s - load).abs() < 1e-12)
}

/// "max / mean / min" Hz, as Table 6 orders them.
fn table6_cell(l: Option<&LayerSummary>) -> String {
    l.map_or("n/a".to_owned(), |l| {
        format!(
            "{} / {} / {}",
            l.max_hz.show(1.0, 2),
            l.mean_hz.show(1.0, 2),
            l.min_hz.show(1.0, 2)
        )
    })
}

/// `runs.csv`: one row per run, load, robot and layer.
fn write_layers_csv(scenario: &Scenario, ctx: &mut Ctx<'_>, results: &[RunResult]) -> Result<()> {
    let mut rows = Vec::new();
    for r in results {
        for (spec, robot) in scenario.robots.iter().zip(&r.robots) {
            for (layer, f) in &robot.layers {
                let mut row = vec![
                    num(r.load),
                    r.run.to_string(),
                    r.seed.to_string(),
                    spec.role.clone(),
                    spec.player.to_string(),
                    layer.clone(),
                ];
                row.extend(f.csv_fields());
                rows.push(row);
            }
        }
    }
    let path = ctx.path("runs.csv");
    write_csv(
        &path,
        &[
            "load_s",
            "run",
            "seed",
            "role",
            "player",
            "layer",
            "cycles",
            "min_hz",
            "mean_hz",
            "max_hz",
            "compute_p50_ms",
            "compute_p99_ms",
            "compute_max_ms",
            "period_p50_ms",
            "period_p99_ms",
            "period_max_ms",
            "jitter_p99_ms",
        ],
        &rows,
    )
}

/// `robots.csv`: one row per run, load and robot: walking, falls, compute, the run's pace.
fn write_robots_csv(scenario: &Scenario, ctx: &mut Ctx<'_>, results: &[RunResult]) -> Result<()> {
    let mut rows = Vec::new();
    for r in results {
        for (spec, robot) in scenario.robots.iter().zip(&r.robots) {
            rows.push(vec![
                num(r.load),
                r.run.to_string(),
                r.seed.to_string(),
                spec.role.clone(),
                spec.player.to_string(),
                robot.role.clone().unwrap_or_default(),
                robot.sensor_frames.to_string(),
                num(robot.window_frames_hz),
                num(robot.walking_s),
                num(robot.upright_s),
                num(robot.observed_s),
                num(robot.path_m),
                robot.falls.to_string(),
                robot.falls_caught.to_string(),
                num(robot.compute_p50_us),
                num(robot.compute_p99_us),
                num(robot.cycle_share_p50),
                robot.ended.clone(),
                num(r.sim_s),
                num(r.wall_s),
                r.machine_load.map_or(String::new(), num),
            ]);
        }
    }
    let path = ctx.path("robots.csv");
    write_csv(
        &path,
        &[
            "load_s",
            "run",
            "seed",
            "role",
            "player",
            "assigned_role",
            "sensor_frames",
            "window_frames_hz",
            "walking_s",
            "upright_s",
            "observed_s",
            "path_m",
            "falls",
            "falls_caught",
            "compute_p50_us",
            "compute_p99_us",
            "cycle_share_p50",
            "ended",
            "run_sim_s",
            "run_wall_s",
            "machine_load_1min",
        ],
        &rows,
    )
}

/// One layer's mean rate per robot and condition: physics, the 2D simulator beside it, the
/// paper's as the reference.
fn plot_layer(scenario: &Scenario, ctx: &mut Ctx<'_>, s: &Summary, layer: &str) -> Result<String> {
    let mut groups = Vec::new();
    let mut physics = Vec::new();
    let mut sim = Vec::new();
    let mut paper = Vec::new();
    let missing = Estimate { mean: f64::NAN, ci95: f64::NAN, n: 0 };
    for robot in &scenario.robots {
        for load in &scenario.loads {
            groups.push(format!("{}, {}", robot.role, load_label(*load)));
            physics.push(find(&s.layers, &robot.role, layer, *load).map_or(missing, |l| l.mean_hz));
            sim.push(
                s.sim_2d
                    .as_ref()
                    .and_then(|sim| find(&sim.layers, &robot.role, layer, *load))
                    .map_or(missing, |l| l.mean_hz),
            );
            paper.push(
                scenario
                    .paper
                    .iter()
                    .find(|p| p.role == robot.role && p.layer == layer)
                    .map(|p| p.mean_hz),
            );
        }
    }
    let mut series = vec![("T1 in rcssservermj".to_owned(), physics)];
    if s.sim_2d.is_some() {
        series.push(("2D simulator".to_owned(), sim));
    }
    let has_paper = paper.iter().any(Option::is_some);
    let figure = Bars {
        title: format!("{layer} layer: mean frequency, without and with deliberative load"),
        y_label: "Hz".into(),
        groups,
        series,
        reference: has_paper.then(|| ("paper (Table 6, mean)".to_owned(), paper)),
        targets: None,
    };
    ctx.plot(&figure, &format!("{layer}_rate"))
}

fn write_report(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    s: &Summary,
    figures: &[(&str, String)],
) -> Result<()> {
    let mut md = Markdown::new(TITLE);
    ctx.report_head(
        super::rates2d::NAME,
        "Booster T1s walk in rcssservermj's MuJoCo physics under the full architecture; the \
         reactive layer drives the walking policy every 20 ms server cycle. Every layer's \
         frequency, compute time per cycle and period are measured and every fall is counted, \
         without and with an artificial computation in every deliberative cycle. The paper's \
         claim, where a biped's gait depends on it: deliberation does not disturb the \
         reactive layer.",
        &mut md,
        s.runs,
    );
    report_setup(scenario, s, &mut md);
    report_targets(s, &mut md);
    report_table6(scenario, s, &mut md);
    report_layers(&s.layers, &mut md);
    report_robots(s, &mut md);
    report_sim(s, &mut md);
    md.heading("Figures");
    for (layer, png) in figures {
        md.image(&format!("{layer} rate"), png);
    }
    ctx.finish_report(
        md,
        &[
            "`runs.csv`: one row per run, load, robot and layer (rates, compute-time and period percentiles)",
            "`robots.csv`: one row per run, load and robot (walking and upright time, path, falls, the process's CPU time per server cycle, the run's simulated and wall-clock time, the machine's load)",
            "`sim/`: the 2D rates experiment run by this command (its own report, CSV and scenario), when the scenario's `[sim]` asks for it",
        ],
    )
}

fn report_setup(scenario: &Scenario, s: &Summary, md: &mut Markdown) {
    md.heading("Setup");
    let rtf: Vec<String> = s
        .conditions
        .iter()
        .map(|c| format!("{} {}", load_label(c.load_s), c.real_time_factor.show(1.0, 3)))
        .collect();
    let restarts: Vec<String> = s
        .conditions
        .iter()
        .map(|c| {
            format!(
                "{}: {} placements, {} restarts",
                load_label(c.load_s),
                c.ball_placements,
                c.restarts
            )
        })
        .collect();
    let [x0, x1, y0, y1] = scenario.ball_area;
    md.bullets(&[
        format!(
            "Robots: {}, each a `strata robot --platform rcssservermj` process with the full \
             architecture on its own threaded host, team `{}`{}; every module thread at the \
             default scheduling policy (`--real-time-priority 0`: on two cores, real-time \
             threads would starve the server the robots wait for)",
            scenario
                .robots
                .iter()
                .map(|r| format!("{} (player {})", r.role, r.player))
                .collect::<Vec<_>>()
                .join(", "),
            scenario.team,
            if scenario.team_messages { ", team messages over UDP" } else { ", no team messages" }
        ),
        "Server: rcssservermj in sync mode, a fresh one per run, paced to real time by the \
         robots (each answer waits for the end of its 20 ms cycle)"
            .to_owned(),
        format!(
            "{} s of simulation per run and condition from the kick-off (after {} s of the \
             game's Ready), runs per condition: {}, conditions alternating within a run; \
             loads per deliberative cycle: {}",
            scenario.duration,
            scenario.ready,
            s.runs,
            scenario
                .loads
                .iter()
                .map(|l| format!("{:.0} ms", l * 1000.0))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        format!(
            "Trainer (monitor port): kicks off, then places the ball at a random point of x in \
             [{x0}, {x1}], y in [{y0}, {y1}] m every {} s, and restarts play when the referee \
             stops it ({})",
            scenario.ball_period,
            restarts.join("; ")
        ),
        format!(
            "Walking, from the ground truth: a 1 s window in which the torso stayed upright \
             (tilt under 20 degrees, the platform's fall onset) and moved at least {} m/s or \
             turned at least {} rad/s; falls are the platform's ground-truth onsets (tilt past 20 \
             degrees) between the kick-off and the stop",
            scenario.walking_speed, scenario.turning_speed
        ),
        format!(
            "Real-time factor (simulated over wall-clock seconds, kick-off to stop): {}",
            rtf.join(", ")
        ),
        format!(
            "Machine: {} logical cores; load {}",
            std::thread::available_parallelism().map_or(1, |n| n.get()),
            crate::describe_load(&s.machine_load_1min)
        ),
        "Rates: min and max over 1 s windows, over each robot's whole run (its Ready \
         included); jitter is the cycle period's 99th percentile minus its median"
            .to_owned(),
    ]);
}

fn report_targets(s: &Summary, md: &mut Markdown) {
    md.heading("Targets");
    let mut rows = Vec::new();
    for c in &s.reactive {
        let shortfall = if c.reactive_rate_kept {
            String::new()
        } else {
            format!(", {:.1} points short", (s.tolerance - c.ratio) * 100.0)
        };
        rows.push(vec![
            format!(
                "{}: reactive rate under +{:.0} ms per deliberative cycle >= {:.0}% of its rate \
                 without",
                c.role,
                c.load_s * 1000.0,
                s.tolerance * 100.0
            ),
            format!(
                "{:.2} -> {:.2} Hz ({:.1}%{shortfall})",
                c.unloaded_reactive_hz,
                c.loaded_reactive_hz,
                c.ratio * 100.0
            ),
            verdict(c.reactive_rate_kept),
        ]);
    }
    for f in &s.falls {
        let ratio = match &f.ratio {
            Some(r) => format!(
                "; ratio {} (95% CI {} to {}){}",
                show_ratio(r.ratio),
                show_ratio(r.low),
                show_ratio(r.high),
                if f.not_higher || !f.measured {
                    String::new()
                } else {
                    format!(", its lower end {} above 1", show_ratio(r.low))
                }
            ),
            None if f.measured => "; no falls in either condition".to_owned(),
            None => String::new(),
        };
        rows.push(vec![
            format!(
                "falls per walking minute under +{:.0} ms not higher than without (95% CI of \
                 the ratio reaches 1)",
                f.load_s * 1000.0
            ),
            if f.measured {
                format!(
                    "without: {} falls in {:.2} min, {}; with: {} in {:.2} min, {}{ratio}",
                    f.unloaded.events,
                    f.unloaded.exposure,
                    f.unloaded.show(3),
                    f.loaded.events,
                    f.loaded.exposure,
                    f.loaded.show(3)
                )
            } else {
                "not measured: a condition had no walking".to_owned()
            },
            verdict(f.not_higher),
        ]);
    }
    for c in &s.reactive {
        let applied = find(&s.layers, &c.role, "deliberative", c.load_s)
            .map_or("n/a".to_owned(), |l| format!("{} ms", l.compute_p50_ms.show(1.0, 1)));
        rows.push(vec![
            format!("{}: the load ran (deliberative compute p50 >= 95% of it)", c.role),
            format!("compute p50 {applied} for a {:.0} ms load", c.load_s * 1000.0),
            verdict(c.load_applied),
        ]);
    }
    md.table(&["target", "measured", "met"], &rows);
    let frames: Vec<String> = s
        .robots
        .iter()
        .map(|r| {
            format!(
                "{}, {}: {} cycles per perception, {} Hz",
                r.role,
                load_label(r.load_s),
                r.reactive_per_frame.show(1.0, 3),
                r.window_reactive_hz.show(1.0, 2)
            )
        })
        .collect();
    md.paragraph(&format!(
        "The reactive layer is triggered by each perception, one per 20 ms server cycle, and \
         the server steps when every robot has answered: the reactive rate in Hz is also the \
         pace at which the machine lets the server and the robots' connection threads run. Two \
         figures the whole-run rates above do not show: reactive cycles per perceived server \
         cycle (1: the layer acted on every perception, whatever the pace), and the reactive \
         rate over the measured window only, kick-off to stop (the perceived server cycles per \
         second of the robot's clock, from its status lines, times the cycles per perception; \
         the whole-run rates include the start and the Ready): {}.",
        frames.join("; ")
    ));
}

fn show_ratio(value: f64) -> String {
    if value.is_infinite() { "infinite".to_owned() } else { format!("{value:.2}") }
}

/// Table 6: the paper's, the 2D simulator's and the T1's, per role, layer and load.
fn report_table6(scenario: &Scenario, s: &Summary, md: &mut Markdown) {
    md.heading("Table 6, beside the paper's and the 2D simulator's");
    let mut headers = vec!["mission / role".to_owned(), "layer".to_owned(), "paper".to_owned()];
    for load in &scenario.loads {
        if s.sim_2d.is_some() {
            headers.push(format!("2D, {}", load_label(*load)));
        }
        headers.push(format!("T1, {}", load_label(*load)));
    }
    let mut rows = Vec::new();
    for robot in &scenario.robots {
        for layer in ["reactive", "deliberative", "planning"] {
            let paper = scenario.paper.iter().find(|p| p.role == robot.role && p.layer == layer);
            let mut row = vec![
                robot.role.clone(),
                layer.to_owned(),
                paper.map_or("n/a".into(), |p| {
                    format!("{} / {} / {}", p.max_hz, p.mean_hz, p.min_hz)
                }),
            ];
            for load in &scenario.loads {
                if let Some(sim) = &s.sim_2d {
                    row.push(table6_cell(find(&sim.layers, &robot.role, layer, *load)));
                }
                row.push(table6_cell(find(&s.layers, &robot.role, layer, *load)));
            }
            rows.push(row);
        }
    }
    let headers: Vec<&str> = headers.iter().map(String::as_str).collect();
    md.table(&headers, &rows);
    md.paragraph(
        "Each cell: max / mean / min Hz (mean ± 95% CI over runs where there are several). The \
         T1's perception, world modeling and reactive layer follow the server's 20 ms cycle \
         (50 Hz); the 2D simulator's sensors run at the NAO's 83 Hz; the paper's robot was a \
         NAO with a 500 MHz processor.",
    );
}

fn report_robots(s: &Summary, md: &mut Markdown) {
    md.heading("Walking, falls and compute per robot");
    let rows: Vec<Vec<String>> = s
        .robots
        .iter()
        .map(|r| {
            vec![
                r.role.clone(),
                load_label(r.load_s),
                if r.assigned_roles.is_empty() {
                    "n/a".to_owned()
                } else {
                    r.assigned_roles.join(", ")
                },
                format!("{:.2}", r.walking_min),
                format!("{:.2}", r.upright_min),
                r.path_m.show(1.0, 1),
                format!("{} ({} caught)", r.falls, r.falls_caught),
                r.reactive_per_frame.show(1.0, 3),
                r.window_frames_hz.show(1.0, 2),
                r.compute_p50_us.show(1.0, 0),
                r.compute_p99_us.show(1.0, 0),
                r.cycle_share_p50.show(100.0, 1),
            ]
        })
        .collect();
    md.table(
        &[
            "robot",
            "condition",
            "role assigned",
            "walking (min)",
            "upright (min)",
            "path per run (m)",
            "falls (protective fall ordered)",
            "reactive cycles per server cycle",
            "server cycles per s, kick-off to stop",
            "process CPU per cycle p50 (us)",
            "p99 (us)",
            "share of the 20 ms cycle, p50 (%)",
        ],
        &rows,
    );
    let rows: Vec<Vec<String>> = s
        .conditions
        .iter()
        .map(|c| {
            vec![
                load_label(c.load_s),
                c.falls_per_walking_min.events.to_string(),
                format!("{:.2}", c.falls_per_walking_min.exposure),
                c.falls_per_walking_min.show(3),
                format!("{:.2}", c.falls_per_upright_min.exposure),
                c.falls_per_upright_min.show(3),
            ]
        })
        .collect();
    md.table(
        &[
            "condition",
            "falls",
            "walking (min)",
            "falls per walking minute (95% CI)",
            "upright (min)",
            "falls per upright minute (95% CI)",
        ],
        &rows,
    );
    md.paragraph(
        "The intervals are exact (Garwood for a rate, Clopper-Pearson on the conditional \
         binomial for the ratio of two): fall counts are small.",
    );
}

fn report_sim(s: &Summary, md: &mut Markdown) {
    md.heading("The 2D simulator, same roles, same command");
    match (&s.sim_2d, &s.sim_2d_command) {
        (Some(sim), Some(command)) => {
            let rows: Vec<Vec<String>> = sim
                .claims
                .iter()
                .map(|c| {
                    vec![
                        c.role.clone(),
                        format!("{:.2}", c.unloaded_reactive_hz),
                        format!("{:.2}", c.loaded_reactive_hz),
                        format!("{:.1}%", c.ratio * 100.0),
                    ]
                })
                .collect();
            md.table(
                &["role", "reactive Hz, no load", "reactive Hz, +200 ms load", "ratio"],
                &rows,
            );
            md.paragraph(&format!(
                "Run just before this report on the same machine ({} s per condition, {} run(s); \
                 its report: `sim/report.md`). Again: `{command}`. The full 2D experiment \
                 (60 s, 2 runs): `strata experiment rates`; docs/experiments.md records it.",
                sim.duration_s, sim.runs
            ));
        }
        _ => md.paragraph(
            "Not run by this command (the scenario's `[sim] duration` is 0). The 2D figures: \
             `strata experiment rates` (docs/experiments.md records them).",
        ),
    }
}
