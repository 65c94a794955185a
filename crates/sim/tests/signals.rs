//! The head referee's signals (`referee.signals`): the Ready gesture cameras see and the
//! whistle microphones hear, with their misses and false detections. Fixed seeds throughout;
//! statistical bounds are loose (four standard deviations or more).

mod common;

use std::time::Duration;

use common::*;
use strata_robot::platform::{Detection, SensorFrame};
use strata_sim::config::SignalConfig;
use strata_sim::{EventKind, FallDirection, GameState, Penalty, RobotId, SimConfig, Simulation};
use strata_spl::{Gesture, ObjectKind};

use std::f64::consts::FRAC_PI_2;

/// Where the referee stands on the default field (half width 3 m, 0.6 m behind the line).
const REFEREE: (f64, f64) = (0.0, -3.6);

/// A quiet world (no noise, manual referee, Playing) with the signals on, as `adjust` sets
/// them.
fn signalling(adjust: impl FnOnce(&mut SignalConfig)) -> Simulation {
    quiet(|c| {
        c.referee.signals = SignalConfig { enabled: true, ..SignalConfig::default() };
        adjust(&mut c.referee.signals);
    })
}

/// Every sensor frame of `robot` over `seconds`, reading each one as a platform does.
fn frames(sim: &mut Simulation, robot: RobotId, seconds: f64) -> Vec<SensorFrame> {
    let mut out = Vec::new();
    let steps = (seconds / 0.012).round() as usize;
    for _ in 0..steps {
        sim.run_for(Duration::from_millis(12));
        if let Some(frame) = sim.take_sensor_frame(robot).expect("known robot") {
            out.push(frame);
        }
    }
    out
}

fn gestures(frame: &SensorFrame) -> Vec<Detection> {
    frame.camera.as_ref().map_or_else(Vec::new, |image| {
        image
            .detections
            .iter()
            .filter(|d| d.class.0 == ObjectKind::Referee.code())
            .copied()
            .collect()
    })
}

/// Images taken, and images that report the Ready gesture.
fn count_gestures(frames: &[SensorFrame]) -> (usize, usize) {
    let images = frames.iter().filter(|f| f.camera.is_some()).count();
    let seen = frames.iter().filter(|f| !gestures(f).is_empty()).count();
    (images, seen)
}

/// Standby -> Ready: the referee starts the gesture.
fn signal_ready(sim: &mut Simulation) {
    sim.set_game_state(GameState::Standby);
    sim.set_game_state(GameState::Ready);
}

/// Set -> Playing: the kick-off whistle.
fn kick_off(sim: &mut Simulation) {
    sim.set_game_state(GameState::Set);
    sim.set_game_state(GameState::Playing);
}

fn whistles(sim: &Simulation) -> Vec<Vec<RobotId>> {
    sim.events()
        .iter()
        .filter_map(|e| match &e.kind {
            EventKind::Whistle { robots } => Some(robots.clone()),
            _ => None,
        })
        .collect()
}

fn false_whistles(sim: &Simulation, robot: RobotId) -> usize {
    sim.events()
        .iter()
        .filter(|e| matches!(e.kind, EventKind::FalseWhistle { robot: r } if r == robot))
        .count()
}

// ---------------------------------------------------------------------------------------------
// The Ready gesture.

#[test]
fn a_robot_facing_the_referee_sees_the_ready_gesture_only_while_it_is_shown() {
    let mut sim = signalling(|s| s.gesture_detection = 1.0);
    only(&mut sim, &[A1]);
    place(&mut sim, A1, 0.0, -1.0, -FRAC_PI_2);
    sim.set_game_state(GameState::Standby);
    let (images, seen) = count_gestures(&frames(&mut sim, A1, 1.0));
    assert!(images > 20 && seen == 0, "no gesture in Standby: {seen} of {images}");

    sim.set_game_state(GameState::Ready);
    let window = frames(&mut sim, A1, 4.9);
    let (images, seen) = count_gestures(&window);
    assert!(images > 140 && seen == images, "every image of the window: {seen} of {images}");
    for frame in &window {
        for d in gestures(frame) {
            assert_eq!(d.variant, Some(Gesture::Ready.code()));
            assert!((d.range - 2.6).abs() < 1e-9 && d.bearing.abs() < 1e-9, "{d:?}");
        }
    }
    frames(&mut sim, A1, 0.2);
    let (images, seen) = count_gestures(&frames(&mut sim, A1, 5.0));
    assert!(images > 140 && seen == 0, "the gesture is over: {seen} of {images}");
}

