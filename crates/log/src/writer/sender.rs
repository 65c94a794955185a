//! A log's sender for one host, which gathers its batches without a lock.

use std::sync::Arc;

use strata_runtime::{ErasedPackage, TapOutput, TapRecord, TapSender, Time};

use super::{Gather, Gathering, Offered, Shared, TopicCache, WhenFull};

/// A log's sender for one host ([`Tap::sender`](strata_runtime::Tap::sender)): the batches of a
/// sender that waits ([`WhenFull::Wait`]) gathered without the lock of the log's shared batch. A
/// real-time sender hands each package over at once and has none. Application records
/// ([`McapTap::record`](crate::McapTap::record)) still go to the shared batch, which is handed over
/// ahead of each of the host's: records written between two runs of the host come after the
/// packages of the first and before those of the second, as they would through the tap itself.
pub(super) struct McapSender {
    pub(super) shared: Arc<Shared>,
    pub(super) topics: Arc<TopicCache>,
    pub(super) gathering: Gathering,
}

impl McapSender {
    pub(super) fn boxed(
        shared: &Arc<Shared>,
        topics: &Arc<TopicCache>,
    ) -> Option<Box<dyn TapSender>> {
        (shared.when_full == WhenFull::Wait).then(|| {
            Box::new(McapSender {
                shared: Arc::clone(shared),
                topics: Arc::clone(topics),
                gathering: Gathering { batch: shared.spare(), modules: Vec::new() },
            }) as Box<dyn TapSender>
        })
    }
}

impl TapSender for McapSender {
    fn package(&mut self, record: &TapRecord<'_>) {
        let shown = Offered::Shown(record.package);
        let output = record.sent_on;
        self.shared.tap_package(&mut self.gathering, &self.topics, &output, record.time, shown);
    }

    fn package_owned(
        &mut self,
        output: &TapOutput<'_>,
        time: Time,
        package: Box<dyn ErasedPackage>,
    ) {
        let given = Offered::Given(package);
        self.shared.tap_package(&mut self.gathering, &self.topics, output, time, given);
    }

    fn flush(&mut self) {
        if !self.gathering.batch.messages.is_empty() {
            let batch = std::mem::replace(&mut self.gathering.batch, self.shared.spare());
            self.gathering.send(&self.shared, Some(batch));
        }
    }
}

impl Drop for McapSender {
    fn drop(&mut self) {
        self.flush();
    }
}
