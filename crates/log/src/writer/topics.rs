//! The logged streams: a topic per package output or application record name, and where the
//! topics of packages are created.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU8, AtomicU64};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use strata_runtime::TapOutput;

use super::{CdrSchema, Shared};

/// One logged stream: the channel a topic gets in the file.
#[derive(Debug)]
pub(super) struct Topic {
    pub(super) id: u32,
    pub(super) name: String,
    pub(super) type_name: String,
    pub(super) dropped: AtomicU64,
    /// Sequence numbers of application records (packages carry their own).
    pub(super) next_seq: AtomicU64,
    /// How a sender that waits hands this topic's packages over
    /// ([`HANDOVER_CLONE`](super::gather::HANDOVER_CLONE) or
    /// [`HANDOVER_ENCODE`](super::gather::HANDOVER_ENCODE)), decided by its first package; 0 until
    /// then.
    pub(super) handover: AtomicU8,
    /// The type's CDR schema, for packages the sender encoded.
    pub(super) cdr: OnceLock<Arc<CdrSchema>>,
    /// The log's [`Derive`](crate::Derive) wants this topic's packages: the writer thread needs
    /// them whole.
    pub(super) derived: bool,
}

/// Per output name, its topic (`None`: the module is not logged).
pub(super) type OutputTopics = HashMap<String, Option<Arc<Topic>>>;

/// Topics of packages by module and output name, where they are created (once each); the
/// usual lookup goes through [`Gathering`](super::Gathering).
#[derive(Default)]
pub(super) struct TopicCache {
    pub(super) prefix: String,
    pub(super) by_name: Mutex<HashMap<String, OutputTopics>>,
}

impl TopicCache {
    /// The topic of a record's output; `None` for modules the options leave out.
    pub(super) fn topic(&self, shared: &Shared, record: &TapOutput<'_>) -> Option<Arc<Topic>> {
        let mut by_name = self.by_name.lock().unwrap_or_else(PoisonError::into_inner);
        let outputs = by_name.entry(record.module_name.to_owned()).or_default();
        outputs
            .entry(record.output.to_owned())
            .or_insert_with(|| {
                let name = self.name(record);
                shared.logs(&name).then(|| shared.new_topic(name, record.type_name, true))
            })
            .clone()
    }

    /// The topic name of an output's packages.
    pub(super) fn name(&self, output: &TapOutput<'_>) -> String {
        format!("{}{}", self.prefix, crate::package_topic(output.module_name, output.output))
    }

    /// Whether the options log this output's packages; the host then shows it to the tap
    /// ([`Tap::wants`](strata_runtime::Tap::wants)). Asked once per output, before its first
    /// package: the topic is created with that package, so topics keep the order their packages
    /// come in.
    pub(super) fn wants(&self, shared: &Shared, output: &TapOutput<'_>) -> bool {
        shared.logs(&self.name(output))
    }
}
