//! The experiment's outputs: `report.md`, `phases.csv`, `robots.csv` and the figures.

use anyhow::Result;
use strata_sim::RobotId;

use super::metrics::{
    KickOffSummary, ReadyPhase, ReadySummary, RobotReady, histogram, kick_off_summary,
    ready_summary,
};
use super::{GameResult, Job, NAME, OBSERVE_PERIOD, Scenario, Summary};
use crate::Ctx;
use crate::plot::Bars;
use crate::report::{Markdown, num, pct, verdict, write_csv};
use crate::stats::{Distribution, Estimate};
use strata_games::matches::robot_name;

/// Why a robot may have missed its position: what the report and `phases.csv` say of it.
fn describe_miss(x: &RobotReady) -> String {
    let mut text = format!("{} {:.2} m", robot_name(x.robot), x.distance);
    match x.believed_ready {
        None => text.push_str(", never believed Ready"),
        Some(t) => text.push_str(&format!(", believed Ready after {t:.1} s")),
    }
    if let Some(d) = x.start_distance {
        text.push_str(&format!(", {d:.2} m from its position then"));
    }
    for (flag, what) in
        [(x.fell, ", fell"), (x.fallen, ", lying at the end"), (x.penalized, ", penalized")]
    {
        if flag {
            text.push_str(what);
        }
    }
    text
}

fn phase_kind(p: &ReadyPhase) -> &'static str {
    match (p.gesture, p.after_goal) {
        (true, _) => "gesture",
        (false, true) => "after_goal",
        (false, false) => "half_start",
    }
}

fn team_name(team: Option<usize>) -> &'static str {
    match team {
        Some(0) => "home",
        Some(_) => "away",
        None => "",
    }
}

fn half_name(first_half: bool) -> &'static str {
    if first_half { "first" } else { "second" }
}

fn opt(value: Option<f64>) -> String {
    value.map_or(String::new(), num)
}

/// `phases.csv`: one row per Ready phase and per kick-off of every game.
pub(super) fn write_phases_csv(
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[GameResult],
    within: f64,
) -> Result<()> {
    let mut rows = Vec::new();
    for (job, r) in jobs.iter().zip(results) {
        let head = |kind: &str, index: usize| {
            vec![
                job.mode().to_owned(),
                job.run.to_string(),
                job.seed.to_string(),
                kind.to_owned(),
                index.to_string(),
            ]
        };
        for (i, p) in r.ready.iter().enumerate() {
            let reached = p.robots.iter().filter(|x| x.reached).count();
            let worst = p.robots.iter().map(|x| x.distance).fold(f64::NAN, f64::max);
            let missed: Vec<String> =
                p.robots.iter().filter(|x| !x.reached).map(describe_miss).collect();
            let mut row = head("ready", i);
            row.extend([
                half_name(p.first_half).to_owned(),
                num(p.phase.start),
                num(p.phase.end),
                team_name(p.kicking_team).to_owned(),
                phase_kind(&p.phase).to_owned(),
                p.robots.len().to_string(),
                reached.to_string(),
                p.all_reached().to_string(),
                num(worst),
                String::new(),
                String::new(),
                missed.join("; "),
            ]);
            rows.push(row);
        }
        for (i, k) in r.kick_offs.iter().enumerate() {
            let delays: Vec<f64> = k.robots.iter().filter_map(|x| x.delay).collect();
            let ok = k.robots.iter().filter(|x| x.delay.is_some_and(|d| d <= within)).count();
            let worst = if k.robots.iter().any(|x| x.delay.is_none()) {
                f64::INFINITY
            } else {
                delays.iter().copied().fold(f64::NAN, f64::max)
            };
            let late: Vec<String> = k
                .robots
                .iter()
                .filter(|x| x.delay.is_none_or(|d| d > within))
                .map(|x| {
                    format!(
                        "{} {}{}",
                        robot_name(x.robot),
                        x.delay.map_or("never".to_owned(), |d| format!("{d:.2} s")),
                        if x.heard { "" } else { " did not hear it" }
                    )
                })
                .collect();
            let before_packets = k
                .robots
                .iter()
                .filter(|x| x.delay.is_none_or(|d| r.packets_after > 0.0 && d >= r.packets_after))
                .count();
            let mut row = head("kick_off", i);
            row.extend([
                half_name(k.first_half).to_owned(),
                num(k.kick_off.time),
                String::new(),
                team_name(k.kicking_team).to_owned(),
                if k.kick_off.whistle { "whistle" } else { "none" }.to_owned(),
                k.robots.len().to_string(),
                ok.to_string(),
                k.all_within(within).to_string(),
                if worst.is_infinite() { "never".to_owned() } else { num(worst) },
                num(crate::stats::percentile(&delays, 0.5)),
                before_packets.to_string(),
                late.join("; "),
            ]);
            rows.push(row);
        }
    }
    let path = ctx.path("phases.csv");
    write_csv(
        &path,
        &[
            "mode",
            "run",
            "seed",
            "kind",
            "index",
            "half",
            "start_s",
            "end_s",
            "kicking_team",
            "cause",
            "robots",
            "robots_ok",
            "all_ok",
            "worst",
            "median_delay_s",
            "not_before_packets",
            "missed",
        ],
        &rows,
    )
}

