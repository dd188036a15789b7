//! The training loop shared by `factory-train` and the tests: env + learner + counters, one PPO update per
//! call, checkpoints that resume exactly, and policy export.

use std::path::Path;
use std::time::Instant;

use burn::prelude::*;
use factory_engine::rng::SplitMix64;
use factory_envs::{EndCauses, Env, StepBuffers};

use crate::checkpoint::{self, PolicyFile};
use crate::config::{DeviceChoice, TrainConfig};
use crate::error::{Result, RlError};
use crate::ppo::{EpisodeTracker, Ppo, UpdateStats};

/// The learner's device for a config choice, and a name for logs.
///
/// `wgpu` is burn's wgpu backend on the engine's own device (one `wgpu::Device` and queue serve the simulator
/// and the learner, DESIGN.md section 1); it needs factory-rl's `wgpu` cargo feature. `cpu` is burn-flex on
/// the host. `auto` takes wgpu when the engine's adapter is a hardware GPU and the feature is built, else
/// flex: over a software rasteriser (lavapipe) flex trains the Table IX MLP several times faster
/// (docs/BENCHMARKS.md).
pub fn resolve_device(choice: DeviceChoice) -> Result<(Device, String)> {
    let flex = |why: &str| (Device::flex(), format!("cpu (burn-flex{why})"));
    match choice {
        DeviceChoice::Cpu => Ok(flex("")),
        DeviceChoice::Wgpu => engine_wgpu_device(),
        DeviceChoice::Auto => match factory_engine::gpu::GpuContext::global() {
            Ok(gpu) if !gpu.is_software() && cfg!(feature = "wgpu") => engine_wgpu_device(),
            Ok(gpu) if !gpu.is_software() => Ok(flex("; auto: built without the wgpu feature")),
            _ => Ok(flex("; auto: no hardware GPU")),
        },
    }
}

/// burn's wgpu runtime registered on the engine's device and queue, once per process (cubecl asks that a
/// setup be registered once; the device is cloned after that).
#[cfg(feature = "wgpu")]
pub fn engine_wgpu_device() -> Result<(Device, String)> {
    static DEVICE: std::sync::OnceLock<std::result::Result<(Device, String), String>> = std::sync::OnceLock::new();
    let made = DEVICE.get_or_init(|| {
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
    });
    made.clone().map_err(|reason| RlError::InvalidValue { field: "ppo.device".into(), reason })
}

/// Without the `wgpu` feature: refused by name.
#[cfg(not(feature = "wgpu"))]
pub fn engine_wgpu_device() -> Result<(Device, String)> {
    Err(RlError::InvalidValue {
        field: "ppo.device".into(),
        reason: "\"wgpu\" needs factory-rl built with `--features wgpu`; valid in this build: \"auto\", \"cpu\"".into(),
    })
}

/// Sets each world's episode step count so its first episode is truncated after a uniform random
/// 1..=`stagger` steps (see `TrainSection::stagger_first_episodes`); 0 leaves the env as it is.
fn stagger_first_episodes(env: &mut dyn Env, stagger: u32, seed: u64) -> Result<()> {
    if stagger == 0 {
        return Ok(());
    }
    let spec = env.spec();
    let max = spec.max_episode_steps;
    if stagger > max {
        return Err(RlError::InvalidValue {
            field: "train.stagger_first_episodes".into(),
            reason: format!("{stagger} steps; valid: 0 (off) to the env's max_episode_steps = {max}"),
        });
    }
    // A generator of its own, so the learner's noise and the env's draws are the same with or without it.
    let mut rng = SplitMix64(seed ^ 0x57A6_6E12);
    let steps: Vec<u32> = (0..spec.env_count).map(|_| max - 1 - (rng.next_u64() % stagger as u64) as u32).collect();
    env.set_episode_steps(&steps)
        .map_err(|e| RlError::InvalidValue { field: "train.stagger_first_episodes".into(), reason: e.to_string() })
}

/// What one update reports.
#[derive(Clone, Debug, serde::Serialize)]
pub struct UpdateReport {
    /// Updates completed, this one included.
    pub update: usize,
    /// Env steps so far (all worlds).
    pub env_steps: u64,
    /// The learner's losses.
    pub stats: UpdateStats,
    /// Episodes that ended during this update's rollout.
    pub episodes: usize,
    /// Their success rate (NaN when none ended).
    pub success_rate: f32,
    /// Their mean undiscounted return (NaN when none ended).
    pub mean_return: f32,
    /// How they ended (`success`, `time_limit`, the env's failure causes).
    pub ended_by: EndCauses,
    /// Wall time of the rollout (simulation and acting) [s].
    pub rollout_seconds: f64,
    /// Wall time of the PPO update [s].
    pub learn_seconds: f64,
}

/// An env and a learner stepping together.
pub struct Trainer {
    /// The resolved config.
    pub cfg: TrainConfig,
    /// The env.
    pub env: Box<dyn Env>,
    /// The learner.
    pub ppo: Ppo,
    /// The env's last outputs (the next rollout starts from its observations).
    pub buf: StepBuffers,
    /// Episode bookkeeping.
    pub episodes: EpisodeTracker,
    /// Updates completed.
    pub updates_done: usize,
    /// Env steps taken.
    pub env_steps: u64,
    /// Training wall time so far, across resumes [s].
    pub wall_seconds: f64,
}

