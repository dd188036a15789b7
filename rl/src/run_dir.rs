//! Run folders: `runs/<config-stem>/<UTC timestamp>/` holding `config.toml` (the resolved config),
//! `checkpoint.bin`, `policy.json`, `metrics.csv` and TensorBoard event files under `tb/`.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Result, RlError};
use crate::train::UpdateReport;

/// The checkpoint inside a run folder.
pub fn checkpoint_path(run: &Path) -> PathBuf {
    run.join("checkpoint.bin")
}

/// The exported policy inside a run folder.
pub fn policy_path(run: &Path) -> PathBuf {
    run.join("policy.json")
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
