//! `strata experiment team` (paper 4.4): complete simulated games. The full architecture plays
//! its baselines (no coordination: no team messages, every field player a striker; no active
//! vision: a fixed head scan), 4 vs 4 (the paper's games) and 7 vs 7, for many seeds, sides
//! alternating; and full-architecture teams play each other with 0 to 100% of the team
//! messages lost, to see how the planning layer's role assignment degrades.

use std::path::Path;

use anyhow::Result;
use serde::{Deserialize, Serialize};
use strata_sim::NoiseLevel;
use strata_soccer::team::TeamConfig;

use super::plot::{Bars, distribution_bars};
use super::report::{Markdown, num, write_csv};
use super::stats::Estimate;
use super::{Check, Ctx, ScenarioError, Validate, finish_log};
use strata_games::logging::{LogSettings, MatchLog};
use strata_games::matches::{Match, MatchConfig, MatchReport, TeamReport};

pub const NAME: &str = "team";
pub const DEFAULT_SCENARIO: &str = include_str!("../scenarios/team.toml");

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    pub field: String,
    pub noise: String,
    /// Length of a half, s.
    pub half_duration: f64,
    /// Matches per (baseline, team size): seeds seed .. seed + runs - 1.
    pub runs: usize,
    /// Robots per team.
    pub players: Vec<u8>,
    /// The full architecture: a built-in team or a team file.
    pub reference: String,
    pub baselines: Vec<String>,
    pub loss: Loss,
    /// The referee sends every state at once (GameController3's `--no-delay`); otherwise
    /// GameController3's delays, and the robots act on the referee's whistle and gesture.
    #[serde(default)]
    pub no_delay: bool,
    #[serde(skip)]
    resolved_reference: Option<TeamConfig>,
    #[serde(skip)]
    resolved_baselines: Vec<TeamConfig>,
    #[serde(skip)]
    resolved_loss_team: Option<TeamConfig>,
    #[serde(skip)]
    noise_level: Option<NoiseLevel>,
}

/// Role statistics under team-message loss: the same team on both sides.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Loss {
    /// Fractions of team messages lost.
    pub levels: Vec<f64>,
    pub players: Vec<u8>,
    pub runs: usize,
    pub team: String,
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        self.field = check.field_preset("field", &self.field, dir)?;
        self.noise_level = Some(check.noise("noise", &self.noise)?);
        check.positive("half_duration", self.half_duration)?;
        check.at_least("runs", self.runs, 1)?;
        for (name, players) in [("players", &self.players), ("loss.players", &self.loss.players)] {
            for (i, p) in players.iter().enumerate() {
                if !(1..=7).contains(p) {
                    return Err(
                        check.fail(&format!("{name}[{i}]"), format!("must be 1 to 7, got {p}"))
                    );
                }
            }
        }
        self.resolved_reference = Some(check.team("reference", &self.reference, dir)?);
        self.resolved_baselines.clear();
        for (i, b) in self.baselines.iter().enumerate() {
            self.resolved_baselines.push(check.team(&format!("baselines[{i}]"), b, dir)?);
        }
        for (i, level) in self.loss.levels.iter().enumerate() {
            check.fraction(&format!("loss.levels[{i}]"), *level)?;
        }
        self.resolved_loss_team = Some(check.team("loss.team", &self.loss.team, dir)?);
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Metric functions.

/// A match from one team's side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Win,
    Draw,
    Loss,
}

pub fn outcome(goals_for: u8, goals_against: u8) -> Outcome {
    match goals_for.cmp(&goals_against) {
        std::cmp::Ordering::Greater => Outcome::Win,
        std::cmp::Ordering::Equal => Outcome::Draw,
        std::cmp::Ordering::Less => Outcome::Loss,
    }
}

/// Wins, draws and losses.
pub fn record(outcomes: &[Outcome]) -> [usize; 3] {
    let count = |o: Outcome| outcomes.iter().filter(|x| **x == o).count();
    [count(Outcome::Win), count(Outcome::Draw), count(Outcome::Loss)]
}

/// What the role statistics of one team in one match say (the columns of `loss.csv`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TeamRoles {
    pub strikers_histogram: [f64; 4],
    pub one_striker: f64,
    pub double_striker_s: f64,
    /// Fraction of the sampled play with two or more strikers.
    pub double_striker_fraction: f64,
    pub role_switches_per_minute: f64,
    pub messages_sent: u64,
    /// Messages sent over the game's budget (1200 per team per game).
    pub budget_used: f64,
}

