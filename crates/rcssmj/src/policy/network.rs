//! The walking network: a 47 → 256 → 128 → 128 → 12 perceptron with ELU (alpha 1) after each
//! hidden layer.
//!
//! Four small dense layers need no inference runtime: a matrix-vector product per layer is a
//! few lines, runs in microseconds, allocates nothing per call, and keeps the dependency tree
//! to the weight file's parser. The weights are stored transposed (input-major) so that each
//! input adds a scaled weight column to every output at once: that inner loop has no
//! dependency between iterations, so the compiler vectorizes it without reassociating sums.

use std::path::Path;

use safetensors::SafeTensors;

use super::{OBSERVATION_LEN, PolicyError};

const SHIPPED_WEIGHTS: &[u8] = include_bytes!("../../assets/t1/t1.safetensors");
const SHIPPED_ORIGIN: &str = "the shipped assets/t1/t1.safetensors";

/// The network's output: one action per leg joint.
pub const ACTION_LEN: usize = 12;

/// Widths of the three hidden layers.
pub const HIDDEN_WIDTHS: [usize; 3] = [256, 128, 128];

/// Tensor names as PyTorch's `nn.Sequential` state dict gives them (indices 1, 3, 5 are the
/// ELUs, which have no parameters).
const LAYER_NAMES: [&str; 4] = ["0", "2", "4", "6"];

const LAYER_WIDTHS: [(usize, usize); 4] = [
    (OBSERVATION_LEN, HIDDEN_WIDTHS[0]),
    (HIDDEN_WIDTHS[0], HIDDEN_WIDTHS[1]),
    (HIDDEN_WIDTHS[1], HIDDEN_WIDTHS[2]),
    (HIDDEN_WIDTHS[2], ACTION_LEN),
];

/// The T1 walking network, loaded from safetensors weights.
#[derive(Clone, PartialEq)]
pub struct WalkNetwork {
    layers: [Dense; 4],
}

impl std::fmt::Debug for WalkNetwork {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let widths: Vec<_> = self.layers.iter().map(|l| (l.inputs, l.outputs())).collect();
        f.debug_struct("WalkNetwork").field("layers", &widths).finish()
    }
}

#[derive(Clone, PartialEq)]
struct Dense {
    inputs: usize,
    /// `inputs` columns of `outputs` weights each: element (o, i) of PyTorch's (out, in) matrix
    /// sits at `i * outputs + o`.
    columns: Vec<f32>,
    bias: Vec<f32>,
}

impl Dense {
    fn outputs(&self) -> usize {
        self.bias.len()
    }

    fn forward(&self, input: &[f32], output: &mut [f32]) {
        output.copy_from_slice(&self.bias);
        for (&x, column) in input.iter().zip(self.columns.chunks_exact(self.bias.len())) {
            for (out, &w) in output.iter_mut().zip(column) {
                *out += w * x;
            }
        }
    }
}

fn elu(values: &mut [f32]) {
    for v in values {
        if *v <= 0.0 {
            *v = v.exp_m1();
        }
    }
}

impl WalkNetwork {
    /// The network shipped with the crate (Booster's T1.pt, converted; see assets/t1/NOTICE).
    pub fn shipped() -> Result<Self, PolicyError> {
        Self::from_safetensors(SHIPPED_WEIGHTS, SHIPPED_ORIGIN)
    }

    /// Reads weights from a safetensors file with the shipped layout.
    pub fn load(path: &Path) -> Result<Self, PolicyError> {
        let bytes = std::fs::read(path)
            .map_err(|source| PolicyError::Read { path: path.to_path_buf(), source })?;
        Self::from_safetensors(&bytes, &path.display().to_string())
    }