#[test]
fn the_gesture_is_not_seen_facing_away_behind_a_robot_beyond_its_range_or_lying() {
    let mut sim = signalling(|s| s.gesture_detection = 1.0);
    only(&mut sim, &[A1, A2, A3, B1, B2]);
    // A1 faces away; A2 looks at it past B1; A3 is 7.6 m away (beyond the camera's 6 m, within
    // the gesture's 10 m); B2 faces it but lies on the ground.
    place(&mut sim, A1, 0.0, -1.0, FRAC_PI_2);
    place(&mut sim, A2, -1.0, 0.0, (-3.6f64).atan2(1.0));
    place(&mut sim, B1, -0.5, -1.8, 0.0);
    place(&mut sim, A3, 4.0, 2.9, (-6.5f64).atan2(-4.0));
    place(&mut sim, B2, 1.0, -1.0, -FRAC_PI_2);
    sim.force_fall(B2, FallDirection::Back).expect("known robot");
    steps(&mut sim, 1.0);
    signal_ready(&mut sim);
    let mut seen = [0usize; 4];
    for _ in 0..(4.5f64 / 0.012) as usize {
        sim.run_for(Duration::from_millis(12));
        for (k, robot) in [A1, A2, A3, B2].into_iter().enumerate() {
            if let Some(frame) = sim.take_sensor_frame(robot).expect("known robot") {
                seen[k] += usize::from(!gestures(&frame).is_empty());
            }
        }
    }
    assert_eq!((seen[0], seen[1], seen[3]), (0, 0, 0), "away, hidden, lying: {seen:?}");
    assert!(seen[2] > 100, "a person is seen farther than the camera's range: {seen:?}");

    // Beyond `gesture_range`.
    let mut sim = signalling(|s| {
        s.gesture_detection = 1.0;
        s.gesture_range = 7.0;
    });
    only(&mut sim, &[A1, A3]);
    place(&mut sim, A1, 0.0, 0.0, -FRAC_PI_2);
    place(&mut sim, A3, 4.0, 2.9, (-6.5f64).atan2(-4.0));
    signal_ready(&mut sim);
    let mut seen = [0usize; 2];
    for _ in 0..(4.5f64 / 0.012) as usize {
        sim.run_for(Duration::from_millis(12));
        for (k, robot) in [A1, A3].into_iter().enumerate() {
            if let Some(frame) = sim.take_sensor_frame(robot).expect("known robot") {
                seen[k] += usize::from(!gestures(&frame).is_empty());
            }
        }
    }
    assert!(seen[0] > 100 && seen[1] == 0, "3.6 m seen, 7.6 m not: {seen:?}");
}

#[test]
fn gesture_detections_come_at_the_configured_rate_with_the_camera_noise() {
    let mut config = SimConfig { seed: 21, ..SimConfig::default() };
    config.referee.auto = false;
    config.referee.signals.enabled = true;
    let mut sim = Simulation::new(config).expect("valid");
    sim.set_game_state(GameState::Playing);
    only(&mut sim, &[A1]);
    place(&mut sim, A1, 1.0, -0.5, (-3.1f64).atan2(-1.0));
    let (mut images, mut seen, mut ranges) = (0, 0, Vec::new());
    for _ in 0..4 {
        signal_ready(&mut sim);
        let window = frames(&mut sim, A1, 4.9);
        let (i, s) = count_gestures(&window);
        images += i;
        seen += s;
        ranges.extend(window.iter().flat_map(gestures).map(|d| d.range));
        frames(&mut sim, A1, 1.0);
    }
    // 0.85 of about 590 images: 500 +- 9 (one standard deviation).
    let rate = seen as f64 / images as f64;
    assert!(images > 560 && (rate - 0.85).abs() < 0.06, "{seen} of {images}");
    let mean = ranges.iter().sum::<f64>() / ranges.len() as f64;
    let distance = (1.0f64.powi(2) + 3.1f64.powi(2)).sqrt();
    assert!((mean - distance).abs() < 0.05, "mean range {mean}, true {distance}");
    assert!(ranges.iter().any(|r| (r - distance).abs() > 0.01), "ranges carry noise");
}

// ---------------------------------------------------------------------------------------------
// The whistle.

