//! Run folders: `runs/<config-stem>/<UTC timestamp>/` holding `config.toml` (the resolved config),
//! `checkpoint.bin`, `policy.json`, `provenance.json` (where the policy came from), `metrics.csv` and
//! TensorBoard event files under `tb/`.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Result, RlError};
use crate::train::{Trainer, UpdateReport};

/// The checkpoint inside a run folder.
pub fn checkpoint_path(run: &Path) -> PathBuf {
    run.join("checkpoint.bin")
}

/// The exported policy inside a run folder.
pub fn policy_path(run: &Path) -> PathBuf {
    run.join("policy.json")
}

/// Where a run's policy came from, rewritten with every export: copied with `policy.json` and
/// `config.toml` into `policies/`, it lets anyone re-run the training and check the file.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Provenance {
    /// SHA-256 of `policy.json`'s bytes (hex).
    pub policy_sha256: String,
    /// The seed of the run (the resolved config is `config.toml` beside this file).
    pub seed: u64,
    /// Updates and env steps trained.
    pub updates: usize,
    /// Env steps trained.
    pub env_steps: u64,
    /// Training wall time summed over the run's sessions [s].
    pub training_seconds: f64,
    /// Each build that trained the run (`git describe --always --dirty` at build time) and the update its
    /// session started from, in order; a resume with the same build adds nothing.
    pub builds: Vec<(String, usize)>,
    /// The CPU the last session ran on (`/proc/cpuinfo`'s model name and the core count; `unknown`
    /// elsewhere).
    pub machine: String,
}

/// The provenance file inside a run folder.
pub fn provenance_path(run: &Path) -> PathBuf {
    run.join("provenance.json")
}

/// This machine's CPU model and logical core count.
fn machine() -> String {
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{model}, {cores} cores")
}

/// Rewrites `run`'s provenance after the policy was exported (`policy_sha256`: the hash of the file written):
/// the trainer's seed and counts, this build appended to the builds when it differs from the last
/// (`session_start`: the update this session started from).
pub fn write_provenance(run: &Path, policy_sha256: &str, trainer: &Trainer, session_start: usize) -> Result<()> {
    let path = provenance_path(run);
    let mut builds = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str::<Provenance>(&t).ok())
        .map(|p| p.builds)
        .unwrap_or_default();
    let commit = env!("FACTORY_BUILD_COMMIT");
    if builds.last().is_none_or(|(c, _)| c != commit) {
        builds.push((commit.to_string(), session_start));
    }
    let p = Provenance {
        policy_sha256: policy_sha256.to_string(),
        seed: trainer.cfg.seed,
        updates: trainer.updates_done,
        env_steps: trainer.env_steps,
        training_seconds: trainer.wall_seconds,
        builds,
        machine: machine(),
    };
    let text = serde_json::to_string_pretty(&p).map_err(|e| RlError::io(&path, std::io::Error::other(e)))?;
    crate::checkpoint::write_atomic(&path, text.as_bytes())
}

/// `YYYYmmdd-HHMMSS` in UTC for a Unix time (Howard Hinnant's days-to-civil algorithm).
pub fn utc_stamp(unix_seconds: u64) -> String {
    let days = (unix_seconds / 86_400) as i64;
    let secs = unix_seconds % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + (m <= 2) as i64;
    format!("{y:04}{m:02}{d:02}-{:02}{:02}{:02}", secs / 3600, secs / 60 % 60, secs % 60)
}

/// The CSV columns of `metrics.csv`. The last three hold space-separated lists: `ended_by` as
/// `cause=count`, `stage_seconds` as `stage=seconds` ([`UpdateReport::stage_seconds`]) and `progress_steps`
/// as ten counts, one per tenth of task progress (empty for an env without progress).
pub const CSV_HEADER: &str = "update,env_steps,wall_seconds,success_rate,mean_return,episodes,actor_loss,critic_loss,bounds_loss,mean_reward,sigma,rollout_seconds,learn_seconds,ended_by,stage_seconds,progress_steps";

/// Appends per-update rows to `metrics.csv`.
pub struct MetricsCsv {
    file: std::fs::File,
    path: PathBuf,
}

impl MetricsCsv {
    /// Opens `run/metrics.csv`, keeping only rows up to update `keep_through` (a resumed run drops the rows
    /// written after its checkpoint, which it is about to redo).
    pub fn open(run: &Path, keep_through: usize) -> Result<Self> {
        let path = run.join("metrics.csv");
        let old = std::fs::read_to_string(&path).unwrap_or_default();
        let mut kept = String::from(CSV_HEADER);
        kept.push('\n');
        for line in old.lines().skip(1) {
            let update: Option<usize> = line.split(',').next().and_then(|u| u.parse().ok());
            if update.is_some_and(|u| u <= keep_through) {
                kept.push_str(line);
                kept.push('\n');
            }
        }
        crate::checkpoint::write_atomic(&path, kept.as_bytes())?;
        let file = std::fs::OpenOptions::new().append(true).open(&path).map_err(|e| RlError::io(&path, e))?;
        Ok(Self { file, path })
    }

    /// Appends one update's row.
    pub fn row(&mut self, r: &UpdateReport, wall_seconds: f64) -> Result<()> {
        let s = &r.stats;
        writeln!(
            self.file,
            "{},{},{:.3},{},{},{},{},{},{},{},{},{:.4},{:.4},{},{},{}",
            r.update,
            r.env_steps,
            wall_seconds,
            r.success_rate,
            r.mean_return,
            r.episodes,
            s.actor_loss,
            s.critic_loss,
            s.bounds_loss,
            s.mean_reward,
            s.sigma,
            r.rollout_seconds,
            r.learn_seconds,
            r.ended_by.summary(),
            r.stage_seconds.iter().map(|(k, v)| format!("{k}={v:.4}")).collect::<Vec<_>>().join(" "),
            r.progress_steps.iter().map(|c| c.to_string()).collect::<Vec<_>>().join(" "),
        )
        .and_then(|_| self.file.flush())
        .map_err(|e| RlError::io(&self.path, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_stamps() {
        assert_eq!(utc_stamp(0), "19700101-000000");
        // 2026-12-04 05:28:58 UTC.
        assert_eq!(utc_stamp(1_796_362_138), "20261204-052858");
        assert_eq!(utc_stamp(951_782_400), "20000229-000000");
    }
}
