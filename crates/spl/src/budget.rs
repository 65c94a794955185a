//! The team-message budget: the GameController counts every team message a team sends and
//! publishes how many are left for the game (`TeamInfo::message_budget`); a team that runs out
//! may not send any more. This accountant decides when one robot may send.

use std::time::Duration;

use serde::{Deserialize, Serialize};

/// How a robot paces its share of the team's budget.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BudgetConfig {
    /// Assumed until the first control packet arrives (the rule book's budget per game).
    pub initial_budget: u16,
    /// Kept back from paced messages: for urgent messages, and to absorb what teammates and
    /// this robot sent after the GameController's last count.
    pub reserve: u16,
    /// Robots of the team sharing the budget; each paces itself to its share.
    pub senders: u8,
    /// Never send paced messages closer together than this (seconds).
    pub min_interval_secs: f64,
}

impl Default for BudgetConfig {
    fn default() -> Self {
        BudgetConfig { initial_budget: 1200, reserve: 60, senders: 7, min_interval_secs: 0.25 }
    }
}

/// Tracks the team's remaining budget and this robot's sends.
#[derive(Clone, Debug)]
pub struct MessageBudget {
    config: BudgetConfig,
    team_remaining: u16,
    sent_since_update: u16,
    last_sent: Option<Duration>,
}

impl MessageBudget {
    /// A budget at `config.initial_budget`, nothing sent yet.
    pub fn new(config: BudgetConfig) -> MessageBudget {
        let team_remaining = config.initial_budget;
        MessageBudget { config, team_remaining, sent_since_update: 0, last_sent: None }
    }

    /// The pacing settings.
    pub fn config(&self) -> &BudgetConfig {
        &self.config
    }

    /// Takes the team's remaining budget from a control packet. Messages this robot sent
    /// before now are assumed counted by it; the reserve covers those still in flight.
    pub fn update(&mut self, team_remaining: u16) {
        self.team_remaining = team_remaining;
        self.sent_since_update = 0;
    }

    /// The team's remaining budget, less what this robot sent since the last update.
    pub fn remaining(&self) -> u16 {
        self.team_remaining.saturating_sub(self.sent_since_update)
    }

    /// Whether a paced message may go now. Pacing spreads this robot's share of the budget
    /// above the reserve evenly over `remaining_game_time`; `now` is any monotonic time.
    pub fn can_send(&self, now: Duration, remaining_game_time: Duration) -> bool {
        let available = self.remaining().saturating_sub(self.config.reserve);
        if available == 0 {
            return false;
        }
        let Some(last) = self.last_sent else { return true };
        let share = f64::from(available) / f64::from(self.config.senders.max(1));
        let interval =
            (remaining_game_time.as_secs_f64() / share).max(self.config.min_interval_secs);
        now.saturating_sub(last).as_secs_f64() >= interval
    }

    /// Whether an urgent message (a fall, a lost ball: the paper's instant messages) may go:
    /// it may use the reserve, but never the last message the team does not have.
    pub fn can_send_urgent(&self) -> bool {
        self.remaining() > 0
    }

    /// Counts a message this robot sent at `now`.
    pub fn record_sent(&mut self, now: Duration) {
        self.sent_since_update = self.sent_since_update.saturating_add(1);
        self.last_sent = Some(now);
    }

    /// `can_send`, and if so `record_sent`: for a robot that sends whenever allowed.
    pub fn try_send(&mut self, now: Duration, remaining_game_time: Duration) -> bool {
        let ok = self.can_send(now, remaining_game_time);
        if ok {
            self.record_sent(now);
        }
        ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn secs(s: f64) -> Duration {
        Duration::from_secs_f64(s)
    }

    #[test]
    fn paces_the_share_over_the_remaining_time() {
        let config =
            BudgetConfig { initial_budget: 160, reserve: 10, senders: 5, min_interval_secs: 0.0 };
        let mut budget = MessageBudget::new(config);
        assert!(budget.try_send(secs(0.0), secs(600.0)));
        // 149 above the reserve, a fifth of it each: one message per 600 / 29.8 = 20.13 s.
        assert!(!budget.can_send(secs(20.0), secs(600.0)));
        assert!(budget.can_send(secs(20.2), secs(600.0)));
        // With less time left, the same share goes faster: 300 / 29.8 = 10.07 s.
        assert!(budget.can_send(secs(10.1), secs(300.0)));
        assert_eq!(budget.remaining(), 159);
    }

    #[test]
    fn reserve_is_only_for_urgent_messages() {
        let mut budget = MessageBudget::new(BudgetConfig::default());
        budget.update(60);
        assert!(!budget.can_send(secs(100.0), secs(10.0)));
        assert!(budget.can_send_urgent());
        budget.update(1);
        assert!(budget.can_send_urgent());
        budget.record_sent(secs(101.0));
        assert_eq!(budget.remaining(), 0);
        assert!(!budget.can_send_urgent());
        budget.update(0);
        assert!(!budget.can_send_urgent());
    }

    #[test]
    fn updates_replace_local_counting() {
        let mut budget = MessageBudget::new(BudgetConfig::default());
        for t in 0..5 {
            budget.record_sent(secs(f64::from(t)));
        }
        assert_eq!(budget.remaining(), 1195);
        budget.update(1000);
        assert_eq!(budget.remaining(), 1000);
    }

    #[test]
    fn min_interval_holds_at_the_end_of_the_game() {
        let mut budget = MessageBudget::new(BudgetConfig::default());
        assert!(budget.try_send(secs(10.0), Duration::ZERO));
        assert!(!budget.can_send(secs(10.1), Duration::ZERO));
        assert!(budget.can_send(secs(10.3), Duration::ZERO));
    }

    #[test]
    fn a_whole_game_spends_the_share_but_never_more() {
        let game = 1200.0;
        let config =
            BudgetConfig { initial_budget: 100, reserve: 10, senders: 1, min_interval_secs: 0.25 };
        let mut budget = MessageBudget::new(config);
        let mut sent = 0;
        for step in 0..=(game as u32 * 10) {
            let now = f64::from(step) / 10.0;
            if budget.try_send(secs(now), secs(game - now)) {
                sent += 1;
            }
            if step % 5 == 0 {
                // The GameController's count, twice a second.
                budget.update(100 - sent);
            }
        }
        assert!((85..=90).contains(&sent), "sent {sent}");
    }
}