pub fn team_roles(team: &TeamReport, budget: u16) -> TeamRoles {
    let h = team.roles.strikers_histogram;
    TeamRoles {
        strikers_histogram: h,
        one_striker: team.roles.one_striker,
        double_striker_s: team.roles.double_striker_s,
        double_striker_fraction: h[2] + h[3],
        role_switches_per_minute: team.roles.role_switches_per_minute,
        messages_sent: team.messages_sent,
        budget_used: team.messages_sent as f64 / f64::from(budget.max(1)),
    }
}

// ---------------------------------------------------------------------------------------------
// Runs.

#[derive(Clone, Debug)]
enum Job {
    /// The reference against a baseline; the reference plays home when `home`.
    Versus {
        baseline: usize,
        players: u8,
        run: usize,
        seed: u64,
        home: bool,
    },
    Loss {
        level: usize,
        players: u8,
        run: usize,
        seed: u64,
    },
}

/// One match's result; a job record holds it (`crate::records`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct RunResult {
    report: MatchReport,
}

fn play(
    scenario: &Scenario,
    job: &Job,
    log: Option<&Path>,
    tick: &dyn Fn(u64),
) -> Result<RunResult> {
    let (home, away, players, seed, loss) = match job {
        Job::Versus { baseline, players, seed, home, .. } => {
            let reference = scenario.resolved_reference.clone().unwrap_or_default();
            let baseline = scenario.resolved_baselines[*baseline].clone();
            let (h, a) = if *home { (reference, baseline) } else { (baseline, reference) };
            (h, a, *players, *seed, 0.0)
        }
        Job::Loss { level, players, seed, .. } => {
            let team = scenario.resolved_loss_team.clone().unwrap_or_default();
            (team.clone(), team, *players, *seed, scenario.loss.levels[*level])
        }
    };
    let config = MatchConfig {
        players,
        seed,
        home,
        away,
        half_duration: scenario.half_duration,
        // Ready and Set after goals and the half-time break run outside the game clock.
        limit: Some(2.0 * scenario.half_duration + 900.0),
        noise: scenario.noise_level.unwrap_or_default(),
        field: scenario.field.clone(),
        packet_loss: loss,
        realtime: false,
        sim: None,
        no_delay: scenario.no_delay,
    };
    let mut game = Match::new(config)?;
    // A match log, as `strata match --log` writes it: replay and the viewer read it.
    let log = match log {
        Some(path) => Some(MatchLog::attach(&mut game, &LogSettings::full(path))?),
        None => None,
    };
    let mut done = 0.0f64;
    let total = match_seconds(scenario);
    let report = game.play(&mut |fraction, _| {
        let now = (fraction * total).floor();
        if now > done {
            tick((now - done) as u64);
            done = now;
        }
    })?;
    if total > done {
        tick((total - done) as u64);
    }
    if let Some(log) = &log {
        finish_log(log.tap());
    }
    Ok(RunResult { report })
}

fn match_seconds(scenario: &Scenario) -> f64 {
    2.0 * scenario.half_duration + 900.0
}

// ---------------------------------------------------------------------------------------------
// The experiment.

#[derive(Clone, Debug, Serialize)]
pub struct Versus {
    pub reference: String,
    pub baseline: String,
    pub players: u8,
    pub matches: usize,
    pub wins: usize,
    pub draws: usize,
    pub losses: usize,
    pub goal_difference: Estimate,
    pub goals_for: Estimate,
    pub goals_against: Estimate,
    pub finished: usize,
    /// The reference team's role statistics in these games.
    pub one_striker: Estimate,
    pub double_striker_s: Estimate,
    pub role_switches_per_minute: Estimate,
    pub budget_used: Estimate,
    pub real_time_factor: Estimate,
}

