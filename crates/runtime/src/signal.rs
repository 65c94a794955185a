//! Ctrl-C: one process-wide handler that stops every host that asked to be stopped by it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use crate::threaded::StopHandle;

struct Registry {
    flag: Arc<AtomicBool>,
    hosts: Mutex<Vec<StopHandle>>,
}

static REGISTRY: OnceLock<Result<Registry, String>> = OnceLock::new();

fn registry() -> Result<&'static Registry, String> {
    REGISTRY
        .get_or_init(|| {
            let flag = Arc::new(AtomicBool::new(false));
            let handler_flag = Arc::clone(&flag);
            ctrlc::set_handler(move || {
                handler_flag.store(true, Ordering::SeqCst);
                if let Some(Ok(registry)) = REGISTRY.get() {
                    let hosts = registry.hosts.lock().unwrap_or_else(|e| e.into_inner());
                    for host in hosts.iter() {
                        host.stop();
                    }
                }
            })
            .map_err(|e| format!("cannot install the Ctrl-C handler: {e}"))?;
            Ok(Registry { flag, hosts: Mutex::new(Vec::new()) })
        })
        .as_ref()
        .map_err(Clone::clone)
}

/// A flag that becomes true when the user presses Ctrl-C (or the process gets SIGTERM).
/// Lockstep runs poll it between events.
pub fn interrupt_flag() -> Result<Arc<AtomicBool>, String> {
    registry().map(|r| Arc::clone(&r.flag))
}

/// Stops `host` cleanly on Ctrl-C.
pub fn stop_on_interrupt(host: StopHandle) -> Result<(), String> {
    let registry = registry()?;
    registry.hosts.lock().unwrap_or_else(|e| e.into_inner()).push(host);
    Ok(())
}
