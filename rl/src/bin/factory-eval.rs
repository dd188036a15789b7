//! `factory-eval --policy FILE [--episodes 1024] [--envs 128] [--config FILE] [--set env.KEY=VALUE]... [--seed S] [--stochastic]
//! [--forces-csv FILE] [--steps-csv FILE] [--json]`: runs an exported policy (its mean action; `--stochastic` samples with its sigma, as training
//! does) and reports the columns of the paper's Tables IV and X-XII (success
//! rate, mean env steps to success). The env is rebuilt from the policy file's own env config, or from
//! `--config`'s `[env]` (refused, showing both specs, if it does not match what the policy was trained on).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use factory_rl::checkpoint::PolicyFile;
use factory_rl::eval::{evaluate, EvalOptions, Trace};
use factory_rl::TrainConfig;

#[derive(Parser, Debug)]
#[command(name = "factory-eval", about = "Evaluate an exported factory-rs policy")]
struct Args {
    /// The policy file (policy.json in a run folder).
    #[arg(long)]
    policy: PathBuf,
    /// Episodes to evaluate.
    #[arg(long, default_value_t = 1024)]
    episodes: usize,
    /// Worlds stepped together.
    #[arg(long, default_value_t = 128)]
    envs: usize,
    /// Take the env from this training config instead of the policy file.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override an env key, e.g. `--set 'env.randomize.hand_angle_deg=[-90, 90]'` (repeatable; env.* only).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Seed of the env's draws.
    #[arg(long, default_value_t = 12345)]
    seed: u64,
    /// Write world 0's per-step contact-force norms at the fingers, nut and bolt (CSV; envs that measure them).
    #[arg(long, value_name = "FILE")]
    forces_csv: Option<PathBuf>,
    /// Write world 0's observation, action, reward and done flags at every step (CSV, named columns).
    #[arg(long, value_name = "FILE")]
    steps_csv: Option<PathBuf>,
    /// Sample actions with the policy's sigma (noise drawn from --seed), as in training, instead of its
    /// mean (the default, as rl_games' player and the paper's tables).
    #[arg(long)]
    stochastic: bool,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

fn main() -> Result<()> {
    let args = Args::parse();
    let policy = PolicyFile::load(&args.policy)?;
    let env_cfg = match &args.config {
        Some(c) => TrainConfig::load(c, &[])?.env,
        None => policy.env_config.clone(),
    };
    let env_cfg = factory_rl::config::env_with_sets(&env_cfg, &args.sets)?;
    let mut env = factory_envs::build(&env_cfg, args.envs, args.seed).context("building the env")?;
    policy.check_spec(env.spec(), &args.policy)?;
    let device = burn::tensor::Device::flex();
    let (model, norm) = policy.build(&device, &args.policy)?;
    let (mut trace, mut steps) = (Trace::default(), Trace::default());
    let report = evaluate(
        env.as_mut(),
        &model,
        norm.as_ref(),
        policy.observation_clip,
        args.episodes,
        &device,
        EvalOptions {
            noise_seed: args.stochastic.then_some(args.seed),
            forces: args.forces_csv.as_ref().map(|_| &mut trace),
            steps: args.steps_csv.as_ref().map(|_| &mut steps),
            progress: true,
        },
    );
    if let Some(path) = &args.forces_csv {
        factory_rl::checkpoint::write_atomic(path, trace.to_csv().as_bytes())?;
    }
    if let Some(path) = &args.steps_csv {
        factory_rl::checkpoint::write_atomic(path, steps.to_csv().as_bytes())?;
    }
    if report.identical_starts && !report.stochastic && args.envs > 1 && !args.json {
        eprintln!(
            "note: every world started from the same observation and acts with the policy's mean, so every \
             episode is the same one (the env has no reset randomisation); --stochastic samples actions as \
             training does"
        );
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!(
            "{} ({} actions): {} episodes, success {:.1}%, mean steps to success {:.1}, mean return {:.3}, mean joint torque \
             norm {:.2} N m; ended: {}",
            policy.env,
            if report.stochastic { "sampled" } else { "mean" },
            report.episodes,
            100.0 * report.success_rate,
            report.mean_steps_to_success,
            report.mean_return,
            report.mean_joint_torque_norm,
            report.ended_by.summary()
        );
    }
    Ok(())
}
