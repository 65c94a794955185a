//! The paper's experiments on T1s in rcssservermj (`strata experiment NAME --engine
//! rcssservermj`): the same names, reports, plots and CSV as on the 2D simulator
//! (the crate root), with each report placing the 2D figures beside the physics ones.
//! Scenarios: `crates/experiments/scenarios/rcssservermj/NAME.toml`.

pub mod fall;
pub mod goal_covering;
pub mod rates;
pub mod team;

use anyhow::{Result, bail};

use crate::{Ctx, EXPERIMENTS};

/// Runs experiment `name` in physics; its summary is what `--json` prints.
pub fn run(name: &str, ctx: &mut Ctx<'_>) -> Result<serde_json::Value> {
    let summary = match name {
        fall::NAME => {
            let scenario = ctx.scenario::<fall::Scenario>(fall::DEFAULT_SCENARIO)?;
            to_json(&fall::run(&scenario, ctx)?)?
        }
        goal_covering::NAME => {
            let scenario =
                ctx.scenario::<goal_covering::Scenario>(goal_covering::DEFAULT_SCENARIO)?;
            to_json(&goal_covering::run(&scenario, ctx)?)?
        }
        crate::rates::NAME => {
            let scenario = ctx.scenario::<rates::Scenario>(rates::DEFAULT_SCENARIO)?;
            to_json(&rates::run(&scenario, ctx)?)?
        }
        team::NAME => {
            let scenario = ctx.scenario::<team::Scenario>(team::DEFAULT_SCENARIO)?;
            to_json(&team::run(&scenario, ctx)?)?
        }
        other => bail!("no experiment `{other}` (try: {}, all)", EXPERIMENTS.join(", ")),
    };
    Ok(summary)
}

fn to_json(value: &impl serde::Serialize) -> Result<serde_json::Value> {
    serde_json::to_value(value).map_err(anyhow::Error::from)
}
