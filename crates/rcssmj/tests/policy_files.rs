//! Loading the walking policy's files: the shipped ones load, and a damaged or mismatched file
//! is an error that says what is wrong and where, never a panic.

use std::path::PathBuf;

use strata_rcssmj::policy::{PolicyError, T1Config, WalkNetwork, WalkPolicy};

const SHIPPED_WEIGHTS: &[u8] = include_bytes!("../assets/t1/t1.safetensors");
const SHIPPED_CONFIG: &str = include_str!("../assets/t1/t1.toml");

/// A safetensors file with these (name, shape) float32 tensors, all values `fill`.
fn safetensors(tensors: &[(&str, Vec<usize>)], fill: f32) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    let mut data = Vec::new();
    for (name, shape) in tensors {
        let start = data.len();
        for _ in 0..shape.iter().product::<usize>() {
            data.extend_from_slice(&fill.to_le_bytes());
        }
        header.insert(
            (*name).to_owned(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [start, data.len()]}),
        );
    }
    let mut text = serde_json::Value::Object(header).to_string().into_bytes();
    while !text.len().is_multiple_of(8) {
        text.push(b' ');
    }
    let mut bytes = (text.len() as u64).to_le_bytes().to_vec();
    bytes.extend(text);
    bytes.extend(data);
    bytes
}

fn t1_shapes() -> Vec<(&'static str, Vec<usize>)> {
    vec![
        ("0.weight", vec![256, 47]),
        ("0.bias", vec![256]),
        ("2.weight", vec![128, 256]),
        ("2.bias", vec![128]),
        ("4.weight", vec![128, 128]),
        ("4.bias", vec![128]),
        ("6.weight", vec![12, 128]),
        ("6.bias", vec![12]),
    ]
}

fn weights_error(bytes: &[u8]) -> String {
    match WalkNetwork::from_safetensors(bytes, "test.safetensors") {
        Ok(_) => String::from("loaded"),
        Err(err) => err.to_string(),
    }
}

#[test]
fn shipped_files_load() -> Result<(), PolicyError> {
    let policy = WalkPolicy::shipped()?;
    assert_eq!(policy.config(), &T1Config::shipped()?);
    Ok(())
}

#[test]
fn well_formed_weights_of_the_right_shapes_load() {
    // Validates the test's own writer, so the failures below are the loader's doing.
    let bytes = safetensors(&t1_shapes(), 0.5);
    assert_eq!(weights_error(&bytes), "loaded");
}

#[test]
fn truncated_weights_are_an_error() {
    for cut in [0, 4, 8, 100, SHIPPED_WEIGHTS.len() / 2, SHIPPED_WEIGHTS.len() - 1] {
        let message = weights_error(&SHIPPED_WEIGHTS[..cut]);
        assert!(message.contains("test.safetensors"), "cut {cut}: {message}");
        assert!(message.contains("not a valid safetensors file"), "cut {cut}: {message}");
    }
}

#[test]
fn corrupt_header_is_an_error() {
    let mut bytes = SHIPPED_WEIGHTS.to_vec();
    bytes[8] = b'#';
    assert!(weights_error(&bytes).contains("not a valid safetensors file"));
    let mut huge = SHIPPED_WEIGHTS.to_vec();
    huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(weights_error(&huge).contains("not a valid safetensors file"));
}

#[test]
fn mis_shaped_tensor_is_named() {
    let mut shapes = t1_shapes();
    shapes[2].1 = vec![128, 255];
    let message = weights_error(&safetensors(&shapes, 0.5));
    assert!(message.contains("`2.weight`"), "{message}");
    assert!(message.contains("[128, 255]"), "{message}");
    assert!(message.contains("[128, 256]"), "{message}");
}

#[test]
fn missing_and_extra_tensors_are_named() {
    let mut shapes = t1_shapes();
    shapes.remove(7);
    let message = weights_error(&safetensors(&shapes, 0.5));
    assert!(message.contains("`6.bias` is missing"), "{message}");

    let mut shapes = t1_shapes();
    shapes.push(("8.weight", vec![12, 12]));
    let message = weights_error(&safetensors(&shapes, 0.5));
    assert!(message.contains("`8.weight`"), "{message}");
}

#[test]
fn non_finite_weights_are_refused() {
    let message = weights_error(&safetensors(&t1_shapes(), f32::NAN));
    assert!(message.contains("not finite"), "{message}");
}

#[test]
fn missing_files_name_the_path() {
    let path = PathBuf::from("/nonexistent/t1-policy/t1.safetensors");
    let message = WalkNetwork::load(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("/nonexistent/t1-policy/t1.safetensors"), "{message}");
    let path = PathBuf::from("/nonexistent/t1-policy/t1.toml");
    let message = T1Config::load(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("/nonexistent/t1-policy/t1.toml"), "{message}");
}

#[test]
fn config_file_errors_name_field_and_file() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::temp_dir().join(format!("strata-policy-files-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("my-t1.toml");

    std::fs::write(&path, SHIPPED_CONFIG.replace("decimation = 10", "decimation = \"ten\""))?;
    let message = T1Config::load(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("my-t1.toml"), "{message}");
    assert!(message.contains("decimation"), "{message}");

    std::fs::write(&path, SHIPPED_CONFIG.replace("clip = 1.0", "clip = 0.0"))?;
    let message = T1Config::load(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("my-t1.toml"), "{message}");
    assert!(message.contains("`action.clip`"), "{message}");

    std::fs::write(&path, SHIPPED_CONFIG.replace("[action]\n", "[acton]\n"))?;
    let message = T1Config::load(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(message.contains("acton"), "{message}");

    std::fs::write(&path, SHIPPED_CONFIG)?;
    assert_eq!(T1Config::load(&path)?, T1Config::shipped()?);
    std::fs::remove_dir_all(&dir)?;
    Ok(())
}
