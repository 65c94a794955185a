//! A learned gaze: a small perceptron that maps an observation of the world model to one of
//! [`GazeChoice`]'s candidates (the policy python/train_gaze.py trains with PPO and exports).
//!
//! The network is the deterministic action head of the trained policy: the observation is
//! normalized as in training (`(x - obs_mean) / obs_std`, clipped to `±obs_clip`), passes
//! through tanh layers (`hidden.0`, `hidden.1`, ...), and the argmax of the `logits` layer's
//! [`GazeChoice::COUNT`] outputs is the choice. A few dense layers need no inference runtime:
//! nalgebra's matrix-vector products run in microseconds, once per deliberative decision.
//!
//! Weights come as float32 safetensors in PyTorch's layout (`weight` is (out, in)). Every
//! tensor is checked when loading (names, dtype, shapes that chain, finite values), so that a
//! wrong file fails with its name and the tensor's instead of producing a wrong gaze.

use std::path::{Path, PathBuf};

use nalgebra::{DMatrix, DVector};
use safetensors::SafeTensors;

use crate::gaze_override::GazeChoice;

/// Why a gaze policy could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum GazePolicyError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{origin}: not a valid safetensors file: {source}")]
    Format {
        origin: String,
        #[source]
        source: safetensors::SafeTensorError,
    },
    #[error("{origin}: tensor `{tensor}` {reason}")]
    Tensor { origin: String, tensor: String, reason: String },
}

/// Hidden layers a file may have: enough for any policy this architecture trains, few enough
/// that a crafted file cannot make loading slow.
const MAX_HIDDEN: usize = 8;

/// Widest layer accepted (the shipped policy's are 64): bounds the memory a file can ask for.
const MAX_WIDTH: usize = 4096;

#[derive(Clone, Debug, PartialEq)]
struct Dense {
    weight: DMatrix<f32>,
    bias: DVector<f32>,
}

impl Dense {
    fn forward(&self, input: &DVector<f32>) -> DVector<f32> {
        &self.weight * input + &self.bias
    }
}

/// The loaded policy: [`GazePolicy::logits`], [`GazePolicy::choose`].
#[derive(Clone, Debug, PartialEq)]
pub struct GazePolicy {
    mean: DVector<f32>,
    std: DVector<f32>,
    clip: f32,
    hidden: Vec<Dense>,
    logits: Dense,
}

impl GazePolicy {
    /// Reads a safetensors file; its observations must have `inputs` numbers.
    pub fn load(path: &Path, inputs: usize) -> Result<GazePolicy, GazePolicyError> {
        let bytes = std::fs::read(path)
            .map_err(|source| GazePolicyError::Read { path: path.to_path_buf(), source })?;
        Self::from_safetensors(&bytes, &path.display().to_string(), inputs)
    }

    /// Parses safetensors bytes holding exactly `obs_mean`, `obs_std`, `obs_clip`,
    /// `hidden.K.weight` and `hidden.K.bias` for K = 0, 1, ..., `logits.weight` and
    /// `logits.bias`, all float32, for observations of `inputs` numbers; `origin` names the
    /// source in errors.
    pub fn from_safetensors(
        bytes: &[u8],
        origin: &str,
        inputs: usize,
    ) -> Result<GazePolicy, GazePolicyError> {
        let tensors = SafeTensors::deserialize(bytes)
            .map_err(|source| GazePolicyError::Format { origin: origin.to_owned(), source })?;
        let names = tensors.names();
        let layers = (0..=MAX_HIDDEN)
            .take_while(|k| names.iter().any(|n| **n == format!("hidden.{k}.weight")))
            .count();
        if layers > MAX_HIDDEN {
            return Err(tensor_error(
                origin,
                &format!("hidden.{MAX_HIDDEN}.weight"),
                &format!("is one hidden layer too many (at most {MAX_HIDDEN})"),
            ));
        }
        let mut expected: Vec<String> =
            ["obs_mean", "obs_std", "obs_clip", "logits.weight", "logits.bias"]
                .map(String::from)
                .to_vec();
        for k in 0..layers {
            expected.push(format!("hidden.{k}.weight"));
            expected.push(format!("hidden.{k}.bias"));
        }
        if let Some(extra) = strata_robot::weights::first_unexpected(&tensors, &expected) {
            return Err(tensor_error(
                origin,
                extra,
                "is not part of a gaze policy (expected obs_mean, obs_std, obs_clip, \
                 hidden.K.weight/.bias for K = 0, 1, ..., logits.weight/.bias)",
            ));
        }
        let mean = read_tensor(&tensors, "obs_mean", &[inputs], origin)?;
        let std = read_tensor(&tensors, "obs_std", &[inputs], origin)?;
        if std.iter().any(|s| *s <= 0.0) {
            return Err(tensor_error(origin, "obs_std", "holds a value that is not positive"));
        }
        let clip = read_tensor(&tensors, "obs_clip", &[1], origin)?[0];
        if clip <= 0.0 {
            return Err(tensor_error(origin, "obs_clip", "is not positive"));
        }
        let mut hidden = Vec::with_capacity(layers);
        let mut width = inputs;
        for k in 0..layers {
            let layer = read_dense(&tensors, &format!("hidden.{k}"), width, None, origin)?;
            width = layer.bias.len();
            hidden.push(layer);
        }
        let logits = read_dense(&tensors, "logits", width, Some(GazeChoice::COUNT), origin)?;
        Ok(GazePolicy {
            mean: DVector::from_vec(mean),
            std: DVector::from_vec(std),
            clip,
            hidden,
            logits,
        })
    }

