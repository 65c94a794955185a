//! Filter consistency on simulated sequences with known noise: the normalized estimation error
//! squared (NEES) of the pose and ball filters stays within the chi-square 95% bounds.

mod world_support;

use nalgebra::Vector2;
use strata_robot::geometry::Pose;
use strata_robot::world::{PoseFeed, PosePrior, WorldModel, WorldModelConfig};
use world_support::{
    Sim, anees_band, config, config_with_lines, gaussian, nees2, nees3, patrol_step, pose_error,
};

const RUNS: usize = 40;
const FRAMES: usize = 450;

struct Nees {
    pose: Vec<Vec<f64>>,
    ball: Vec<Vec<f64>>,
    pose_error: Vec<f64>,
    heading_error: Vec<f64>,
    ball_error: Vec<f64>,
}

/// What the pose filter is corrected with.
#[derive(Clone, Copy)]
struct Setup {
    feed: PoseFeed,
    lines: bool,
}

const DEFAULT: Setup = Setup { feed: PoseFeed::Gained, lines: false };

impl Nees {
    fn new() -> Nees {
        Nees {
            pose: vec![Vec::new(); FRAMES],
            ball: vec![Vec::new(); FRAMES],
            pose_error: Vec::new(),
            heading_error: Vec::new(),
            ball_error: Vec::new(),
        }
    }

    fn of(setup: Setup) -> Nees {
        let mut nees = Nees::new();
        for seed in 0..RUNS as u64 {
            run(seed, setup, &mut nees);
        }
        nees
    }
}

