//! Training configs: one TOML file with `[env]` (the env plugin, selected by `type`), `[ppo]` (the learner,
//! defaults from the paper's Table IX and IsaacGymEnvs' FactoryTask*PPO.yaml) and `[train]` (batch size and
//! schedule). Unknown keys are refused with the valid ones listed; `--set ppo.horizon=64` overrides any key.
//!
//! ```toml
//! seed = 0
//! [env]
//! type = "point_mass"
//! [train]
//! env_count = 128
//! updates = 200
//! [ppo]
//! horizon = 32
//! ```

use std::path::Path;

use factory_envs::EnvConfig;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RlError};

/// Where the learner's tensors live.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeviceChoice {
    /// burn's wgpu backend when the engine runs on a hardware GPU, burn-flex when it runs on a software
    /// rasteriser (see `train::resolve_device`).
    Auto,
    /// burn's wgpu backend on the engine's own device and queue.
    Wgpu,
    /// burn-flex on the host CPU.
    Cpu,
}

/// Where the env of a rollout runs (`[train] rollout`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RolloutChoice {
    /// The env's device implementation where it has one for the learner's device (`point_mass` on any,
    /// `franka_nut_bolt` on a wgpu learner built with the `wgpu` feature), else the host env.
    Auto,
    /// The host env: observations uploaded and actions read back every step.
    Host,
    /// The env's device implementation on the learner's device: nothing read back per step (refused for an
    /// env that has none).
    Device,
}

/// `[ppo]`: the learner. Defaults are the paper's Table IX (IsaacGymEnvs FactoryTaskNutBoltScrewPPO.yaml).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Control steps per env per rollout.
    pub horizon: usize,
    /// Samples per gradient step.
    pub minibatch_size: usize,
    /// Passes over each rollout.
    pub epochs: usize,
    /// Adam learning rate (fixed schedule).
    pub learning_rate: f64,
    /// Discount per control step.
    pub gamma: f32,
    /// GAE lambda.
    pub gae_lambda: f32,
    /// PPO ratio clip epsilon.
    pub clip_ratio: f32,
    /// Clip the value update around the rollout's value by `clip_ratio` too (rl_games `clip_value`).
    pub clip_value: bool,
    /// Weight of the value loss (the loss adds `0.5 * critic_coef * value_loss`, as rl_games does).
    pub critic_coef: f32,
    /// Weight of the entropy bonus.
    pub entropy_coef: f32,
    /// Weight of the bounds loss that keeps action means within [-1.1, 1.1] (rl_games `bounds_loss_coef`).
    pub bounds_loss_coef: f32,
    /// Gradient clipping by norm, per parameter tensor (0 turns it off).
    pub max_grad_norm: f32,
    /// Hidden layer widths of the shared actor-critic trunk (ELU).
    pub hidden: Vec<usize>,
    /// Initial log standard deviation of the Gaussian policy (state-independent, learned: rl_games
    /// `fixed_sigma`).
    pub init_log_std: f32,
    /// Normalise observations with running statistics (clamped to +-`observation_clip`).
    pub normalize_observation: bool,
    /// Clamp of normalised observations.
    pub observation_clip: f32,
    /// The critic predicts values normalised by running statistics of the returns.
    pub normalize_value: bool,
    /// Normalise advantages over each rollout.
    pub normalize_advantage: bool,
    /// Add `gamma * V(s)` to the reward of truncated steps (rl_games `value_bootstrap`).
    pub value_bootstrap: bool,
    /// Where the learner runs: "auto", "wgpu" or "cpu".
    pub device: DeviceChoice,
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            horizon: 32,
            minibatch_size: 512,
            epochs: 8,
            learning_rate: 1e-4,
            gamma: 0.99,
            gae_lambda: 0.95,
            clip_ratio: 0.2,
            clip_value: true,
            critic_coef: 2.0,
            entropy_coef: 0.0,
            bounds_loss_coef: 1e-4,
            max_grad_norm: 1.0,
            hidden: vec![256, 128, 64],
            init_log_std: 0.0,
            normalize_observation: true,
            observation_clip: 5.0,
            normalize_value: true,
            normalize_advantage: true,
            value_bootstrap: true,
            device: DeviceChoice::Auto,
        }
    }
}

/// `[train]`: the run's size and schedule.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainSection {
    /// Worlds stepped together.
    pub env_count: usize,
    /// PPO updates (one rollout of `ppo.horizon` steps each).
    pub updates: usize,
    /// Write a checkpoint every this many updates (and at the end, and on Ctrl-C).
    pub checkpoint_every: usize,
    /// Control steps; 0 turns it off. Each world's first episode is cut short (truncated, its value
    /// bootstrapped) after a uniform random 1..=N steps, so the worlds' later episodes run out of phase,
    /// as rsl_rl's `init_at_random_ep_len`. Without it, every world of a task with no reset randomisation
    /// and long episodes (Screw: ~2000 steps, 60 updates of horizon 32) is in the same phase at once, and
    /// the learner sees the start of an episode only in a few updates per generation. At most the env's
    /// `max_episode_steps`.
    pub stagger_first_episodes: u32,
    /// Where the env runs: "auto" (its device implementation where it has one), "host" or "device".
    pub rollout: RolloutChoice,
}

