use std::path::PathBuf;

/// Why the walking policy's configuration or network could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    #[error("cannot read {}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{origin}: {source}")]
    ConfigSyntax {
        origin: String,
        #[source]
        source: Box<toml::de::Error>,
    },
    #[error("{origin}: `{field}` {reason}")]
    ConfigValue { origin: String, field: String, reason: String },
    #[error("{origin}: not a valid safetensors file: {source}")]
    WeightsFormat {
        origin: String,
        #[source]
        source: safetensors::SafeTensorError,
    },
    #[error("{origin}: tensor `{tensor}` {reason}")]
    WeightsTensor { origin: String, tensor: String, reason: String },
}