/// The columns of `robots.csv`.
const ROBOT_COLUMNS: [&str; 18] = [
    "mode",
    "run",
    "seed",
    "kind",
    "index",
    "time_s",
    "robot",
    "distance_m",
    "start_distance_m",
    "believed_ready_after_s",
    "fell",
    "fallen",
    "penalized",
    "delay_s",
    "heard_whistle",
    "duration_s",
    "own_false_whistle",
    "ok",
];

/// `robots.csv`: one row per robot per Ready phase (time: its end) and kick-off (time: the
/// whistle), and one per false start.
pub(super) fn write_robots_csv(
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[GameResult],
) -> Result<()> {
    let mut rows = Vec::new();
    for (job, r) in jobs.iter().zip(results) {
        let mut push =
            |kind: &str, index: usize, time: f64, robot: RobotId, cells: &[(&str, String)]| {
                let mut row = vec![String::new(); ROBOT_COLUMNS.len()];
                let fixed = [
                    ("mode", job.mode().to_owned()),
                    ("run", job.run.to_string()),
                    ("seed", job.seed.to_string()),
                    ("kind", kind.to_owned()),
                    ("index", index.to_string()),
                    ("time_s", num(time)),
                    ("robot", robot_name(robot)),
                ];
                for (column, value) in fixed.iter().chain(cells) {
                    if let Some(i) = ROBOT_COLUMNS.iter().position(|c| c == column) {
                        row[i] = value.clone();
                    }
                }
                rows.push(row);
            };
        for (i, p) in r.ready.iter().enumerate() {
            for x in &p.robots {
                push(
                    "ready",
                    i,
                    p.phase.end,
                    x.robot,
                    &[
                        ("distance_m", num(x.distance)),
                        ("start_distance_m", opt(x.start_distance)),
                        ("believed_ready_after_s", opt(x.believed_ready)),
                        ("fell", x.fell.to_string()),
                        ("fallen", x.fallen.to_string()),
                        ("penalized", x.penalized.to_string()),
                        ("ok", x.reached.to_string()),
                    ],
                );
            }
        }
        for (i, k) in r.kick_offs.iter().enumerate() {
            for x in &k.robots {
                push(
                    "kick_off",
                    i,
                    k.kick_off.time,
                    x.robot,
                    &[
                        ("delay_s", opt(x.delay)),
                        ("heard_whistle", x.heard.to_string()),
                        ("ok", x.delay.is_some_and(|d| d <= r.start_within).to_string()),
                    ],
                );
            }
        }
        for (i, f) in r.false_starts.iter().enumerate() {
            push(
                "false_start",
                i,
                f.time,
                f.robot,
                &[
                    ("duration_s", num(f.duration)),
                    ("own_false_whistle", f.own_whistle.to_string()),
                ],
            );
        }
    }
    let path = ctx.path("robots.csv");
    write_csv(&path, &ROBOT_COLUMNS, &rows)
}