#[test]
fn robots_within_whistle_range_hear_the_kick_off_whistle_once() {
    let mut sim = signalling(|s| {
        s.whistle_miss = 0.0;
        s.whistle_false_rate = 0.0;
        s.whistle_range = 4.0;
    });
    only(&mut sim, &[A1, A2, B1]);
    place(&mut sim, A1, 0.0, -1.0, 0.0); // 2.6 m from the referee
    place(&mut sim, B1, 4.0, 2.9, 0.0); // 7.6 m
    // Penalized with the ball at +y, A2 waits beside its re-entry point at -y, 3.2 m away.
    sim.place_ball(point(0.0, 1.0), strata_robot::Vector::new(0.0, 0.0)).expect("a valid ball");
    sim.penalize(A2, Penalty::PlayerPushing, None).expect("known robot");
    let held = sim.robot(A2).expect("known robot").pose.position();
    assert!(held.distance(point(REFEREE.0, REFEREE.1)) < 4.0, "held within range: {held:?}");
    steps(&mut sim, 1.0);
    for robot in [A1, A2, B1] {
        sim.take_sensor_frame(robot).expect("known robot");
    }
    kick_off(&mut sim);
    let heard =
        |frames: &[SensorFrame]| frames.iter().filter_map(|f| f.whistle).collect::<Vec<_>>();
    let a1 = frames(&mut sim, A1, 2.0);
    let confidence = heard(&a1);
    assert_eq!(confidence.len(), 1, "once, in the next frame");
    assert!(a1[0].whistle.is_some(), "in the next frame");
    assert!((0.6..=1.0).contains(&confidence[0]), "{confidence:?}");
    // A2 and B1 were not read: the report waits in the frame a platform reads next.
    let a2 = sim.take_sensor_frame(A2).expect("known robot").expect("a frame");
    assert!(a2.whistle.is_some_and(|c| (0.6..=1.0).contains(&c)), "{:?}", a2.whistle);
    assert!(heard(&frames(&mut sim, B1, 1.0)).is_empty());
    let b1 = sim.take_sensor_frame(B1).expect("known robot");
    assert!(b1.is_none_or(|f| f.whistle.is_none()));
    assert_eq!(whistles(&sim), [vec![A1, A2]]);

    // A goal is whistled too.
    sim.place_ball(
        point(sim.field().half_length() + 0.3, 0.0),
        strata_robot::Vector::new(0.0, 0.0),
    )
    .expect("a valid ball");
    let a1 = frames(&mut sim, A1, 1.0);
    assert_eq!(heard(&a1).len(), 1, "the goal's whistle");
    assert!(sim.events().iter().any(|e| matches!(e.kind, EventKind::Goal { team: 0, .. })));
    assert_eq!(whistles(&sim).len(), 2);

    // Playing entered from anything but Set is no kick-off.
    sim.set_game_state(GameState::Ready);
    sim.set_game_state(GameState::Playing);
    assert!(heard(&frames(&mut sim, A1, 1.0)).is_empty());
    assert_eq!(whistles(&sim).len(), 2);
}

#[test]
fn robots_miss_whistles_at_about_the_configured_rate() {
    let mut sim = signalling(|s| {
        s.whistle_miss = 0.3;
        s.whistle_false_rate = 0.0;
    });
    // Every robot is within the default 12 m of the referee.
    let robots = sim.robot_ids().count();
    let mut confidences = Vec::new();
    for _ in 0..100 {
        kick_off(&mut sim);
        steps(&mut sim, 0.1);
        for robot in sim.robot_ids().collect::<Vec<_>>() {
            if let Some(frame) = sim.take_sensor_frame(robot).expect("known robot") {
                confidences.extend(frame.whistle);
            }
        }
    }
    let heard: usize = whistles(&sim).iter().map(Vec::len).sum();
    assert_eq!(heard, confidences.len(), "every hearing reaches a frame");
    // 1400 chances to hear at 0.7: 980 +- 17 (one standard deviation).
    let total = 100 * robots;
    let missed = (total - heard) as f64 / total as f64;
    assert!((missed - 0.3).abs() < 0.05, "{heard} of {total} heard");
    assert!(confidences.iter().all(|c| (0.6..=1.0).contains(c)));
    let mean = confidences.iter().sum::<f64>() / confidences.len() as f64;
    assert!((mean - 0.8).abs() < 0.02, "uniform in [0.6, 1]: mean {mean}");
}

