//! factory-rl: PPO for factory-rs envs in burn 0.22 (the paper's Table IX), checkpoints and policy export,
//! and the `factory-train` / `factory-eval` binaries.

pub mod config;
pub mod error;
pub mod model;
pub mod normalizer;
pub mod ppo;

pub use config::{DeviceChoice, PpoConfig, RolloutChoice, TrainConfig};
pub use error::{Result, RlError};
pub use ppo::{EpisodeTracker, Ppo, UpdateStats};
pub mod baseline;
pub mod checkpoint;
pub mod cli;
pub mod eval;
pub mod plot;
pub mod run_dir;
pub mod session;
#[cfg(test)]
mod test_support;
pub mod train;