const DELAY_EDGES: [f64; 8] = [0.0, 0.1, 0.2, 0.3, 0.5, 1.0, 5.0, 15.0];
const DELAY_BINS: [&str; 8] =
    ["< 0.1 s", "0.1-0.2", "0.2-0.3", "0.3-0.5", "0.5-1", "1-5", "5-15", ">= 15 s or never"];
const DISTANCE_EDGES: [f64; 6] = [0.0, 0.1, 0.25, 0.5, 1.0, 2.0];
const DISTANCE_BINS: [&str; 6] = ["< 0.1 m", "0.1-0.25", "0.25-0.5", "0.5-1", "1-2", ">= 2 m"];

fn bars_of(fractions: &[f64]) -> Vec<Estimate> {
    fractions.iter().map(|f| Estimate { mean: f * 100.0, ci95: 0.0, n: 1 }).collect()
}

/// The figures: the distribution of kick-off start delays and of distances at the end of
/// Ready, with signals and with `--no-delay`.
pub(super) fn plot_figures(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[GameResult],
) -> Result<[String; 2]> {
    let games = |baseline: bool| {
        jobs.iter().zip(results).filter(move |(j, _)| j.baseline == baseline).map(|(_, r)| r)
    };
    let delays = |baseline: bool| -> Vec<Option<f64>> {
        games(baseline)
            .flat_map(|r| &r.kick_offs)
            .flat_map(|k| &k.robots)
            .map(|x| x.delay)
            .collect()
    };
    let distances = |baseline: bool| -> Vec<Option<f64>> {
        games(baseline)
            .flat_map(|r| &r.ready)
            .flat_map(|p| &p.robots)
            .map(|x| Some(x.distance))
            .collect()
    };
    let mut delay_series =
        vec![("with signals".to_owned(), bars_of(&histogram(&delays(false), &DELAY_EDGES)))];
    let mut distance_series =
        vec![("with signals".to_owned(), bars_of(&histogram(&distances(false), &DISTANCE_EDGES)))];
    if jobs.iter().any(|j| j.baseline) {
        delay_series.push((
            "--no-delay (from the state change)".to_owned(),
            bars_of(&histogram(&delays(true), &DELAY_EDGES)),
        ));
        distance_series.push((
            "--no-delay".to_owned(),
            bars_of(&histogram(&distances(true), &DISTANCE_EDGES)),
        ));
    }
    let delay_png = ctx.plot(
        &Bars {
            title: format!(
                "Kick-off: whistle to each robot's decision showing Playing ({0} vs {0})",
                scenario.players
            ),
            y_label: "% of robots on the field".into(),
            groups: DELAY_BINS.iter().map(|s| (*s).to_owned()).collect(),
            series: delay_series,
            reference: None,
            targets: None,
        },
        "kick_off_delays",
    )?;
    let distance_png = ctx.plot(
        &Bars {
            title: format!(
                "End of Ready: distance to the kick-off position (tolerance {} m)",
                scenario.tolerance
            ),
            y_label: "% of robots on the field".into(),
            groups: DISTANCE_BINS.iter().map(|s| (*s).to_owned()).collect(),
            series: distance_series,
            reference: None,
            targets: None,
        },
        "ready_distances",
    )?;
    Ok([delay_png, distance_png])
}

fn show(d: Option<&Distribution>, f: impl Fn(&Distribution) -> f64) -> String {
    d.map_or("n/a".to_owned(), |d| format!("{:.2}", f(d)))
}

