//! The fall experiment's outputs: `falls.csv`, `pushes.csv`, `runs.csv`, the latency plots and
//! `report.md` with the targets and the 2D figures beside the T1's.

use anyhow::Result;
use strata_rcssmj::falls::{FALL_ONSET_TILT, UPRIGHT_HOLD};

use super::{Fall, Push, PushMethod, RunResult, Scenario, Summary, Target};
use crate::Ctx;
use crate::describe_load;
use crate::plot::{Bars, Panel, Series, Stack};
use crate::report::{Markdown, num, write_csv};
use crate::stats::Distribution;
use crate::stats::Estimate;

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), num)
}

pub(super) fn write_outputs(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    results: &[RunResult],
    pushes: &[Push],
    falls: &[Fall],
    s: &Summary,
) -> Result<()> {
    let rows: Vec<Vec<String>> = falls
        .iter()
        .map(|f| {
            vec![
                f.kind.to_owned(),
                f.run.to_string(),
                f.player.to_string(),
                f.cause.clone(),
                num(f.onset),
                opt(f.crossing),
                opt(f.ordered),
                opt(f.onset_to_command),
                opt(f.percept_to_command),
                opt(f.reaction),
                opt(f.onset_to_standing),
                f.helped_up.to_string(),
            ]
        })
        .collect();
    write_csv(
        &ctx.path("falls.csv"),
        &[
            "kind",
            "run",
            "player",
            "cause",
            "onset_s",
            "crossing_s",
            "ordered_s",
            "onset_to_command_s",
            "percept_to_command_s",
            "newest_percept_to_command_s",
            "onset_to_standing_s",
            "helped_up",
        ],
        &rows,
    )?;
    let rows: Vec<Vec<String>> = pushes
        .iter()
        .map(|p| {
            vec![
                p.run.to_string(),
                num(p.at),
                p.direction.to_owned(),
                p.fell.to_string(),
                p.helped_up.to_string(),
            ]
        })
        .collect();
    write_csv(&ctx.path("pushes.csv"), &["run", "at_s", "direction", "fell", "helped_up"], &rows)?;
    let rows: Vec<Vec<String>> = results
        .iter()
        .map(|r| {
            vec![
                r.kind.to_owned(),
                r.run.to_string(),
                r.seed.to_string(),
                r.robots.to_string(),
                num(r.played_s),
                num(r.walking_s),
                num(r.upright_s),
                r.falls.to_string(),
                r.false_falls.len().to_string(),
                r.false_falls.iter().map(|t| format!("{t:.2}")).collect::<Vec<_>>().join(" "),
                num(r.reactive_hz),
            ]
        })
        .collect();
    write_csv(
        &ctx.path("runs.csv"),
        &[
            "kind",
            "run",
            "seed",
            "robots",
            "played_s",
            "walking_robot_s",
            "upright_robot_s",
            "falls",
            "false_positives",
            "false_positive_times_s",
            "reactive_hz",
        ],
        &rows,
    )?;
    let figures = plot(scenario, ctx, falls)?;
    write_report(scenario, ctx, s, &figures)
}

/// Histogram bins of the latencies, ms: 10 ms wide.
pub(super) fn histogram(values_ms: &[f64]) -> (Vec<String>, Vec<Estimate>) {
    let finite: Vec<f64> = values_ms.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return (vec!["no falls".to_owned()], vec![Estimate::of(&[0.0])]);
    }
    let lo = (finite.iter().copied().fold(f64::INFINITY, f64::min) / 10.0).floor() as i64;
    let hi = (finite.iter().copied().fold(f64::NEG_INFINITY, f64::max) / 10.0).floor() as i64;
    (lo..=hi)
        .map(|bin| {
            let count = finite.iter().filter(|v| (*v / 10.0).floor() as i64 == bin).count();
            (format!("{} to {} ms", bin * 10, bin * 10 + 10), Estimate::of(&[count as f64]))
        })
        .unzip()
}

fn cdf(values_ms: &[f64]) -> Vec<(f64, f64)> {
    let mut sorted: Vec<f64> = values_ms.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len() as f64;
    sorted.iter().enumerate().map(|(i, v)| (*v, (i + 1) as f64 / n)).collect()
}

struct Plots {
    histogram: String,
    cdf: String,
}