impl Default for TrainSection {
    fn default() -> Self {
        Self {
            env_count: 128,
            updates: 1024,
            checkpoint_every: 50,
            stagger_first_episodes: 0,
            rollout: RolloutChoice::Auto,
        }
    }
}

/// A whole training config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Seed of the env draws, the network initialisation, the exploration noise and the minibatch order.
    #[serde(default)]
    pub seed: u64,
    /// The env plugin and its settings.
    pub env: EnvConfig,
    /// The learner.
    #[serde(default)]
    pub ppo: PpoConfig,
    /// Size and schedule.
    #[serde(default)]
    pub train: TrainSection,
}

impl TrainConfig {
    /// Reads `path`, applies `key=value` overrides (dotted keys, TOML values; a bare word is a string), checks.
    pub fn load(path: &Path, sets: &[String]) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| RlError::io(path, e))?;
        Self::from_str_with(&text, &path.display().to_string(), sets)
    }

    /// As [`load`](Self::load) from a string; `file` names it in errors.
    pub fn from_str_with(text: &str, file: &str, sets: &[String]) -> Result<Self> {
        let mut value: toml::Value =
            toml::from_str(text).map_err(|e| RlError::Config { file: file.into(), reason: e.to_string() })?;
        for set in sets {
            apply_set(&mut value, set)?;
        }
        let env_value = value
            .get("env")
            .cloned()
            .ok_or_else(|| RlError::Config { file: file.into(), reason: "no [env] table".into() })?;
        // The env table first, so an unknown env key or type gets the env registry's message.
        EnvConfig::from_toml(env_value)
            .map_err(|e| RlError::Config { file: file.into(), reason: format!("[env]: {e}") })?;
        let cfg: TrainConfig = value
            .try_into()
            .map_err(|e: toml::de::Error| RlError::Config { file: file.into(), reason: e.to_string() })?;
        cfg.check()?;
        Ok(cfg)
    }

    /// Checks values serde cannot.
    pub fn check(&self) -> Result<()> {
        let bad = |field: &str, reason: String| Err(RlError::InvalidValue { field: field.into(), reason });
        let p = &self.ppo;
        if p.horizon == 0 {
            return bad("ppo.horizon", "must be at least 1".into());
        }
        if self.train.env_count == 0 {
            return bad("train.env_count", "must be at least 1".into());
        }
        if p.minibatch_size == 0 || p.minibatch_size > p.horizon * self.train.env_count {
            return bad(
                "ppo.minibatch_size",
                format!(
                    "{} must be in 1..={} (ppo.horizon * train.env_count)",
                    p.minibatch_size,
                    p.horizon * self.train.env_count
                ),
            );
        }
        if p.epochs == 0 {
            return bad("ppo.epochs", "must be at least 1".into());
        }
        if !(p.learning_rate.is_finite() && p.learning_rate > 0.0) {
            return bad("ppo.learning_rate", format!("{} is not a finite number > 0", p.learning_rate));
        }
        for (field, v, lo, hi) in [("ppo.gamma", p.gamma, 0.0, 1.0), ("ppo.gae_lambda", p.gae_lambda, 0.0, 1.0)] {
            if !(v >= lo && v <= hi) {
                return bad(field, format!("{v} is outside [{lo}, {hi}]"));
            }
        }
        for (field, v) in [
            ("ppo.clip_ratio", p.clip_ratio),
            ("ppo.critic_coef", p.critic_coef),
            ("ppo.entropy_coef", p.entropy_coef),
            ("ppo.bounds_loss_coef", p.bounds_loss_coef),
            ("ppo.max_grad_norm", p.max_grad_norm),
            ("ppo.observation_clip", p.observation_clip),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("{v} is not a finite number >= 0"));
            }
        }
        if p.hidden.is_empty() || p.hidden.contains(&0) {
            return bad("ppo.hidden", format!("{:?}: need at least one layer, each at least 1 wide", p.hidden));
        }
        if self.train.updates == 0 {
            return bad("train.updates", "must be at least 1".into());
        }
        if self.train.checkpoint_every == 0 {
            return bad("train.checkpoint_every", "must be at least 1".into());
        }
        Ok(())
    }

    /// The resolved config as TOML (saved in the run folder).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a TrainConfig always serialises")
    }
}

/// `env` with `env.key=value` overrides applied (factory-eval's `--set`: evaluate a policy on, say, the
/// paper's Table III reset ranges); keys outside `env.` are refused by name, and the result is checked as a
/// config's `[env]` is.
pub fn env_with_sets(env: &EnvConfig, sets: &[String]) -> Result<EnvConfig> {
    let mut root = toml::Value::Table(Default::default());
    let table =
        toml::Value::try_from(env).map_err(|e| RlError::Config { file: "env".into(), reason: e.to_string() })?;
    root.as_table_mut().expect("a table").insert("env".into(), table);
    for set in sets {
        if !set.trim_start().starts_with("env.") {
            return Err(RlError::Config {
                file: format!("--set {set}"),
                reason: "only env.* keys can be set here (the policy fixes the rest)".into(),
            });
        }
        apply_set(&mut root, set)?;
    }
    let env = root.get("env").cloned().expect("set above");
    EnvConfig::from_toml(env).map_err(|e| RlError::Config { file: "--set".into(), reason: format!("[env]: {e}") })
}