/// `report.md`.
pub(super) fn write_report(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    s: &Summary,
    jobs: &[Job],
    results: &[GameResult],
    figures: &[String; 2],
) -> Result<()> {
    let mut md = Markdown::new("The referee's signals: Ready gesture and kick-off whistle");
    ctx.report_head(
        NAME,
        "Under the SPL rules robots must see the head referee's Ready gesture and hear the \
         kick-off whistle; GameController3 keeps sending Standby for 45 s after the gesture and \
         Set for 15 s after the whistle. Complete games with GameController3's timing measure \
         whether the robots act on the signals themselves: every robot in its kick-off position \
         by the end of Ready, every robot playing within a second of the whistle, few false \
         starts, and what it costs in speed against GameController3's `--no-delay`.",
        &mut md,
        s.runs,
    );
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    md.heading("Setup");
    md.bullets(&[
        format!(
            "{0} vs {0}, team `{1}` on both sides, field `{2}`, noise `{3}`, halves of {4} s, lockstep host (deterministic for a seed), automatic referee with GameController3's timing and the referee's signals (`RefereeConfig::game_controller3`)",
            scenario.players, scenario.team, scenario.field, scenario.noise, scenario.half_duration
        ),
        format!(
            "Baseline: the first {} seeds again with GameController3's `--no-delay` (instant states, no signals), each run beside its seed's game with signals",
            s.baseline_runs
        ),
        format!(
            "Ready: a robot on the field (present, not penalized) at the last look before Set (looks every {} s; the referee's placement at Set moves robots) reached its kick-off position when within {} m of it (position only), in its own team's frame, which changes ends at half time",
            OBSERVE_PERIOD.as_secs_f64(),
            scenario.tolerance
        ),
        format!(
            "Kick-off: from the referee's whistle (Set -> Playing) to the first package of the robot's planning decision showing Playing; in time within {} s; robots on the field at the last look before the whistle. A robot already in Playing at the whistle counts 0 s (and as a false start)",
            scenario.start_within
        ),
        format!(
            "False start: a robot's decision going to Playing while the true game is in Set with no true whistle in the {} s before",
            scenario.false_start_window
        ),
        format!(
            "Machine: {cores} logical cores, {}; {}",
            cpu_model().unwrap_or_else(|| "CPU model unknown".to_owned()),
            if s.real_time.release_build {
                "release build"
            } else {
                "debug build (its real-time factors are not the release build's)"
            }
        ),
        format!("Machine load: {}", crate::describe_load(&s.machine_load_1min)),
        format!("Wall time of the experiment: {:.0} s", s.wall_s),
    ]);

    md.heading("Targets");
    let rows: Vec<Vec<String>> = s
        .targets
        .iter()
        .map(|t| {
            let (value, target) = if t.target > 1.0 {
                (format!("{:.0}x", t.value), format!(">= {:.0}x", t.target))
            } else {
                (pct(t.value), format!(">= {}", pct(t.target)))
            };
            vec![t.what.clone(), value, target, verdict(t.met)]
        })
        .collect();
    let mut rows = rows;
    rows.push(vec![
        "false whistle starts".to_owned(),
        format!("{} episodes", s.false_starts.episodes),
        "reported".to_owned(),
        "-".to_owned(),
    ]);
    md.table(&["measure", "value", "target", "met"], &rows);

    report_ready(s, jobs, results, &mut md);
    report_kick_offs(s, jobs, results, &mut md);
    report_false_starts(s, jobs, results, &mut md);
    report_real_time(s, &mut md);
    report_games(jobs, results, s.start_within, &mut md);

    md.heading("Figures");
    md.image("Kick-off start delays", &figures[0]);
    md.image("Distances to the kick-off position at the end of Ready", &figures[1]);
    ctx.finish_report(
        md,
        &[
            "`phases.csv`: one row per Ready phase and per kick-off of every game (robots on the field, how many made it, the worst, who missed and why)",
            "`robots.csv`: one row per robot per Ready phase (distance, fallen, when it believed Ready) and per kick-off (delay, whether it heard the whistle), and each false start",
        ],
    )
}

