//! The baselines a learned policy's success rate stands beside (`factory-eval --baseline`), each in the
//! policy's raw action space, so that a rate shows what was learned and not what the env gives away:
//!
//! - `zero`: the zero action at every step. It is not "doing nothing" in every env: with the Screw task's
//!   unidirectional yaw a zero action already turns the nut at half rate.
//! - `constant`: the best constant action of a small sweep ([`constant_candidates`]: zero, and each action
//!   entry alone at -1, -0.5, 0.5 and 1), chosen by successes and then mean return over a few episodes per
//!   candidate, all candidates side by side in one batch ([`sweep_constants`]); the chosen action is then
//!   evaluated like any other actor. `--constant` names one and skips the sweep.
//! - `untrained`: the network a training run with the same seed starts from ([`crate::ppo::initial_model`]:
//!   the policy file's hidden widths, the default initial log-std), fed observations normalised with the
//!   policy's statistics, so it differs from the policy in its weights alone.
//! - `scripted`: the env's hand-written controller ([`factory_envs::Env::scripted_actions`]), the reference an
//!   engineer would write; it is not a bar the policy must clear to count as learned (the paper's tasks are
//!   scriptable), but it shows what the physics allows.

use burn::prelude::*;

use crate::checkpoint::PolicyFile;
use crate::eval::{evaluate_actor, Actor, EvalOptions};
use crate::model::ActorCritic;
use crate::Result;

/// `factory-eval --baseline`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Baseline {
    /// The zero action.
    Zero,
    /// The best constant action of a small sweep (or `--constant`).
    Constant,
    /// A freshly initialised network.
    Untrained,
    /// The env's scripted controller.
    Scripted,
}

impl Baseline {
    /// The name a report records (`zero`, `constant`, `untrained`, `scripted`).
    pub fn name(self) -> &'static str {
        match self {
            Baseline::Zero => "zero",
            Baseline::Constant => "constant",
            Baseline::Untrained => "untrained",
            Baseline::Scripted => "scripted",
        }
    }
}

/// The values each action entry takes alone in the constant sweep.
pub const SWEEP_VALUES: [f32; 4] = [-1.0, -0.5, 0.5, 1.0];

/// The constant sweep's candidates: the zero action first, then each entry alone at each of
/// [`SWEEP_VALUES`] (1 + 4 x action_dim actions).
pub fn constant_candidates(action_dim: usize) -> Vec<Vec<f32>> {
    let mut out = vec![vec![0.0; action_dim]];
    for k in 0..action_dim {
        for v in SWEEP_VALUES {
            let mut a = vec![0.0; action_dim];
            a[k] = v;
            out.push(a);
        }
    }
    out
}

/// One candidate of the constant sweep and how it did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SweepPoint {
    /// The action (raw action space).
    pub action: Vec<f32>,
    /// Episodes it ran.
    pub episodes: usize,
    /// Episodes that ended in success.
    pub successes: usize,
    /// Mean undiscounted return.
    pub mean_return: f64,
}

/// Runs every candidate side by side in `env` (world `w` takes candidate `w % candidates.len()`; the env's
/// world count must be a multiple of the candidates'), `episodes_per_world` consecutive episodes a world,
/// and returns how each did, in the candidates' order.
pub fn sweep_constants(
    env: &mut dyn factory_envs::Env,
    candidates: &[Vec<f32>],
    episodes_per_world: usize,
    device: &Device,
    progress: bool,
) -> Result<Vec<SweepPoint>> {
    let (n, a_dim) = (env.spec().env_count, env.spec().action_dim());
    let k = candidates.len();
    if k == 0 || n % k != 0 || candidates.iter().any(|c| c.len() != a_dim) {
        return Err(crate::RlError::InvalidValue {
            field: "constant sweep".into(),
            reason: format!("{k} candidates of {a_dim} entries cannot share {n} worlds evenly"),
        });
    }
    let actions: Vec<f32> = (0..n).flat_map(|w| candidates[w % k].iter().copied()).collect();
    let opts = EvalOptions { progress, ..Default::default() };
    let report = evaluate_actor(env, Actor::Fixed(&actions), n * episodes_per_world, device, opts)?;
    let mut points: Vec<SweepPoint> = candidates
        .iter()
        .map(|a| SweepPoint { action: a.clone(), episodes: 0, successes: 0, mean_return: 0.0 })
        .collect();
    for r in &report.episode_records {
        let p = &mut points[r.world % k];
        p.episodes += 1;
        p.successes += (r.ended_by == "success") as usize;
        p.mean_return += r.ret;
    }
    for p in &mut points {
        p.mean_return /= p.episodes.max(1) as f64;
    }
    Ok(points)
}