fn plot(scenario: &Scenario, ctx: &mut Ctx<'_>, falls: &[Fall]) -> Result<Plots> {
    let onset: Vec<f64> =
        falls.iter().filter_map(|f| f.onset_to_command.map(|l| l * 1e3)).collect();
    let percept: Vec<f64> =
        falls.iter().filter_map(|f| f.percept_to_command.map(|l| l * 1e3)).collect();
    let (groups, counts) = histogram(&onset);
    let histogram = ctx.plot(
        &Bars {
            title: "T1 in rcssservermj: ground-truth onset to Fall command".into(),
            y_label: "falls".into(),
            groups,
            series: vec![("falls".into(), counts)],
            reference: None,
            targets: None,
        },
        "latency_histogram",
    )?;
    let t = &scenario.targets;
    let vertical = |x: f64| vec![(x, 0.0), (x, 1.0)];
    let cdf = ctx.plot(
        &Stack {
            title: "T1 in rcssservermj: fall detection latency, cumulative".into(),
            x_label: "ms (negative: ordered before the onset, predicted by the gyroscope)".into(),
            panels: vec![Panel {
                title: format!("{} falls with a Fall order", onset.len()),
                y_label: "fraction of falls".into(),
                y_range: Some((0.0, 1.02)),
                series: vec![
                    Series {
                        name: "ground-truth onset to command".into(),
                        points: cdf(&onset),
                        colour: 0,
                    },
                    Series {
                        name: "first percept to command".into(),
                        points: cdf(&percept),
                        colour: 1,
                    },
                    Series {
                        name: format!("paper: {:.0} ms", t.onset_to_command_ms),
                        points: vertical(t.onset_to_command_ms),
                        colour: 7,
                    },
                    Series {
                        name: format!("2 cycles: {:.0} ms", t.percept_to_command_ms),
                        points: vertical(t.percept_to_command_ms),
                        colour: 3,
                    },
                ],
            }],
        },
        "latency_cdf",
    )?;
    Ok(Plots { histogram, cdf })
}

fn ms(v: f64) -> String {
    if v.is_finite() { format!("{:.1}", v * 1000.0) } else { "n/a".to_owned() }
}

fn secs(v: f64) -> String {
    if v.is_finite() { format!("{v:.2}") } else { "n/a".to_owned() }
}

fn by_how_much(t: &Target, unit: &str) -> String {
    if !t.measured.is_finite() {
        "**no** (nothing measured)".to_owned()
    } else if t.met {
        "yes".to_owned()
    } else {
        format!("**no**: {:.1} {unit} over", t.measured - t.target)
    }
}

fn write_report(scenario: &Scenario, ctx: &mut Ctx<'_>, s: &Summary, plots: &Plots) -> Result<()> {
    let mut md =
        Markdown::new("Fall detection and recovery of T1s in rcssservermj (paper 4.3, Fig. 6)");
    what_was_run(&mut md, scenario, ctx, s);
    definitions(&mut md);
    targets(&mut md, s);
    beside_2d(&mut md, s);
    counts(&mut md, s);
    md.heading("Figures");
    md.image("Onset to Fall command, histogram", &plots.histogram);
    md.image("Fall detection latency, cumulative", &plots.cdf);
    ctx.finish_report(
        md,
        &[
            "`falls.csv`: every fall (run, robot, cause, onset, interpolated crossing, order, onset to command, percept to command, onset to standing)",
            "`pushes.csv`: every push (time, direction, whether the robot fell, whether it was helped up)",
            "`runs.csv`: every run (time played, robot-seconds walking and upright, falls, false positives and their times, reactive rate)",
            "`2d/`: the 2D simulator's fall experiment on the lockstep host, when the scenario runs it",
        ],
    )
}

