//! `factory-eval --policy RUN_DIR/policy.json`: runs an exported policy (its mean action; `--stochastic`
//! samples with its sigma, as training does) and reports the columns of the paper's Tables IV and X-XII
//! (success rate with its 95% Wilson interval, mean env steps to success) in the env's own outcome words, or
//! as one JSON object with `--json` (with every episode's outcome and the report's provenance: command,
//! build commit, policy hash, seed, env config). `--baseline zero|constant|untrained|scripted` runs a
//! baseline over the same episodes instead (factory_rl::baseline). The env is rebuilt from the policy
//! file's own env config, or from `--config`'s `[env]` (refused, showing both specs, if it does not match
//! what the policy was trained on). The flags are `factory-eval --help` (docs/CLI.md).

use anyhow::{Context, Result};
use burn::tensor::Device;
use clap::Parser;
use factory_rl::baseline::{self, Baseline};
use factory_rl::checkpoint::PolicyFile;
use factory_rl::cli::EvalArgs;
use factory_rl::eval::{evaluate_actor, Actor, EvalOptions, EvalReport, Provenance, Trace};
use factory_rl::TrainConfig;

/// The constant baseline's action: `--constant`, or the best of the sweep (returned with the sweep).
fn constant_action(
    args: &EvalArgs,
    env_cfg: &factory_envs::EnvConfig,
    action_dim: usize,
    device: &Device,
) -> Result<(Vec<f32>, Vec<baseline::SweepPoint>)> {
    if let Some(text) = &args.constant {
        return Ok((baseline::parse_constant(text, action_dim)?, Vec::new()));
    }
    let candidates = baseline::constant_candidates(action_dim);
    if !args.json {
        eprintln!(
            "constant baseline: sweeping {} actions, {} episodes each (seed {})",
            candidates.len(),
            args.sweep_episodes,
            args.seed
        );
    }
    let mut env = factory_envs::build(env_cfg, candidates.len(), args.seed).context("building the sweep's env")?;
    let points = baseline::sweep_constants(env.as_mut(), &candidates, args.sweep_episodes, device, true)?;
    let best = baseline::best_point(&points).expect("the sweep has candidates").action.clone();
    Ok((best, points))
}

fn main() -> Result<()> {
    let args = EvalArgs::parse();
    let (policy, policy_sha256) = PolicyFile::load_hashed(&args.policy)?;
    let env_cfg = match &args.config {
        Some(c) => TrainConfig::load(c, &[])?.env,
        None => policy.env_config.clone(),
    };
    let env_cfg = factory_rl::config::env_with_sets(&env_cfg, &args.sets)?;
    let mut env = factory_envs::build(&env_cfg, args.envs, args.seed).context("building the env")?;
    policy.check_spec(env.spec(), &args.policy)?;
    let device = Device::flex();
    let baseline = if args.constant.is_some() { Some(Baseline::Constant) } else { args.baseline };
    let a_dim = env.spec().action_dim();
    let (model, norm) = match baseline {
        Some(Baseline::Untrained) => {
            (Some(baseline::untrained_model(&policy, args.seed, &device)), policy.normalizer(&device))
        }
        None => {
            let (model, norm) = policy.build(&device, &args.policy)?;
            (Some(model), norm)
        }
        _ => (None, None),
    };
    let (constant, sweep) = match baseline {
        Some(Baseline::Constant) => constant_action(&args, &env_cfg, a_dim, &device)?,
        _ => (Vec::new(), Vec::new()),
    };
    let fixed: Vec<f32> = match baseline {
        Some(Baseline::Zero) => vec![0.0; args.envs * a_dim],
        Some(Baseline::Constant) => constant.iter().copied().cycle().take(args.envs * a_dim).collect(),
        _ => Vec::new(),
    };
    let actor = match (baseline, &model) {
        (Some(Baseline::Scripted), _) => Actor::Scripted,
        (Some(Baseline::Zero | Baseline::Constant), _) => Actor::Fixed(&fixed),
        (_, Some(model)) => Actor::Policy { model, norm: norm.as_ref(), clip: policy.observation_clip },
        (_, None) => unreachable!("a network is built for the policy and the untrained baseline"),
    };
    let (mut trace, mut steps) = (Trace::default(), Trace::default());
    let opts = EvalOptions {
        noise_seed: args.stochastic.then_some(args.seed),
        forces: args.forces_csv.as_ref().map(|_| &mut trace),
        steps: args.steps_csv.as_ref().map(|_| &mut steps),
        progress: true,
    };
    let mut report: EvalReport = evaluate_actor(env.as_mut(), actor, args.episodes, &device, opts)?;
    report.actor = baseline.map_or("policy", Baseline::name).into();
    report.constant_action = constant;
    report.constant_sweep = sweep;
    report.provenance = Some(Provenance {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        commit: env!("FACTORY_BUILD_COMMIT").into(),
        policy: args.policy.display().to_string(),
        policy_sha256,
        seed: args.seed,
        envs: args.envs,
        env_config: env_cfg.clone(),
    });
    if let Some(path) = &args.forces_csv {
        factory_rl::checkpoint::write_atomic(path, trace.to_csv().as_bytes())?;
    }
    if let Some(path) = &args.steps_csv {
        factory_rl::checkpoint::write_atomic(path, steps.to_csv().as_bytes())?;
    }
    if report.identical_starts && !report.stochastic && args.envs > 1 && !args.json {
        eprintln!(
            "note: every world started from the same observation and acts deterministically, so every episode \
             is the same one (the env has no reset randomisation); --stochastic samples a network's actions as \
             training does"
        );
    }
    if args.stochastic && !args.json && baseline.is_some_and(|b| b != Baseline::Untrained) {
        eprintln!("note: --stochastic samples a network's actions only; this baseline acts deterministically");
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
