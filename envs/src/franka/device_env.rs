//! [`FrankaNutBolt`] as a [`DeviceEnv`] (cargo feature `wgpu`, which implies `device`): the Screw step of
//! [`ScrewStepGpu`] reading the policy's action tensor and writing the observation, reward and flag tensors on
//! the learner's device, with no readback per step.
//!
//! The learner must run on burn's wgpu runtime registered on the engine's own device and queue
//! (factory-rl's `engine_wgpu_device`): tensors and the engine's buffers are then buffers of one
//! `wgpu::Device`, and a step hands them over with `copy_buffer_to_buffer` on the shared queue. burn's side
//! of a tensor is reached through its CubeCL primitive (`client.get_resource`); its pending work is
//! submitted first (`client.flush`), so on the one queue the policy's action is written before the step
//! reads it, and the step's outputs are written before any later tensor op reads them.
//!
//! A step records the env's whole step and the five copies in one submission; an action costs one copy in
//! (world_count x 12 floats), the outputs five copies out. Episode ends are counted on the device; what
//! the learner reads back is its per-update summary.

use burn::backend::wgpu::{AutoCompiler, CubeTensor, Wgpu};
use burn::cubecl::wgpu::WgpuServer;
use burn::prelude::*;
use factory_engine::gpu::GpuContext;
use factory_engine::wgpu;

use super::nut_bolt::{FrankaNutBolt, FrankaNutBoltConfig};
use super::screw_step::{ScrewStepGpu, CAUSES};
use crate::device::{DeviceEnv, DeviceStep};
use crate::env::{Env, EnvSpec};
use crate::error::{EnvError, Result};

/// Start states drawn for resets when the config randomises them ([`ScrewStepGpu::new`]).
pub const RESET_BANK: usize = 4096;

/// The wgpu buffer behind a contiguous f32 tensor on burn's wgpu runtime: (claim, buffer, byte offset,
/// bytes), after the runtime's pending work was submitted. The claim keeps the allocation in place (CubeCL
/// neither frees nor moves a claimed allocation): hold it until the commands that use the buffer are
/// submitted. Refuses a tensor on another runtime.
fn tensor_buffer(primitive: &CubeTensor, what: &str) -> Result<(impl Sized, wgpu::Buffer, u64, u64)> {
    let bad = |reason: String| EnvError::InvalidValue { field: "ppo.device", reason };
    let resource = primitive
        .client
        .get_resource::<WgpuServer<AutoCompiler>>(primitive.handle.clone())
        .map_err(|e| bad(format!("{what}: not a tensor of the engine's wgpu device ({e:?})")))?;
    primitive.client.flush().map_err(|e| bad(format!("{what}: flushing burn's queue: {e:?}")))?;
    let (buffer, offset, size) = {
        let r = resource.resource();
        (r.buffer.clone(), r.offset, r.size)
    };
    Ok((resource, buffer, offset, size))
}

fn wgpu_primitive<const D: usize>(t: Tensor<D>, what: &str) -> Result<CubeTensor> {
    t.try_into_primitive::<Wgpu>().map_err(|e| EnvError::InvalidValue {
        field: "ppo.device",
        reason: format!(
            "{what}: the device-resident franka_nut_bolt needs the learner on burn's wgpu runtime over the \
             engine's device (ppo.device = \"wgpu\"); got {e:?}"
        ),
    })
}

/// Whether `device` is burn's wgpu runtime (where [`FrankaNutBoltDevice`] can run).
pub fn is_wgpu(device: &Device) -> bool {
    wgpu_primitive(Tensor::<1>::zeros([1], device), "probe").and_then(|p| tensor_buffer(&p, "probe")).is_ok()
}

/// The device-resident FrankaNutBolt (module docs).
pub struct FrankaNutBoltDevice {
    env: FrankaNutBolt,
    step: ScrewStepGpu,
    gpu: &'static GpuContext,
    device: Device,
    spec: EnvSpec,
}

impl FrankaNutBoltDevice {
    /// `env_count` worlds on `device` (burn's wgpu runtime over the engine's device); `seed` draws the reset
    /// bank. Refuses what [`FrankaNutBolt::new`] and [`ScrewStepGpu::new`] refuse, and a device that is not
    /// burn's wgpu runtime.
    pub fn new(cfg: &FrankaNutBoltConfig, env_count: usize, seed: u64, device: &Device) -> Result<Self> {
        if cfg.balanced_grip {
            return Err(EnvError::InvalidValue {
                field: "balanced_grip",
                reason: "the device rollout does not balance the fingers; use the host rollout \
                         (train.rollout = \"host\")"
                    .into(),
            });
        }
        let gpu = GpuContext::global()?;
        tensor_buffer(&wgpu_primitive(Tensor::<1>::zeros([1], device), "the learner's device")?, "probe")?;
        let mut env = FrankaNutBolt::new(cfg, env_count, seed)?;
        let step = ScrewStepGpu::new(gpu, &mut env, RESET_BANK)?;
        let spec = env.spec().clone();
        Ok(Self { env, step, gpu, device: device.clone(), spec })
    }