#[test]
fn false_whistles_come_at_about_the_configured_rate() {
    let mut sim = signalling(|s| s.whistle_false_rate = 6.0);
    let frames = frames(&mut sim, A1, 600.0);
    let reported: Vec<f64> = frames.iter().filter_map(|f| f.whistle).collect();
    assert_eq!(reported.len(), false_whistles(&sim, A1), "every false detection is reported");
    assert!(reported.iter().all(|c| (0.5..=0.8).contains(c)), "{reported:?}");
    // 6 a minute for 10 minutes per robot: 60 +- 8 for one, 840 +- 29 for 14.
    assert!((30..=90).contains(&reported.len()), "{}", reported.len());
    let all: usize = sim.robot_ids().map(|r| false_whistles(&sim, r)).sum();
    assert!((720..=960).contains(&all), "{all}");
    assert!(whistles(&sim).is_empty(), "no true whistle");
}

// ---------------------------------------------------------------------------------------------
// Off, and deterministic.

#[test]
fn disabled_signals_produce_no_whistle_and_no_gesture() {
    let mut sim = quiet(|c| {
        c.referee.signals = SignalConfig {
            enabled: false,
            gesture_detection: 1.0,
            whistle_miss: 0.0,
            whistle_false_rate: 600.0,
            ..SignalConfig::default()
        };
    });
    only(&mut sim, &[A1]);
    place(&mut sim, A1, 0.0, -1.0, -FRAC_PI_2);
    signal_ready(&mut sim);
    let mut all = frames(&mut sim, A1, 3.0);
    kick_off(&mut sim);
    all.extend(frames(&mut sim, A1, 3.0));
    assert!(all.iter().all(|f| f.whistle.is_none() && gestures(f).is_empty()));
    assert!(count_gestures(&all).0 > 170, "images were taken");
    assert!(
        !sim.events()
            .iter()
            .any(|e| matches!(e.kind, EventKind::Whistle { .. } | EventKind::FalseWhistle { .. }))
    );
}

/// A game of the automatic referee through Standby, with robots walking and looking around:
/// every sensor frame of every robot, and the ground truth.
fn game(seed: u64, signals: bool) -> (Vec<SensorFrame>, strata_sim::GroundTruth) {
    let mut config = SimConfig { seed, ..SimConfig::default() };
    config.referee.standby_duration = 3.0;
    config.referee.ready_duration = 10.0;
    config.referee.signals.enabled = signals;
    config.referee.signals.whistle_false_rate = 2.0;
    let mut sim = Simulation::new(config).expect("valid");
    let ids: Vec<RobotId> = sim.robot_ids().collect();
    let mut frames = Vec::new();
    for step in 0..(40.0f64 / 0.012) as usize {
        if step % 100 == 0 {
            for (i, id) in ids.iter().enumerate() {
                let k = (step / 100 + i) as f64;
                walk(
                    &mut sim,
                    *id,
                    0.1 * (k * 0.7).sin(),
                    0.05 * (k * 0.3).cos(),
                    (k * 0.11).sin(),
                );
                look(&mut sim, *id, (k * 0.9).sin(), 0.1);
            }
        }
        sim.run_for(Duration::from_millis(12));
        for id in &ids {
            frames.extend(sim.take_sensor_frame(*id).expect("known robot"));
        }
    }
    (frames, sim.ground_truth())
}

#[test]
fn signals_are_deterministic_and_leave_every_other_draw_as_it_was() {
    let (frames, truth) = game(3, true);
    let (again, truth_again) = game(3, true);
    assert_eq!(frames, again, "the same seed gave different frames");
    assert_eq!(truth, truth_again, "the same seed gave different worlds");
    let signalled =
        |k: &EventKind| matches!(k, EventKind::Whistle { .. } | EventKind::FalseWhistle { .. });
    assert!(
        truth
            .events
            .iter()
            .any(|e| matches!(&e.kind, EventKind::Whistle { robots } if robots.len() > 10))
    );
    assert!(frames.iter().any(|f| !gestures(f).is_empty()), "the gesture was seen");

    // The robots do not act on the signals here, so without them the world is the same and
    // so is every frame but for the signals.
    let (quiet_frames, quiet_truth) = game(3, false);
    let mut strip = truth.clone();
    strip.events.retain(|e| !signalled(&e.kind));
    assert_eq!(strip, quiet_truth);
    assert_eq!(frames.len(), quiet_frames.len());
    for (mut signal, plain) in frames.into_iter().zip(quiet_frames) {
        signal.whistle = None;
        if let Some(image) = signal.camera.as_mut() {
            image.detections.retain(|d| d.class.0 != ObjectKind::Referee.code());
        }
        assert_eq!(signal, plain);
    }
}
