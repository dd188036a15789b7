//! `factory-train --config configs/screw.toml`: PPO training with a progress bar, metrics.csv and
//! TensorBoard event files in the run folder, atomic checkpoints every `train.checkpoint_every` updates,
//! Ctrl-C (or SIGTERM, SIGHUP) saving and exiting cleanly, the final policy exported to `policy.json` and a
//! short summary at the end. The flags are `factory-train --help` (docs/CLI.md).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{bail, Context, Result};
use clap::Parser;
use factory_rl::cli::TrainArgs;
use factory_rl::run_dir::{checkpoint_path, policy_path, utc_stamp};
use factory_rl::session::{run_session, Progress};
use factory_rl::train::{resolve_device, Trainer};
use factory_rl::TrainConfig;

fn main() -> Result<()> {
    let args = TrainArgs::parse();
    let (mut trainer, run) = match &args.resume {
        Some(run) => resume(&args, run)?,
        None => start(&args)?,
    };
    let stop = stop_on_signal()?;
    let progress = if args.json { Progress::Json } else { Progress::Bar };
    let s = run_session(&mut trainer, &run, progress, &stop)?;
    if s.interrupted {
        eprintln!(
            "interrupted at update {}: saved; continue with  factory-train --resume {}",
            trainer.updates_done,
            run.display()
        );
    } else {
        eprintln!(
            "done: {} updates, {} env steps in {:.1} s; policy {}",
            trainer.updates_done,
            trainer.env_steps,
            trainer.wall_seconds,
            policy_path(&run).display()
        );
    }
    if !args.json {
        let rows = [
            ("speed", s.speed_line()),
            ("episodes", s.episodes.clone()),
            ("run folder", run.display().to_string()),
            ("evaluate", format!("factory-eval --policy {}", policy_path(&run).display())),
            ("plot", format!("factory-plot --metrics {} --out curve.svg", run.join("metrics.csv").display())),
        ];
        for (label, value) in rows {
            eprintln!("  {label:<12}  {value}");
        }
    }
    Ok(())
}

/// The trainer and run folder of `--resume RUN_DIR` (only `--updates` may change).
fn resume(args: &TrainArgs, run: &Path) -> Result<(Trainer, PathBuf)> {
    if args.config.is_some() || !args.sets.is_empty() || args.seed.is_some() || args.envs.is_some() {
        bail!("--resume continues the run with its saved config; only --updates may change");
    }
    let ck = checkpoint_path(run);
    let mut name = String::new();
    let mut t = Trainer::resume_on(&ck, |cfg| {
        let (device, n) = resolve_device(cfg.ppo.device)?;
        name = n;
        Ok(device)
    })
    .with_context(|| format!("resuming {}", run.display()))?;
    if let Some(u) = args.updates {
        t.cfg.train.updates = u;
    }
    eprintln!("resuming {} at update {} on {name}; env on {}", run.display(), t.updates_done, t.run.place());
    Ok((t, run.to_path_buf()))
}

/// The config a run without `--config` trains: a few Screw updates on 4 worlds, the whole loop (simulator,
/// controller, learner, checkpoints) in a few minutes on a CPU.
const DEFAULT_CONFIG: &str = include_str!("../../../configs/screw_quick.toml");
/// How errors and the run name refer to [`DEFAULT_CONFIG`].
const DEFAULT_CONFIG_NAME: &str = "configs/screw_quick.toml (built in)";

/// A new trainer from `--config` and the overrides, and its new run folder.
fn start(args: &TrainArgs) -> Result<(Trainer, PathBuf)> {
    let mut sets = args.sets.clone();
    if let Some(s) = args.seed {
        sets.push(format!("seed={s}"));
    }
    if let Some(n) = args.envs {
        sets.push(format!("train.env_count={n}"));
    }
    if let Some(u) = args.updates {
        sets.push(format!("train.updates={u}"));
    }
    let (cfg, stem) = match &args.config {
        Some(config) => {
            let stem = config.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or("run".into());
            (TrainConfig::load(config, &sets)?, stem)
        }
        None => {
            eprintln!("no --config: the built-in short Screw run, {DEFAULT_CONFIG_NAME}");
            (TrainConfig::from_str_with(DEFAULT_CONFIG, DEFAULT_CONFIG_NAME, &sets)?, "screw_quick".to_string())
        }
    };
    let run = match &args.run_dir {
        Some(d) => d.clone(),
        None => {
            let now = SystemTime::now().duration_since(UNIX_EPOCH)?.as_secs();
            Path::new("runs").join(stem).join(utc_stamp(now))
        }
    };
    if checkpoint_path(&run).exists() {
        bail!("{} already holds a run; continue it with --resume {0}", run.display());
    }
    std::fs::create_dir_all(&run).with_context(|| format!("creating {}", run.display()))?;
    let (device, name) = resolve_device(cfg.ppo.device)?;
    let t = Trainer::new(cfg, device)?;
    eprintln!("run {} on {name}; env on {}", run.display(), t.run.place());
    Ok((t, run))
}

/// Ctrl-C, and SIGTERM / SIGHUP (a cluster's scheduler preempting the job, a closed terminal): the flag the
/// loop reads to finish the update, save and exit. A second signal exits at once; the last checkpoint is
/// whole (atomic).
fn stop_on_signal() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            eprintln!("second interrupt: exiting now; the last checkpoint is kept");
            std::process::exit(130);
        }
        eprintln!("interrupt: saving after this update (again to exit now)");
    })
    .context("installing the Ctrl-C / SIGTERM handler")?;
    Ok(stop)
}