/// The sweep's best point: most successes, then the highest mean return, then the earlier candidate.
pub fn best_point(points: &[SweepPoint]) -> Option<&SweepPoint> {
    points.iter().reduce(|best, p| {
        let better =
            p.successes > best.successes || (p.successes == best.successes && p.mean_return > best.mean_return);
        if better {
            p
        } else {
            best
        }
    })
}

/// The `untrained` baseline's network for `policy`'s spec and widths, drawn from `seed` as a training run
/// with that seed starts.
pub fn untrained_model(policy: &PolicyFile, seed: u64, device: &Device) -> ActorCritic {
    let cfg = crate::PpoConfig { hidden: policy.hidden.clone(), ..Default::default() };
    crate::ppo::initial_model(&cfg, policy.observation_names.len(), policy.action_names.len(), seed, device).0
}

/// Parses `--constant`'s comma-separated action, `action_dim` entries each in [-1, 1].
pub fn parse_constant(text: &str, action_dim: usize) -> Result<Vec<f32>> {
    let bad = |reason: String| crate::RlError::InvalidValue { field: "--constant".into(), reason };
    let values: Vec<f32> = text
        .split(',')
        .map(|x| x.trim().parse::<f32>().map_err(|e| bad(format!("`{x}` is not a number ({e})"))))
        .collect::<Result<_>>()?;
    if values.len() != action_dim {
        return Err(bad(format!("{} entries, the policy's action has {action_dim}", values.len())));
    }
    if let Some(v) = values.iter().find(|v| !(-1.0..=1.0).contains(*v)) {
        return Err(bad(format!("{v} is outside the raw action range [-1, 1]")));
    }
    Ok(values)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_are_zero_then_each_entry_alone() {
        let c = constant_candidates(2);
        assert_eq!(c.len(), 9);
        assert_eq!(c[0], vec![0.0, 0.0]);
        assert_eq!(c[1], vec![-1.0, 0.0]);
        assert_eq!(c[8], vec![0.0, 1.0]);
        assert!(c[1..].iter().all(|a| a.iter().filter(|x| **x != 0.0).count() == 1));
    }

    #[test]
    fn best_point_takes_successes_then_return_then_the_first() {
        let p = |s: usize, r: f64| SweepPoint {
            action: vec![s as f32, r as f32],
            episodes: 4,
            successes: s,
            mean_return: r,
        };
        let pts = [p(1, -5.0), p(3, -9.0), p(3, -2.0), p(3, -2.0), p(0, 10.0)];
        assert_eq!(best_point(&pts).unwrap(), &pts[2]);
        assert!(best_point(&[]).is_none());
    }

    #[test]
    fn parse_constant_names_what_is_wrong() {
        assert_eq!(parse_constant("0, -0.5", 2).unwrap(), vec![0.0, -0.5]);
        let e = parse_constant("0,x", 2).unwrap_err().to_string();
        assert!(e.contains("--constant") && e.contains("`x`"), "{e}");
        let e = parse_constant("0", 2).unwrap_err().to_string();
        assert!(e.contains("1 entries") && e.contains("has 2"), "{e}");
        let e = parse_constant("0,1.5", 2).unwrap_err().to_string();
        assert!(e.contains("1.5") && e.contains("[-1, 1]"), "{e}");
    }
}
