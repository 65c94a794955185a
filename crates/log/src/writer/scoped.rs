//! [`ScopedTap`]: one host's tap into a log shared by several, under a topic prefix.

use std::sync::Arc;

use strata_runtime::{ErasedPackage, Tap, TapOutput, TapRecord, TapSender, Time};

use super::{Locked, McapSender, McapTap, Offered, TopicCache};

/// A tap logging under a topic prefix into a shared [`McapTap`] (see [`McapTap::scoped`]).
pub struct ScopedTap {
    pub(super) tap: Arc<McapTap>,
    pub(super) topics: Arc<TopicCache>,
}

impl std::fmt::Debug for ScopedTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScopedTap").field("prefix", &self.topics.prefix).finish()
    }
}

impl ScopedTap {
    pub fn prefix(&self) -> &str {
        &self.topics.prefix
    }

    pub fn log(&self) -> &Arc<McapTap> {
        &self.tap
    }
}

impl Tap for ScopedTap {
    fn wants(&self, output: &TapOutput<'_>) -> bool {
        self.topics.wants(&self.tap.shared, output)
    }

    fn package(&self, record: &TapRecord<'_>) {
        let shown = Offered::Shown(record.package);
        let shared = &self.tap.shared;
        let output = record.sent_on;
        shared.tap_package(&mut Locked(&shared.pending), &self.topics, &output, record.time, shown);
    }

    fn package_owned(&self, output: &TapOutput<'_>, time: Time, package: Box<dyn ErasedPackage>) {
        let shared = &self.tap.shared;
        let given = Offered::Given(package);
        shared.tap_package(&mut Locked(&shared.pending), &self.topics, output, time, given);
    }

    fn sender(&self) -> Option<Box<dyn TapSender>> {
        McapSender::boxed(&self.tap.shared, &self.topics)
    }
}
