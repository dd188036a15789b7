//! The crate's error type.

use std::path::PathBuf;

/// Everything that can go wrong configuring, checkpointing or loading a learner.
#[derive(Debug, thiserror::Error)]
pub enum RlError {
    /// A config could not be read (syntax error, unknown key with the valid ones, wrong value type).
    #[error("{file}: {reason}")]
    Config {
        /// The config file (or `--set` for an override).
        file: String,
        /// What is wrong.
        reason: String,
    },
    /// A config field has a value the learner cannot use.
    #[error("config field `{field}`: {reason}")]
    InvalidValue {
        /// The field as written in TOML (`ppo.minibatch_size`).
        field: String,
        /// What is wrong and what would be valid.
        reason: String,
    },
    /// An env could not be built.
    #[error(transparent)]
    Env(#[from] factory_envs::EnvError),
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A checkpoint or policy file is malformed.
    #[error("{path}: {reason}")]
    BadFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A policy was exported for another observation/action spec than the env it is asked to drive.
    #[error("policy {path} was exported for\n  {policy}\nbut the env is\n  {env}")]
    SpecMismatch {
        /// The policy file.
        path: PathBuf,
        /// The policy's spec.
        policy: String,
        /// The env's spec.
        env: String,
    },
}

impl RlError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        RlError::Io { path: path.into(), source }
    }
}

/// `Result` with [`RlError`].
pub type Result<T, E = RlError> = std::result::Result<T, E>;