fn report_ready(s: &Summary, jobs: &[Job], results: &[GameResult], md: &mut Markdown) {
    md.heading("Ready phases");
    let row = |name: &str, r: &ReadySummary| {
        vec![
            name.to_owned(),
            r.phases.to_string(),
            format!("{} ({})", r.phases_reached, pct(r.phase_rate)),
            format!("{} of {} ({})", r.robots_reached, r.robots, pct(r.robot_rate)),
            show(r.distance.as_ref(), |d| d.median),
            show(r.distance.as_ref(), |d| d.p95),
            show(r.distance.as_ref(), |d| d.max),
            format!(
                "{} / {} / {} / {}",
                r.missed_fell, r.missed_fallen, r.missed_penalized, r.missed_never_ready
            ),
        ]
    };
    let mut rows = vec![
        row("signals: all", &s.ready),
        row("signals: start of a half (gesture)", &s.ready_half_start),
        row("signals: after a goal", &s.ready_after_goal),
    ];
    if s.baseline_runs > 0 {
        rows.extend([
            row("--no-delay: all", &s.baseline_ready),
            row("--no-delay: start of a half", &s.baseline_ready_half_start),
            row("--no-delay: after a goal", &s.baseline_ready_after_goal),
        ]);
    }
    md.table(
        &[
            "games",
            "Ready phases",
            "every robot reached",
            "robots reached",
            "distance median m",
            "p95 m",
            "max m",
            "missed: fell / lying at the end / penalized / never believed Ready",
        ],
        &rows,
    );
    let missed: Vec<String> = jobs
        .iter()
        .zip(results)
        .filter(|(j, _)| !j.baseline)
        .flat_map(|(j, r)| {
            r.ready.iter().enumerate().flat_map(move |(i, p)| {
                p.robots.iter().filter(|x| !x.reached).map(move |x| {
                    format!(
                        "seed {}, phase {i} ({} half, {}, {:.0} s, kicking {}): {}",
                        j.seed,
                        half_name(p.first_half),
                        match phase_kind(&p.phase) {
                            "gesture" => "after the gesture",
                            "after_goal" => "after a goal",
                            _ => "start of a half",
                        },
                        p.phase.end - p.phase.start,
                        team_name(p.kicking_team),
                        describe_miss(x)
                    )
                })
            })
        })
        .collect();
    if missed.is_empty() {
        md.paragraph(
            "Every robot on the field reached its kick-off position in every Ready phase.",
        );
    } else {
        md.paragraph(
            "Robots that missed their kick-off position (games with signals): the distance at \
             the end, when their decision first showed Ready (after a goal the packets keep \
             showing Playing for GameController3's delay and there is no gesture to see) and \
             how far from their position they were then, and what happened to them in the phase \
             (a fall, a penalty).",
        );
        md.bullets(&missed);
    }
}

fn report_kick_offs(s: &Summary, jobs: &[Job], results: &[GameResult], md: &mut Markdown) {
    md.heading("Kick-off starts");
    let row = |name: &str, k: &KickOffSummary, packets: bool| {
        vec![
            name.to_owned(),
            k.kick_offs.to_string(),
            format!("{} ({})", k.all_within, pct(k.phase_rate)),
            format!("{} of {} ({})", k.robots_within, k.robots, pct(k.robot_rate)),
            show(k.delay.as_ref(), |d| d.median),
            show(k.delay.as_ref(), |d| d.p95),
            show(k.delay.as_ref(), |d| d.max),
            if packets { k.not_before_packets.to_string() } else { "n/a".to_owned() },
            format!("{} of {}", k.heard, k.robots),
        ]
    };
    let mut rows = vec![row("signals", &s.kick_offs, true)];
    if s.baseline_runs > 0 {
        rows.push(row("--no-delay (from the state change)", &s.baseline_kick_offs, false));
    }
    md.table(
        &[
            "games",
            "kick-offs",
            &format!("every robot within {} s", s.start_within),
            "robots within",
            "delay median s",
            "p95 s",
            "max s",
            "robots not started before the packets",
            "robots that heard the whistle",
        ],
        &rows,
    );
    let late: Vec<String> = jobs
        .iter()
        .zip(results)
        .filter(|(j, _)| !j.baseline)
        .flat_map(|(j, r)| {
            r.kick_offs.iter().enumerate().flat_map(move |(i, k)| {
                k.robots.iter().filter(|x| x.delay.is_none_or(|d| d > s.start_within)).map(
                    move |x| {
                        format!(
                            "seed {}, kick-off {i} ({} half, at {:.1} s): {} {}{}",
                            j.seed,
                            half_name(k.first_half),
                            k.kick_off.time,
                            robot_name(x.robot),
                            x.delay
                                .map_or("never started".to_owned(), |d| format!("after {d:.2} s")),
                            if x.heard { "" } else { ", did not hear the whistle" }
                        )
                    },
                )
            })
        })
        .collect();
    if late.is_empty() {
        md.paragraph("Every robot on the field started in time at every kick-off.");
    } else {
        md.paragraph("Robots that started late (games with signals):");
        md.bullets(&late);
    }
}

