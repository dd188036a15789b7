//! `factory-calibrate --config configs/screw_table_iii.toml --out starts.json`: FrankaCalibrate (paper App.
//! D3) for the Screw task. Draws starts from the config's reset ranges, holds each with zero actions and
//! keeps those where the nut stays put in the hand (factory_envs::franka::nut_bolt::calibrate), then writes
//! them to a versioned file that the env draws its resets from with `randomize.starts_file`. The flags are
//! `factory-calibrate --help` (docs/CLI.md).

use anyhow::{bail, Context, Result};
use clap::Parser;
use factory_envs::franka::nut_bolt::calibrate::calibrate;
use factory_envs::EnvConfig;
use factory_rl::cli::CalibrateArgs;
use factory_rl::TrainConfig;

fn main() -> Result<()> {
    let args = CalibrateArgs::parse();
    let cfg = TrainConfig::load(&args.config, &args.sets)?;
    let EnvConfig::FrankaNutBolt(env) = &cfg.env else {
        bail!("{}: [env] is `{}`; calibration needs a `franka_nut_bolt` env", args.config.display(), cfg.env.name());
    };
    if !(args.hold_s.is_finite() && args.hold_s > 0.0) {
        bail!("--hold-s {} is not a duration > 0 s", args.hold_s);
    }
    let hold_steps = (args.hold_s / env.dt).round().max(1.0) as u32;
    eprintln!(
        "calibrating {} starts ({} rounds of {} worlds), each held {hold_steps} steps ({} s)",
        args.rounds * args.worlds,
        args.rounds,
        args.worlds,
        args.hold_s
    );
    let file = calibrate(env, args.worlds, args.rounds, args.seed, hold_steps, args.max_slip_mm, |drawn, kept| {
        eprintln!("calibrate: {drawn} drawn, {kept} stable")
    })
    .context("calibrating")?;
    if file.starts.is_empty() {
        bail!("none of the {} starts held still; nothing written to {}", file.drawn, args.out.display());
    }
    file.save(&args.out)?;
    let mut slips: Vec<f32> = file.starts.iter().map(|s| s.slip_mm).collect();
    slips.sort_by(f32::total_cmp);
    let kept = file.starts.len();
    println!("{} of {} starts stable ({:.1}%)", kept, file.drawn, 100.0 * kept as f64 / file.drawn as f64);
    println!("  slip over the hold: median {:.3} mm, largest kept {:.3} mm", slips[kept / 2], slips[kept - 1]);
    let out = args.out.display();
    println!("  wrote {out}; an env draws from it with --set 'env.randomize.starts_file=\"{out}\"'");
    Ok(())
}
