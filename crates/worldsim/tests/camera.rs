//! The head camera: what hides a marker, and how noisy its measurements are for a fixed seed.

use std::f64::consts::FRAC_PI_2;

use strata_robot::geometry::{Global, Point, Pose, Segment};
use strata_robot::platform::{ActuatorOrders, HeadAngles, HeadOrder, ObjectClass};
use strata_runtime::Time;
use strata_worldsim::{CameraConfig, Marker, World, WorldSim, WorldSimConfig};

const BEACON: ObjectClass = ObjectClass(1);

fn p(x: f64, y: f64) -> Point<Global> {
    Point::new(x, y)
}

fn sim(world: World, camera: CameraConfig, seed: u64) -> WorldSim {
    let config = WorldSimConfig { camera, ..WorldSimConfig::default() };
    WorldSim::new(config, world, &[Pose::new(0.0, 0.0, 0.0)], seed).expect("valid world")
}

fn certain() -> CameraConfig {
    CameraConfig { detection_probability: 1.0, ..CameraConfig::default() }
}

#[test]
fn a_wall_hides_a_marker_behind_it_and_not_one_on_its_near_face() {
    // A wall across the view at x = 2; one marker behind it, one on its face, one beside it.
    let mut world = World::new(vec![Segment::new(p(2.0, -0.5), p(2.0, 0.5))]);
    world.add_marker(Marker::at("behind", BEACON, Some(0), p(3.0, 0.0)));
    world.add_marker(Marker::at("on the wall", BEACON, Some(1), p(1.98, 0.2)));
    world.add_marker(Marker::at("beside", BEACON, Some(2), p(3.0, 1.0)));
    let mut sim = sim(world, certain(), 1);
    let seen: Vec<_> = sim.look(0).iter().map(|d| d.variant).collect();
    assert_eq!(seen, vec![Some(1), Some(2)]);

    // From behind the wall the one on its face is hidden and the other two are in sight.
    sim.set_pose(0, Pose::new(6.0, 0.0, std::f64::consts::PI)).expect("robot 0");
    let seen: Vec<_> = sim.look(0).iter().map(|d| d.variant).collect();
    assert_eq!(seen, vec![Some(0), Some(2)]);
}

#[test]
fn the_camera_sees_only_inside_its_field_of_view_and_range_and_follows_the_head() {
    let mut world = World::default();
    let ahead = world.add_marker(Marker::at("ahead", BEACON, Some(0), p(3.0, 0.0)));
    world.add_marker(Marker::at("left", BEACON, Some(1), p(0.0, 3.0)));
    world.add_marker(Marker::at("far", BEACON, Some(2), p(7.0, 0.2)));
    world.add_marker(Marker::at("too near", BEACON, Some(3), p(0.2, 0.0)));
    let mut sim = sim(world, certain(), 2);
    let seen = sim.look(0);
    assert_eq!(seen.iter().map(|d| d.variant).collect::<Vec<_>>(), vec![Some(0)]);
    assert!((seen[0].range - 3.0).abs() < 0.5 && seen[0].bearing.abs() < 0.1, "{seen:?}");

    // A marker the application takes away is not reported.
    sim.world_mut().place(ahead, None);
    assert!(sim.look(0).is_empty());

    // Turning the head to the left brings the marker on the left into view.
    let head = HeadOrder { target: HeadAngles { yaw: FRAC_PI_2, pitch: 0.0 }, max_speed: 0.0 };
    sim.apply_orders(0, &ActuatorOrders { head: Some(head), body: None }).expect("head");
    sim.advance_to(Time::from_secs_f64(1.0), &mut ());
    let seen = sim.look(0);
    assert_eq!(seen.iter().map(|d| d.variant).collect::<Vec<_>>(), vec![Some(1)]);
    assert!(seen[0].bearing.abs() < 0.1, "relative to the optical axis: {seen:?}");
}

#[test]
fn noise_and_misses_have_the_configured_statistics_and_repeat_for_a_seed() {
    let camera = CameraConfig {
        detection_probability: 0.8,
        range_sigma: 0.05,
        range_sigma_per_metre: 0.05,
        bearing_sigma: 0.03,
        ..CameraConfig::default()
    };
    let mut world = World::default();
    world.add_marker(Marker::at("beacon", BEACON, None, p(4.0, 0.0)));
    let looks = 4000;
    let draw = |seed| {
        let mut sim = sim(world.clone(), camera.clone(), seed);
        (0..looks).flat_map(|_| sim.look(0)).collect::<Vec<_>>()
    };
    let seen = draw(11);
    assert_eq!(seen, draw(11), "one seed, one run");
    assert_ne!(seen, draw(12));

    let rate = seen.len() as f64 / f64::from(looks);
    assert!((rate - 0.8).abs() < 0.02, "detection rate {rate}");
    let stats = |values: Vec<f64>| {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        (mean, sd)
    };
    let (range_mean, range_sd) = stats(seen.iter().map(|d| d.range - 4.0).collect());
    let (bearing_mean, bearing_sd) = stats(seen.iter().map(|d| d.bearing).collect());
    // sigma = 0.05 + 0.05 * 4 m = 0.25 m; the mean of ~3200 draws is within 3 standard errors.
    assert!(range_mean.abs() < 3.0 * 0.25 / 3200f64.sqrt(), "range bias {range_mean}");
    assert!((range_sd / 0.25 - 1.0).abs() < 0.05, "range sigma {range_sd}");
    assert!(bearing_mean.abs() < 3.0 * 0.03 / 3200f64.sqrt(), "bearing bias {bearing_mean}");
    assert!((bearing_sd / 0.03 - 1.0).abs() < 0.05, "bearing sigma {bearing_sd}");
}