#[derive(Clone, Debug, Serialize)]
pub struct LossCondition {
    pub loss: f64,
    pub players: u8,
    /// Team samples (two per match).
    pub teams: usize,
    pub strikers_histogram: [Estimate; 4],
    pub one_striker: Estimate,
    pub double_striker_s: Estimate,
    pub double_striker_fraction: Estimate,
    pub role_switches_per_minute: Estimate,
    pub messages_sent: Estimate,
    pub budget_used: Estimate,
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub scenario: String,
    pub seed: u64,
    pub runs: usize,
    pub half_duration: f64,
    pub versus: Vec<Versus>,
    pub loss: Vec<LossCondition>,
}

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let runs = ctx.runs(scenario.runs);
    let loss_runs = ctx.options.runs.unwrap_or(scenario.loss.runs).max(1);
    let mut jobs = Vec::new();
    for players in &scenario.players {
        for baseline in 0..scenario.baselines.len() {
            for run in 0..runs {
                // Sides alternate: the kick-off and the first half's end are not an advantage.
                jobs.push(Job::Versus {
                    baseline,
                    players: *players,
                    run,
                    seed: ctx.seed(run),
                    home: run % 2 == 0,
                });
            }
        }
    }
    for players in &scenario.loss.players {
        for level in 0..scenario.loss.levels.len() {
            for run in 0..loss_runs {
                jobs.push(Job::Loss { level, players: *players, run, seed: ctx.seed(run) });
            }
        }
    }
    let bar = ctx.progress((match_seconds(scenario) * jobs.len() as f64) as u64, "simulated s");
    let log = ctx.options.log.clone();
    let results = ctx.run_jobs(&jobs, |i, job| {
        play(scenario, job, log.as_deref().filter(|_| i == 0), &|n| bar.inc(n))
    })?;
    bar.finish_and_clear();

    let mut versus = Vec::new();
    for players in &scenario.players {
        for (b, baseline) in scenario.baselines.iter().enumerate() {
            let games: Vec<(&MatchReport, usize)> = jobs
                .iter()
                .zip(&results)
                .filter_map(|(j, r)| match j {
                    Job::Versus { baseline, players: p, home, .. }
                        if *baseline == b && p == players =>
                    {
                        Some((&r.report, if *home { 0 } else { 1 }))
                    }
                    _ => None,
                })
                .collect();
            let outcomes: Vec<Outcome> =
                games.iter().map(|(r, us)| outcome(r.score[*us], r.score[1 - us])).collect();
            let [wins, draws, losses] = record(&outcomes);
            let e = |f: &dyn Fn(&MatchReport, usize) -> f64| {
                Estimate::of(&games.iter().map(|(r, us)| f(r, *us)).collect::<Vec<_>>())
            };
            versus.push(Versus {
                reference: scenario.reference.clone(),
                baseline: baseline.clone(),
                players: *players,
                matches: games.len(),
                wins,
                draws,
                losses,
                goal_difference: e(&|r, us| f64::from(r.score[us]) - f64::from(r.score[1 - us])),
                goals_for: e(&|r, us| f64::from(r.score[us])),
                goals_against: e(&|r, us| f64::from(r.score[1 - us])),
                finished: games.iter().filter(|(r, _)| r.finished).count(),
                one_striker: e(&|r, us| r.teams[us].roles.one_striker),
                double_striker_s: e(&|r, us| r.teams[us].roles.double_striker_s),
                role_switches_per_minute: e(&|r, us| r.teams[us].roles.role_switches_per_minute),
                budget_used: e(&|r, us| r.teams[us].messages_sent as f64 / 1200.0),
                real_time_factor: e(&|r, _| r.real_time_factor),
            });
        }
    }
    let mut loss = Vec::new();
    for players in &scenario.loss.players {
        for (l, level) in scenario.loss.levels.iter().enumerate() {
            let teams: Vec<TeamRoles> = jobs
                .iter()
                .zip(&results)
                .filter(|(j, _)| matches!(j, Job::Loss { level, players: p, .. } if *level == l && p == players))
                .flat_map(|(_, r)| r.report.teams.iter().map(|t| team_roles(t, 1200)).collect::<Vec<_>>())
                .collect();
            let e = |f: &dyn Fn(&TeamRoles) -> f64| {
                Estimate::of(&teams.iter().map(f).collect::<Vec<_>>())
            };
            loss.push(LossCondition {
                loss: *level,
                players: *players,
                teams: teams.len(),
                strikers_histogram: [0, 1, 2, 3].map(|k| e(&|t| t.strikers_histogram[k])),
                one_striker: e(&|t| t.one_striker),
                double_striker_s: e(&|t| t.double_striker_s),
                double_striker_fraction: e(&|t| t.double_striker_fraction),
                role_switches_per_minute: e(&|t| t.role_switches_per_minute),
                messages_sent: e(&|t| t.messages_sent as f64),
                budget_used: e(&|t| t.budget_used),
            });
        }
    }
    let summary = Summary {
        experiment: NAME.to_owned(),
        scenario: ctx.scenario_source.clone(),
        seed: ctx.options.seed,
        runs,
        half_duration: scenario.half_duration,
        versus,
        loss,
    };
    write_outputs(scenario, ctx, &jobs, &results, &summary, runs, loss_runs)?;
    Ok(summary)
}

