//! The training loop shared by `factory-train` and the tests: env + learner + counters, one PPO update per
//! call, checkpoints that resume exactly, and policy export.

use std::path::Path;
use std::time::Instant;

use burn::prelude::*;
use factory_engine::rng::SplitMix64;
use factory_envs::{DeviceEnv, EndCauses, Env, EnvSpec, StepBuffers};

use crate::checkpoint::{self, PolicyFile};
use crate::config::{DeviceChoice, RolloutChoice, TrainConfig};
use crate::error::{Result, RlError};
use crate::model::to_vec;
use crate::ppo::{DeviceEpisodes, EpisodeTracker, Ppo, UpdateStats};

/// The learner's device for a config choice, and a name for logs.
///
/// `wgpu` is burn's wgpu backend on the engine's own device (one `wgpu::Device` and queue serve the simulator
/// and the learner, docs/ARCHITECTURE.md section 2); it needs factory-rl's `wgpu` cargo feature. `cpu` is burn-flex on
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

/// burn's wgpu runtime registered on the engine's device and queue, once per process
/// ([`factory_envs::device::engine_wgpu_device`]); its errors name `ppo.device`.
#[cfg(feature = "wgpu")]
pub fn engine_wgpu_device() -> Result<(Device, String)> {
    factory_envs::device::engine_wgpu_device()
        .map_err(|reason| RlError::InvalidValue { field: "ppo.device".into(), reason })
}

/// Without the `wgpu` feature: refused by name.
#[cfg(not(feature = "wgpu"))]
pub fn engine_wgpu_device() -> Result<(Device, String)> {
    Err(RlError::InvalidValue {
        field: "ppo.device".into(),
        reason: "\"wgpu\" needs factory-rl built with `--features wgpu`; valid in this build: \"auto\", \"cpu\"".into(),
    })
}

/// Each world's episode step count so that its first episode is truncated after a uniform random
/// 1..=`stagger` steps (see `TrainSection::stagger_first_episodes`); None for 0 (the env is left as it is).
fn staggered_steps(spec: &EnvSpec, stagger: u32, seed: u64) -> Result<Option<Vec<u32>>> {
    if stagger == 0 {
        return Ok(None);
    }
    let max = spec.max_episode_steps;
    if stagger > max {
        return Err(RlError::InvalidValue {
            field: "train.stagger_first_episodes".into(),
            reason: format!("{stagger} steps; valid: 0 (off) to the env's max_episode_steps = {max}"),
        });
    }
    // A generator of its own, so the learner's noise and the env's draws are the same with or without it.
    let mut rng = SplitMix64(seed ^ 0x57A6_6E12);
    Ok(Some((0..spec.env_count).map(|_| max - 1 - (rng.next_u64() % stagger as u64) as u32).collect()))
}

fn stagger_error(e: factory_envs::EnvError) -> RlError {
    RlError::InvalidValue { field: "train.stagger_first_episodes".into(), reason: e.to_string() }
}

/// The env a run steps and its episode bookkeeping: on the host, or on the learner's device.
// One per trainer: the variants' size difference costs nothing.
#[allow(clippy::large_enum_variant)]
pub enum EnvRun {
    /// A host env: its observations are uploaded and its actions read back every step.
    Host {
        env: Box<dyn Env>,
        /// The env's last outputs (the next rollout starts from its observations).
        buf: StepBuffers,
        episodes: EpisodeTracker,
    },
    /// A device env on the learner's device: a rollout reads nothing back; the episode tallies come with the
    /// update's summary.
    Device {
        env: Box<dyn DeviceEnv>,
        /// The observations the next rollout starts from, [env_count, observation_dim].
        obs: Tensor<2>,
        episodes: DeviceEpisodes,
    },
}

impl EnvRun {
    /// The env's spec.
    pub fn spec(&self) -> &EnvSpec {
        match self {
            EnvRun::Host { env, .. } => env.spec(),
            EnvRun::Device { env, .. } => env.spec(),
        }
    }

    /// Whether the env runs on the learner's device.
    pub fn on_device(&self) -> bool {
        matches!(self, EnvRun::Device { .. })
    }