/// Applies one `a.b.c=value` override to a TOML tree.
fn apply_set(root: &mut toml::Value, set: &str) -> Result<()> {
    let err = |reason: String| RlError::Config { file: format!("--set {set}"), reason };
    let (key, raw) = set.split_once('=').ok_or_else(|| err("expected key=value".into()))?;
    let key = key.trim();
    // A TOML value if it parses as one (numbers, booleans, arrays, quoted strings), else a bare string.
    let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(raw.trim().to_owned()));
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(err(format!("`{key}` is not a dotted key")));
    }
    let mut node = root;
    for p in &parts[..parts.len() - 1] {
        let table = node.as_table_mut().ok_or_else(|| err(format!("`{p}` is not a table")))?;
        node = table.entry(p.to_string()).or_insert_with(|| toml::Value::Table(Default::default()));
    }
    let table = node.as_table_mut().ok_or_else(|| err(format!("`{key}`'s parent is not a table")))?;
    table.insert(parts[parts.len() - 1].to_string(), value);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str = "[env]\ntype = \"point_mass\"\n";

    #[test]
    fn defaults_are_table_ix() {
        let c = TrainConfig::from_str_with(MIN, "t.toml", &[]).unwrap();
        assert_eq!(c.ppo.hidden, vec![256, 128, 64]);
        assert_eq!((c.ppo.learning_rate, c.ppo.gamma, c.ppo.gae_lambda, c.ppo.clip_ratio), (1e-4, 0.99, 0.95, 0.2));
        assert_eq!((c.ppo.critic_coef, c.ppo.entropy_coef, c.ppo.minibatch_size, c.ppo.epochs), (2.0, 0.0, 512, 8));
    }

    /// Every config the project ships parses and checks (a renamed or removed key breaks here, not in a
    /// user's run), and a bad `solve` is refused naming its valid values.
    #[test]
    fn shipped_configs_load() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                TrainConfig::load(&path, &[]).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                n += 1;
            }
        }
        assert!(n >= 3, "only {n} configs in {}", dir.display());
        let e = TrainConfig::load(&dir.join("screw.toml"), &["env.solve=gpu".into()]).unwrap_err().to_string();
        assert!(e.contains("gpu") && e.contains("device"), "{e}");
    }

    #[test]
    fn unknown_key_is_named_with_valid_ones() {
        let e = TrainConfig::from_str_with(&format!("{MIN}[ppo]\nhorizn = 3\n"), "t.toml", &[]).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("t.toml") && s.contains("horizn") && s.contains("horizon"), "{s}");
        let e = TrainConfig::from_str_with(&format!("{MIN}dt2 = 1\n"), "t.toml", &["env.dt2=1".into()]).unwrap_err();
        assert!(e.to_string().contains("dt2"), "{e}");
    }

    #[test]
    fn wrong_type_is_named() {
        let e = TrainConfig::from_str_with(&format!("{MIN}[ppo]\nhorizon = \"long\"\n"), "t.toml", &[]).unwrap_err();
        assert!(e.to_string().contains("horizon"), "{e}");
    }

    #[test]
    fn set_overrides_and_checks() {
        let c = TrainConfig::from_str_with(MIN, "t.toml", &["ppo.horizon=16".into(), "ppo.device=cpu".into()]).unwrap();
        assert_eq!(c.ppo.horizon, 16);
        assert_eq!(c.ppo.device, DeviceChoice::Cpu);
        let e = TrainConfig::from_str_with(MIN, "t.toml", &["ppo.minibatch_size=100000".into()]).unwrap_err();
        assert!(e.to_string().contains("ppo.minibatch_size"), "{e}");
    }

    #[test]
    fn env_sets_apply_to_the_env_only() {
        let cfg = TrainConfig::from_str_with(MIN, "t", &[]).unwrap();
        let sets = ["env.max_episode_steps=7".to_string()];
        let env = env_with_sets(&cfg.env, &sets).unwrap();
        let EnvConfig::PointMass(c) = &env else { panic!("{env:?}") };
        assert_eq!(c.max_episode_steps, 7);
        let e = env_with_sets(&cfg.env, &["ppo.horizon=3".into()]).unwrap_err().to_string();
        assert!(e.contains("ppo.horizon") && e.contains("env."), "{e}");
        let e = env_with_sets(&cfg.env, &["env.max_episode_step=3".into()]).unwrap_err().to_string();
        assert!(e.contains("max_episode_step"), "{e}");
    }

    #[test]
    fn resolved_config_round_trips() {
        let c = TrainConfig::from_str_with(MIN, "t.toml", &["train.env_count=17".into()]).unwrap();
        let back = TrainConfig::from_str_with(&c.to_toml(), "resolved.toml", &[]).unwrap();
        assert_eq!(c, back);
    }
}
