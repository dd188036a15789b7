//! Device-resident envs: the [`DeviceEnv`] plugin trait, whose observations, rewards and done flags are burn
//! tensors on the learner's device and whose actions are read there, so a rollout needs no per-step transfer
//! between host and device: observations and actions never leave the device. The module is the cargo feature
//! `device` (burn is a dependency only with it).
//!
//! Semantics are [`Env`](crate::Env)'s (Gymnasium vector envs, same-step autoreset): every
//! [`DeviceEnv::step`] advances all worlds, reports terminated / truncated / success per world, and resets the
//! worlds whose episode ended, returning the first observation of their next episode. Flags are 0.0 / 1.0 in
//! f32 tensors so the learner masks with products, as it does with the host env's buffers.
//!
//! A host [`Env`](crate::Env) costs one upload of the observations and one download of the actions per step;
//! on a machine with a GPU that round trip, not the arithmetic, bounds a small env. A `DeviceEnv` computes
//! the step with tensor ops (or kernels writing into the tensors' buffers) on the same device as the policy.

use burn::prelude::*;

use crate::env::EnvSpec;
use crate::error::{EnvError, Result};

/// What one [`DeviceEnv::step`] (or reset) returns, all on the env's device.
#[derive(Clone, Debug)]
pub struct DeviceStep {
    /// Observations [units per `EnvSpec::observation_names`], shape [env_count, observation_dim]; for a world
    /// whose episode ended this step, the first observation of its next episode.
    pub observation: Tensor<2>,
    /// Rewards of this step, shape [env_count].
    pub reward: Tensor<1>,
    /// 1.0 where the episode reached a terminal state this step, else 0.0; [env_count].
    pub terminated: Tensor<1>,
    /// 1.0 where the episode hit `max_episode_steps` without terminating, else 0.0; [env_count].
    pub truncated: Tensor<1>,
    /// 1.0 where the episode ended in success this step, else 0.0; [env_count].
    pub success: Tensor<1>,
    /// Where an episode terminated without success this step, 1 + the index of its cause in
    /// [`DeviceEnv::failure_causes`], else 0 (whole numbers in f32); [env_count]. None for an env that names
    /// no causes.
    pub failure: Option<Tensor<1>>,
}

/// A batch of `env_count` worlds stepped together on a burn device.
pub trait DeviceEnv: Send {
    /// The env's spec.
    fn spec(&self) -> &EnvSpec;

    /// Starts a new episode in every world (rewards and flags zero).
    fn reset(&mut self) -> DeviceStep;

    /// Applies `action` (shape [env_count, action_dim], clipped to [-1, 1]) for one control step, resets the
    /// worlds whose episode ended and returns the step's results (see the module docs).
    fn step(&mut self, action: Tensor<2>) -> DeviceStep;

    /// Hook: the names of the causes [`DeviceStep::failure`] numbers (as the host env's
    /// `StepBuffers::failure`: `slipped`, `fallen`, ...); none by default.
    fn failure_causes(&self) -> &'static [&'static str] {
        &[]
    }

    /// Hook: the env's whole state as bytes (read back from the device: for checkpoints, not per step), so a
    /// resumed run continues exactly; `None` (the default) when the env cannot.
    fn save_state(&self) -> Option<Vec<u8>> {
        None
    }

    /// Hook: restores what [`save_state`](Self::save_state) wrote for an env of the same spec.
    fn load_state(&mut self, _bytes: &[u8]) -> Result<()> {
        Err(EnvError::InvalidValue {
            field: "state",
            reason: format!("device env `{}` cannot restore a state", self.spec().name),
        })
    }

    /// Hook: as [`Env::set_episode_steps`](crate::Env::set_episode_steps) (each world's step count within its
    /// running episode); the default refuses.
    fn set_episode_steps(&mut self, _steps: &[u32]) -> Result<()> {
        Err(EnvError::InvalidValue {
            field: "episode_steps",
            reason: format!("device env `{}` cannot set its episodes' step counts", self.spec().name),
        })
    }
}

/// burn's wgpu runtime registered on the engine's device and queue (`WgpuSetup` from the engine's
/// `GpuContext`), once per process (cubecl asks that a setup be registered once; the device is cloned after
/// that): the learner's device under which device envs and the engine share buffers. Returns the device and
/// a description; the error says why the runtime could not be made. Needs the `wgpu` feature.
#[cfg(feature = "wgpu")]
pub fn engine_wgpu_device() -> std::result::Result<(Device, String), String> {
    static DEVICE: std::sync::OnceLock<std::result::Result<(Device, String), String>> = std::sync::OnceLock::new();
    DEVICE
        .get_or_init(|| {
            let gpu = factory_engine::gpu::GpuContext::global().map_err(|e| e.to_string())?;
            let setup = burn::tensor::wgpu::WgpuSetup {
                instance: gpu.instance.clone(),
                adapter: gpu.adapter.clone(),
                device: gpu.device.clone(),
                queue: gpu.queue.clone(),
                backend: gpu.info.backend,
            };
            let device = Device::wgpu_options().setup(setup).init().map_err(|e| e.to_string())?;
            Ok((device, format!("wgpu (burn on the engine's device: {}, {:?})", gpu.info.name, gpu.info.backend)))
        })
        .clone()
}
