//! The engine's error type. Loading and configuring fail with context (file, line, field, valid values);
//! stepping never fails.

use std::path::PathBuf;

/// Everything that can go wrong while loading assets, baking SDFs or building GPU pipelines.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// An I/O failure on a named file.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A malformed text asset (OBJ, URDF): file, 1-based line and what was wrong.
    #[error("{path}:{line}: {message}")]
    Parse { path: PathBuf, line: usize, message: String },
    /// A well-formed asset whose content cannot be used (empty mesh, missing link, ...).
    #[error("{path}: {message}")]
    Asset { path: PathBuf, message: String },
    /// A configuration value out of range: the field, the value, and what would be valid.
    #[error("invalid {field} = {value}: {expected}")]
    Config { field: &'static str, value: String, expected: String },
    /// A request that would need more memory than allowed; refused before allocating.
    #[error("{what} would need {needed_bytes} bytes, more than the limit of {limit_bytes} bytes; {hint}")]
    TooLarge { what: String, needed_bytes: u64, limit_bytes: u64, hint: String },
    /// No usable GPU/software adapter, or one short of a needed limit or feature.
    #[error("{0}")]
    Gpu(String),
}

/// Shorthand used across the engine.
pub type Result<T, E = EngineError> = std::result::Result<T, E>;

impl EngineError {
    /// Wraps an I/O error with the file it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        EngineError::Io { path: path.into(), source }
    }
}