/// Writes every output file: the raw data, the figures and the report.
#[allow(clippy::too_many_arguments)]
fn write_outputs(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
    s: &Summary,
    runs: usize,
    loss_runs: usize,
) -> Result<()> {
    write_matches_csv(scenario, ctx, jobs, results)?;
    let (gd_png, hist_png, conflicts_png, budget_png) = plot_figures(scenario, ctx, s)?;
    let figures = Figures { gd_png, hist_png, conflicts_png, budget_png };
    write_report(scenario, ctx, s, runs, loss_runs, figures)
}

/// `matches.csv`: one row per team per match.
fn write_matches_csv(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    jobs: &[Job],
    results: &[RunResult],
) -> Result<()> {
    let mut rows = Vec::new();
    for (job, r) in jobs.iter().zip(results) {
        let (kind, condition, players, run, seed) = match job {
            Job::Versus { baseline, players, run, seed, home } => (
                "versus",
                format!(
                    "{} vs {}{}",
                    scenario.reference,
                    scenario.baselines[*baseline],
                    if *home { " (home)" } else { " (away)" }
                ),
                *players,
                *run,
                *seed,
            ),
            Job::Loss { level, players, run, seed } => {
                ("loss", format!("loss {}", scenario.loss.levels[*level]), *players, *run, *seed)
            }
        };
        let m = &r.report;
        for (t, team) in m.teams.iter().enumerate() {
            let roles = team_roles(team, 1200);
            rows.push(vec![
                kind.to_owned(),
                condition.clone(),
                players.to_string(),
                run.to_string(),
                seed.to_string(),
                if t == 0 { "home" } else { "away" }.to_owned(),
                team.name.clone(),
                team.goals.to_string(),
                m.score[1 - t].to_string(),
                m.finished.to_string(),
                num(m.simulated_s),
                team.falls.to_string(),
                team.penalties.to_string(),
                num(roles.strikers_histogram[0]),
                num(roles.strikers_histogram[1]),
                num(roles.strikers_histogram[2]),
                num(roles.strikers_histogram[3]),
                num(roles.double_striker_s),
                num(roles.role_switches_per_minute),
                roles.messages_sent.to_string(),
                team.message_budget_left.to_string(),
                num(m.real_time_factor),
            ]);
        }
    }
    let csv = ctx.path("matches.csv");
    write_csv(
        &csv,
        &[
            "kind",
            "condition",
            "players",
            "run",
            "seed",
            "side",
            "team",
            "goals_for",
            "goals_against",
            "finished",
            "simulated_s",
            "falls",
            "penalties",
            "strikers_0",
            "strikers_1",
            "strikers_2",
            "strikers_3_or_more",
            "double_striker_s",
            "role_switches_per_min",
            "messages_sent",
            "budget_left",
            "real_time_factor",
        ],
        &rows,
    )
}