/// The setting and the command that reproduces the report.
fn what_was_run(md: &mut Markdown, scenario: &Scenario, ctx: &Ctx<'_>, s: &Summary) {
    let p = &scenario.pushes;
    let w = &scenario.walking;
    md.paragraph(
        "Booster T1s in rcssservermj (MuJoCo), each a `strata robot --platform rcssservermj` \
         process under the full architecture, walking with the learned policy every 20 ms. \
         Falls are caused in physics; each robot's platform measures them against the server's \
         ground truth, and the experiment reads its report.",
    );
    md.heading("What was run");
    let scenario_arg = match &ctx.options.scenario {
        Some(path) => format!(" --scenario {}", path.display()),
        None => String::new(),
    };
    md.bullets(&[
        format!(
            "Command: `strata experiment fall --engine rcssservermj --runs {} --seed {}{scenario_arg}`",
            s.push_runs, s.seed
        ),
        format!("Scenario: {}", ctx.scenario_source),
        format!(
            "Pushes: {} run(s) x {} pushes of one T1 (player {}, team `{}`) walking after a ball \
             placed {} m ahead; pushed {} once upright {}-{} s; directions {:?} in turn",
            s.push_runs,
            p.pushes_per_run,
            p.player,
            scenario.team,
            p.chase_distance,
            match p.method {
                PushMethod::Ball => format!(
                    "by the ball shot at the torso ({} m/s, centre {} m high, from {} m on the \
                     side opposite to the push)",
                    p.ball_speed, p.ball_height, p.ball_distance
                ),
                PushMethod::Tilt => format!(
                    "by placing it tilted {} degrees towards the push's side (every joint \
                     reset to zero: the fallback, not a physical push)",
                    p.tilt_degrees
                ),
            },
            p.settle[0],
            p.settle[1],
            p.directions.iter().map(|d| d.name()).collect::<Vec<_>>()
        ),
        format!(
            "Walking: {} run(s) of {} T1s (one team, no team messages: each is a striker) \
             chasing a ball the trainer moves every {} s, {} s of play each, no pushes; their \
             collisions and stumbles are falls too",
            w.runs, w.robots, w.ball_every, w.duration
        ),
        format!(
            "The trainer puts a robot that is not standing {} s after a push back upright \
             (counted as helped up; its fall has no standing time)",
            p.recovery_timeout
        ),
        format!("Machine load: {}", describe_load(&s.machine_load_1min)),
        format!("strata {}", env!("CARGO_PKG_VERSION")),
    ]);
}

/// What each measured figure means.
fn definitions(md: &mut Markdown) {
    md.heading("Definitions");
    md.bullets(&[
        format!(
            "Onset (ground truth): the torso's tilt from the vertical passing {:.0} degrees, in \
             the orientation the server sends every 20 ms. The crossing is interpolated \
             linearly between the last perception under the angle and the first past it.",
            FALL_ONSET_TILT.to_degrees()
        ),
        "First percept that showed the fall: that first perception past the angle. \
         Percept to command: from its arrival at the robot's process to the protective Fall \
         order reaching the platform (the machine's clock). Onset to command: percept to \
         command plus the time from the interpolated crossing to that perception (at most one \
         20 ms cycle); the server runs in real time, paced by the platform. A negative value: \
         the fall detector extrapolated the tilt with the gyroscope and ordered the Fall before \
         the torso passed the angle (an order up to 0.6 s before counts for the fall)."
            .to_owned(),
        format!(
            "Standing again: the first perception of {UPRIGHT_HOLD} s in which the tilt stayed \
             under {:.0} degrees and the body was in no special motion (protective fall, lying, \
             get-up, kick). Onset to standing is measured for falls the robot got up from by \
             itself.",
            FALL_ONSET_TILT.to_degrees()
        ),
        format!(
            "False positive: a protective Fall order given with the torso under {:.0} degrees \
             that stayed under it for the following 0.6 s (the protective fall's duration). \
             Walking time: robot-seconds of the walking runs in which the robot stood (ground \
             truth: torso above 0.5 m, tilt under 10 degrees) while chasing the ball, sampled \
             every 0.5 s; of them, moving: faster than 0.05 m/s (the rest is turning, looking \
             for the ball, kicking).",
            FALL_ONSET_TILT.to_degrees()
        ),
    ]);
}

/// The paper's targets, and whether they were met.
fn targets(md: &mut Markdown, s: &Summary) {
    md.heading("Targets");
    let fp = &s.target_false_positives;
    md.table(
        &["target", "measured", "met"],
        &[
            vec![
                format!(
                    "median onset to Fall command <= {:.0} ms (the paper's)",
                    s.target_onset_to_command_ms.target
                ),
                format!(
                    "{} ms over {} falls",
                    ms(s.target_onset_to_command_ms.measured / 1000.0),
                    s.onset_to_command.n
                ),
                by_how_much(&s.target_onset_to_command_ms, "ms"),
            ],
            vec![
                format!(
                    "median first percept to Fall command <= {:.0} ms (2 cycles)",
                    s.target_percept_to_command_ms.target
                ),
                format!(
                    "{} ms over {} falls",
                    ms(s.target_percept_to_command_ms.measured / 1000.0),
                    s.percept_to_command.n
                ),
                by_how_much(&s.target_percept_to_command_ms, "ms"),
            ],
            vec![
                format!("0 false positives in {:.0} robot-minutes of walking", fp.target),
                format!(
                    "{} false positives in {:.2} robot-minutes of play chasing the ball, \
                     standing ({:.2} of them moving)",
                    s.false_positives_walking, s.playing_robot_minutes, s.walking_robot_minutes,
                ),
                if fp.met {
                    "yes".to_owned()
                } else if s.false_positives_walking > 0 {
                    format!("**no**: {} false positives", s.false_positives_walking)
                } else {
                    format!(
                        "**not shown**: none, but only {:.2} of the {:.0} minutes were played",
                        s.playing_robot_minutes, fp.target
                    )
                },
            ],
        ],
    );
}

