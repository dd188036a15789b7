//! `factory-train --config configs/screw.toml [--set key=value]... [--seed S] [--envs N] [--updates N]
//! [--resume RUN_DIR] [--run-dir DIR] [--json]`: PPO training with a progress bar, metrics.csv and
//! TensorBoard event files in the run folder, atomic checkpoints every `train.checkpoint_every` updates,
//! Ctrl-C (or SIGTERM, SIGHUP) saving and exiting cleanly, and the final policy exported to `policy.json`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use anyhow::{bail, Context, Result};
use clap::Parser;
use factory_rl::run_dir::{checkpoint_path, policy_path, utc_stamp, MetricsCsv};
use factory_rl::train::{resolve_device, RecentEpisodes, Trainer};
use factory_rl::TrainConfig;
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Parser, Debug)]
#[command(name = "factory-train", about = "Train a PPO policy on a factory-rs env")]
struct Args {
    /// The training config (TOML). Not needed with --resume.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override a config key, e.g. `--set ppo.horizon=64` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Seed (same as --set seed=S).
    #[arg(long)]
    seed: Option<u64>,
    /// Worlds stepped together (same as --set train.env_count=N).
    #[arg(long)]
    envs: Option<usize>,
    /// Total PPO updates (same as --set train.updates=N; with --resume, the new total).
    #[arg(long)]
    updates: Option<usize>,
    /// Continue the run in this folder from its checkpoint.
    #[arg(long, value_name = "RUN_DIR")]
    resume: Option<PathBuf>,
    /// Where the run goes (default runs/<config-stem>/<UTC timestamp>).
    #[arg(long, value_name = "DIR")]
    run_dir: Option<PathBuf>,
    /// One JSON object per update on stdout instead of the progress bar.
    #[arg(long)]
    json: bool,
}

fn main() -> Result<()> {
    let args = Args::parse();
    let (mut trainer, run) = match &args.resume {
        Some(run) => {
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
            (t, run.clone())
        }
        None => {
            let Some(config) = &args.config else { bail!("give --config FILE (or --resume RUN_DIR)") };
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
            let cfg = TrainConfig::load(config, &sets)?;
            let run = match &args.run_dir {
                Some(d) => d.clone(),
                None => {
                    let stem = config.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or("run".into());
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
            (t, run)
        }
    };
    factory_rl::checkpoint::write_atomic(&run.join("config.toml"), trainer.cfg.to_toml().as_bytes())?;
    let mut csv = MetricsCsv::open(&run, trainer.updates_done)?;
    let mut tb = tensorboard_rs::summary_writer::SummaryWriter::new(run.join("tb"));

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // Ctrl-C, and SIGTERM / SIGHUP (a cluster's scheduler preempting the job, a closed terminal): finish
        // the update, save, exit. A second signal exits at once; the last checkpoint is whole (atomic).
        ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                eprintln!("second interrupt: exiting now; the last checkpoint is kept");
                std::process::exit(130);
            }
            eprintln!("interrupt: saving after this update (again to exit now)");
        })
        .context("installing the Ctrl-C / SIGTERM handler")?;
    }
    let total = trainer.cfg.train.updates;
    let bar = if args.json {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::new(total as u64);
        b.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} updates  {msg}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        b.set_position(trainer.updates_done as u64);
        b
    };
    let every = trainer.cfg.train.checkpoint_every;
    let started = Instant::now();
    let steps_at_start = trainer.env_steps;
    let mut interrupted = false;
    let mut recent = RecentEpisodes::new(50);
    while trainer.updates_done < total {
        let r = trainer.update();
        recent.push(&r);
        csv.row(&r, trainer.wall_seconds)?;
        let sps = (trainer.env_steps - steps_at_start) as f64 / started.elapsed().as_secs_f64();
        let step = r.update;
        for (tag, v) in [
            ("episode/success_rate", r.success_rate),
            ("episode/mean_return", r.mean_return),
            ("loss/actor", r.stats.actor_loss),
            ("loss/critic", r.stats.critic_loss),
            ("loss/bounds", r.stats.bounds_loss),
            ("policy/sigma", r.stats.sigma),
            ("perf/env_steps_per_second", sps as f32),
        ] {
            if v.is_finite() {
                tb.add_scalar(tag, v, step);
            }
        }
        for (cause, count) in &r.ended_by.0 {
            tb.add_scalar(&format!("episode/ended_{cause}"), *count as f32, step);
        }
        if args.json {
            println!("{}", serde_json::json!({"report": r, "env_steps_per_second": sps}));
        } else {
            bar.set_position(step as u64);
            bar.set_message(format!(
                "{sps:.0} env-steps/s  reward {:.4}/step  {}",
                r.stats.mean_reward,
                recent.summary()
            ));
        }
        if step % every == 0 || step == total {
            trainer.save_checkpoint(&checkpoint_path(&run))?;
            trainer.export_policy(&policy_path(&run))?;
            tb.flush();
        }
        if stop.load(Ordering::SeqCst) {
            interrupted = true;
            break;
        }
    }
    trainer.save_checkpoint(&checkpoint_path(&run))?;
    trainer.export_policy(&policy_path(&run))?;
    tb.flush();
    bar.finish_and_clear();
    if interrupted {
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
    Ok(())
}