impl Trainer {
    /// A fresh run.
    pub fn new(cfg: TrainConfig, device: Device) -> Result<Self> {
        let mut env = factory_envs::build(&cfg.env, cfg.train.env_count, cfg.seed)?;
        let spec = env.spec().clone();
        let mut buf = StepBuffers::new(&spec);
        env.reset(&mut buf);
        stagger_first_episodes(env.as_mut(), cfg.train.stagger_first_episodes, cfg.seed)?;
        let ppo = Ppo::new(&cfg.ppo, spec.env_count, spec.observation_dim(), spec.action_dim(), cfg.seed, device);
        Ok(Self {
            episodes: EpisodeTracker::new(spec.env_count),
            cfg,
            env,
            ppo,
            buf,
            updates_done: 0,
            env_steps: 0,
            wall_seconds: 0.0,
        })
    }

    /// Continues the run saved in checkpoint `path` (its own config; `device` may differ).
    pub fn resume(path: &Path, device: Device) -> Result<Self> {
        Self::resume_on(path, |_| Ok(device))
    }

    /// As [`resume`](Self::resume), the device chosen from the checkpoint's config (the file is read once).
    pub fn resume_on(path: &Path, device: impl FnOnce(&TrainConfig) -> Result<Device>) -> Result<Self> {
        let ck = checkpoint::read(path)?;
        let cfg = TrainConfig::from_str_with(&ck.meta.config, &path.display().to_string(), &[])?;
        let device = device(&cfg)?;
        let mut t = Self::new(cfg, device)?;
        checkpoint::restore(&mut t.ppo, &ck, path)?;
        let bad = |reason: String| RlError::BadFile { path: path.into(), reason };
        if ck.meta.observation.len() != t.buf.observation.len() {
            return Err(bad(format!(
                "observation of length {}, the env has {}",
                ck.meta.observation.len(),
                t.buf.observation.len()
            )));
        }
        match &ck.env_state {
            Some(state) => {
                t.env.load_state(state)?;
                t.buf.observation.copy_from_slice(&ck.meta.observation);
                t.episodes.running_return = ck.meta.running_return.clone();
                t.episodes.running_length = ck.meta.running_length.clone();
            }
            // The env cannot restore its worlds: they start fresh episodes (already reset by `new`).
            None => {}
        }
        t.updates_done = ck.meta.updates_done;
        t.env_steps = ck.meta.env_steps;
        t.wall_seconds = ck.meta.wall_seconds;
        Ok(t)
    }

    /// One rollout and one PPO update.
    pub fn update(&mut self) -> UpdateReport {
        let t0 = Instant::now();
        let rollout = self.ppo.collect(self.env.as_mut(), &mut self.buf, &mut self.episodes);
        let t1 = Instant::now();
        let stats = self.ppo.update(rollout);
        let t2 = Instant::now();
        self.updates_done += 1;
        self.env_steps += (self.cfg.ppo.horizon * self.cfg.train.env_count) as u64;
        self.wall_seconds += (t2 - t0).as_secs_f64();
        let (finished, ended_by) = self.episodes.take();
        let k = finished.len();
        let (ret, succ) = finished.iter().fold((0.0f64, 0usize), |(r, s), e| (r + e.0 as f64, s + e.2 as usize));
        UpdateReport {
            update: self.updates_done,
            env_steps: self.env_steps,
            stats,
            episodes: k,
            success_rate: if k > 0 { succ as f32 / k as f32 } else { f32::NAN },
            mean_return: if k > 0 { (ret / k as f64) as f32 } else { f32::NAN },
            ended_by,
            rollout_seconds: (t1 - t0).as_secs_f64(),
            learn_seconds: (t2 - t1).as_secs_f64(),
        }
    }

    /// Writes a checkpoint atomically.
    pub fn save_checkpoint(&self, path: &Path) -> Result<()> {
        checkpoint::save(
            path,
            &self.ppo,
            &self.cfg.to_toml(),
            self.updates_done,
            self.env_steps,
            self.wall_seconds,
            &self.buf.observation,
            &self.episodes,
            self.env.save_state(),
        )
    }

    /// Exports the policy.
    pub fn export_policy(&self, path: &Path) -> Result<()> {
        PolicyFile::from_learner(&self.ppo, self.env.spec(), &self.cfg.env, self.updates_done, self.env_steps)
            .save(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cpu` is flex; `wgpu` is the engine's device with the feature and refused by name without it; `auto`
    /// never picks wgpu over a software rasteriser.
    #[test]
    fn device_choices_resolve_or_are_refused_by_name() {
        let (_, name) = resolve_device(DeviceChoice::Cpu).unwrap();
        assert!(name.contains("flex"), "{name}");
        match resolve_device(DeviceChoice::Wgpu) {
            Ok((_, name)) => assert!(cfg!(feature = "wgpu") && name.contains("engine's device"), "{name}"),
            Err(e) => {
                let e = e.to_string();
                assert!(!cfg!(feature = "wgpu") || factory_engine::gpu::GpuContext::global().is_err(), "{e}");
                assert!(e.contains("ppo.device"), "{e}");
            }
        }
        let software = factory_engine::gpu::GpuContext::global().map(|g| g.is_software()).unwrap_or(true);
        let (_, name) = resolve_device(DeviceChoice::Auto).unwrap();
        if software {
            assert!(name.contains("flex"), "auto over a software adapter: {name}");
        }
    }
}
