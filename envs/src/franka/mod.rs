//! Franka environments: the shared nut-and-bolt scene ([`scene`]) and the FrankaNutBolt env with its task
//! plugins ([`nut_bolt`]; today the Screw task). Its step on the device ([`screw_step`], [`action_gpu`]) needs
//! only the engine; `device_env`, the env as a burn-tensor `DeviceEnv`, is the cargo feature `wgpu`.

pub mod action_gpu;
#[cfg(feature = "wgpu")]
pub mod device_env;
pub mod nut_bolt;
pub mod scene;
pub mod screw_step;
