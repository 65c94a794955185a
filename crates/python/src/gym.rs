//! `strata._native.GazeEnv`: the step API of the keeper's gaze environment
//! (`strata_experiments::goal_covering::gym`); `strata.gym.GazeEnv` makes it a Gymnasium one.

use pyo3::prelude::*;
use strata_experiments::goal_covering::gym::{self, GazeEnvConfig, OBS_LEN, OBS_LIMIT};
use strata_soccer::gaze_override::GazeChoice;

use crate::{config_error, from_json, run_error};

/// What `step` returns: observation, reward, terminated, truncated, and the info's fields
/// (time, path, coverage, ball unknown, pose error).
type StepTuple = (Vec<f32>, f64, bool, bool, (f64, usize, f64, f64, f64));

#[derive(Debug)]
#[pyclass(module = "strata._native", unsendable)]
pub struct GazeEnv {
    env: gym::GazeEnv,
}

#[pymethods]
impl GazeEnv {
    /// `config_json`: the fields of `GazeEnvConfig` (scenario, method, deliberative_hz, path,
    /// unknown_penalty, pose_penalty, pose_tolerance), all optional.
    #[new]
    fn new(config_json: &str) -> PyResult<GazeEnv> {
        let config: GazeEnvConfig = from_json(config_json, "GazeEnv config")?;
        let env = gym::GazeEnv::new(config).map_err(|e| config_error(format!("{e:#}")))?;
        Ok(GazeEnv { env })
    }

    #[classattr]
    fn observation_size() -> usize {
        OBS_LEN
    }

    #[classattr]
    fn observation_limit() -> f32 {
        OBS_LIMIT
    }

    #[classattr]
    fn actions() -> usize {
        GazeChoice::COUNT
    }

    fn paths(&self) -> usize {
        self.env.paths()
    }

    fn step_seconds(&self) -> f64 {
        self.env.step_seconds()
    }

    fn reset(&mut self, seed: u64) -> PyResult<Vec<f32>> {
        self.env.reset(seed).map_err(run_error)
    }

    fn step(&mut self, action: usize) -> PyResult<StepTuple> {
        let s = self.env.step(action).map_err(run_error)?;
        let i = s.info;
        Ok((
            s.observation,
            s.reward,
            s.terminated,
            s.truncated,
            (i.time, i.path, i.coverage, i.ball_unknown, i.pose_error),
        ))
    }
}