    /// Where the env runs, for logs: "the learner's device" or "the host".
    pub fn place(&self) -> &'static str {
        if self.on_device() {
            "the learner's device"
        } else {
            "the host"
        }
    }

    /// The current observations (read back from the device for a device env), shape [env_count * obs_dim].
    pub fn observation(&self) -> Vec<f32> {
        match self {
            EnvRun::Host { buf, .. } => buf.observation.clone(),
            EnvRun::Device { obs, .. } => to_vec(obs.clone()),
        }
    }

    /// Each world's running episode's return and length so far.
    fn running(&self) -> (Vec<f32>, Vec<u32>) {
        match self {
            EnvRun::Host { episodes, .. } => (episodes.running_return.clone(), episodes.running_length.clone()),
            EnvRun::Device { episodes, .. } => (
                to_vec(episodes.running_return.clone()),
                to_vec(episodes.running_length.clone()).iter().map(|&l| l as u32).collect(),
            ),
        }
    }

    /// Restores a checkpoint's env state, observations and running episodes.
    fn restore(&mut self, state: &[u8], observation: &[f32], ret: &[f32], len: &[u32]) -> Result<()> {
        match self {
            EnvRun::Host { env, buf, episodes } => {
                env.load_state(state)?;
                buf.observation.copy_from_slice(observation);
                episodes.running_return = ret.to_vec();
                episodes.running_length = len.to_vec();
            }
            EnvRun::Device { env, obs, episodes } => {
                env.load_state(state)?;
                let device = obs.device();
                *obs = Tensor::<1>::from_floats(observation, &device).reshape(obs.dims());
                episodes.running_return = Tensor::from_floats(ret, &device);
                let len: Vec<f32> = len.iter().map(|&l| l as f32).collect();
                episodes.running_length = Tensor::from_floats(len.as_slice(), &device);
            }
        }
        Ok(())
    }

    fn save_state(&self) -> Option<Vec<u8>> {
        match self {
            EnvRun::Host { env, .. } => env.save_state(),
            EnvRun::Device { env, .. } => env.save_state(),
        }
    }
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
    /// The update's wall time by stage [s]: a host env's own stages ([`factory_envs::EnvProfile`]; the
    /// Franka envs: `contacts`, `solve`, `controller`, `task`), `policy` (acting), `rollout_other` (the rest
    /// of the rollout) and `learn`. A device rollout (nothing waited for per stage) has `rollout_other` and
    /// `learn` only.
    pub stage_seconds: std::collections::BTreeMap<String, f64>,
    /// This rollout's world-steps by task progress tenth ([`factory_envs::EnvProfile::progress_steps`]);
    /// empty when the env does not report progress.
    pub progress_steps: Vec<u64>,
    /// This rollout's work counts by name ([`factory_envs::EnvProfile::work`]); empty where not counted.
    pub work: std::collections::BTreeMap<String, u64>,
}

/// An update's stage times [s], progress counts and work counts ([`UpdateReport`]'s fields).
type ProfileDelta = (std::collections::BTreeMap<String, f64>, Vec<u64>, std::collections::BTreeMap<String, u64>);

/// The episodes that ended over the last `window` updates, for a progress line: with long episodes (Screw:
/// ~1750 steps, 55 updates of horizon 32) most single updates end none.
#[derive(Clone, Debug)]
pub struct RecentEpisodes {
    window: usize,
    /// How each update's episodes in the window ended.
    updates: std::collections::VecDeque<EndCauses>,
}

impl RecentEpisodes {
    /// Over the last `window` updates (at least 1).
    pub fn new(window: usize) -> Self {
        Self { window: window.max(1), updates: Default::default() }
    }

    /// Adds an update's episodes, dropping the oldest beyond the window.
    pub fn push(&mut self, r: &UpdateReport) {
        self.updates.push_back(r.ended_by.clone());
        while self.updates.len() > self.window {
            self.updates.pop_front();
        }
    }

    /// `success 88.3% of 77 episodes in the last 50 updates (fallen 6, slipped 3)`: the failures and time
    /// limits by cause; `no episode ended in the last N updates` when none did.
    pub fn summary(&self) -> String {
        let n = self.updates.len();
        let mut all = EndCauses::default();
        for (cause, count) in self.updates.iter().flat_map(|c| c.0.iter()) {
            all.add(cause, *count);
        }
        let episodes = all.total();
        if episodes == 0 {
            return format!("no episode ended in the last {n} updates");
        }
        let succeeded = all.0.remove("success").unwrap_or(0);
        let rest = all.0.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ");
        format!(
            "success {:.1}% of {episodes} episodes in the last {n} updates{}",
            100.0 * succeeded as f64 / episodes as f64,
            if rest.is_empty() { String::new() } else { format!(" ({rest})") }
        )
    }
}