/// The figures: goals against the baselines; strikers, conflicts and messages by loss.
fn plot_figures(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    s: &Summary,
) -> Result<(String, String, String, String)> {
    // Figures.
    let versus_groups: Vec<String> = s
        .versus
        .iter()
        .map(|v| format!("vs {} ({}v{})", v.baseline, v.players, v.players))
        .collect();
    let gd_png = ctx.plot(
        &Bars {
            title: format!("Goal difference of `{}` against the baselines", scenario.reference),
            y_label: "goals per match (for - against); bars start at 0".into(),
            groups: versus_groups.clone(),
            series: vec![
                ("goals for".into(), s.versus.iter().map(|v| v.goals_for).collect()),
                ("goals against".into(), s.versus.iter().map(|v| v.goals_against).collect()),
            ],
            reference: None,
            targets: None,
        },
        "goals",
    )?;
    let loss_groups: Vec<String> = s
        .loss
        .iter()
        .map(|l| format!("{:.0}% loss ({}v{})", l.loss * 100.0, l.players, l.players))
        .collect();
    let hist: Vec<Vec<Estimate>> = s
        .loss
        .iter()
        .map(|l| {
            l.strikers_histogram
                .iter()
                .map(|e| Estimate { mean: e.mean * 100.0, ci95: e.ci95 * 100.0, n: e.n })
                .collect()
        })
        .collect();
    let hist_png = ctx.plot(
        &distribution_bars(
            "Strikers per team over time, by team-message loss",
            "% of sampled play",
            loss_groups.clone(),
            &["0 strikers", "1 striker", "2 strikers", "3 or more"],
            &hist,
        ),
        "strikers_histogram",
    )?;
    let conflicts_png = ctx.plot(
        &Bars {
            title: "Double-striker conflicts and role switches, by team-message loss".into(),
            y_label: "s per match / switches per robot-minute x 10".into(),
            groups: loss_groups.clone(),
            series: vec![
                (
                    "double-striker time (s)".into(),
                    s.loss.iter().map(|l| l.double_striker_s).collect(),
                ),
                (
                    "role switches per robot-minute x 10".into(),
                    s.loss
                        .iter()
                        .map(|l| Estimate {
                            mean: l.role_switches_per_minute.mean * 10.0,
                            ci95: l.role_switches_per_minute.ci95 * 10.0,
                            n: l.role_switches_per_minute.n,
                        })
                        .collect(),
                ),
            ],
            reference: None,
            targets: None,
        },
        "conflicts",
    )?;
    let budget_png = ctx.plot(
        &Bars {
            title: "Team messages used, against the budget of 1200 per game".into(),
            y_label: "% of the budget".into(),
            groups: loss_groups,
            series: vec![(
                "messages sent".into(),
                s.loss
                    .iter()
                    .map(|l| Estimate {
                        mean: l.budget_used.mean * 100.0,
                        ci95: l.budget_used.ci95 * 100.0,
                        n: l.budget_used.n,
                    })
                    .collect(),
            )],
            reference: None,
            targets: Some(("budget".into(), s.loss.iter().map(|_| Some(100.0)).collect())),
        },
        "budget",
    )?;
    Ok((gd_png, hist_png, conflicts_png, budget_png))
}

/// The figures the report shows, as [`Ctx::plot`] names them.
struct Figures {
    gd_png: String,
    hist_png: String,
    conflicts_png: String,
    budget_png: String,
}

/// `report.md`: the setup, the matches against the baselines, the role statistics under
/// message loss, and the figures.
fn write_report(
    scenario: &Scenario,
    ctx: &mut Ctx<'_>,
    s: &Summary,
    runs: usize,
    loss_runs: usize,
    figures: Figures,
) -> Result<()> {
    let Figures { gd_png, hist_png, conflicts_png, budget_png } = figures;
    let mut md = Markdown::new("Group behaviors in games (paper 4.4)");
    ctx.report_head(
        NAME,
        "The paper validated group behaviors by playing: simulated games of four against four, \
         laboratory games and RoboCup 2010, without numbers. Here the full architecture plays \
         its baselines for many seeds, and the role assignment of the planning layer is measured \
         while team messages are lost.",
        &mut md,
        runs,
    );
    report_setup(scenario, runs, loss_runs, &mut md);
    report_versus(s, &mut md);
    report_loss(s, &mut md);
    md.heading("Figures");
    md.image("Goals for and against", &gd_png);
    md.image("Strikers per team", &hist_png);
    md.image("Double-striker time and role switches", &conflicts_png);
    md.image("Team messages against the budget", &budget_png);
    ctx.finish_report(
        md,
        &[
            "`matches.csv`: one row per team per match (score, falls, penalties, strikers histogram, conflicts, role switches, messages)",
        ],
    )
}

/// What was run.
fn report_setup(scenario: &Scenario, runs: usize, loss_runs: usize, md: &mut Markdown) {
    md.bullets(&[
        format!(
            "Field `{}`, noise `{}`, halves of {} s, lockstep host (deterministic), automatic referee",
            scenario.field, scenario.noise, scenario.half_duration
        ),
        format!(
            "`{}` against {}: {} matches per pairing and team size ({}), sides alternating by seed",
            scenario.reference,
            scenario.baselines.iter().map(|b| format!("`{b}`")).collect::<Vec<_>>().join(", "),
            runs,
            scenario.players.iter().map(|p| format!("{p} vs {p}")).collect::<Vec<_>>().join(", ")
        ),
        format!(
            "Team-message loss: `{}` against itself at {} loss, {} matches each ({}), both teams counted",
            scenario.loss.team,
            scenario.loss.levels.iter().map(|l| format!("{:.0}%", l * 100.0)).collect::<Vec<_>>().join(", "),
            loss_runs,
            scenario.loss.players.iter().map(|p| format!("{p} vs {p}")).collect::<Vec<_>>().join(", ")
        ),
        "Roles are sampled once per simulated second of play; a striker is the robot going to the ball (striker, or active defender when defending); penalized and fallen robots play no role".to_owned(),
    ]);
}

