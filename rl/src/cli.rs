//! The command lines of `factory-train`, `factory-eval` and `factory-plot` (clap), here in the library so
//! that docs/CLI.md is generated from and checked against them (rl/tests/cli_doc.rs). The binaries in
//! src/bin/ parse these and run.

use std::path::PathBuf;

use clap::Parser;

use crate::baseline::Baseline;

// `factory-train`'s arguments (a doc comment here would become the command's about text).
#[derive(Parser, Debug)]
#[command(name = "factory-train", about = "Train a PPO policy on a factory-rs env")]
pub struct TrainArgs {
    /// The training config (TOML). Without it (and without --resume): a short built-in Screw run, the
    /// repository's configs/screw_quick.toml (4 worlds, 4 updates).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Override a config key, e.g. `--set ppo.horizon=64` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Seed (same as --set seed=S).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worlds stepped together (same as --set train.env_count=N).
    #[arg(long)]
    pub envs: Option<usize>,
    /// Total PPO updates (same as --set train.updates=N; with --resume, the new total).
    #[arg(long)]
    pub updates: Option<usize>,
    /// Continue the run in this folder from its checkpoint.
    #[arg(long, value_name = "RUN_DIR")]
    pub resume: Option<PathBuf>,
    /// Where the run goes (default runs/<config-stem>/<UTC timestamp>).
    #[arg(long, value_name = "DIR")]
    pub run_dir: Option<PathBuf>,
    /// One JSON object per update on stdout instead of the progress bar.
    #[arg(long)]
    pub json: bool,
}

// `factory-eval`'s arguments.
#[derive(Parser, Debug)]
#[command(name = "factory-eval", about = "Evaluate an exported factory-rs policy")]
pub struct EvalArgs {
    /// The policy file (policy.json in a run folder).
    #[arg(long)]
    pub policy: PathBuf,
    /// Episodes to evaluate.
    #[arg(long, default_value_t = 1024)]
    pub episodes: usize,
    /// Worlds stepped together.
    #[arg(long, default_value_t = 128)]
    pub envs: usize,
    /// Take the env from this training config instead of the policy file.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Override an env key, e.g. `--set 'env.randomize.hand_angle_deg=[-90, 90]'` (repeatable; env.* only).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Seed of the env's draws.
    #[arg(long, default_value_t = 12345)]
    pub seed: u64,
    /// Write world 0's per-step contact-force norms at the fingers, nut and bolt (CSV; envs that measure them).
    #[arg(long, value_name = "FILE")]
    pub forces_csv: Option<PathBuf>,
    /// Write world 0's observation, action, reward and done flags at every step (CSV, named columns).
    #[arg(long, value_name = "FILE")]
    pub steps_csv: Option<PathBuf>,
    /// Sample actions with the policy's sigma (noise drawn from --seed), as in training, instead of its
    /// mean (the default, as rl_games' player and the paper's tables).
    #[arg(long)]
    pub stochastic: bool,
    /// Evaluate a baseline over the same episodes instead of the policy (whose file still gives the env and
    /// its spec): the zero action, the best constant action of a small sweep, an untrained network, or the
    /// env's scripted controller.
    #[arg(long, value_enum)]
    pub baseline: Option<Baseline>,
    /// The constant baseline's action, comma-separated in the raw action space, instead of the sweep
    /// (implies `--baseline constant`).
    #[arg(long, value_name = "A,B,...")]
    pub constant: Option<String>,
    /// Episodes per candidate in the constant baseline's sweep (one world per candidate).
    #[arg(long, default_value_t = 4)]
    pub sweep_episodes: usize,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

// `factory-calibrate`'s arguments.
#[derive(Parser, Debug)]
#[command(
    name = "factory-calibrate",
    about = "Keep the stable Screw starts of a config's reset ranges (FrankaCalibrate, paper App. D3)"
)]
pub struct CalibrateArgs {
    /// The training config whose `[env]` (a `franka_nut_bolt` env) gives the ranges and the physics.
    #[arg(long)]
    pub config: PathBuf,
    /// Override a key, e.g. `--set 'env.randomize.hand_angle_deg=[-45, 45]'` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// The calibration file to write (JSON; an env reads it with `randomize.starts_file`).
    #[arg(long)]
    pub out: PathBuf,
    /// Worlds held together per round.
    #[arg(long, default_value_t = 64)]
    pub worlds: usize,
    /// Rounds of draws (worlds x rounds starts are tried).
    #[arg(long, default_value_t = 4)]
    pub rounds: usize,
    /// Seed of the draws.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// How long each start is held with zero actions [s].
    #[arg(long, default_value_t = 1.0)]
    pub hold_s: f32,
    /// The largest slip of the nut relative to the pads over the hold that is kept [mm].
    #[arg(long, default_value_t = 1.0)]
    pub max_slip_mm: f32,
}

// `factory-plot`'s arguments.
#[derive(Parser, Debug)]
#[command(name = "factory-plot", about = "Plot a factory-rs run's learning curve")]
pub struct PlotArgs {
    /// The run's metrics.csv.
    #[arg(long)]
    pub metrics: PathBuf,
    /// The SVG to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Average over windows of this many updates.
    #[arg(long, default_value_t = 8)]
    pub smooth: usize,
    /// Title (default: the metrics file's folder).
    #[arg(long)]
    pub title: Option<String>,
}
