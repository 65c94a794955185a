//! What actuation has told the reactive layer about each resource.

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use crate::command::{ActuationMessage, Resource, ResourceGroup};

/// What actuation has told the reactive layer about each resource.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ActuationStatus {
    /// Resources whose command is about to finish (actuation asks for the next action).
    pub finishing: BTreeSet<Resource>,
    /// Resources executing a cyclic command in its execution stage (changeable now).
    pub cyclic_part: BTreeSet<Resource>,
    /// Resources busy with a special (non-parametric) sequence.
    pub busy: BTreeSet<Resource>,
    /// The last rejection, for reports.
    pub last_rejection: Option<String>,
}

impl ActuationStatus {
    /// Folds actuation messages in, in arrival order.
    pub fn apply(&mut self, message: &ActuationMessage) {
        match message {
            ActuationMessage::CommandOdometry { .. } => {}
            ActuationMessage::CommandFinishing { resource, .. } => {
                self.finishing.insert(*resource);
                self.cyclic_part.remove(resource);
            }
            ActuationMessage::CommandCyclicPart { resource } => {
                self.cyclic_part.insert(*resource);
                self.finishing.remove(resource);
            }
            ActuationMessage::CommandRejected { resource, reason } => {
                self.last_rejection = Some(format!("{resource:?}: {reason}"));
            }
            ActuationMessage::ResourceBusy { resource } => {
                self.busy.insert(*resource);
            }
            ActuationMessage::ResourceReleased { resource } => {
                self.busy.remove(resource);
                self.finishing.remove(resource);
                self.cyclic_part.remove(resource);
            }
        }
    }

    pub fn is_busy(&self, group: ResourceGroup) -> bool {
        self.busy.iter().any(|r| group.uses(*r))
    }
}
