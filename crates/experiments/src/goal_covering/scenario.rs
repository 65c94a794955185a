//! The scenario file: methods, fixed trajectories, seeded random paths, the measures' settings
//! and the paper's Table 5 rows.

use super::*;

pub const DEFAULT_SCENARIO: &str = include_str!("../../scenarios/goal-covering.toml");

/// The scenario (`scenarios/goal-covering.toml`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    /// Field preset or field file.
    pub field: String,
    /// Simulator noise preset: none, default, high.
    pub noise: String,
    /// Runs per (method, rate, trajectory).
    pub runs: usize,
    /// Ball speed along every fixed trajectory, m/s (needed when there are any).
    #[serde(default)]
    pub ball_speed: Option<f64>,
    /// Deliberative-layer rates, Hz.
    pub deliberative_hz: Vec<f64>,
    /// Sensor rate, Hz: the reactive layer runs on every percept.
    pub reactive_hz: f64,
    /// Seconds before the ball starts moving (the keeper localizes); not measured.
    pub warmup: f64,
    /// Seconds measured after the ball stops.
    pub settle: f64,
    /// Sampling period of the metrics, s of simulated time.
    pub sample_period: f64,
    /// Keeper's start pose, team frame [x, y, theta].
    pub keeper_start: [f64; 3],
    /// The method the targets apply to and the baselines are compared with.
    pub reference: String,
    /// Mean pose error the reference method must stay under, m.
    pub target_pose_error: f64,
    pub methods: Vec<Method>,
    /// Fixed trajectories, run at `ball_speed`.
    #[serde(default)]
    pub trajectories: Vec<Trajectory>,
    /// Seeded random paths at speeds drawn from a range, run after the fixed trajectories.
    #[serde(default)]
    pub random: Option<RandomPaths>,
    /// How the time to re-cover is measured.
    #[serde(default)]
    pub recover: Recover,
    /// The paper's Table 5, and the targets per rate.
    #[serde(default)]
    pub paper: Vec<PaperRow>,
    #[serde(skip)]
    pub(super) resolved: Vec<TeamConfig>,
    /// Per method, its learned gaze, loaded.
    #[serde(skip)]
    pub(super) policies: Vec<Option<Arc<GazePolicy>>>,
    #[serde(skip)]
    pub(super) noise_level: Option<NoiseLevel>,
    /// The fixed trajectories, then the random paths: what the runs follow.
    #[serde(skip)]
    pub paths: Vec<BallPath>,
    /// The report's speed bands, m/s [low, high].
    #[serde(skip)]
    pub speed_bands: Vec<[f64; 2]>,
}

/// Seeded random ball paths: the method is measured on paths nobody drew by hand.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RandomPaths {
    /// How many paths.
    pub paths: usize,
    /// The paths and their speeds are drawn from this seed alone, not from `--seed`: every run
    /// of every method follows the same paths.
    pub seed: u64,
    /// Range of the ball's speed [min, max], m/s; each path's constant speed is drawn uniformly.
    pub speed: [f64; 2],
    /// Range of the number of straight segments of a path [min, max].
    pub segments: [usize; 2],
    /// Shortest segment, m.
    pub min_segment: f64,
    /// Where waypoints are drawn, keeper's team frame [[x_min, y_min], [x_max, y_max]], m;
    /// segments that enter the own penalty area (0.1 m margin) are drawn again, since there the
    /// keeper leaves its goal to clear the ball.
    pub region: [[f64; 2]; 2],
    /// The report splits `speed` into this many equal bands.
    pub speed_bands: usize,
}

/// The definition of the time to re-cover.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Recover {
    /// A change of the ball's direction: its velocity has turned by more than this since the
    /// previous change (or since it started moving), degrees.
    pub turn: f64,
    /// Covered again: the keeper's coverage is at least the covering pose's minus this.
    pub tolerance: f64,
    /// ... for this long without interruption, s: a keeper sweeping through the right place is
    /// not covering.
    pub hold: f64,
}

impl Default for Recover {
    fn default() -> Self {
        Recover { turn: 40.0, tolerance: 0.05, hold: 0.5 }
    }
}

