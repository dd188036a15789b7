//! A training session: what `factory-train` does between building (or resuming) a [`Trainer`] and printing
//! its summary. The resolved config goes to the run folder's `config.toml`, each update appends a row to
//! `metrics.csv` and scalars to the TensorBoard event files under `tb/`, and the checkpoint and the exported
//! policy are written (atomically) every `train.checkpoint_every` updates, at the last update and when the
//! session stops early. The stop flag is read between updates, so an interrupted session ends on a whole
//! update and resumes exactly (`factory-train --resume`).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use tensorboard_rs::summary_writer::SummaryWriter;

use crate::checkpoint::write_atomic;
use crate::run_dir::{checkpoint_path, policy_path, write_provenance, MetricsCsv};
use crate::train::{RecentEpisodes, Trainer, UpdateReport};
use crate::Result;

/// How a session reports while it runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Progress {
    /// Nothing on the terminal (tests, scripts that read the run folder).
    #[default]
    Quiet,
    /// A progress bar on stderr with the pace and the recent episodes.
    Bar,
    /// One JSON object per update on stdout.
    Json,
}

/// What a session did (this session only, not the run's earlier sessions).
#[derive(Clone, Debug)]
pub struct SessionSummary {
    /// The session stopped on the stop flag (after a whole update, saved).
    pub interrupted: bool,
    /// Updates done in this session.
    pub updates: usize,
    /// Env steps taken in this session.
    pub env_steps: u64,
    /// Wall time of this session [s].
    pub seconds: f64,
    /// How the last 50 updates' episodes ended, in words.
    pub episodes: String,
}

impl SessionSummary {
    /// `3330 env-steps/s (20 updates, 40960 env steps in 12.3 s this session)`.
    pub fn speed_line(&self) -> String {
        format!(
            "{:.0} env-steps/s ({} updates, {} env steps in {:.1} s this session)",
            self.env_steps as f64 / self.seconds.max(1e-9),
            self.updates,
            self.env_steps,
            self.seconds
        )
    }
}

/// Trains `trainer` to its `train.updates` in the run folder `run`, stopping early after the update during
/// which `stop` is set.
pub fn run_session(trainer: &mut Trainer, run: &Path, progress: Progress, stop: &AtomicBool) -> Result<SessionSummary> {
    write_atomic(&run.join("config.toml"), trainer.cfg.to_toml().as_bytes())?;
    let mut csv = MetricsCsv::open(run, trainer.updates_done)?;
    let mut tb = SummaryWriter::new(run.join("tb"));
    let total = trainer.cfg.train.updates;
    let bar = match progress {
        Progress::Bar => progress_bar(total, trainer.updates_done),
        Progress::Quiet | Progress::Json => ProgressBar::hidden(),
    };
    let every = trainer.cfg.train.checkpoint_every;
    let started = Instant::now();
    let (updates_at_start, steps_at_start) = (trainer.updates_done, trainer.env_steps);
    let mut interrupted = false;
    let mut recent = RecentEpisodes::new(50);
    while trainer.updates_done < total {
        let r = trainer.update();
        recent.push(&r);
        csv.row(&r, trainer.wall_seconds)?;
        let sps = (trainer.env_steps - steps_at_start) as f64 / started.elapsed().as_secs_f64();
        log_tensorboard(&mut tb, &r, sps);
        match progress {
            Progress::Json => println!("{}", serde_json::json!({"report": r, "env_steps_per_second": sps})),
            Progress::Bar => {
                bar.set_position(r.update as u64);
                bar.set_message(format!(
                    "{sps:.0} env-steps/s  reward {:.4}/step  {}",
                    r.stats.mean_reward,
                    recent.summary()
                ));
            }
            Progress::Quiet => {}
        }
        if r.update % every == 0 || r.update == total {
            save(trainer, run, &mut tb, updates_at_start)?;
        }
        if stop.load(Ordering::SeqCst) {
            interrupted = true;
            break;
        }
    }
    save(trainer, run, &mut tb, updates_at_start)?;
    bar.finish_and_clear();
    Ok(SessionSummary {
        interrupted,
        updates: trainer.updates_done - updates_at_start,
        env_steps: trainer.env_steps - steps_at_start,
        seconds: started.elapsed().as_secs_f64(),
        episodes: recent.summary(),
    })
}

/// The checkpoint, the policy and its provenance, each atomic, and the event files flushed
/// (`session_start`: the update this session started from).
fn save(trainer: &Trainer, run: &Path, tb: &mut SummaryWriter, session_start: usize) -> Result<()> {
    trainer.save_checkpoint(&checkpoint_path(run))?;
    let policy_sha256 = trainer.export_policy(&policy_path(run))?;
    write_provenance(run, &policy_sha256, trainer, session_start)?;
    tb.flush();
    Ok(())
}

/// The updates' progress bar on stderr, at `done` of `total`.
fn progress_bar(total: usize, done: usize) -> ProgressBar {
    let b = ProgressBar::new(total as u64);
    b.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} updates  {msg}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    b.set_position(done as u64);
    b
}

/// An update's figures as TensorBoard scalars (the non-finite ones left out).
fn log_tensorboard(tb: &mut SummaryWriter, r: &UpdateReport, sps: f64) {
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
}
