//! Checkpoints (everything a run needs to continue exactly) and exported policies (what evaluation and
//! chaining need to act), both written atomically: a killed or failed write leaves the previous file intact.
//!
//! A checkpoint is one file: the magic `FRCKPT01`, then three length-prefixed (u64 little-endian) sections:
//! JSON metadata (config, counters, generator, network parameters with their ids, normaliser statistics,
//! the last observation and the running episodes), the Adam state (burnpack bytes), and the env's own state
//! (empty when the env cannot save one). A policy is a JSON file (see [`PolicyFile`]).

use std::path::{Path, PathBuf};

use burn::prelude::*;
use factory_envs::EnvSpec;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};
use crate::model::{to_vec, ActorCritic};
use crate::normalizer::RunningMeanStd;
use crate::ppo::Ppo;

const MAGIC: &[u8; 8] = b"FRCKPT01";
/// The `format` string of a policy file.
pub const POLICY_FORMAT: &str = "factory-rs policy v1";

/// A normaliser's statistics on the host.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Stats {
    /// Mean per entry.
    pub mean: Vec<f32>,
    /// Variance per entry.
    pub var: Vec<f32>,
    /// Samples merged.
    pub count: f64,
}

impl Stats {
    /// Reads `n`'s statistics back (checkpoint and export only).
    pub fn of(n: &RunningMeanStd) -> Self {
        Self { mean: to_vec(n.mean.clone()), var: to_vec(n.var.clone()), count: n.count }
    }

    /// A normaliser holding these statistics on `device`.
    pub fn to_normalizer(&self, device: &Device) -> RunningMeanStd {
        RunningMeanStd {
            mean: Tensor::from_floats(self.mean.as_slice(), device),
            var: Tensor::from_floats(self.var.as_slice(), device),
            count: self.count,
        }
    }
}

/// One parameter tensor: its id (so the optimizer state applies after loading), shape and values.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ParamEntry {
    /// burn's parameter id.
    pub id: u64,
    /// Shape.
    pub shape: Vec<usize>,
    /// Values, row-major.
    pub values: Vec<f32>,
}

fn params_of(model: &ActorCritic) -> Vec<ParamEntry> {
    model.export().into_iter().map(|(id, shape, values)| ParamEntry { id, shape, values }).collect()
}

fn load_params(model: ActorCritic, params: &[ParamEntry], device: &Device, path: &Path) -> Result<ActorCritic> {
    let raw: Vec<_> = params.iter().map(|p| (p.id, p.shape.clone(), p.values.clone())).collect();
    model.import(&raw, device).map_err(|reason| RlError::BadFile { path: path.into(), reason })
}

/// The metadata section of a checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CheckpointMeta {
    /// The resolved training config (TOML).
    pub config: String,
    /// Updates completed.
    pub updates_done: usize,
    /// Env steps taken (all worlds).
    pub env_steps: u64,
    /// Wall time spent training before this checkpoint [s].
    pub wall_seconds: f64,
    /// The learner's generator state.
    pub rng: u64,
    /// Network parameters.
    pub params: Vec<ParamEntry>,
    /// Observation statistics.
    pub obs_norm: Stats,
    /// Return statistics.
    pub value_norm: Stats,
    /// The observation the next rollout starts from, [env_count * obs_dim].
    pub observation: Vec<f32>,
    /// Running episodes' returns and lengths.
    pub running_return: Vec<f32>,
    /// Running episodes' lengths.
    pub running_length: Vec<u32>,
}

/// What [`save`] writes and [`load`] returns besides the learner.
pub struct Checkpoint {
    /// Metadata.
    pub meta: CheckpointMeta,
    /// The env's state (None when it cannot save one).
    pub env_state: Option<Vec<u8>>,
    /// Adam's state (burnpack bytes).
    pub optim: Vec<u8>,
}