/// The matches against the baselines.
fn report_versus(s: &Summary, md: &mut Markdown) {
    md.heading("Matches against the baselines");
    let rows: Vec<Vec<String>> = s
        .versus
        .iter()
        .map(|v| {
            vec![
                format!("{} vs {}", v.reference, v.baseline),
                format!("{0} vs {0}", v.players),
                v.matches.to_string(),
                format!("{} / {} / {}", v.wins, v.draws, v.losses),
                v.goal_difference.show(1.0, 2),
                v.goals_for.show(1.0, 2),
                v.goals_against.show(1.0, 2),
                format!("{} of {}", v.finished, v.matches),
                v.one_striker.show(100.0, 1),
                v.double_striker_s.show(1.0, 0),
                v.role_switches_per_minute.show(1.0, 2),
                v.budget_used.show(100.0, 0),
            ]
        })
        .collect();
    md.table(
        &[
            "pairing",
            "size",
            "matches",
            "W / D / L",
            "goal difference",
            "goals for",
            "goals against",
            "finished",
            "one striker % (ours)",
            "double-striker s (ours)",
            "role switches / robot-min (ours)",
            "budget used % (ours)",
        ],
        &rows,
    );
    md.paragraph("W / D / L and goals are from the full architecture's side; ± is the 95% confidence interval over matches.");
}

/// The role statistics under team-message loss.
fn report_loss(s: &Summary, md: &mut Markdown) {
    md.heading("Role statistics under team-message loss");
    let rows: Vec<Vec<String>> = s
        .loss
        .iter()
        .map(|l| {
            vec![
                format!("{:.0}%", l.loss * 100.0),
                format!("{0} vs {0}", l.players),
                l.teams.to_string(),
                l.strikers_histogram[0].show(100.0, 1),
                l.strikers_histogram[1].show(100.0, 1),
                l.strikers_histogram[2].show(100.0, 1),
                l.strikers_histogram[3].show(100.0, 1),
                l.double_striker_s.show(1.0, 0),
                l.role_switches_per_minute.show(1.0, 2),
                l.messages_sent.show(1.0, 0),
                l.budget_used.show(100.0, 0),
            ]
        })
        .collect();
    md.table(
        &[
            "message loss",
            "size",
            "teams",
            "0 strikers %",
            "1 striker %",
            "2 strikers %",
            "3+ strikers %",
            "double-striker s per match",
            "role switches / robot-min",
            "messages sent",
            "budget used %",
        ],
        &rows,
    );
    md.paragraph(
        "The paper reports no numbers for its games; its claim is that the robots executed group \
         behaviors (one striker, a supporting striker cover) and stayed reactive. Without \
         messages (100% loss) every field player falls back to the default mission (attack, \
         striker), so the histogram's weight moves to two or more strikers.",
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outcomes_and_records() {
        let o = [outcome(2, 0), outcome(1, 1), outcome(0, 3), outcome(4, 1)];
        assert_eq!(o, [Outcome::Win, Outcome::Draw, Outcome::Loss, Outcome::Win]);
        assert_eq!(record(&o), [2, 1, 1]);
    }

    #[test]
    fn team_roles_from_a_hand_made_report() {
        let team = TeamReport {
            name: "full".into(),
            team_number: 10,
            goals: 1,
            falls: 0,
            penalties: 0,
            messages_sent: 600,
            message_budget_left: 600,
            roles: strata_games::matches::RoleStats {
                one_striker: 0.7,
                strikers_histogram: [0.1, 0.7, 0.15, 0.05],
                double_striker_s: 120.0,
                role_switches_per_minute: 0.5,
                samples: 600,
            },
        };
        let r = team_roles(&team, 1200);
        assert!((r.double_striker_fraction - 0.2).abs() < 1e-12);
        assert!((r.budget_used - 0.5).abs() < 1e-12);
        assert_eq!(r.messages_sent, 600);
    }

    #[test]
    fn the_built_in_scenario_is_valid() {
        let mut scenario: Scenario =
            super::super::parse_scenario(DEFAULT_SCENARIO, "built-in").expect("parses");
        scenario.validate(&Check { source_name: "built-in" }, None).expect("valid");
        assert_eq!(scenario.players, vec![4, 7]);
        assert_eq!(scenario.loss.levels, vec![0.0, 0.25, 0.5, 1.0]);
    }
}
