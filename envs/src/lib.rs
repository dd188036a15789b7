//! factory-envs: batched environments behind one [`Env`] plugin trait (Gymnasium semantics: terminated vs
//! truncated, auto-reset of finished worlds inside `step`), an explicit registry selected by `type` in TOML,
//! and the tasks. Crates depend downward: rl -> envs -> controllers -> engine.
//!
//! The trait, the registry's [`build`] and the host envs need no learner and build without burn. The device
//! envs, whose observations, actions and flags are burn tensors on the learner's device (`device::DeviceEnv`,
//! `PointMassDevice`, the registry's `build_device`), are the cargo feature `device`, which
//! factory-rl turns on; the feature `wgpu` adds the Franka device env on burn's wgpu runtime
//! (`franka::device_env`) and implies `device`.

#[cfg(feature = "device")]
pub mod device;
pub mod env;
pub mod error;
pub mod franka;
pub mod point_mass;
#[cfg(feature = "device")]
pub mod point_mass_device;
pub mod registry;

#[cfg(feature = "device")]
pub use device::{DeviceEnv, DeviceStep};
pub use env::{EndCauses, Env, EnvProfile, EnvSpec, StepBuffers, StepDiagnostics, PROGRESS_BINS};
pub use error::{EnvError, Result};
pub use franka::nut_bolt::{FrankaNutBolt, FrankaNutBoltConfig};
pub use point_mass::{PointMass, PointMassConfig};
#[cfg(feature = "device")]
pub use point_mass_device::PointMassDevice;
#[cfg(feature = "device")]
pub use registry::build_device;
pub use registry::{build, EnvConfig, NAMES};