/// The T1's figures beside the 2D simulator's.
fn beside_2d(md: &mut Markdown, s: &Summary) {
    md.heading("Results beside the 2D simulator");
    let d = |x: &Distribution, f: &dyn Fn(f64) -> String| {
        vec![f(x.median), f(x.p95), f(x.min), f(x.max), x.n.to_string()]
    };
    let mut rows = vec![
        [vec!["onset to Fall command (ms)".to_owned()], d(&s.onset_to_command, &ms)].concat(),
        [vec!["first percept to Fall command (ms)".to_owned()], d(&s.percept_to_command, &ms)]
            .concat(),
        [vec!["newest percept to Fall command (ms)".to_owned()], d(&s.reaction, &ms)].concat(),
        [vec!["onset to standing (s)".to_owned()], d(&s.onset_to_standing, &secs)].concat(),
    ];
    for row in &mut rows {
        row.insert(1, String::new());
    }
    for (row, figure) in rows.iter_mut().zip(0..) {
        row[1] = s
            .sim2d
            .iter()
            .map(|f| match figure {
                0 => format!("{:.0}", f.onset_to_command_median_ms),
                1 => "n/a".to_owned(),
                2 => format!("{:.0}", f.percepts_to_command_median_ms),
                _ => format!("{:.2}", f.standing_median_s),
            })
            .collect::<Vec<_>>()
            .join(" / ");
    }
    md.table(
        &["measure", "2D median (documented / lockstep)", "T1: median", "p95", "min", "max", "n"],
        &rows,
    );
    md.bullets(
        &s.sim2d
            .iter()
            .map(|f| {
                format!(
                    "2D, {}{}",
                    f.source,
                    f.false_positives
                        .zip(f.walking_hours)
                        .map(|(n, h)| format!(
                            "; {n} false positives in {:.1} min of walking",
                            h * 60.0
                        ))
                        .unwrap_or_default()
                )
            })
            .collect::<Vec<_>>(),
    );
    md.paragraph(
        "The 2D simulator's onset is the first instant of a scripted pendulum fall, which no \
         detector sees for about 450 ms; its \"percepts to command\" (from the percepts that \
         triggered the Fall command to the command) is the architecture's share, and compares \
         with the T1's newest percept to command. On the T1 the onset is a tilt of 20 degrees, \
         which a fall passes well before the robot is on the ground. The T1's fall detector \
         (`strata_rcssmj::controller::fall_detector`, unless the team file sets its own) orders \
         the Fall once the tilt extrapolated 0.1 s ahead with the gyroscope passes 0.5 rad \
         (28.6 degrees), or once the tilt itself passes 20 degrees, from which no T1 in games \
         caught itself: a fast fall can be ordered before its onset, a robot placed tilted at rest \
         (the tilt push) at its first percept.",
    );
}

/// What happened, counted.
fn counts(md: &mut Markdown, s: &Summary) {
    md.heading("Counts");
    md.table(
        &["measure", "value"],
        &[
            vec![
                "pushes (with a fall within the window)".to_owned(),
                format!("{} ({})", s.pushes, s.pushes_with_fall),
            ],
            vec![
                "falls: pushed + no push in the push runs + walking runs".to_owned(),
                format!(
                    "{} = {} + {} + {}",
                    s.falls, s.falls_pushed, s.falls_unpushed, s.falls_walking
                ),
            ],
            vec![
                "with a Fall order (of them before the onset perception)".to_owned(),
                format!("{} ({})", s.detected, s.ordered_before_onset),
            ],
            vec![
                "stood up by itself (helped up by the trainer)".to_owned(),
                format!("{} ({})", s.stood_up, s.helped_up),
            ],
            vec![
                "false positives: walking runs / push runs".to_owned(),
                format!("{} / {}", s.false_positives_walking, s.false_positives_pushes),
            ],
            vec!["reactive layer rate (Hz), mean over runs".to_owned(), s.reactive_hz.show(1.0, 1)],
        ],
    );
    if s.pushes > 0 && s.pushes_with_fall < s.pushes {
        md.paragraph(&format!(
            "{} of {} pushes did not make the robot fall: the walking policy caught them.",
            s.pushes - s.pushes_with_fall,
            s.pushes
        ));
    }
}
