//! The platform's record of falls against the server's ground truth: when the torso's tilt
//! passed the onset angle, when the robot's protective-fall order reached the platform, when
//! the robot stood again, and the protective-fall orders that no fall followed (false alarms).
//! The time from the onset to the order is the architecture's fall detection latency (the
//! paper's 51 ms figure), measured on this machine's clock from the perception's arrival: the
//! server's own clock only counts 20 ms cycles.

use std::time::Instant;

use serde::{Deserialize, Serialize};

/// Torso tilt from which a fall counts as begun, for [`FallRecord`], rad (20 degrees: beyond
/// what standing and walking sway reach).
pub const FALL_ONSET_TILT: f64 = 0.35;

/// How long before a fall's onset a protective-fall order still counts for it, s (the
/// protective fall's duration). An order that no onset follows within this time, with the
/// torso under the onset tilt all along, is a false alarm.
pub const ORDER_BEFORE_ONSET: f64 = 0.6;

/// How long the robot must stay upright (torso tilt under [`FALL_ONSET_TILT`]) and in no special
/// motion, neither lying nor falling nor getting up, before it counts as standing again, s of
/// the server's time: a get-up that ends tilted, or a robot that topples again at once, is not
/// standing.
pub const UPRIGHT_HOLD: f64 = 1.0;

/// One fall as the platform saw it: the perception in which the torso's tilt first passed
/// [`FALL_ONSET_TILT`] (the ground truth of the onset), the robot's protective-fall order, and
/// the robot standing again. The fall detector extrapolates the tilt with the gyroscope, so a
/// fast fall can be ordered before the torso passes the onset tilt: an order at most
/// [`ORDER_BEFORE_ONSET`] before the onset counts for it, with a negative latency.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FallRecord {
    /// The server's time of the onset perception (the first in which the tilt was past the
    /// onset angle), s.
    pub onset: f64,
    /// When the tilt passed the onset angle, interpolated linearly between the last perception
    /// under it and the onset perception, server time, s (the onset perception's time when no
    /// earlier perception is known).
    #[serde(default)]
    pub crossing: Option<f64>,
    /// The server's time of the newest perception when the order came, s; `None` if no
    /// protective-fall order came (yet).
    pub ordered: Option<f64>,
    /// From the onset perception's arrival to the order, s (negative: ordered before): the time
    /// from the first percept that showed the fall to the command.
    pub latency: Option<f64>,
    /// From the interpolated crossing to the order, s: the time from the sensors' last
    /// perception before the crossing to the onset perception (`onset - crossing`, at most one
    /// 20 ms cycle) plus `latency`. The server runs in real time (the platform paces it), so
    /// its seconds and the machine's are the same.
    #[serde(default)]
    pub onset_to_order: Option<f64>,
    /// Standing again: the server's time of the first perception of the first stretch of
    /// [`UPRIGHT_HOLD`] s after the onset in which the torso's tilt stayed under
    /// [`FALL_ONSET_TILT`] and the body was in no special motion (neither the protective fall,
    /// lying, a get-up nor a kick). `None`: not standing again (yet).
    #[serde(default)]
    pub upright: Option<f64>,
    /// From the arrival of the newest perception when the order came to the order, s: the
    /// architecture's own reaction to its newest data (the fall detector may have seen the
    /// fall in an earlier perception: this is a lower bound of its share).
    #[serde(default)]
    pub reaction: Option<f64>,
    #[serde(skip)]
    onset_at: Option<Instant>,
}

/// Every fall since the platform connected.
#[derive(Clone, Debug, Default)]
pub struct FallLog {
    /// Whether the torso was tilted beyond the onset angle in the newest perception.
    tilted: bool,
    /// The newest perception's server time and tilt, for the crossing's interpolation.
    last: Option<(f64, f64)>,
    /// When the newest perception arrived.
    last_arrival: Option<Instant>,
    falls: Vec<FallRecord>,
    /// A protective-fall order that came with no fall begun: the server's time then, and the
    /// order's instant.
    early_order: Option<(Option<f64>, Instant)>,
    /// The newest order's reaction time, for a fall it predicted.
    early_reaction: Option<f64>,
    /// Orders given with the torso under the onset tilt, waiting for a tilt past it to confirm
    /// them: the server's time then, and the order's instant.
    unconfirmed: Vec<(Option<f64>, Instant)>,
    /// Server time since which the robot has been upright, while the newest fall waits for it.
    upright_since: Option<f64>,
    /// The server's time of every protective-fall order that no fall followed.
    false_falls: Vec<f64>,
}