/// Writes a checkpoint of `ppo` (and the env state, observation and running episodes' returns and lengths given) to `path` atomically.
#[allow(clippy::too_many_arguments)]
pub fn save(
    path: &Path,
    ppo: &Ppo,
    config_toml: &str,
    updates_done: usize,
    env_steps: u64,
    wall_seconds: f64,
    observation: &[f32],
    running: &(Vec<f32>, Vec<u32>),
    env_state: Option<Vec<u8>>,
) -> Result<()> {
    let meta = CheckpointMeta {
        config: config_toml.to_owned(),
        updates_done,
        env_steps,
        wall_seconds,
        rng: ppo.rng.0,
        params: params_of(&ppo.model),
        obs_norm: Stats::of(&ppo.obs_norm),
        value_norm: Stats::of(&ppo.value_norm),
        observation: observation.to_vec(),
        running_return: running.0.clone(),
        running_length: running.1.clone(),
    };
    let json = serde_json::to_vec(&meta).expect("checkpoint metadata serialises");
    let optim = ppo
        .optim
        .into_bytes()
        .map_err(|e| RlError::BadFile { path: path.into(), reason: format!("optimizer state: {e:?}") })?;
    let env = env_state.unwrap_or_default();
    let mut bytes = Vec::with_capacity(32 + json.len() + optim.len() + env.len());
    bytes.extend_from_slice(MAGIC);
    for section in [json.as_slice(), &optim[..], env.as_slice()] {
        bytes.extend_from_slice(&(section.len() as u64).to_le_bytes());
        bytes.extend_from_slice(section);
    }
    write_atomic(path, &bytes)
}

/// Reads a checkpoint file's sections.
pub fn read(path: &Path) -> Result<Checkpoint> {
    let bytes = std::fs::read(path).map_err(|e| RlError::io(path, e))?;
    let bad = |reason: String| RlError::BadFile { path: path.into(), reason };
    if bytes.len() < 8 || &bytes[..8] != MAGIC {
        return Err(bad("not a factory-rs checkpoint (bad magic)".into()));
    }
    let mut at = 8;
    let mut sections = Vec::new();
    for name in ["metadata", "optimizer", "env"] {
        let len = bytes
            .get(at..at + 8)
            .map(|b| u64::from_le_bytes(b.try_into().unwrap()) as usize)
            .ok_or_else(|| bad(format!("truncated before the {name} section")))?;
        at += 8;
        let s = bytes.get(at..at + len).ok_or_else(|| bad(format!("truncated {name} section")))?;
        sections.push(s.to_vec());
        at += len;
    }
    let meta: CheckpointMeta = serde_json::from_slice(&sections[0]).map_err(|e| bad(format!("metadata: {e}")))?;
    let env = std::mem::take(&mut sections[2]);
    Ok(Checkpoint { meta, env_state: (!env.is_empty()).then_some(env), optim: std::mem::take(&mut sections[1]) })
}

/// Restores the learner's network, optimizer, normalisers and generator from a checkpoint.
pub fn restore(ppo: &mut Ppo, ck: &Checkpoint, path: &Path) -> Result<()> {
    let model = ppo.model.clone();
    ppo.model = load_params(model, &ck.meta.params, &ppo.train_device, path)?;
    let optim = std::mem::replace(&mut ppo.optim, burn::optim::AdamConfig::new().init());
    ppo.optim = optim
        .from_bytes(burn::tensor::Bytes::from_bytes_vec(ck.optim.clone()))
        .map_err(|e| RlError::BadFile { path: path.into(), reason: format!("optimizer state: {e:?}") })?;
    ppo.obs_norm = ck.meta.obs_norm.to_normalizer(&ppo.device);
    ppo.value_norm = ck.meta.value_norm.to_normalizer(&ppo.device);
    ppo.rng.0 = ck.meta.rng;
    Ok(())
}

/// An exported policy: what acting needs (network, observation statistics, the spec it was trained on).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PolicyFile {
    /// [`POLICY_FORMAT`].
    pub format: String,
    /// The env it was trained on (`type` name).
    pub env: String,
    /// That env's config, so evaluation can rebuild it.
    pub env_config: factory_envs::EnvConfig,
    /// Observation entries, in order.
    pub observation_names: Vec<String>,
    /// Action entries, in order.
    pub action_names: Vec<String>,
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Whether observations are normalised, and their clamp.
    pub normalize_observation: bool,
    /// Clamp of normalised observations.
    pub observation_clip: f32,
    /// Observation statistics.
    pub obs_norm: Stats,
    /// Network parameters.
    pub params: Vec<ParamEntry>,
    /// Updates and env steps it was trained for.
    pub updates: usize,
    /// Env steps it was trained for.
    pub env_steps: u64,
}

