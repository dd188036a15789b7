//! Franka environments: the shared nut-and-bolt scene ([`scene`]) and the FrankaNutBolt env with its task
//! plugins ([`nut_bolt`]; today the Screw task).

pub mod action_gpu;
#[cfg(feature = "wgpu")]
pub mod device_env;
pub mod nut_bolt;
pub mod scene;
pub mod screw_step;
