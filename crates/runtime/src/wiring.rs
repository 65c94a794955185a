//! What both hosts derive from a checked graph: who reads each output, who writes each input.

use std::sync::Arc;

use crate::graph::{
    Graph, InputDecl, InputMode, InputRef, ModuleDecl, OutputRef, ProcessingTime, Trigger,
};
use crate::message::ErasedInput;
use crate::module::Module;
use crate::package::ModuleId;
use crate::stats::InputStats;
use crate::tap::TapOutput;

pub(crate) struct Reader {
    pub(crate) input: InputRef,
    pub(crate) slot: Arc<dyn ErasedInput>,
    /// The mode of the trigger this input is part of (`None`: it triggers nothing), beside the
    /// slot so that a delivery need not look at the reading module's trigger.
    pub(crate) trigger: Option<InputMode>,
}

pub(crate) struct OutputWiring {
    pub(crate) name: String,
    pub(crate) type_name: &'static str,
    pub(crate) wake_on_ready: bool,
    pub(crate) readers: Vec<Reader>,
    /// Which of the host's taps want this output's packages, a bit each
    /// ([`Wiring::select_tapped`]).
    pub(crate) tapped: u64,
}

/// Per module: its outputs' readers and its inputs' writers.
pub(crate) struct Wiring {
    /// Unique to this host in the process (see [`crate::TapRecord::host`]).
    pub(crate) host: u64,
    pub(crate) names: Vec<String>,
    pub(crate) outputs: Vec<Vec<OutputWiring>>,
    /// Per module, per input: the writing output and whether the writer wants to be woken when
    /// the input is emptied.
    pub(crate) writers: Vec<Vec<Option<(OutputRef, bool)>>>,
}

pub(crate) struct ModuleParts {
    pub(crate) id: ModuleId,
    pub(crate) name: String,
    pub(crate) module: Box<dyn Module>,
    pub(crate) trigger: Trigger,
    pub(crate) priority: i32,
    pub(crate) real_time: bool,
    pub(crate) processing_time: ProcessingTime,
    pub(crate) inputs: Vec<InputDecl>,
}

impl Wiring {
    /// Asks the taps once which outputs they want ([`Tap::wants`]); the host shows each only
    /// those.
    pub(crate) fn select_tapped(&mut self, taps: &crate::tap::HostTaps) {
        for ((m, outputs), module_name) in self.outputs.iter_mut().enumerate().zip(&self.names) {
            for (port, output) in outputs.iter_mut().enumerate() {
                output.tapped = taps.wanting(&TapOutput {
                    host: self.host,
                    module: ModuleId(m as u32),
                    module_name,
                    port: port as u16,
                    output: &output.name,
                    type_name: output.type_name,
                });
            }
        }
    }
}

impl ModuleParts {
    /// Whether the module's trigger condition holds now that `port` received data. `stored`:
    /// the package is known to be pending on `port` (the lockstep host has just stored it), so
    /// an `Any` trigger need not lock the input to look.
    pub(crate) fn triggered_by_arrival(&self, port: u16, stored: bool) -> bool {
        match &self.trigger {
            Trigger::Periodic { .. } => false,
            Trigger::OnInput { mode, inputs } => {
                if !inputs.iter().any(|i| i.port == port) {
                    return false;
                }
                match mode {
                    crate::graph::InputMode::Any => {
                        stored
                            || self
                                .inputs
                                .get(usize::from(port))
                                .is_some_and(|decl| decl.slot.has_pending())
                    }
                    crate::graph::InputMode::All => inputs.iter().all(|i| {
                        self.inputs.get(usize::from(i.port)).is_some_and(|d| d.slot.has_pending())
                    }),
                }
            }
        }
    }

    pub(crate) fn input_stats(&self) -> Vec<InputStats> {
        self.inputs
            .iter()
            .map(|decl| InputStats {
                port: decl.name.clone(),
                policy: decl.slot.policy(),
                counters: decl.slot.counters(),
            })
            .collect()
    }
}

pub(crate) fn split(graph: Graph) -> (Wiring, Vec<ModuleParts>) {
    let Graph { modules, readers, writers, externals: _ } = graph;
    let names: Vec<String> = modules.iter().map(|m| m.name.clone()).collect();
    let outputs: Vec<Vec<OutputWiring>> = modules
        .iter()
        .enumerate()
        .map(|(m, decl)| {
            decl.outputs
                .iter()
                .enumerate()
                .map(|(p, out)| OutputWiring {
                    name: out.name.clone(),
                    type_name: out.type_name,
                    wake_on_ready: out.wake_on_ready,
                    readers: readers[m][p]
                        .iter()
                        .map(|r| {
                            let reader: &ModuleDecl = &modules[r.module.index()];
                            Reader {
                                input: *r,
                                slot: Arc::clone(&reader.inputs[usize::from(r.port)].slot),
                                trigger: reader.trigger.as_ref().and_then(|t| t.mode_of(r.port)),
                            }
                        })
                        .collect(),
                    tapped: 0,
                })
                .collect()
        })
        .collect();
    let writers = writers
        .iter()
        .map(|per_input| {
            per_input
                .iter()
                .map(|w| {
                    w.map(|o| {
                        (o, modules[o.module.index()].outputs[usize::from(o.port)].wake_on_ready)
                    })
                })
                .collect()
        })
        .collect();
    let parts = modules
        .into_iter()
        .enumerate()
        .filter_map(|(i, decl)| {
            let ModuleDecl {
                name,
                module,
                trigger,
                priority,
                real_time,
                processing_time,
                inputs,
                ..
            } = decl;
            Some(ModuleParts {
                id: ModuleId(i as u32),
                name,
                module: module?,
                // `build` gives every module a trigger; periodic at 1 Hz is never reached.
                trigger: trigger
                    .unwrap_or_else(|| Trigger::every(std::time::Duration::from_secs(1))),
                priority,
                real_time,
                processing_time,
                inputs,
            })
        })
        .collect();
    static HOSTS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let host = HOSTS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    (Wiring { host, names, outputs, writers }, parts)
}