/// An env and a learner stepping together.
pub struct Trainer {
    /// The resolved config.
    pub cfg: TrainConfig,
    /// The env and its episode bookkeeping.
    pub run: EnvRun,
    /// The learner.
    pub ppo: Ppo,
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
        let (n, seed) = (cfg.train.env_count, cfg.seed);
        let device_env = match cfg.train.rollout {
            RolloutChoice::Host => None,
            RolloutChoice::Auto | RolloutChoice::Device => factory_envs::build_device(&cfg.env, n, seed, &device)?,
        };
        let run = match device_env {
            Some(mut env) => {
                let obs = env.reset().observation;
                if let Some(steps) = staggered_steps(env.spec(), cfg.train.stagger_first_episodes, seed)? {
                    env.set_episode_steps(&steps).map_err(stagger_error)?;
                }
                let episodes = DeviceEpisodes::with_causes(n, env.failure_causes().len(), &device);
                EnvRun::Device { env, obs, episodes }
            }
            None if cfg.train.rollout == RolloutChoice::Device => {
                return Err(RlError::InvalidValue {
                    field: "train.rollout".into(),
                    reason: format!(
                        "\"device\": env `{}` has no device implementation for this learner (ppo.device = {:?}); valid for it: \
                         \"auto\", \"host\" (franka_nut_bolt runs on the device with ppo.device = \"wgpu\", built \
                         with factory-rl's `wgpu` feature, and solve other than \"host\")",
                        cfg.env.name(),
                        cfg.ppo.device
                    ),
                })
            }
            None => {
                let mut env = factory_envs::build(&cfg.env, n, seed)?;
                let mut buf = StepBuffers::new(env.spec());
                env.reset(&mut buf);
                if let Some(steps) = staggered_steps(env.spec(), cfg.train.stagger_first_episodes, seed)? {
                    env.set_episode_steps(&steps).map_err(stagger_error)?;
                }
                EnvRun::Host { env, buf, episodes: EpisodeTracker::new(n) }
            }
        };
        let spec = run.spec();
        let ppo = Ppo::new(&cfg.ppo, spec.env_count, spec.observation_dim(), spec.action_dim(), seed, device);
        Ok(Self { cfg, run, ppo, updates_done: 0, env_steps: 0, wall_seconds: 0.0 })
    }

    /// The env's spec.
    pub fn spec(&self) -> &EnvSpec {
        self.run.spec()
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
        let spec = t.spec();
        let expected = spec.env_count * spec.observation_dim();
        if ck.meta.observation.len() != expected {
            return Err(bad(format!("observation of length {}, the env has {expected}", ck.meta.observation.len())));
        }
        // Without a saved env state (the env cannot save one) the worlds start fresh episodes (reset by `new`).
        if let Some(state) = &ck.env_state {
            let m = &ck.meta;
            t.run.restore(state, &m.observation, &m.running_return, &m.running_length)?;
        }
        t.updates_done = ck.meta.updates_done;
        t.env_steps = ck.meta.env_steps;
        t.wall_seconds = ck.meta.wall_seconds;
        Ok(t)
    }

    /// One rollout and one PPO update.
    pub fn update(&mut self) -> UpdateReport {
        let before = self.profile();
        let t0 = Instant::now();
        let (t1, stats, k, succ, ret, ended_by) = match &mut self.run {
            EnvRun::Host { env, buf, episodes } => {
                let rollout = self.ppo.collect(env.as_mut(), buf, episodes);
                let t1 = Instant::now();
                let stats = self.ppo.update(rollout);
                let (finished, ended_by) = episodes.take();
                let (ret, succ) =
                    finished.iter().fold((0.0f64, 0usize), |(r, s), e| (r + e.0 as f64, s + e.2 as usize));
                (t1, stats, finished.len(), succ, ret, ended_by)
            }
            EnvRun::Device { env, obs, episodes } => {
                let rollout = self.ppo.collect_device(env.as_mut(), obs, episodes);
                let t1 = Instant::now();
                // The tallies come back with the update's summary (`DeviceEpisodes::totals`).
                let (stats, t) = self.ppo.update_with(rollout, Some(episodes.take()));
                let ended_by = DeviceEpisodes::ended_by(&t, env.failure_causes());
                let succ = ended_by.0.get("success").copied().unwrap_or(0);
                (t1, stats, ended_by.total(), succ, t[2] as f64, ended_by)
            }
        };
        let t2 = Instant::now();
        let (stage_seconds, progress_steps, work) =
            self.profile_delta(before, (t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64());
        self.updates_done += 1;
        self.env_steps += (self.cfg.ppo.horizon * self.cfg.train.env_count) as u64;
        self.wall_seconds += (t2 - t0).as_secs_f64();
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
            stage_seconds,
            progress_steps,
            work,
        }
    }

    /// The host env's profile and the learner's acting time so far.
    fn profile(&self) -> (Option<factory_envs::EnvProfile>, f64) {
        match &self.run {
            EnvRun::Host { env, .. } => (env.profile(), self.ppo.act_seconds),
            EnvRun::Device { .. } => (None, self.ppo.act_seconds),
        }
    }

    /// An update's stage times, progress counts and work counts: what [`profile`](Self::profile) gained
    /// since `before`.
    fn profile_delta(&self, before: (Option<factory_envs::EnvProfile>, f64), rollout: f64, learn: f64) -> ProfileDelta {
        let (env_before, act_before) = before;
        let (env_after, act_after) = self.profile();
        let mut stages = std::collections::BTreeMap::new();
        let mut progress = Vec::new();
        let mut work = std::collections::BTreeMap::new();
        let mut accounted = 0.0;
        if let (Some(a), Some(b)) = (env_after, env_before) {
            for (name, s) in &a.stage_seconds {
                let was = b.stage_seconds.iter().find(|(n, _)| n == name).map_or(0.0, |(_, s)| *s);
                stages.insert(name.to_string(), s - was);
                accounted += s - was;
            }
            progress = a.progress_steps.iter().zip(&b.progress_steps).map(|(x, y)| x - y).collect();
            for (name, c) in &a.work {
                let was = b.work.iter().find(|(n, _)| n == name).map_or(0, |(_, c)| *c);
                work.insert(name.to_string(), c - was);
            }
        }
        if matches!(self.run, EnvRun::Host { .. }) {
            stages.insert("policy".into(), act_after - act_before);
            accounted += act_after - act_before;
        }
        stages.insert("rollout_other".into(), (rollout - accounted).max(0.0));
        stages.insert("learn".into(), learn);
        (stages, progress, work)
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
            &self.run.observation(),
            &self.run.running(),
            self.run.save_state(),
        )
    }

    /// Exports the policy; returns the SHA-256 of the file written (hex).
    pub fn export_policy(&self, path: &Path) -> Result<String> {
        PolicyFile::from_learner(&self.ppo, self.run.spec(), &self.cfg.env, self.updates_done, self.env_steps)
            .save(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recent_episodes_sum_over_their_window() {
        let report = |episodes: usize, ends: &[(&str, usize)]| UpdateReport {
            update: 0,
            env_steps: 0,
            stats: UpdateStats::default(),
            episodes,
            success_rate: f32::NAN,
            mean_return: f32::NAN,
            ended_by: EndCauses(ends.iter().map(|(k, v)| (k.to_string(), *v)).collect()),
            rollout_seconds: 0.0,
            learn_seconds: 0.0,
            stage_seconds: Default::default(),
            progress_steps: Vec::new(),
            work: Default::default(),
        };
        let mut r = RecentEpisodes::new(2);
        r.push(&report(0, &[]));
        assert_eq!(r.summary(), "no episode ended in the last 1 updates");
        r.push(&report(4, &[("success", 3), ("slipped", 1)]));
        r.push(&report(4, &[("success", 2), ("fallen", 1), ("slipped", 1)]));
        assert_eq!(r.summary(), "success 62.5% of 8 episodes in the last 2 updates (fallen 1, slipped 2)");
        r.push(&report(1, &[("success", 1)]));
        assert_eq!(r.summary(), "success 60.0% of 5 episodes in the last 2 updates (fallen 1, slipped 1)");
    }

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
