//! The crate's error type.

use crate::registry::NAMES;

/// Everything that can go wrong when reading an env config or building an env.
#[derive(Debug, thiserror::Error)]
pub enum EnvError {
    /// A config field has a value the env cannot use.
    #[error("env config field `{field}`: {reason}")]
    InvalidValue {
        /// The config field's name as written in TOML.
        field: &'static str,
        /// What is wrong with it and what would be valid.
        reason: String,
    },
    /// The config's `type` names no registered env.
    #[error("unknown env type `{0}`; valid types: {valid}", valid = NAMES.join(", "))]
    UnknownType(String),
    /// The TOML could not be read into an env config (syntax error, unknown key, wrong value type).
    #[error("invalid env config: {0}")]
    Parse(String),
    /// The engine refused the scene (URDF, SDF, GPU, solver settings).
    #[error(transparent)]
    Engine(#[from] factory_engine::EngineError),
    /// The controller config was refused.
    #[error("[env.controller]: {0}")]
    Controller(#[from] factory_controllers::ControllerError),
    /// Building the scene failed for another reason (named).
    #[error("building the scene: {0}")]
    Build(String),
    /// A buffer handed to the env has the wrong length.
    #[error("`{field}` has length {len}, expected {expected}")]
    Shape {
        /// The buffer.
        field: &'static str,
        /// Its length.
        len: usize,
        /// The length the env's spec implies.
        expected: usize,
    },
}

/// `Result` with [`EnvError`].
pub type Result<T, E = EnvError> = std::result::Result<T, E>;