    /// The host env underneath (its scene holds the device buffers; its host state is stale while stepping).
    pub fn host(&self) -> &FrankaNutBolt {
        &self.env
    }

    /// The device step.
    pub fn device_step(&self) -> &ScrewStepGpu {
        &self.step
    }

    /// Fresh output tensors, and the copies of the step's buffers into them recorded into `enc`; the claims
    /// on their memory to hold until `enc` is submitted.
    fn outputs(&self, enc: &mut wgpu::CommandEncoder) -> Result<(DeviceStep, Vec<impl Sized>)> {
        let n = self.spec.env_count;
        let d = self.spec.observation_dim();
        let observation = Tensor::<2>::empty([n, d], &self.device);
        // step_out's planes: reward, terminated, truncated, success and the outcome (screw_step::CAUSES).
        let planes: Vec<Tensor<1>> = (0..5).map(|_| Tensor::<1>::empty([n], &self.device)).collect();
        let mut claims = Vec::new();
        let (claim, buf, off, _) = tensor_buffer(&wgpu_primitive(observation.clone(), "observation")?, "observation")?;
        claims.push(claim);
        enc.copy_buffer_to_buffer(&self.step.obs, 0, &buf, off, (n * d * 4) as u64);
        for (k, t) in planes.iter().enumerate() {
            let (claim, buf, off, _) = tensor_buffer(&wgpu_primitive(t.clone(), "flags")?, "flags")?;
            claims.push(claim);
            enc.copy_buffer_to_buffer(&self.step.step_out, (k * n * 4) as u64, &buf, off, (n * 4) as u64);
        }
        let [reward, terminated, truncated, success, outcome]: [Tensor<1>; 5] = planes.try_into().expect("5 planes");
        // CAUSES: 0 running, 1 success, then the failures in failure_causes()' order.
        let failure = Some(outcome.sub_scalar(1.0).clamp_min(0.0));
        Ok((DeviceStep { observation, reward, terminated, truncated, success, failure }, claims))
    }

    fn try_step(&mut self, action: Tensor<2>) -> Result<DeviceStep> {
        let n = self.spec.env_count;
        let action = action.reshape([n * 12]);
        let (claim, buf, off, size) = tensor_buffer(&wgpu_primitive(action.clone(), "action")?, "action")?;
        if size < (n * 12 * 4) as u64 {
            return Err(EnvError::Shape { field: "action", len: size as usize / 4, expected: n * 12 });
        }
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&buf, off, &self.step.action.actions, 0, (n * 12 * 4) as u64);
        self.step.encode_step(&mut enc, &self.env.scene().sim);
        let (out, claims) = self.outputs(&mut enc)?;
        self.gpu.queue.submit([enc.finish()]);
        drop((claim, claims));
        Ok(out)
    }
}

impl DeviceEnv for FrankaNutBoltDevice {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset(&mut self) -> DeviceStep {
        self.step.reset(self.gpu, &mut self.env).expect("the state keeps the shapes new() checked");
        let mut enc = self.gpu.device.create_command_encoder(&Default::default());
        let (out, claims) = self.outputs(&mut enc).expect("new() checked the device");
        self.gpu.queue.submit([enc.finish()]);
        drop(claims);
        out
    }

    fn step(&mut self, action: Tensor<2>) -> DeviceStep {
        match self.try_step(action) {
            Ok(out) => out,
            Err(e) => panic!("franka_nut_bolt (device): {e}"),
        }
    }

    fn failure_causes(&self) -> &'static [&'static str] {
        &CAUSES[2..]
    }

    /// The device state (module docs of [`ScrewStepGpu::save`]), read back once: a resumed run continues
    /// its episodes exactly.
    fn save_state(&self) -> Option<Vec<u8>> {
        Some(self.step.save(self.gpu, &self.env.scene().sim))
    }

    fn load_state(&mut self, bytes: &[u8]) -> Result<()> {
        self.step.load(self.gpu, &self.env.scene().sim, bytes)
    }

    fn set_episode_steps(&mut self, steps: &[u32]) -> Result<()> {
        crate::env::check_episode_steps(&self.spec, steps)?;
        self.step.set_episode_steps(self.gpu, steps)
    }
}