fn report_false_starts(s: &Summary, jobs: &[Job], results: &[GameResult], md: &mut Markdown) {
    md.heading("False starts");
    let f = &s.false_starts;
    md.bullets(&[
        format!(
            "False whistle detections: {} ({} while the true game was in Set, where acting on one moves a robot before the kick-off)",
            f.false_whistles, f.false_whistles_in_set
        ),
        format!(
            "False starts (a robot's decision in Playing during Set, no true whistle in the {} s before): {} ({} by the robot's own false detection, {} following a teammate's, relayed in a team message), {:.1} robot-seconds in Playing before the kick-off in all",
            s.false_start_window,
            f.episodes,
            f.own_whistle,
            f.episodes - f.own_whistle,
            f.seconds
        ),
    ]);
    let episodes: Vec<String> = jobs
        .iter()
        .zip(results)
        .filter(|(j, _)| !j.baseline)
        .flat_map(|(j, r)| {
            r.false_starts.iter().map(move |e| {
                format!(
                    "seed {}: {} at {:.1} s, for {} s ({})",
                    j.seed,
                    robot_name(e.robot),
                    e.time,
                    if e.duration.is_finite() { format!("{:.1}", e.duration) } else { "?".into() },
                    if e.own_whistle { "its own false whistle" } else { "a teammate's, relayed" }
                )
            })
        })
        .collect();
    if !episodes.is_empty() {
        md.bullets(&episodes);
    }
}

fn report_real_time(s: &Summary, md: &mut Markdown) {
    md.heading("Real-time factor");
    let r = &s.real_time;
    md.table(
        &["games", "n", "real-time factor (mean ± 95% CI)", "lowest"],
        &[
            vec![
                "signals (GameController3 timing)".to_owned(),
                r.signals.n.to_string(),
                r.signals.show(1.0, 0),
                format!("{:.0}", r.signals_min),
            ],
            vec![
                "--no-delay (baseline, same seeds)".to_owned(),
                r.baseline.n.to_string(),
                r.baseline.show(1.0, 0),
                String::new(),
            ],
        ],
    );
    md.paragraph(&format!(
        "Signals over baseline on the baseline's seeds: {:.3}. Simulated seconds per wall second \
         of each game, {} games at a time; the games with signals are longer (Standby and \
         GameController3's Ready), so the ratio compares speed, not game length.",
        r.ratio, s.threads
    ));
}

fn report_games(jobs: &[Job], results: &[GameResult], within: f64, md: &mut Markdown) {
    md.heading("Games");
    let rows: Vec<Vec<String>> = jobs
        .iter()
        .zip(results)
        .map(|(j, r)| {
            let ready = ready_summary(&r.ready);
            let kick = kick_off_summary(&r.kick_offs, within, r.packets_after);
            vec![
                j.seed.to_string(),
                j.mode().to_owned(),
                format!("{}-{}", r.score[0], r.score[1]),
                r.finished.to_string(),
                format!("{} / {}", ready.phases_reached, ready.phases),
                format!("{} / {}", kick.all_within, kick.kick_offs),
                r.false_starts.len().to_string(),
                format!("{} ({} in Set)", r.false_whistles, r.false_whistles_in_set),
                format!("{:.0}", r.simulated_s),
                format!("{:.1}", r.wall_s),
                format!("{:.0}", r.real_time_factor),
            ]
        })
        .collect();
    md.table(
        &[
            "seed",
            "referee",
            "score",
            "finished",
            "Ready phases all reached",
            "kick-offs all in time",
            "false starts",
            "false whistles",
            "simulated s",
            "wall s",
            "real-time factor",
        ],
        &rows,
    );
}

/// The CPU's model name (Linux), for the report's machine line.
fn cpu_model() -> Option<String> {
    let text = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    text.lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split_once(':'))
        .map(|(_, v)| v.trim().to_owned())
}