impl FallLog {
    /// A perception that arrived at `arrived`, stamped `time` by the server, with the torso
    /// tilted `tilt` rad; `protecting`: the body is in a special motion (its protective fall, a
    /// get-up, a kick) or lying (a tilt past the onset then is the same fall, not a new one,
    /// and the robot is not standing).
    pub fn perception(&mut self, time: Option<f64>, tilt: f64, protecting: bool, arrived: Instant) {
        let tilted = tilt > FALL_ONSET_TILT;
        self.confirm_orders(time, tilted, arrived);
        if let Some(time) = time {
            let early = self.early_order.take().filter(|(_, at)| {
                arrived.saturating_duration_since(*at).as_secs_f64() <= ORDER_BEFORE_ONSET
            });
            if tilted && !self.tilted && (!protecting || early.is_some()) {
                let crossing = match self.last {
                    Some((t0, tilt0)) if t0 < time && tilt0 <= FALL_ONSET_TILT && tilt > tilt0 => {
                        t0 + (FALL_ONSET_TILT - tilt0) / (tilt - tilt0) * (time - t0)
                    }
                    _ => time,
                };
                let (ordered, latency) = match early {
                    Some((ordered, at)) => {
                        (ordered, Some(-arrived.saturating_duration_since(at).as_secs_f64()))
                    }
                    None => (None, None),
                };
                self.falls.push(FallRecord {
                    onset: time,
                    crossing: Some(crossing),
                    ordered,
                    latency,
                    onset_to_order: latency.map(|l| time - crossing + l),
                    upright: None,
                    reaction: latency.and(self.early_reaction),
                    onset_at: Some(arrived),
                });
                self.upright_since = None;
            } else {
                // Still waiting for the onset it predicted.
                self.early_order = early;
            }
            self.track_upright(time, tilted || protecting);
            self.last = Some((time, tilt));
        }
        self.tilted = tilted;
        self.last_arrival = Some(arrived);
    }

    /// Standing again after the newest fall: [`UPRIGHT_HOLD`] s upright in no special motion.
    fn track_upright(&mut self, time: f64, down: bool) {
        let Some(fall) = self.falls.last_mut().filter(|f| f.upright.is_none()) else {
            return;
        };
        if down {
            self.upright_since = None;
            return;
        }
        let since = *self.upright_since.get_or_insert(time);
        // The server's times have two decimals: a hair's tolerance.
        if time - since >= UPRIGHT_HOLD - 1e-6 {
            fall.upright = Some(since);
            self.upright_since = None;
        }
    }

    /// Orders given while the torso was under the onset tilt: a tilt past it confirms them;
    /// [`ORDER_BEFORE_ONSET`] s without one makes them false alarms.
    fn confirm_orders(&mut self, time: Option<f64>, tilted: bool, arrived: Instant) {
        let false_falls = &mut self.false_falls;
        self.unconfirmed.retain(|(ordered, at)| {
            let waited = arrived.saturating_duration_since(*at).as_secs_f64();
            if waited <= ORDER_BEFORE_ONSET {
                // Confirmed by this tilt, or still waiting.
                return !tilted;
            }
            if let Some(t) = ordered.or(time) {
                false_falls.push(t);
            }
            false
        });
    }

