//! `strata experiment team --engine rcssservermj` (paper 4.4): games of T1s in physics, the
//! full architecture against its no-coordination baseline, one game per seed with the sides
//! alternating, beside the same games on the 2D simulator (same team size, half length and
//! seeds, on its own field). The games are [`strata_games::physics::game`]'s: a robot process each,
//! both halves under the server's referee.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use serde::{Deserialize, Serialize};
use strata_soccer::team::TeamConfig;

use crate::plot::Bars;
use crate::report::{Markdown, num, pct, verdict, write_csv};
use crate::stats::Estimate;
use crate::{Check, Ctx, ScenarioError, Validate};
use strata_games::matches::{Match, MatchConfig, MatchReport};
use strata_games::physics::game::{self, GameConfig, MAX_PLAYERS, RULES_HALF_TIME};
use strata_games::physics::robot::strata_exe;

pub const NAME: &str = "team";
pub const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/rcssservermj/team.toml");

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    /// Robots per team.
    pub players: u8,
    /// Play seconds per half (at most the server's 300).
    pub half: f64,
    /// Games: seeds seed .. seed + runs - 1; the reference team is at home in even runs.
    pub runs: usize,
    /// The full architecture: a built-in team or a team file.
    pub reference: String,
    /// What it plays against.
    pub baseline: String,
    /// The 2D simulator's field for the games beside.
    pub field_2d: String,
    #[serde(skip)]
    resolved: Option<(TeamConfig, TeamConfig)>,
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        if self.players == 0 || self.players > MAX_PLAYERS {
            return Err(check.fail("players", format!("must be 1 to {MAX_PLAYERS}")));
        }
        check.positive("half", self.half)?;
        if self.half > RULES_HALF_TIME {
            return Err(check.fail("half", format!("must be at most {RULES_HALF_TIME} s")));
        }
        check.at_least("runs", self.runs, 1)?;
        self.field_2d = check.field_preset("field_2d", &self.field_2d, dir)?;
        let reference = check.team("reference", &self.reference, dir)?;
        let baseline = check.team("baseline", &self.baseline, dir)?;
        self.resolved = Some((reference, baseline));
        Ok(())
    }
}

/// One game from the reference team's side.
#[derive(Clone, Debug, Serialize)]
pub struct Game {
    pub run: usize,
    pub seed: u64,
    pub reference_home: bool,
    pub goals_for: u8,
    pub goals_against: u8,
    pub finished: bool,
    pub falls: usize,
    pub stood_up: usize,
    /// Share of sampled play with exactly one robot going to the ball (reference, baseline).
    pub one_striker: [f64; 2],
    pub messages_sent: [u64; 2],
    pub real_time_factor: f64,
    pub max_robot_cpu_share: f64,
    /// The same seed and sides on the 2D simulator: goals for and against.
    pub goals_2d: [u8; 2],
}