/// A path the ball follows in a run, at a constant speed.
#[derive(Clone, Debug, Serialize)]
pub struct BallPath {
    pub trajectory: Trajectory,
    /// m/s.
    pub speed: f64,
    /// Drawn from `[random]`.
    pub random: bool,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Method {
    pub name: String,
    /// A built-in team (full, always-ball, fixed-scan, entropy, ...) or a team TOML file.
    pub team: String,
    /// A learned gaze ([`super::learned`]): at each deliberative decision the team's gaze is
    /// this policy's choice. `"shipped"`: the policy shipped with the crate
    /// (data/gaze-policy.safetensors); otherwise a safetensors file (relative to the scenario's
    /// directory). The team must make gaze candidates (a value-function or entropy gaze).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy: Option<String>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Trajectory {
    pub name: String,
    /// Polyline in the keeper's team frame (own goal at -x), m.
    pub waypoints: Vec<[f64; 2]>,
}

impl Trajectory {
    pub fn length(&self) -> f64 {
        self.waypoints
            .windows(2)
            .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
            .sum()
    }

    /// Where the ball is `s` metres along the path, and its direction there (unit vector).
    pub fn at(&self, s: f64) -> ([f64; 2], [f64; 2]) {
        let mut left = s.max(0.0);
        let mut last = ([0.0; 2], [0.0; 2]);
        for w in self.waypoints.windows(2) {
            let (d, e) = (w[1][0] - w[0][0], w[1][1] - w[0][1]);
            let length = d.hypot(e);
            if length <= 0.0 {
                continue;
            }
            let direction = [d / length, e / length];
            if left <= length {
                return ([w[0][0] + direction[0] * left, w[0][1] + direction[1] * left], direction);
            }
            left -= length;
            last = (w[1], direction);
        }
        last
    }
}

/// The checks both goal-covering scenarios (2D and physics) make of their methods, reference
/// and trajectories; the methods' teams, resolved.
pub(crate) fn check_methods_and_trajectories(
    check: &Check<'_>,
    dir: Option<&Path>,
    methods: &[Method],
    reference: &str,
    trajectories: &[Trajectory],
) -> Result<Vec<TeamConfig>, ScenarioError> {
    let resolved = check_methods(check, dir, methods, reference)?;
    if let Some(i) = methods.iter().position(|m| m.policy.is_some()) {
        return Err(check.fail(
            &format!("methods[{i}].policy"),
            "a learned gaze runs in the 2D goal-covering experiment only",
        ));
    }
    check_trajectories(check, trajectories, false)?;
    Ok(resolved)
}

/// Per method, its learned gaze loaded (`None` for the others); the team of one must make
/// gaze candidates for the policy to choose among.
pub(super) fn load_policies(
    check: &Check<'_>,
    dir: Option<&Path>,
    methods: &[Method],
    resolved: &[TeamConfig],
) -> Result<Vec<Option<Arc<GazePolicy>>>, ScenarioError> {
    let mut policies = Vec::with_capacity(methods.len());
    for (i, (method, team)) in methods.iter().zip(resolved).enumerate() {
        let Some(source) = &method.policy else {
            policies.push(None);
            continue;
        };
        let field = format!("methods[{i}].policy");
        if matches!(team.behavior.gaze, GazeStrategy::AlwaysBall | GazeStrategy::FixedScan) {
            return Err(check.fail(
                &field,
                format!(
                    "team `{}` makes no gaze candidates to choose from (use a value-function or \
                     entropy gaze)",
                    method.team
                ),
            ));
        }
        let policy = if source == SHIPPED_POLICY {
            learned::shipped_policy()
        } else {
            let path = dir.map_or_else(|| Path::new(source).to_path_buf(), |d| d.join(source));
            learned::load_policy(&path)
        };
        policies.push(Some(Arc::new(policy.map_err(|e| check.fail(&field, e.to_string()))?)));
    }
    Ok(policies)
}

/// The methods' teams, resolved; the reference is one of them.
pub(super) fn check_methods(
    check: &Check<'_>,
    dir: Option<&Path>,
    methods: &[Method],
    reference: &str,
) -> Result<Vec<TeamConfig>, ScenarioError> {
    check.not_empty("methods", methods)?;
    let mut resolved = Vec::with_capacity(methods.len());
    for (i, m) in methods.iter().enumerate() {
        resolved.push(check.team(&format!("methods[{i}].team"), &m.team, dir)?);
    }
    if !methods.iter().any(|m| m.name == reference) {
        return Err(check.fail("reference", format!("`{reference}` is not one of the methods")));
    }
    Ok(resolved)
}

/// Fixed trajectories: at least one unless random paths are drawn; each a finite polyline.
pub(super) fn check_trajectories(
    check: &Check<'_>,
    trajectories: &[Trajectory],
    random_paths: bool,
) -> Result<(), ScenarioError> {
    if !random_paths {
        check.not_empty("trajectories", trajectories)?;
    }
    for (i, t) in trajectories.iter().enumerate() {
        if t.waypoints.len() < 2 {
            return Err(
                check.fail(&format!("trajectories[{i}].waypoints"), "needs at least two points")
            );
        }
        if t.waypoints.iter().flatten().any(|v| !v.is_finite()) {
            return Err(check.fail(&format!("trajectories[{i}].waypoints"), "must be finite"));
        }
    }
    Ok(())
}

impl RandomPaths {
    /// The section's own checks; the region must lie on the field.
    fn check(&self, check: &Check<'_>, field: &TeamField) -> Result<(), ScenarioError> {
        check.at_least("random.paths", self.paths, 1)?;
        let [low, high] = self.speed;
        check.positive("random.speed[0]", low)?;
        check.positive("random.speed[1]", high)?;
        if low > high {
            return Err(check.fail("random.speed", format!("[{low}, {high}]: min above max")));
        }
        let [fewest, most] = self.segments;
        check.at_least("random.segments[0]", fewest, 1)?;
        if fewest > most {
            return Err(check.fail("random.segments", format!("[{fewest}, {most}]: min above max")));
        }
        check.positive("random.min_segment", self.min_segment)?;
        let [[x0, y0], [x1, y1]] = self.region;
        if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) || x0 >= x1 || y0 >= y1 {
            return Err(check.fail(
                "random.region",
                "must be [[x_min, y_min], [x_max, y_max]] with finite x_min < x_max, y_min < y_max",
            ));
        }
        if !field.is_inside(Point::new(x0, y0), 0.0) || !field.is_inside(Point::new(x1, y1), 0.0) {
            return Err(check.fail(
                "random.region",
                format!(
                    "must lie on the field (|x| <= {}, |y| <= {})",
                    field.half_length, field.half_width
                ),
            ));
        }
        check.at_least("random.speed_bands", self.speed_bands, 1)?;
        Ok(())
    }
}

