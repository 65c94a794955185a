//! Learned weights shipped as safetensors files (a walking policy, a gaze policy): one reader
//! for every network, so that each refuses a bad file the same way, naming the tensor.

use safetensors::{Dtype, SafeTensors};

/// What is wrong with one tensor of a weights file: the caller names the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TensorError {
    pub tensor: String,
    pub reason: String,
}

impl TensorError {
    pub fn new(tensor: &str, reason: &str) -> TensorError {
        TensorError { tensor: tensor.to_owned(), reason: reason.to_owned() }
    }
}

/// The tensor `name` as float32 values in row-major order: present, of dtype F32, of exactly
/// `shape`, and finite (a NaN weight would make every output NaN without a word).
pub fn read_f32(
    tensors: &SafeTensors<'_>,
    name: &str,
    shape: &[usize],
) -> Result<Vec<f32>, TensorError> {
    let view = tensors.tensor(name).map_err(|_| TensorError::new(name, "is missing"))?;
    if view.dtype() != Dtype::F32 {
        return Err(TensorError::new(name, &format!("has dtype {:?}, expected F32", view.dtype())));
    }
    if view.shape() != shape {
        return Err(TensorError::new(
            name,
            &format!("has shape {:?}, expected {shape:?}", view.shape()),
        ));
    }
    let values: Vec<f32> =
        view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    if values.iter().any(|v| !v.is_finite()) {
        return Err(TensorError::new(name, "holds a value that is not finite"));
    }
    Ok(values)
}

/// The first tensor (in name order) whose name is not in `expected`: a file of another network
/// is refused by name rather than half read.
pub fn first_unexpected<'a>(tensors: &'a SafeTensors<'_>, expected: &[String]) -> Option<&'a str> {
    let mut names = tensors.names();
    names.sort();
    names.into_iter().find(|name| !expected.iter().any(|e| e.as_str() == *name))
}