impl PolicyFile {
    /// The spec line shown when a policy and an env disagree.
    pub fn spec_line(env: &str, obs: &[String], act: &[String]) -> String {
        format!("env `{env}`, observations [{}], actions [{}]", obs.join(", "), act.join(", "))
    }

    /// Refuses an env whose spec differs from the policy's, showing both.
    pub fn check_spec(&self, spec: &EnvSpec, path: &Path) -> Result<()> {
        if self.env != spec.name
            || self.observation_names != spec.observation_names
            || self.action_names != spec.action_names
        {
            return Err(RlError::SpecMismatch {
                path: path.into(),
                policy: Self::spec_line(&self.env, &self.observation_names, &self.action_names),
                env: Self::spec_line(&spec.name, &spec.observation_names, &spec.action_names),
            });
        }
        Ok(())
    }

    /// Exports `ppo`'s policy for `spec`.
    pub fn from_learner(
        ppo: &Ppo,
        spec: &EnvSpec,
        env_config: &factory_envs::EnvConfig,
        updates: usize,
        env_steps: u64,
    ) -> Self {
        Self {
            format: POLICY_FORMAT.into(),
            env: spec.name.clone(),
            env_config: env_config.clone(),
            observation_names: spec.observation_names.clone(),
            action_names: spec.action_names.clone(),
            hidden: ppo.cfg.hidden.clone(),
            normalize_observation: ppo.cfg.normalize_observation,
            observation_clip: ppo.cfg.observation_clip,
            obs_norm: Stats::of(&ppo.obs_norm),
            params: params_of(&ppo.model),
            updates,
            env_steps,
        }
    }

    /// Writes the policy atomically and returns the SHA-256 of the bytes written (hex).
    pub fn save(&self, path: &Path) -> Result<String> {
        let bytes = serde_json::to_vec(self).expect("policy serialises");
        write_atomic(path, &bytes)?;
        Ok(sha256_hex(&bytes))
    }

    /// Reads a policy file.
    pub fn load(path: &Path) -> Result<Self> {
        Ok(Self::load_hashed(path)?.0)
    }

    /// Reads a policy file, with the SHA-256 of its bytes (hex).
    pub fn load_hashed(path: &Path) -> Result<(Self, String)> {
        let bytes = std::fs::read(path).map_err(|e| RlError::io(path, e))?;
        let p: PolicyFile = serde_json::from_slice(&bytes)
            .map_err(|e| RlError::BadFile { path: path.into(), reason: format!("not a policy file: {e}") })?;
        if p.format != POLICY_FORMAT {
            return Err(RlError::BadFile {
                path: path.into(),
                reason: format!("format `{}`, expected `{POLICY_FORMAT}`", p.format),
            });
        }
        Ok((p, sha256_hex(&bytes)))
    }

    /// The observation normaliser the policy acts with (None when it takes raw observations).
    pub fn normalizer(&self, device: &Device) -> Option<RunningMeanStd> {
        self.normalize_observation.then(|| self.obs_norm.to_normalizer(device))
    }

    /// The network and observation normaliser on `device` (no autodiff), for acting.
    pub fn build(&self, device: &Device, path: &Path) -> Result<(ActorCritic, Option<RunningMeanStd>)> {
        let mut rng = factory_engine::rng::SplitMix64(0);
        let model = ActorCritic::new(
            self.observation_names.len(),
            self.action_names.len(),
            &self.hidden,
            0.0,
            &mut rng,
            device,
        );
        let model = load_params(model, &self.params, device, path)?;
        Ok((model, self.normalizer(device)))
    }
}

/// The SHA-256 of `bytes` as lower-case hex: how reports and provenance files name a policy file.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    format!("{:x}", Sha256::digest(bytes))
}

/// Atomic write with this crate's error.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    factory_engine::fsutil::write_atomic(path, bytes)
        .map_err(|e| RlError::io(PathBuf::from(path), std::io::Error::other(e.to_string())))
}
