//! The crate's error type.

/// Everything that can go wrong while building or exporting an asset.
#[derive(Debug, thiserror::Error)]
pub enum AssetError {
    /// A size name that is not in the table (e.g. `M5`); `valid` lists the accepted names.
    #[error("unknown size {given}; valid: {valid}")]
    UnknownSize {
        /// What was asked for.
        given: String,
        /// The accepted names, comma separated.
        valid: String,
    },
    /// A fit name other than `tight` or `loose`.
    #[error("unknown fit {given}; valid: {valid}")]
    UnknownFit {
        /// What was asked for.
        given: String,
        /// The accepted names, comma separated.
        valid: String,
    },
    /// A generation option outside its valid range.
    #[error("invalid {name} = {value}: {expected}")]
    InvalidOption {
        /// The option's name.
        name: &'static str,
        /// The rejected value, formatted.
        value: String,
        /// What the option accepts.
        expected: String,
    },
    /// A thread profile that cannot be built from the given diameters (crest or root flat of negative
    /// width); cannot happen for the ISO table but guards hand-made specs.
    #[error("invalid thread profile: {0}")]
    Profile(String),
    /// Writing a file failed.
    #[error(transparent)]
    Engine(#[from] factory_engine::EngineError),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, AssetError>;
