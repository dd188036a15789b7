//! `factory-eval --policy RUN_DIR/policy.json`: runs an exported policy (its mean action; `--stochastic`
//! samples with its sigma, as training does) and reports the columns of the paper's Tables IV and X-XII
//! (success rate, mean env steps to success) in the env's own outcome words, or as one JSON object with
//! `--json`. The env is rebuilt from the policy file's own env config, or from `--config`'s `[env]`
//! (refused, showing both specs, if it does not match what the policy was trained on). The flags are
//! `factory-eval --help` (docs/CLI.md).

use anyhow::{Context, Result};
use clap::Parser;
use factory_rl::checkpoint::PolicyFile;
use factory_rl::cli::EvalArgs;
use factory_rl::eval::{evaluate, EvalOptions, Trace};
use factory_rl::TrainConfig;

fn main() -> Result<()> {
    let args = EvalArgs::parse();
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
        print!("{}", report.summary(&policy.env, args.envs));
        for (what, path) in [("forces", &args.forces_csv), ("steps", &args.steps_csv)] {
            if let Some(p) = path {
                println!("  wrote {what} {}", p.display());
            }
        }
    }
    Ok(())
}
