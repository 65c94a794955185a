//! The paper's experiments on T1s in rcssservermj (`strata experiment NAME --engine
//! rcssservermj`): the same names, reports, plots and CSV as on the 2D simulator
//! (`crate::experiments`), with each report placing the 2D figures beside the physics ones.
//! Scenarios: `crates/strata/scenarios/rcssservermj/NAME.toml`.

pub mod fall;

use anyhow::{Result, bail};

use crate::experiments::{Ctx, EXPERIMENTS};

/// Runs experiment `name` in physics; its summary is what `--json` prints.
pub fn run(name: &str, ctx: &mut Ctx<'_>) -> Result<serde_json::Value> {
    if !EXPERIMENTS.contains(&name) {
        bail!("no experiment `{name}` (try: {}, all)", EXPERIMENTS.join(", "));
    }
    match name {
        fall::NAME => {
            let scenario = ctx.scenario::<fall::Scenario>(fall::DEFAULT_SCENARIO)?;
            Ok(serde_json::to_value(fall::run(&scenario, ctx)?)?)
        }
        _ => {
            bail!("`{name}` does not run on rcssservermj in this version (run it without --engine)")
        }
    }
}