impl Game {
    fn difference(&self) -> f64 {
        f64::from(self.goals_for) - f64::from(self.goals_against)
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub experiment: String,
    pub engine: String,
    pub players: u8,
    pub half_s: f64,
    pub reference: String,
    pub baseline: String,
    /// The 2D simulator's field for the games beside.
    pub field_2d: String,
    pub games: Vec<Game>,
    /// Reference goals minus baseline goals per game.
    pub goal_difference: Estimate,
    pub goal_difference_2d: Estimate,
    pub record: [usize; 3],
    pub targets: Targets,
}

#[derive(Clone, Debug, Serialize)]
pub struct Targets {
    /// Every game ran to the end of both halves.
    pub games_finished: bool,
    /// Both teams scored at least once over all games.
    pub both_teams_scored: bool,
    /// Falls, and how many of them the robot stood up from.
    pub falls: usize,
    pub stood_up: usize,
    /// The full team beats the baseline: the goal difference's 95 % interval is above 0.
    pub reference_wins: bool,
    /// Every robot under 10 % of its game's CPU.
    pub cpu_per_robot_met: bool,
}

pub fn run(scenario: &Scenario, ctx: &mut Ctx<'_>) -> Result<Summary> {
    let runs = ctx.runs(scenario.runs);
    let (reference, baseline) =
        scenario.resolved.clone().context("the scenario was not validated")?;
    // The robots read their teams from files, whatever the scenario's paths were relative to.
    let teams_dir = std::env::temp_dir().join(format!("strata-team-3d-{}", std::process::id()));
    std::fs::create_dir_all(&teams_dir)
        .with_context(|| format!("creating {}", teams_dir.display()))?;
    let reference_file = write_team(&teams_dir, "reference", &reference)?;
    let baseline_file = write_team(&teams_dir, "baseline", &baseline)?;
    let exe = strata_exe(ctx.options.strata_exe.as_deref())?;

    let bar = ctx.progress((runs as f64 * 2.0 * scenario.half) as u64, "games in physics");
    let mut games = Vec::new();
    for run in 0..runs {
        let seed = ctx.seed(run);
        let reference_home = run % 2 == 0;
        let (home, away) = if reference_home {
            (&reference_file, &baseline_file)
        } else {
            (&baseline_file, &reference_file)
        };
        let config = GameConfig {
            exe: exe.clone(),
            players: scenario.players,
            seed,
            home: home.display().to_string(),
            away: away.display().to_string(),
            half: scenario.half,
            limit: None,
            log: None,
            join_timeout: std::time::Duration::from_secs(180),
            stall_timeout: std::time::Duration::from_secs(90),
        };
        let done = run as f64 * 2.0 * scenario.half;
        let report = game::play(&config, &mut |fraction, line| {
            bar.set_position((done + fraction * 2.0 * scenario.half) as u64);
            bar.set_message(format!("game {} of {runs}: {line}", run + 1));
        })
        .with_context(|| format!("game {} (seed {seed})", run + 1))?;
        let flat = match_2d(scenario, &reference, &baseline, seed, reference_home)?;
        games.push(game_of(run, seed, reference_home, &report, &flat));
    }
    bar.finish_and_clear();
    let _ = std::fs::remove_dir_all(&teams_dir);

    let differences: Vec<f64> = games.iter().map(Game::difference).collect();
    let differences_2d: Vec<f64> =
        games.iter().map(|g| f64::from(g.goals_2d[0]) - f64::from(g.goals_2d[1])).collect();
    let goal_difference = Estimate::of(&differences);
    let record = [
        games.iter().filter(|g| g.goals_for > g.goals_against).count(),
        games.iter().filter(|g| g.goals_for == g.goals_against).count(),
        games.iter().filter(|g| g.goals_for < g.goals_against).count(),
    ];
    let falls = games.iter().map(|g| g.falls).sum();
    let targets = Targets {
        games_finished: games.iter().all(|g| g.finished),
        both_teams_scored: games.iter().any(|g| g.goals_for > 0)
            && games.iter().any(|g| g.goals_against > 0),
        falls,
        stood_up: games.iter().map(|g| g.stood_up).sum(),
        reference_wins: goal_difference.n >= 2 && goal_difference.low() > 0.0,
        cpu_per_robot_met: games.iter().all(|g| g.max_robot_cpu_share < 0.10),
    };
    let summary = Summary {
        experiment: NAME.to_owned(),
        engine: "rcssservermj".to_owned(),
        players: scenario.players,
        half_s: scenario.half,
        reference: reference.name.clone(),
        baseline: baseline.name.clone(),
        field_2d: scenario.field_2d.clone(),
        games,
        goal_difference,
        goal_difference_2d: Estimate::of(&differences_2d),
        record,
        targets,
    };
    write_outputs(&summary, ctx, runs)?;
    Ok(summary)
}

fn write_team(dir: &Path, stem: &str, team: &TeamConfig) -> Result<PathBuf> {
    let path = dir.join(format!("{stem}.toml"));
    let text = toml::to_string(team).context("writing a team configuration")?;
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// The same game on the 2D simulator: lockstep, deterministic for the seed.
fn match_2d(
    scenario: &Scenario,
    reference: &TeamConfig,
    baseline: &TeamConfig,
    seed: u64,
    reference_home: bool,
) -> Result<MatchReport> {
    let (home, away) = if reference_home {
        (reference.clone(), baseline.clone())
    } else {
        (baseline.clone(), reference.clone())
    };
    let config = MatchConfig {
        players: scenario.players,
        seed,
        home,
        away,
        half_duration: scenario.half,
        field: scenario.field_2d.clone(),
        // rcssservermj's referee has no delays and no signals: the comparison has none either.
        no_delay: true,
        ..MatchConfig::default()
    };
    Match::new(config)?.play(&mut |_, _| {})
}

fn game_of(
    run: usize,
    seed: u64,
    reference_home: bool,
    report: &MatchReport,
    flat: &MatchReport,
) -> Game {
    let (us, them) = if reference_home { (0, 1) } else { (1, 0) };
    let physics = report.physics.as_ref();
    Game {
        run,
        seed,
        reference_home,
        goals_for: report.score[us],
        goals_against: report.score[them],
        finished: report.finished,
        falls: physics.map_or(0, |p| p.robots.iter().map(|r| r.falls).sum()),
        stood_up: physics.map_or(0, |p| p.robots.iter().map(|r| r.stood_up).sum()),
        one_striker: [report.teams[us].roles.one_striker, report.teams[them].roles.one_striker],
        messages_sent: [report.teams[us].messages_sent, report.teams[them].messages_sent],
        real_time_factor: report.real_time_factor,
        max_robot_cpu_share: physics.map_or(f64::NAN, |p| p.cpu.max_robot_share),
        goals_2d: [flat.score[us], flat.score[them]],
    }
}

fn write_outputs(summary: &Summary, ctx: &mut Ctx<'_>, runs: usize) -> Result<()> {
    write_games_csv(summary, ctx)?;
    let image = ctx.plot(&goal_difference_figure(summary), "goal-difference")?;
    let mut md = Markdown::new("Team play in physics: the full architecture against a baseline");
    ctx.report_head(
        "games of T1s in rcssservermj, the same seeds on the 2D simulator beside",
        "Paper 4.4: complete games. Here on Booster T1s in the RoboCup simulation league's \
         MuJoCo server, each robot a `strata robot` process with the full architecture, the \
         server's referee ruling; the sides alternate from game to game.",
        &mut md,
        runs,
    );
    targets_table(&mut md, summary);
    games_table(&mut md, summary);
    md.image("goal difference", &image);
    ctx.finish_report(md, &["`games.csv`: one row per game, the reference team's side first"])
}

/// `games.csv`: one row per game.
fn write_games_csv(summary: &Summary, ctx: &mut Ctx<'_>) -> Result<()> {
    let rows: Vec<Vec<String>> = summary
        .games
        .iter()
        .map(|g| {
            vec![
                g.run.to_string(),
                g.seed.to_string(),
                g.reference_home.to_string(),
                g.goals_for.to_string(),
                g.goals_against.to_string(),
                g.finished.to_string(),
                g.falls.to_string(),
                g.stood_up.to_string(),
                num(g.one_striker[0]),
                num(g.one_striker[1]),
                g.messages_sent[0].to_string(),
                g.messages_sent[1].to_string(),
                num(g.real_time_factor),
                num(g.max_robot_cpu_share),
                g.goals_2d[0].to_string(),
                g.goals_2d[1].to_string(),
            ]
        })
        .collect();
    let csv = ctx.path("games.csv");
    write_csv(
        &csv,
        &[
            "run",
            "seed",
            "reference_home",
            "goals_for",
            "goals_against",
            "finished",
            "falls",
            "stood_up",
            "one_striker_reference",
            "one_striker_baseline",
            "messages_reference",
            "messages_baseline",
            "real_time_factor",
            "max_robot_cpu_share",
            "goals_for_2d",
            "goals_against_2d",
        ],
        &rows,
    )
}

/// The goal difference per game, in physics and on the 2D simulator.
fn goal_difference_figure(summary: &Summary) -> Bars {
    Bars {
        title: format!(
            "{} against {}: goal difference per game ({} vs {}, {:.0} s halves)",
            summary.reference, summary.baseline, summary.players, summary.players, summary.half_s
        ),
        y_label: "goals for - goals against".to_owned(),
        groups: vec!["2D simulator".to_owned(), "T1s in rcssservermj".to_owned()],
        series: vec![(
            "goal difference (mean, 95 % CI)".to_owned(),
            vec![summary.goal_difference_2d, summary.goal_difference],
        )],
        reference: None,
        targets: Some(("above 0: the full team wins".to_owned(), vec![Some(0.0), Some(0.0)])),
    }
}

/// The targets, and whether they were met.
fn targets_table(md: &mut Markdown, summary: &Summary) {
    md.heading("Targets");
    let t = &summary.targets;
    md.table(
        &["target", "measured", "met"],
        &[
            vec![
                "every game runs both halves to the end, no hang".to_owned(),
                format!(
                    "{} of {} finished",
                    summary.games.iter().filter(|g| g.finished).count(),
                    summary.games.len()
                ),
                verdict(t.games_finished),
            ],
            vec![
                "both teams score at least once over the games".to_owned(),
                format!(
                    "{} goals for, {} against",
                    summary.games.iter().map(|g| u32::from(g.goals_for)).sum::<u32>(),
                    summary.games.iter().map(|g| u32::from(g.goals_against)).sum::<u32>()
                ),
                verdict(t.both_teams_scored),
            ],
            vec![
                "robots get up after falls".to_owned(),
                format!("{} falls, stood up after {}", t.falls, t.stood_up),
                verdict(t.falls == 0 || t.stood_up > 0),
            ],
            vec![
                format!(
                    "{} beats {} (goal difference CI above 0)",
                    summary.reference, summary.baseline
                ),
                format!(
                    "{} per game (record {}-{}-{}){}",
                    summary.goal_difference.show(1.0, 2),
                    summary.record[0],
                    summary.record[1],
                    summary.record[2],
                    if t.reference_wins {
                        String::new()
                    } else {
                        format!(
                            "; missed: the interval's low end is {:.2}",
                            summary.goal_difference.low()
                        )
                    }
                ),
                verdict(t.reference_wins),
            ],
            vec![
                "Strata's compute per robot under 10 % of the game's CPU".to_owned(),
                format!(
                    "largest robot share {}",
                    pct(summary.games.iter().map(|g| g.max_robot_cpu_share).fold(0.0, f64::max))
                ),
                verdict(t.cpu_per_robot_met),
            ],
        ],
    );
}

/// Every game, physics beside 2D.
fn games_table(md: &mut Markdown, summary: &Summary) {
    md.heading("Games");
    let games: Vec<Vec<String>> = summary
        .games
        .iter()
        .map(|g| {
            vec![
                g.seed.to_string(),
                if g.reference_home { "home" } else { "away" }.to_owned(),
                format!("{}-{}", g.goals_for, g.goals_against),
                format!("{}-{}", g.goals_2d[0], g.goals_2d[1]),
                format!("{}/{}", g.stood_up, g.falls),
                format!("{} / {}", pct(g.one_striker[0]), pct(g.one_striker[1])),
                format!("{} / {}", g.messages_sent[0], g.messages_sent[1]),
                format!("{:.2}", g.real_time_factor),
                pct(g.max_robot_cpu_share),
            ]
        })
        .collect();
    md.table(
        &[
            "seed",
            "reference",
            "score (physics)",
            "score (2D)",
            "stood up / falls",
            "one striker (ref / base)",
            "messages (ref / base)",
            "real-time factor",
            "largest robot CPU share",
        ],
        &games,
    );
    md.paragraph(&format!(
        "Goal difference per game: {} in physics, {} on the 2D simulator (same seeds and sides, \
         field `{}`). A seed does not reproduce a game in physics: MuJoCo steps in the server's \
         process when every robot has answered, the robots run in real time, and the server's \
         audio model is not seeded; it fixes what Strata draws.",
        summary.goal_difference.show(1.0, 2),
        summary.goal_difference_2d.show(1.0, 2),
        summary.field_2d
    ));
}
