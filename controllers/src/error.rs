//! The crate's error type.

use crate::registry::NAMES;

/// Everything that can go wrong when reading a controller config or building a controller.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    /// A vector-valued config field has the wrong number of entries.
    #[error("controller config field `{field}` has length {len}, expected {expected}")]
    WrongLength {
        /// The config field's name as written in TOML.
        field: &'static str,
        /// The length given.
        len: usize,
        /// The length the controller needs (6 for task-space vectors, `arm_dof`, `dof - arm_dof` or `dof`).
        expected: usize,
    },
    /// A config field has a value the controller cannot use (negative gain, axis flag not 0 or 1, ...).
    #[error("controller config field `{field}`: {reason}")]
    InvalidValue {
        /// The config field's name as written in TOML.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// The config's `type` names no registered controller.
    #[error("unknown controller type `{0}`; valid types: {valid}", valid = NAMES.join(", "))]
    UnknownType(String),
    /// The config has no `type` key.
    #[error("controller config has no `type`; valid types: {valid}", valid = NAMES.join(", "))]
    MissingType,
    /// The TOML could not be read into a controller config (syntax error, unknown key, wrong value type).
    #[error("invalid controller config: {0}")]
    Parse(String),
    /// The robot's degree-of-freedom counts are unusable.
    #[error("invalid robot dof: dof {dof}, arm_dof {arm_dof} (need 1 <= arm_dof <= {max} and arm_dof <= dof)")]
    InvalidDof {
        /// Degrees of freedom per world.
        dof: usize,
        /// Arm joints among them.
        arm_dof: usize,
        /// The largest arm the fixed-size linear algebra supports.
        max: usize,
    },
    /// An [`ArmBatch`](crate::ArmBatch) or [`Targets`](crate::Targets) buffer has the wrong length.
    #[error("`{field}` has length {len}, expected {expected}")]
    Shape {
        /// The buffer, as `ArmBatch.joint_q`, `Targets.gripper_q`, ...
        field: &'static str,
        /// Its length.
        len: usize,
        /// The length the batch's `world_count`, `dof` and `arm_dof` imply.
        expected: usize,
    },
}

/// `Result` with [`ControllerError`].
pub type Result<T, E = ControllerError> = std::result::Result<T, E>;
