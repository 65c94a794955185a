//! Cost of world modeling: a full update (ball + 10 landmark filters + the pose filter) per
//! percept frame, the published world state, and the expected update of one active-vision
//! candidate.
//!
//! Run: `cargo bench -p strata-robot --bench world`

use std::hint::black_box;

use criterion::Criterion;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use strata_robot::geometry::{Global, Odometry, Point, Pose};
use strata_robot::percept::{CameraPercepts, Observation, Percepts, ViewCone};
use strata_robot::platform::ObjectClass;
use strata_robot::world::{
    ExpectedBelief, ExpectedObservation, ObjectKind, ObjectOfInterest, PosePrior, SensingCandidate,
    WorldModel, WorldModelConfig,
};
use strata_runtime::Time;

const BALL: ObjectClass = ObjectClass(1);
const DT: f64 = 1.0 / 30.0;

fn landmarks() -> Vec<(&'static str, ObjectClass, Vec<Point<Global>>)> {
    let p = |x: f64, y: f64| Point::new(x, y);
    vec![
        (
            "goal_post",
            ObjectClass(10),
            vec![p(4.5, 0.8), p(4.5, -0.8), p(-4.5, 0.8), p(-4.5, -0.8)],
        ),
        ("penalty_mark", ObjectClass(15), vec![p(3.2, 0.0), p(-3.2, 0.0)]),
        ("corner", ObjectClass(11), vec![p(4.5, 3.0), p(4.5, -3.0), p(-4.5, 3.0), p(-4.5, -3.0)]),
    ]
}

fn config() -> WorldModelConfig {
    let mut objects: Vec<ObjectOfInterest> = landmarks()
        .into_iter()
        .map(|(name, class, positions)| ObjectOfInterest {
            name: name.to_owned(),
            class,
            variant: None,
            kind: ObjectKind::Landmark { positions, position_noise: 1e-4 },
            confidence: None,
        })
        .collect();
    objects.push(ObjectOfInterest {
        name: "ball".to_owned(),
        class: BALL,
        variant: None,
        kind: ObjectKind::Mobile { friction: 0.4, acceleration_noise: 0.3, max_speed: 3.0 },
        confidence: None,
    });
    WorldModelConfig {
        objects,
        pose: strata_robot::world::PoseConfig {
            initial: Some(PosePrior { pose: Pose::new(0.5, 0.3, 0.1), sigma: [0.1, 0.1, 0.05] }),
            ..Default::default()
        },
        ..WorldModelConfig::default()
    }
}