    /// Numbers an observation has.
    pub fn inputs(&self) -> usize {
        self.mean.len()
    }

    /// The [`GazeChoice::COUNT`] logits for `observation` (of [`GazePolicy::inputs`] numbers;
    /// missing ones count as 0, extra ones are ignored).
    pub fn logits(&self, observation: &[f32]) -> Vec<f32> {
        let mut x = DVector::from_fn(self.inputs(), |i, _| {
            let value = observation.get(i).copied().unwrap_or(0.0);
            ((value - self.mean[i]) / self.std[i]).clamp(-self.clip, self.clip)
        });
        for layer in &self.hidden {
            x = layer.forward(&x).map(f32::tanh);
        }
        self.logits.forward(&x).iter().copied().collect()
    }

    /// The index of the highest logit (the first of equal ones, as numpy's argmax).
    pub fn action(&self, observation: &[f32]) -> usize {
        let logits = self.logits(observation);
        let mut best = 0;
        for (i, v) in logits.iter().enumerate() {
            if *v > logits[best] {
                best = i;
            }
        }
        best
    }

    /// The gaze the policy chooses for `observation`.
    pub fn choose(&self, observation: &[f32]) -> GazeChoice {
        // The logits layer has COUNT outputs (checked when loading), so the index is a choice.
        GazeChoice::from_index(self.action(observation)).unwrap_or(GazeChoice::Ball)
    }
}

fn tensor_error(origin: &str, tensor: &str, reason: &str) -> GazePolicyError {
    GazePolicyError::Tensor {
        origin: origin.to_owned(),
        tensor: tensor.to_owned(),
        reason: reason.to_owned(),
    }
}

/// `name.weight` (out, `inputs`) and `name.bias` (out); `outputs` fixes out when given.
fn read_dense(
    tensors: &SafeTensors<'_>,
    name: &str,
    inputs: usize,
    outputs: Option<usize>,
    origin: &str,
) -> Result<Dense, GazePolicyError> {
    let weight_name = format!("{name}.weight");
    let out = match outputs {
        Some(out) => out,
        None => {
            let view = tensors
                .tensor(&weight_name)
                .map_err(|_| tensor_error(origin, &weight_name, "is missing"))?;
            match view.shape() {
                [out, _] if (1..=MAX_WIDTH).contains(out) => *out,
                shape => {
                    return Err(tensor_error(
                        origin,
                        &weight_name,
                        &format!(
                            "has shape {shape:?}, expected [outputs (1 to {MAX_WIDTH}), {inputs}]"
                        ),
                    ));
                }
            }
        }
    };
    let weight = read_tensor(tensors, &weight_name, &[out, inputs], origin)?;
    let bias = read_tensor(tensors, &format!("{name}.bias"), &[out], origin)?;
    Ok(Dense {
        weight: DMatrix::from_row_slice(out, inputs, &weight),
        bias: DVector::from_vec(bias),
    })
}