    /// Parses safetensors bytes holding exactly `0.weight`, `0.bias`, `2.weight`, ..., `6.bias`
    /// as float32 with the T1 network's shapes; `origin` names the source in errors.
    pub fn from_safetensors(bytes: &[u8], origin: &str) -> Result<Self, PolicyError> {
        let tensors = SafeTensors::deserialize(bytes)
            .map_err(|source| PolicyError::WeightsFormat { origin: origin.to_owned(), source })?;
        let expected: Vec<String> = LAYER_NAMES
            .iter()
            .flat_map(|layer| [format!("{layer}.weight"), format!("{layer}.bias")])
            .collect();
        if let Some(extra) = strata_robot::weights::first_unexpected(&tensors, &expected) {
            return Err(tensor_error(
                origin,
                extra,
                "is not part of the T1 network (expected 0/2/4/6 .weight and .bias)",
            ));
        }
        let mut layers = Vec::with_capacity(LAYER_NAMES.len());
        for (layer, (inputs, outputs)) in LAYER_NAMES.iter().zip(LAYER_WIDTHS) {
            let weight =
                read_tensor(&tensors, &format!("{layer}.weight"), &[outputs, inputs], origin)?;
            let bias = read_tensor(&tensors, &format!("{layer}.bias"), &[outputs], origin)?;
            let mut columns = vec![0.0; inputs * outputs];
            for (o, row) in weight.chunks_exact(inputs).enumerate() {
                for (i, &w) in row.iter().enumerate() {
                    columns[i * outputs + o] = w;
                }
            }
            layers.push(Dense { inputs, columns, bias });
        }
        let layers: [Dense; 4] = layers
            .try_into()
            .map_err(|_| tensor_error(origin, "0.weight", "layer count mismatch"))?;
        Ok(Self { layers })
    }

    /// The raw action (before clipping) for one observation.
    pub fn forward(&self, observation: &[f32; OBSERVATION_LEN]) -> [f32; ACTION_LEN] {
        let [first, second, third, last] = &self.layers;
        let mut h1 = [0.0f32; HIDDEN_WIDTHS[0]];
        let mut h2 = [0.0f32; HIDDEN_WIDTHS[1]];
        let mut h3 = [0.0f32; HIDDEN_WIDTHS[2]];
        let mut action = [0.0f32; ACTION_LEN];
        first.forward(observation, &mut h1);
        elu(&mut h1);
        second.forward(&h1, &mut h2);
        elu(&mut h2);
        third.forward(&h2, &mut h3);
        elu(&mut h3);
        last.forward(&h3, &mut action);
        action
    }
}

fn tensor_error(origin: &str, tensor: &str, reason: &str) -> PolicyError {
    PolicyError::WeightsTensor {
        origin: origin.to_owned(),
        tensor: tensor.to_owned(),
        reason: reason.to_owned(),
    }
}

fn read_tensor(
    tensors: &SafeTensors<'_>,
    name: &str,
    shape: &[usize],
    origin: &str,
) -> Result<Vec<f32>, PolicyError> {
    strata_robot::weights::read_f32(tensors, name, shape)
        .map_err(|e| tensor_error(origin, &e.tensor, &e.reason))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn elu_is_identity_above_zero_and_saturates_at_minus_one() {
        let mut values = [2.0f32, 0.0, -1.0, -30.0];
        elu(&mut values);
        assert_eq!(values[0], 2.0);
        assert_eq!(values[1], 0.0);
        assert!((values[2] - (-0.632_120_55)).abs() < 1e-6);
        assert!((values[3] + 1.0).abs() < 1e-6);
    }

    #[test]
    fn dense_layer_matches_row_major_product() {
        // PyTorch's (out = 2, in = 3) weight [[1, 2, 3], [4, 5, 6]], stored input-major.
        let layer =
            Dense { inputs: 3, columns: vec![1.0, 4.0, 2.0, 5.0, 3.0, 6.0], bias: vec![0.5, -0.5] };
        let mut out = [0.0; 2];
        layer.forward(&[1.0, 1.0, 2.0], &mut out);
        assert_eq!(out, [9.5, 20.5]);
    }
}