/// Attempts at drawing one waypoint before the region is declared unusable.
pub(super) const WAYPOINT_ATTEMPTS: usize = 10_000;

/// The random paths of `random`, drawn from its seed alone: the same on every machine and for
/// every `--seed`. A segment is drawn again when it is shorter than `min_segment` or passes
/// within 0.1 m of the own penalty area.
pub fn random_paths(random: &RandomPaths, field: &TeamField) -> Result<Vec<BallPath>, String> {
    use rand::{RngExt as _, SeedableRng as _};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(random.seed);
    let [[x0, y0], [x1, y1]] = random.region;
    let clear = |a: Point<FieldFrame>, b: Point<FieldFrame>| {
        let steps = (a.distance(b) / 0.05).ceil().max(1.0) as usize;
        (0..=steps).all(|k| !field.in_own_penalty_area(a.lerp(b, k as f64 / steps as f64), 0.1))
    };
    let mut paths = Vec::with_capacity(random.paths);
    for i in 0..random.paths {
        let speed = rng.random_range(random.speed[0]..=random.speed[1]);
        let segments = rng.random_range(random.segments[0]..=random.segments[1]);
        let mut waypoints: Vec<Point<FieldFrame>> = Vec::with_capacity(segments + 1);
        while waypoints.len() <= segments {
            let drawn = (0..WAYPOINT_ATTEMPTS).find_map(|_| {
                let p = Point::new(rng.random_range(x0..=x1), rng.random_range(y0..=y1));
                let fits = match waypoints.last() {
                    None => clear(p, p),
                    Some(&last) => last.distance(p) >= random.min_segment && clear(last, p),
                };
                fits.then_some(p)
            });
            let Some(p) = drawn else {
                return Err(format!(
                    "no segment of at least {} m outside the own penalty area found in \
                     {WAYPOINT_ATTEMPTS} draws for path {i}",
                    random.min_segment
                ));
            };
            waypoints.push(p);
        }
        paths.push(BallPath {
            trajectory: Trajectory {
                name: format!("random-{i}"),
                waypoints: waypoints.iter().map(|p| [p.x, p.y]).collect(),
            },
            speed,
            random: true,
        });
    }
    Ok(paths)
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PaperRow {
    pub deliberative_hz: f64,
    /// Table 5: fraction of time the robot decides to observe the ball.
    pub observe_ball: f64,
    /// Table 5: fraction of time the ball position is unknown.
    pub ball_unknown: f64,
    /// The target for the reference method's ball-unknown fraction.
    pub target_ball_unknown: f64,
}

impl Validate for Scenario {
    fn validate(&mut self, check: &Check<'_>, dir: Option<&Path>) -> Result<(), ScenarioError> {
        self.field = check.field_preset("field", &self.field, dir)?;
        self.noise_level = Some(check.noise("noise", &self.noise)?);
        check.at_least("runs", self.runs, 1)?;
        if let Some(speed) = self.ball_speed {
            check.positive("ball_speed", speed)?;
        }
        check.not_empty("deliberative_hz", &self.deliberative_hz)?;
        for (i, hz) in self.deliberative_hz.iter().enumerate() {
            check.positive(&format!("deliberative_hz[{i}]"), *hz)?;
        }
        check.positive("reactive_hz", self.reactive_hz)?;
        check.non_negative("warmup", self.warmup)?;
        check.non_negative("settle", self.settle)?;
        check.positive("sample_period", self.sample_period)?;
        check.positive("target_pose_error", self.target_pose_error)?;
        if !self.keeper_start.iter().all(|v| v.is_finite()) {
            return Err(check.fail("keeper_start", "must be three finite numbers"));
        }
        self.resolved = check_methods(check, dir, &self.methods, &self.reference)?;
        self.policies = load_policies(check, dir, &self.methods, &self.resolved)?;
        check_trajectories(check, &self.trajectories, self.random.is_some())?;
        check.positive("recover.turn", self.recover.turn)?;
        if self.recover.turn >= 180.0 {
            return Err(check.fail("recover.turn", "must be under 180 degrees"));
        }
        check.fraction("recover.tolerance", self.recover.tolerance)?;
        check.non_negative("recover.hold", self.recover.hold)?;
        self.paths = Vec::new();
        if !self.trajectories.is_empty() {
            let Some(speed) = self.ball_speed else {
                return Err(check.fail("ball_speed", "is needed by the fixed `trajectories`"));
            };
            self.paths.extend(self.trajectories.iter().map(|t| BallPath {
                trajectory: t.clone(),
                speed,
                random: false,
            }));
        }
        self.speed_bands = Vec::new();
        if let Some(random) = &self.random {
            let field = strata_spl::Field::preset(&self.field)
                .or_else(|_| strata_spl::Field::load(&self.field))
                .map_err(|e| check.fail("field", e.to_string()))?;
            let field = TeamField::new(field, 1.0);
            random.check(check, &field)?;
            self.paths
                .extend(random_paths(random, &field).map_err(|e| check.fail("random.region", e))?);
            let [low, high] = random.speed;
            let width = (high - low) / random.speed_bands as f64;
            self.speed_bands = (0..random.speed_bands)
                .map(|i| [low + width * i as f64, low + width * (i + 1) as f64])
                .collect();
        }
        for path in &self.paths {
            if self.speed_band(path.speed).is_none() {
                self.speed_bands.push([path.speed, path.speed]);
            }
        }
        for (i, row) in self.paper.iter().enumerate() {
            check.fraction(&format!("paper[{i}].observe_ball"), row.observe_ball)?;
            check.fraction(&format!("paper[{i}].ball_unknown"), row.ball_unknown)?;
            check.fraction(&format!("paper[{i}].target_ball_unknown"), row.target_ball_unknown)?;
        }
        Ok(())
    }
}

impl Scenario {
    pub(super) fn paper_row(&self, hz: f64) -> Option<&PaperRow> {
        self.paper.iter().find(|r| (r.deliberative_hz - hz).abs() < 1e-9)
    }

    /// The speed band `speed` falls in (bands include both ends; the first that fits).
    pub fn speed_band(&self, speed: f64) -> Option<usize> {
        let slack = 1e-9;
        self.speed_bands
            .iter()
            .position(|[low, high]| speed >= low - slack && speed <= high + slack)
    }
}

/// "0.1-0.2 m/s", or "0.2 m/s" for a single speed.
pub(super) fn band_label(band: [f64; 2]) -> String {
    if (band[1] - band[0]).abs() < 1e-9 {
        format!("{} m/s", num_short(band[0]))
    } else {
        format!("{}-{} m/s", num_short(band[0]), num_short(band[1]))
    }
}

pub(super) fn num_short(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

// ---------------------------------------------------------------------------------------------
// Metrics of one run, from its trace.

/// One sample of a run.
/// One object's head multiplexer scores: (object, S_d, S_r, final).
pub type ObjectScores = (String, f64, f64, f64);
