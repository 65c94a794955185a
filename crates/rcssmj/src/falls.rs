//! The platform's record of falls against the server's ground truth: when the torso's tilt
//! passed the onset angle, and when the robot's protective-fall order reached the platform.
//! The time between them is the architecture's fall detection latency (the paper's 51 ms
//! figure), measured on this machine's clock from the perception's arrival: the server's own
//! clock only counts 20 ms cycles.

use std::time::Instant;

use serde::{Deserialize, Serialize};

/// Torso tilt from which a fall counts as begun, for [`FallRecord`], rad (20 degrees: beyond
/// what standing and walking sway reach).
pub const FALL_ONSET_TILT: f64 = 0.35;

/// How long before a fall's onset a protective-fall order still counts for it, s (the
/// protective fall's duration).
pub const ORDER_BEFORE_ONSET: f64 = 0.6;

/// One fall as the platform saw it: the perception in which the torso's tilt first passed
/// [`FALL_ONSET_TILT`] (the ground truth of the onset), and the robot's protective-fall order.
/// The fall detector extrapolates the tilt with the gyroscope, so a fast fall can be ordered
/// before the torso passes the onset tilt: an order at most [`ORDER_BEFORE_ONSET`] before the
/// onset counts for it, with a negative latency.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FallRecord {
    /// The server's time of the onset, s.
    pub onset: f64,
    /// The server's time of the newest perception when the order came, s; `None` if no
    /// protective-fall order came (yet).
    pub ordered: Option<f64>,
    /// From the onset perception's arrival to the order, s (negative: ordered before).
    pub latency: Option<f64>,
    #[serde(skip)]
    onset_at: Option<Instant>,
}

/// Every fall since the platform connected.
#[derive(Clone, Debug, Default)]
pub struct FallLog {
    /// Whether the torso was tilted beyond the onset angle in the newest perception.
    tilted: bool,
    falls: Vec<FallRecord>,
    /// A protective-fall order that came with no fall begun: the server's time then, and the
    /// order's instant.
    early_order: Option<(Option<f64>, Instant)>,
}

impl FallLog {
    /// A perception that arrived at `arrived`, stamped `time` by the server, with the torso
    /// tilted `tilt` rad; `protecting`: the body is in its protective fall or lying already (a
    /// tilt past the onset then is the same fall, not a new one).
    pub fn perception(&mut self, time: Option<f64>, tilt: f64, protecting: bool, arrived: Instant) {
        let tilted = tilt > FALL_ONSET_TILT;
        if let Some(time) = time {
            let early = self.early_order.take().filter(|(_, at)| {
                arrived.saturating_duration_since(*at).as_secs_f64() <= ORDER_BEFORE_ONSET
            });
            if tilted && !self.tilted && (!protecting || early.is_some()) {
                let (ordered, latency) = match early {
                    Some((ordered, at)) => {
                        (ordered, Some(-arrived.saturating_duration_since(at).as_secs_f64()))
                    }
                    None => (None, None),
                };
                self.falls.push(FallRecord {
                    onset: time,
                    ordered,
                    latency,
                    onset_at: Some(arrived),
                });
            } else {
                // Still waiting for the onset it predicted.
                self.early_order = early;
            }
        }
        self.tilted = tilted;
    }

    /// A protective-fall order reached the platform at `now`; `time`: the server's time of
    /// the newest perception.
    pub fn order(&mut self, time: Option<f64>, now: Instant) {
        tracing::debug!(?time, tilted = self.tilted, "protective fall ordered");
        let tilted = self.tilted;
        match self.falls.last_mut() {
            // The fall under way (a stumble that came upright again was not ordered).
            Some(fall) if fall.ordered.is_none() && tilted => {
                fall.ordered = time;
                fall.latency =
                    fall.onset_at.map(|at| now.saturating_duration_since(at).as_secs_f64());
            }
            // Ordered before the tilt passed the onset: the fall detector predicted it.
            _ => self.early_order = Some((time, now)),
        }
    }

    pub fn falls(&self) -> &[FallRecord] {
        &self.falls
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
    }
}