fn read_tensor(
    tensors: &SafeTensors<'_>,
    name: &str,
    shape: &[usize],
    origin: &str,
) -> Result<Vec<f32>, GazePolicyError> {
    strata_robot::weights::read_f32(tensors, name, shape)
        .map_err(|e| tensor_error(origin, &e.tensor, &e.reason))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A safetensors file of float32 tensors (name, shape, values from `fill(index)`).
    fn file(tensors: &[(&str, Vec<usize>)], fill: impl Fn(usize) -> f32) -> Vec<u8> {
        let data: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
            .iter()
            .map(|(name, shape)| {
                let n: usize = shape.iter().product();
                let bytes = (0..n).flat_map(|i| fill(i).to_le_bytes()).collect();
                ((*name).to_owned(), shape.clone(), bytes)
            })
            .collect();
        let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = data
            .iter()
            .map(|(name, shape, bytes)| {
                let view = safetensors::tensor::TensorView::new(
                    safetensors::Dtype::F32,
                    shape.clone(),
                    bytes,
                )
                .expect("a consistent test tensor");
                (name.clone(), view)
            })
            .collect();
        safetensors::tensor::serialize(views, None).expect("serializable test tensors")
    }

    fn shapes(inputs: usize, width: usize) -> Vec<(&'static str, Vec<usize>)> {
        vec![
            ("obs_mean", vec![inputs]),
            ("obs_std", vec![inputs]),
            ("obs_clip", vec![1]),
            ("hidden.0.weight", vec![width, inputs]),
            ("hidden.0.bias", vec![width]),
            ("hidden.1.weight", vec![width, width]),
            ("hidden.1.bias", vec![width]),
            ("logits.weight", vec![GazeChoice::COUNT, width]),
            ("logits.bias", vec![GazeChoice::COUNT]),
        ]
    }

    fn error(bytes: &[u8], inputs: usize) -> String {
        match GazePolicy::from_safetensors(bytes, "test.safetensors", inputs) {
            Ok(_) => panic!("loaded a bad file"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn a_well_formed_file_loads_and_chooses() {
        let bytes = file(&shapes(4, 3), |i| 0.1 * (i % 5) as f32 + 0.1);
        let policy = GazePolicy::from_safetensors(&bytes, "test.safetensors", 4).expect("loads");
        assert_eq!(policy.inputs(), 4);
        assert_eq!(policy.logits(&[0.0; 4]).len(), GazeChoice::COUNT);
        let index = policy.action(&[1.0, -1.0, 2.0, 0.5]);
        assert!(index < GazeChoice::COUNT);
        assert_eq!(
            policy.choose(&[1.0, -1.0, 2.0, 0.5]),
            GazeChoice::from_index(index).expect("a choice")
        );
    }

    #[test]
    fn errors_name_the_file_and_the_tensor() {
        let mut bad = shapes(4, 3);
        bad[5] = ("hidden.1.weight", vec![3, 2]);
        let message = error(&file(&bad, |_| 1.0), 4);
        assert!(message.contains("test.safetensors"), "{message}");
        assert!(message.contains("`hidden.1.weight`"), "{message}");
        assert!(message.contains("expected [3, 3]"), "{message}");

        let message = error(&file(&shapes(4, 3), |_| 1.0), 5);
        assert!(message.contains("`obs_mean`") && message.contains("[5]"), "{message}");

        let mut missing = shapes(4, 3);
        missing.retain(|(n, _)| *n != "logits.bias");
        assert!(error(&file(&missing, |_| 1.0), 4).contains("`logits.bias` is missing"));

        let mut extra = shapes(4, 3);
        extra.push(("hidden.3.weight", vec![3, 3]));
        assert!(error(&file(&extra, |_| 1.0), 4).contains("`hidden.3.weight` is not part"));

        let zero_std = file(&shapes(4, 3), |_| 0.0);
        assert!(error(&zero_std, 4).contains("`obs_std` holds a value that is not positive"));

        let nan = file(&shapes(4, 3), |i| if i == 2 { f32::NAN } else { 1.0 });
        assert!(error(&nan, 4).contains("not finite"));

        let bytes = file(&shapes(4, 3), |_| 1.0);
        for cut in [0, 7, 8, 20, bytes.len() - 1] {
            let message = error(&bytes[..cut], 4);
            assert!(message.contains("not a valid safetensors file"), "cut {cut}: {message}");
        }
    }

    #[test]
    fn the_forward_pass_is_normalize_tanh_layers_then_logits() {
        // One input, one hidden unit: logit k = w_k * tanh(2 * clip((x - 1) / 2)) + b_k.
        let tensors = [
            ("obs_mean", vec![1]),
            ("obs_std", vec![1]),
            ("obs_clip", vec![1]),
            ("hidden.0.weight", vec![1, 1]),
            ("hidden.0.bias", vec![1]),
            ("logits.weight", vec![GazeChoice::COUNT, 1]),
            ("logits.bias", vec![GazeChoice::COUNT]),
        ];
        let values: Vec<Vec<f32>> = vec![
            vec![1.0],
            vec![2.0],
            vec![3.0],
            vec![2.0],
            vec![0.0],
            (0..GazeChoice::COUNT).map(|k| k as f32 - 6.0).collect(),
            vec![0.0; GazeChoice::COUNT],
        ];
        let mut bytes_of = Vec::new();
        for ((name, shape), v) in tensors.iter().zip(&values) {
            bytes_of.push((*name, shape.clone(), v.clone()));
        }
        let data: Vec<(String, Vec<usize>, Vec<u8>)> = bytes_of
            .iter()
            .map(|(n, s, v)| {
                ((*n).to_owned(), s.clone(), v.iter().flat_map(|x| x.to_le_bytes()).collect())
            })
            .collect();
        let views: Vec<_> = data
            .iter()
            .map(|(n, s, b)| {
                (
                    n.clone(),
                    safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b)
                        .expect("a tensor"),
                )
            })
            .collect();
        let bytes = safetensors::tensor::serialize(views, None).expect("serializable");
        let policy = GazePolicy::from_safetensors(&bytes, "t", 1).expect("loads");
        let h = (2.0f32 * 1.0).tanh(); // x = 3: (3 - 1) / 2 = 1
        let logits = policy.logits(&[3.0]);
        assert!((logits[12] - 6.0 * h).abs() < 1e-6);
        assert_eq!(policy.action(&[3.0]), 12);
        // Clipped at 3 standard deviations: x = 100 acts as x = 7.
        let far = policy.logits(&[100.0]);
        assert!((far[0] - (-6.0 * (2.0f32 * 3.0).tanh())).abs() < 1e-6);
        assert_eq!(policy.action(&[-100.0]), 0);
    }
}
