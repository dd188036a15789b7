//! factory-envs: batched environments behind one [`Env`] plugin trait (Gymnasium semantics: terminated vs
//! truncated, auto-reset of finished worlds inside `step`), an explicit registry selected by `type` in TOML,
//! and the tasks. Crates depend downward: rl -> envs -> controllers -> engine.

pub mod device;
pub mod env;
pub mod error;
pub mod franka;
pub mod point_mass;
pub mod point_mass_device;
pub mod registry;

pub use device::{DeviceEnv, DeviceStep};
pub use env::{EndCauses, Env, EnvSpec, StepBuffers, StepDiagnostics};
pub use error::{EnvError, Result};
pub use franka::nut_bolt::{FrankaNutBolt, FrankaNutBoltConfig};
pub use point_mass::{PointMass, PointMassConfig};
pub use point_mass_device::PointMassDevice;
pub use registry::{build, build_device, EnvConfig, NAMES};
