//! The live viewer's tap on a running match: it asks the host for the outputs it draws only,
//! and what it is shown becomes the picture of the game.

use std::sync::{Arc, PoisonError};

use strata_games::matches::{Match, MatchConfig};
use strata_view::LiveTap;

#[test]
fn a_live_match_shows_every_robot_with_its_own_estimate_and_the_true_ball() {
    let config = MatchConfig { players: 2, seed: 3, limit: Some(40.0), ..MatchConfig::default() };
    let mut game = Match::new(config).expect("a valid match");
    let (data, tap) = LiveTap::for_match(&game, None);
    game.add_tap(Arc::new(tap));
    game.play(&mut |_, _| {}).expect("the match runs");

    let data = data.read().unwrap_or_else(PoisonError::into_inner);
    let frame = data.frame(Some(39.0));
    assert_eq!(frame.robots.len(), 4, "two robots a team: {:?}", frame.robots);
    assert!(frame.ball.is_some(), "the true ball from the ground truth");
    assert!(frame.game.is_some(), "the game state from the ground truth");
    for robot in &frame.robots {
        assert!(robot.pose.is_some(), "{}: its true pose", robot.name);
        assert!(robot.estimate.is_some(), "{}: its world model's pose", robot.name);
        assert!(robot.mission.is_some(), "{}: its planning decision", robot.name);
        // The scene's team-to-field turn: the away team's estimates land where its robots
        // are, not mirrored through the centre.
        let (truth, estimate) =
            (robot.pose.unwrap_or_default(), robot.estimate.unwrap_or_default());
        if !robot.lost {
            let error = (truth.x - estimate.x).hypot(truth.y - estimate.y);
            assert!(error < 1.0, "{}: estimate {error:.2} m from the truth", robot.name);
        }
        let ball = robot.ball.as_ref().expect("a ball estimate");
        assert_eq!(ball.ellipse.len(), 24, "{}: the scene's covariance ellipse", robot.name);
        let (cx, cy) = ball.ellipse.iter().fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
        let centre = (cx / 24.0 - ball.x).hypot(cy / 24.0 - ball.y);
        assert!(centre < 1e-3, "{}: the ellipse around the estimate ({centre})", robot.name);
    }
}