    /// A protective-fall order reached the platform at `now`; `time`: the server's time of
    /// the newest perception.
    pub fn order(&mut self, time: Option<f64>, now: Instant) {
        tracing::debug!(?time, tilted = self.tilted, "protective fall ordered");
        let tilted = self.tilted;
        if !tilted {
            self.unconfirmed.push((time, now));
        }
        let reaction = self.last_arrival.map(|at| now.saturating_duration_since(at).as_secs_f64());
        match self.falls.last_mut() {
            // The fall under way (a stumble that came upright again was not ordered).
            Some(fall) if fall.ordered.is_none() && tilted => {
                fall.ordered = time;
                fall.latency =
                    fall.onset_at.map(|at| now.saturating_duration_since(at).as_secs_f64());
                fall.onset_to_order =
                    fall.latency.zip(fall.crossing).map(|(l, c)| fall.onset - c + l);
                fall.reaction = reaction;
            }
            // Ordered before the tilt passed the onset: the fall detector predicted it.
            _ => {
                self.early_order = Some((time, now));
                self.early_reaction = reaction;
            }
        }
    }

    pub fn falls(&self) -> &[FallRecord] {
        &self.falls
    }

    /// The server's time of every protective-fall order that no fall followed: given with the
    /// torso under [`FALL_ONSET_TILT`], which then stayed under it for [`ORDER_BEFORE_ONSET`] s.
    pub fn false_falls(&self) -> &[f64] {
        &self.false_falls
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;

    const UPRIGHT: f64 = 0.05;
    const TILTED: f64 = 0.5;

    fn ms(start: Instant, ms: u64) -> Instant {
        start + Duration::from_millis(ms)
    }

    #[test]
    fn an_order_after_the_onset_has_its_latency() {
        let t0 = Instant::now();
        let mut log = FallLog::default();
        log.perception(Some(1.00), UPRIGHT, false, ms(t0, 0));
        log.perception(Some(1.02), TILTED, false, ms(t0, 20));
        log.order(Some(1.02), ms(t0, 27));
        let [fall] = log.falls() else { panic!("one fall: {:?}", log.falls()) };
        assert_eq!((fall.onset, fall.ordered), (1.02, Some(1.02)));
        assert!((fall.latency.unwrap_or_default() - 0.007).abs() < 1e-9, "{fall:?}");
    }

    #[test]
    fn an_order_shortly_before_the_onset_counts_for_it_with_a_negative_latency() {
        let t0 = Instant::now();
        let mut log = FallLog::default();
        log.perception(Some(1.00), UPRIGHT, false, ms(t0, 0));
        log.order(Some(1.00), ms(t0, 5));
        log.perception(Some(1.02), UPRIGHT, true, ms(t0, 20));
        log.perception(Some(1.04), TILTED, true, ms(t0, 45));
        // Tilted again while falling: the same fall.
        log.perception(Some(1.06), UPRIGHT, true, ms(t0, 60));
        log.perception(Some(1.08), TILTED, true, ms(t0, 80));
        let [fall] = log.falls() else { panic!("one fall: {:?}", log.falls()) };
        assert_eq!((fall.onset, fall.ordered), (1.04, Some(1.00)));
        assert!((fall.latency.unwrap_or_default() + 0.040).abs() < 1e-9, "{fall:?}");
    }

    #[test]
    fn an_order_long_before_or_after_a_stumble_is_not_that_fall_s() {
        let t0 = Instant::now();
        let mut log = FallLog::default();
        // A stumble past the onset tilt, upright again, never ordered.
        log.perception(Some(1.00), TILTED, false, ms(t0, 0));
        log.perception(Some(1.02), UPRIGHT, false, ms(t0, 20));
        // A false alarm long after: not the stumble's order, and too early for the next fall.
        log.order(Some(3.00), ms(t0, 2000));
        log.perception(Some(4.00), TILTED, false, ms(t0, 3000));
        let falls = log.falls();
        assert_eq!(falls.len(), 2, "{falls:?}");
        assert!(falls.iter().all(|f| f.ordered.is_none() && f.latency.is_none()), "{falls:?}");
        assert_eq!(log.false_falls(), [3.00], "the order no fall followed is a false alarm");
    }

    #[test]
    fn the_crossing_is_interpolated_and_onset_to_order_adds_the_cycle_before_the_onset() {
        let t0 = Instant::now();
        let mut log = FallLog::default();
        log.perception(Some(1.00), 0.25, false, ms(t0, 0));
        log.perception(Some(1.02), 0.45, false, ms(t0, 20));
        log.order(Some(1.02), ms(t0, 27));
        let [fall] = log.falls() else { panic!("one fall: {:?}", log.falls()) };
        let crossing = fall.crossing.unwrap_or_default();
        assert!((crossing - 1.01).abs() < 1e-9, "half way between 0.25 and 0.45 rad: {fall:?}");
        let onset_to_order = fall.onset_to_order.unwrap_or_default();
        assert!((onset_to_order - 0.017).abs() < 1e-9, "10 ms + 7 ms: {fall:?}");
        let reaction = fall.reaction.unwrap_or_default();
        assert!((reaction - 0.007).abs() < 1e-9, "from the newest perception: {fall:?}");
        assert!(log.false_falls().is_empty());
    }

    /// Perceptions every 20 ms from `from` s to `to` s (exclusive), arriving on the same clock.
    fn perceive(log: &mut FallLog, t0: Instant, from: f64, to: f64, tilt: f64, protecting: bool) {
        let mut t = from;
        while t < to - 1e-9 {
            let at = ms(t0, (t * 1000.0).round() as u64);
            log.perception(Some((t * 100.0).round() / 100.0), tilt, protecting, at);
            t += 0.02;
        }
    }

    #[test]
    fn standing_again_is_the_start_of_a_second_upright_in_no_special_motion() {
        let t0 = Instant::now();
        let mut log = FallLog::default();
        perceive(&mut log, t0, 0.0, 1.0, UPRIGHT, false);
        perceive(&mut log, t0, 1.0, 1.1, TILTED, false);
        log.order(Some(1.08), ms(t0, 1085));
        // Lying, then getting up: the torso passes upright during the get-up (a special
        // motion), which is not standing.
        perceive(&mut log, t0, 1.1, 3.0, 1.5, true);
        perceive(&mut log, t0, 3.0, 4.0, UPRIGHT, true);
        // Standing half a second, toppling again without a new onset (still protecting), then
        // standing for good from 5.0 s.
        perceive(&mut log, t0, 4.0, 4.5, UPRIGHT, false);
        perceive(&mut log, t0, 4.5, 5.0, 0.6, true);
        perceive(&mut log, t0, 5.0, 5.9, UPRIGHT, false);
        assert_eq!(log.falls()[0].upright, None, "not upright for a second yet");
        perceive(&mut log, t0, 5.9, 7.0, UPRIGHT, false);
        let [fall] = log.falls() else { panic!("one fall: {:?}", log.falls()) };
        assert_eq!(fall.upright, Some(5.0), "{fall:?}");
        assert!(log.false_falls().is_empty(), "the order had its fall: {:?}", log.false_falls());
    }

    #[test]
    fn an_order_no_tilt_followed_is_a_false_alarm_and_orders_while_lying_are_not() {
        let t0 = Instant::now();
        let mut log = FallLog::default();
        perceive(&mut log, t0, 0.0, 1.0, UPRIGHT, false);
        log.order(Some(0.98), ms(t0, 990));
        perceive(&mut log, t0, 1.0, 1.5, UPRIGHT, true);
        assert!(log.false_falls().is_empty(), "still within the protective fall's time");
        perceive(&mut log, t0, 1.5, 2.0, UPRIGHT, false);
        assert_eq!(log.false_falls(), [0.98]);
        assert!(log.falls().is_empty());
        // A real fall, ordered twice while the torso is past the onset tilt: no false alarm.
        perceive(&mut log, t0, 2.0, 2.3, TILTED, false);
        log.order(Some(2.28), ms(t0, 2285));
        perceive(&mut log, t0, 2.3, 3.0, 1.5, true);
        log.order(Some(2.98), ms(t0, 2985));
        perceive(&mut log, t0, 3.0, 4.0, 1.5, true);
        assert_eq!(log.false_falls(), [0.98]);
        assert_eq!(log.falls().len(), 1);
        assert_eq!(log.falls()[0].ordered, Some(2.28));
    }
}