/// A robot standing near the centre circle, turning its head over the field: every landmark is
/// seen at some point and several in each image, with the ball.
fn frames(n: usize) -> Vec<Percepts> {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let pose = Pose::new(0.5, 0.3, 0.1);
    let all: Vec<(ObjectClass, Point<Global>)> = landmarks()
        .into_iter()
        .flat_map(|(_, class, positions)| positions.into_iter().map(move |p| (class, p)))
        .chain([(BALL, Point::new(1.5, -0.4))])
        .collect();
    (0..n)
        .map(|k| {
            let t = k as f64 * DT;
            let view =
                ViewCone { direction: 2.6 * (t * 1.3).sin(), fov: 1.6, range: 7.0, near: 0.0 };
            let observations = all
                .iter()
                .filter_map(|&(class, m)| {
                    let p = pose.to_robot(m);
                    view.contains(p, 0.0).then(|| {
                        let n1: f64 = StandardNormal.sample(&mut rng);
                        let n2: f64 = StandardNormal.sample(&mut rng);
                        let range_sigma = 0.05 + 0.08 * p.range();
                        Observation {
                            class,
                            variant: None,
                            range: p.range() + range_sigma * n1,
                            bearing: p.bearing() + 0.035 * n2,
                            orientation: None,
                            range_sigma,
                            bearing_sigma: 0.035,
                        }
                    })
                })
                .collect();
            let stamp = Time::from_secs_f64(t);
            Percepts {
                stamp,
                camera: Some(CameraPercepts { stamp, view, observations }),
                ..Percepts::default()
            }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let mut frames = frames(600);
    let mean_observations =
        frames.iter().map(|f| f.observations().len()).sum::<usize>() as f64 / frames.len() as f64;
    let mut world = WorldModel::new(config()).expect("valid config");
    let mut time = 0.0;
    // Warm up: every filter tracked.
    for f in &frames {
        time += DT;
        world.process(Odometry { dx: 0.0, dy: 0.0, dtheta: 0.0 }, f);
    }
    let state = world.state();
    let tracked = state.objects.iter().filter(|o| o.tracked).count();
    println!(
        "world model: {} filters ({tracked} tracked) + pose filter, {mean_observations:.1} observations per image, pose lost: {}",
        state.objects.len(),
        state.pose.lost
    );
    let mut k = 0usize;
    let mut sign = 1.0;
    c.bench_function("world/update_per_percept_frame", |b| {
        b.iter(|| {
            // Tiny back-and-forth steps: the robot stays put, the filters still predict.
            sign = -sign;
            let odometry = Odometry { dx: 0.002 * sign, dy: 0.0, dtheta: 0.003 * sign };
            let frame = &mut frames[k % 600];
            time += DT;
            let stamp = Time::from_secs_f64(time);
            frame.stamp = stamp;
            if let Some(camera) = &mut frame.camera {
                camera.stamp = stamp;
            }
            world.process(black_box(odometry), black_box(&frames[k % 600]));
            k += 1;
        })
    });
    c.bench_function("world/world_state_snapshot", |b| b.iter(|| black_box(world.state())));
    let state = world.state();
    let id = |name: &str| world.object_id(name).expect("configured");
    let candidate = SensingCandidate {
        observations: ["ball", "goal_post#0", "goal_post#1", "penalty_mark#0"]
            .iter()
            .map(|name| ExpectedObservation {
                object: id(name),
                range_sigma: 0.2,
                bearing_sigma: 0.035,
                detection_probability: 0.8,
            })
            .collect(),
        lines: Vec::new(),
    };
    let mut out = ExpectedBelief::default();
    c.bench_function("world/expected_update_one_candidate", |b| {
        b.iter(|| {
            state.expected_update_into(black_box(&candidate), &mut out);
            black_box(&out);
        })
    });
    let view = ViewCone { direction: 0.3, fov: 1.0, range: 7.0, near: 0.0 };
    c.bench_function("world/sensing_candidate_and_expected_update", |b| {
        b.iter(|| {
            let candidate = state.sensing_candidate(black_box(&view), 0.1);
            state.expected_update_into(&candidate, &mut out);
            black_box(&out);
        })
    });
}

/// The worst case: lost on a symmetric field without a hint, every image tries to recover from
/// the landmark estimates (pairs of landmarks times map instances) and finds two mirror poses.
fn bench_lost(c: &mut Criterion) {
    let mut cfg = config();
    cfg.pose.initial = None;
    let mut world = WorldModel::new(cfg).expect("valid config");
    let mut frames = frames(600);
    let mut time = 0.0;
    for f in &frames {
        time += DT;
        world.process(Odometry::ZERO, f);
    }
    let state = world.state();
    println!(
        "lost: {} landmark filters tracked, pose lost: {}",
        state.objects.iter().filter(|o| o.tracked && o.map_position.is_some()).count(),
        state.pose.lost
    );
    let mut k = 0usize;
    c.bench_function("world/update_per_percept_frame_while_lost", |b| {
        b.iter(|| {
            let frame = &mut frames[k % 600];
            time += DT;
            let stamp = Time::from_secs_f64(time);
            frame.stamp = stamp;
            if let Some(camera) = &mut frame.camera {
                camera.stamp = stamp;
            }
            world.process(Odometry::ZERO, black_box(&frames[k % 600]));
            k += 1;
        })
    });
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    bench(&mut c);
    bench_lost(&mut c);
    c.final_summary();
}