fn run(seed: u64, setup: Setup, nees: &mut Nees) {
    let sigma = [0.2, 0.2, 0.1];
    let mean = Pose::new(-2.0, -1.0, 0.3);
    let mut sim = Sim::new(seed, mean);
    // The truth is drawn from the prior the filter starts with.
    sim.truth = Pose::new(
        mean.x + sigma[0] * gaussian(&mut sim.rng),
        mean.y + sigma[1] * gaussian(&mut sim.rng),
        mean.theta + sigma[2] * gaussian(&mut sim.rng),
    );
    sim.ball = Vector2::new(-1.0, -0.5);
    // A rolling ball, its velocity within the filter's prior on a new track's velocity.
    sim.ball_velocity = Vector2::new(0.5 * gaussian(&mut sim.rng), 0.5 * gaussian(&mut sim.rng));
    sim.see_lines = setup.lines;
    let prior = Some(PosePrior { pose: mean, sigma });
    let mut config: WorldModelConfig =
        if setup.lines { config_with_lines(prior) } else { config(prior) };
    config.pose.feed = setup.feed;
    let mut world = WorldModel::new(config).expect("valid config");
    let ball = world.object_id("ball").expect("configured");
    for frame in 0..FRAMES {
        let (odometry, percepts) = sim.frame(patrol_step(&sim));
        world.process(odometry, &percepts);
        let state = world.state();
        assert!(!state.pose.lost, "seed {seed} frame {frame}: lost");
        let e = pose_error(&state.pose.pose, &sim.truth);
        nees.pose[frame].push(nees3(&e, &state.pose.covariance));
        nees.pose_error.push(e.xy().norm());
        nees.heading_error.push(e.z.abs());
        if let Some(f) = world.filter(ball) {
            let truth = sim.ball_in_robot_frame();
            let e = f.position_vector() - truth;
            nees.ball[frame].push(nees2(&e, &f.position_covariance()));
            nees.ball_error.push(e.norm());
        }
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Fraction of frames whose average NEES over the runs lies inside the 95% band, and the mean.
fn summarize(per_frame: &[Vec<f64>], dof: f64) -> (f64, f64, usize) {
    let mut inside = 0;
    let mut counted = 0;
    let mut all = Vec::new();
    for values in per_frame {
        if values.len() < RUNS / 2 {
            continue;
        }
        let (lo, hi) = anees_band(dof, values.len());
        let a = mean(values);
        counted += 1;
        if (lo..=hi).contains(&a) {
            inside += 1;
        }
        all.push(a);
    }
    (inside as f64 / counted.max(1) as f64, mean(&all), counted)
}

#[test]
fn pose_and_ball_filters_are_consistent() {
    let nees = Nees::of(DEFAULT);
    for chunk in 0..FRAMES / 30 {
        let r = chunk * 30..(chunk + 1) * 30;
        let p: Vec<f64> = nees.pose[r.clone()].iter().map(|v| mean(v)).collect();
        let b: Vec<f64> = nees.ball[r.clone()].iter().map(|v| mean(v)).collect();
        let n: usize = nees.ball[r.clone()].iter().map(|v| v.len()).sum::<usize>() / 30;
        println!("frames {:>3}: pose {:.2} ball {:.2} (runs {n})", r.start, mean(&p), mean(&b));
    }
    let (pose_inside, pose_mean, pose_frames) = summarize(&nees.pose, 3.0);
    let (ball_inside, ball_mean, ball_frames) = summarize(&nees.ball, 2.0);
    let (lo3, hi3) = anees_band(3.0, RUNS);
    let (lo2, hi2) = anees_band(2.0, RUNS);
    println!(
        "pose: ANEES mean {pose_mean:.3} (95% band {lo3:.2}..{hi3:.2}), {:.1}% of {pose_frames} frames inside; mean error {:.3} m, {:.2} deg",
        pose_inside * 100.0,
        mean(&nees.pose_error),
        mean(&nees.heading_error).to_degrees()
    );
    println!(
        "ball: ANEES mean {ball_mean:.3} (95% band {lo2:.2}..{hi2:.2}), {:.1}% of {ball_frames} frames inside; mean error {:.3} m",
        ball_inside * 100.0,
        mean(&nees.ball_error)
    );
    assert!((lo3..=hi3).contains(&pose_mean), "pose ANEES {pose_mean}");
    assert!((lo2..=hi2).contains(&ball_mean), "ball ANEES {ball_mean}");
    assert!(pose_inside >= 0.8, "pose ANEES inside the band in {pose_inside}");
    assert!(ball_inside >= 0.8, "ball ANEES inside the band in {ball_inside}");
}

/// The pose's ANEES over the frames most runs reached, and its mean position and heading error.
fn pose_summary(nees: &Nees, label: &str) -> (f64, f64, f64) {
    let (inside, anees, frames) = summarize(&nees.pose, 3.0);
    let (error, heading) = (mean(&nees.pose_error), mean(&nees.heading_error));
    let (lo, hi) = anees_band(3.0, RUNS);
    println!(
        "{label}: pose ANEES {anees:.2} (95% band {lo:.2}..{hi:.2}), {:.1}% of {frames} frames inside; mean error {:.1} cm, {:.2} deg",
        inside * 100.0,
        error * 100.0,
        heading.to_degrees()
    );
    (anees, error, heading)
}

/// docs/world-model.md "What the pose filter is fed": the paper's wording fed literally (each
/// frame, the landmark filters' whole estimates) counts every past observation again and the
/// pose filter claims far more certainty than it has; what the filters gained does not.
#[test]
fn feeding_whole_landmark_estimates_makes_the_pose_overconfident() {
    let (gained, gained_error, _) = pose_summary(&Nees::of(DEFAULT), "gained information");
    let (estimates, estimates_error, _) =
        pose_summary(&Nees::of(Setup { feed: PoseFeed::Estimates, ..DEFAULT }), "whole estimates");
    let (_, hi) = anees_band(3.0, RUNS);
    assert!(gained <= hi, "gained information: ANEES {gained}");
    assert!(estimates > 2.0 * hi, "whole estimates: ANEES {estimates} not overconfident");
    assert!(
        estimates_error > gained_error,
        "whole estimates {estimates_error} m vs gained {gained_error} m"
    );
}

/// The painted lines as observations: the pose stays consistent and gets more accurate, most
/// of all in heading (a line's direction is a heading measurement of its own).
#[test]
fn field_lines_make_the_pose_more_accurate_and_keep_it_consistent() {
    let (_, error, heading) = pose_summary(&Nees::of(DEFAULT), "landmarks");
    let (anees, lines_error, lines_heading) =
        pose_summary(&Nees::of(Setup { lines: true, ..DEFAULT }), "landmarks and lines");
    let (lo, hi) = anees_band(3.0, RUNS);
    assert!((lo..=hi).contains(&anees), "with lines: ANEES {anees}");
    assert!(lines_error < error, "position error {lines_error} m with lines vs {error} m");
    assert!(lines_heading < heading, "heading error {lines_heading} with lines vs {heading}");
}

/// A line map the filter cannot use is refused naming the field.
#[test]
fn a_bad_line_map_is_refused_naming_the_field() {
    let mut config = config_with_lines(None);
    config.lines.segments[3][1] = config.lines.segments[3][0];
    let error = WorldModel::new(config).expect_err("a segment without length");
    assert_eq!(error.field, "lines.segments[3]");
    let mut config = config_with_lines(None);
    config.lines.direction_sigma = 0.0;
    let error = WorldModel::new(config).expect_err("no direction noise");
    assert_eq!(error.field, "lines.direction_sigma");
}
