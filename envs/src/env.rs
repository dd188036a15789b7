//! The batched [`Env`] plugin trait and the buffers it fills.
//!
//! Semantics follow Gymnasium's vector envs (`gymnasium.vector.VectorEnv`, autoreset mode "same-step"):
//! every call to [`Env::step`] advances all `env_count` worlds by one control step and reports, per world, the
//! reward, whether the episode reached a terminal state (`terminated`: success or failure, no value beyond it)
//! or was cut by the time limit (`truncated`: the value beyond it is bootstrapped by the learner), and whether
//! it ended in success. A world whose episode ended is reset inside the same call (a masked reset: the others
//! are untouched), and the observation returned for it is the first of its new episode. This is what
//! IsaacGymEnvs does (`reset_buf` then `reset_idx` within `post_physics_step`), so a learner ported from it
//! needs no change: with `value_bootstrap` it adds `gamma * V(s_t)` to the reward of truncated steps.
//!
//! All buffers are flat, world-first, and `f32` (flags are 0.0 or 1.0) so they go to a tensor in one copy.

use serde::{Deserialize, Serialize};

use crate::error::{EnvError, Result};

/// What an env consumes and produces; fixed for its lifetime.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvSpec {
    /// The env's registered `type` name (`point_mass`, ...).
    pub name: String,
    /// Worlds stepped together (the batch axis).
    pub env_count: usize,
    /// One name per observation entry, in order (`goal_dx_m`, ...); its length is the observation size.
    pub observation_names: Vec<String>,
    /// One name per action entry, in order; its length is the action size. Actions are in [-1, 1] (values
    /// outside are clipped by the env).
    pub action_names: Vec<String>,
    /// Control steps after which an episode is truncated.
    pub max_episode_steps: u32,
}

impl EnvSpec {
    /// Entries per observation.
    pub fn observation_dim(&self) -> usize {
        self.observation_names.len()
    }

    /// Entries per action.
    pub fn action_dim(&self) -> usize {
        self.action_names.len()
    }
}

/// What one [`Env::step`] (or [`Env::reset`]) writes, for all worlds.
#[derive(Clone, Debug, Default)]
pub struct StepBuffers {
    /// Observations [units per `EnvSpec::observation_names`], shape [env_count * observation_dim]; for a world
    /// whose episode ended this step, the first observation of its next episode.
    pub observation: Vec<f32>,
    /// Rewards of this step, shape [env_count].
    pub reward: Vec<f32>,
    /// 1.0 where the episode reached a terminal state this step (success or failure), else 0.0; [env_count].
    pub terminated: Vec<f32>,
    /// 1.0 where the episode hit `max_episode_steps` this step without terminating, else 0.0; [env_count].
    pub truncated: Vec<f32>,
    /// 1.0 where the episode ended in success this step, else 0.0; [env_count].
    pub success: Vec<f32>,
    /// Why an episode that terminated without success ended this step (`slipped`, `diverged`, ...), where the
    /// env tells; None elsewhere (and where it does not); [env_count]. Host-side bookkeeping for logs and
    /// evaluation: the learner never reads it.
    pub failure: Vec<Option<&'static str>>,
}

impl StepBuffers {
    /// Zeroed buffers sized for `spec`.
    pub fn new(spec: &EnvSpec) -> Self {
        let n = spec.env_count;
        Self {
            observation: vec![0.0; n * spec.observation_dim()],
            reward: vec![0.0; n],
            terminated: vec![0.0; n],
            truncated: vec![0.0; n],
            success: vec![0.0; n],
            failure: vec![None; n],
        }
    }

    /// 1.0 where the episode ended this step for any reason.
    pub fn done(&self, world: usize) -> bool {
        self.terminated[world] != 0.0 || self.truncated[world] != 0.0
    }

    /// How `world`'s episode ended this step: `success`, `time_limit`, the env's failure cause, or `failure`
    /// where the env names none; None while it runs.
    pub fn end_cause(&self, world: usize) -> Option<&'static str> {
        if self.success[world] != 0.0 {
            Some("success")
        } else if self.terminated[world] != 0.0 {
            Some(self.failure[world].unwrap_or("failure"))
        } else if self.truncated[world] != 0.0 {
            Some("time_limit")
        } else {
            None
        }
    }
}

/// Episodes counted by how they ended ([`StepBuffers::end_cause`]), in name order.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct EndCauses(pub std::collections::BTreeMap<String, usize>);

impl EndCauses {
    /// Counts `world`'s episode if it ended this step.
    pub fn record(&mut self, buf: &StepBuffers, world: usize) {
        if let Some(c) = buf.end_cause(world) {
            self.add(c, 1);
        }
    }

    /// Counts `count` episodes that ended by `cause` (none: no entry).
    pub fn add(&mut self, cause: &str, count: usize) {
        if count > 0 {
            *self.0.entry(cause.to_string()).or_default() += count;
        }
    }

    /// Episodes counted, all causes.
    pub fn total(&self) -> usize {
        self.0.values().sum()
    }

    /// `name=count` pairs separated by spaces (`slipped=2 success=14`); empty when none ended.
    pub fn summary(&self) -> String {
        self.0.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(" ")
    }
}

/// Measurements of the last step per world, for evaluation (the paper's joint-torque column in Tables IV and
/// X-XII, and the contact forces of its Fig. S17). Taken before the step's resets.
#[derive(Clone, Debug, Default)]
pub struct StepDiagnostics {
    /// Norm of the commanded arm joint torques [N m], shape [env_count].
    pub joint_torque_norm: Vec<f32>,
    /// Contact-force norms [N] by name (`left_finger`, `bolt`, ...), each of shape [env_count].
    pub contact_force_norms: Vec<(String, Vec<f32>)>,
}

/// Tenths of task progress that [`EnvProfile::progress_steps`] counts world-steps in.
pub const PROGRESS_BINS: usize = 10;

/// Where a host env's stepping time goes and how far through their tasks its worlds are, summed over every
/// step since the env was built ([`Env::profile`]). The trainer reports it per update; the whole-run
/// training benchmark weighs its phases by the progress counts (docs/BENCHMARKS.md).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EnvProfile {
    /// Wall time of each stage of [`Env::step`] [s], by name (the Franka envs: `contacts`, `solve`,
    /// `controller`, `task`), summed over every step.
    pub stage_seconds: Vec<(&'static str, f64)>,
    /// World-steps by the world's task progress after the step (0 at the task's start, 1 at its end; Screw:
    /// the nut's descent from resting on the bolt's tip to seated): entry k counts progress in
    /// [k / 10, (k + 1) / 10), the last one including 1; shape [PROGRESS_BINS].
    pub progress_steps: [u64; PROGRESS_BINS],
    /// Work counted over every step, by name (the Franka envs: `candidates`, the query triangles within
    /// reach of an SDF that contact generation ran its descent on; `contacts`, the contacts the solver got
    /// after reduction), for the roofline of docs/BENCHMARKS.md. Empty where not counted (a device solve).
    pub work: Vec<(&'static str, u64)>,
}

impl EnvProfile {
    /// Adds `seconds` to stage `name` (a new stage goes last).
    pub fn add_seconds(&mut self, name: &'static str, seconds: f64) {
        match self.stage_seconds.iter_mut().find(|(n, _)| *n == name) {
            Some((_, s)) => *s += seconds,
            None => self.stage_seconds.push((name, seconds)),
        }
    }

    /// Adds `count` to work counter `name` (a new counter goes last).
    pub fn add_work(&mut self, name: &'static str, count: u64) {
        match self.work.iter_mut().find(|(n, _)| *n == name) {
            Some((_, c)) => *c += count,
            None => self.work.push((name, count)),
        }
    }

    /// Counts one world-step at `progress` (clamped to [0, 1]; NaN counts as 0).
    pub fn add_progress(&mut self, progress: f32) {
        let p = if progress.is_nan() { 0.0 } else { progress.clamp(0.0, 1.0) };
        let k = ((p * PROGRESS_BINS as f32) as usize).min(PROGRESS_BINS - 1);
        self.progress_steps[k] += 1;
    }
}

/// A batch of `env_count` worlds stepped together.
///
/// Implementations write into the caller's [`StepBuffers`] (sized by [`StepBuffers::new`]); stepping does not
/// fail (a diverging world is the env's to detect and end as a failure), building the env does.
pub trait Env: Send {
    /// The env's spec.
    fn spec(&self) -> &EnvSpec;

    /// Starts a new episode in every world and writes the observations (rewards and flags are zeroed).
    fn reset(&mut self, out: &mut StepBuffers);

    /// Applies `action` (shape [env_count * action_dim], clipped to [-1, 1]) for one control step, writes the
    /// step's results and resets the worlds whose episode ended (see the module docs).
    fn step(&mut self, action: &[f32], out: &mut StepBuffers);

    /// Hook: the last step's measurements (None, the default, when the env has none).
    fn diagnostics(&self) -> Option<StepDiagnostics> {
        None
    }

    /// Hook: the env's stage times and progress counts so far (None, the default, when it keeps none).
    fn profile(&self) -> Option<EnvProfile> {
        None
    }

    /// Hook: the controller an engineer would write by hand for the task, as actions for the current state
    /// in the policy's raw action space (shape [env_count * action_dim], in [-1, 1]): the `scripted` baseline
    /// that a learned policy is compared with. `None` (the default) when the env has none.
    fn scripted_actions(&self) -> Option<Vec<f32>> {
        None
    }

    /// Hook: the env's whole state (worlds, episode counters, generator) as bytes, so a checkpoint can resume
    /// exactly; `None` (the default) when the env cannot, and a resumed run then starts fresh episodes.
    fn save_state(&self) -> Option<Vec<u8>> {
        None
    }

    /// Hook: restores what [`save_state`](Self::save_state) wrote for an env of the same spec.
    fn load_state(&mut self, _bytes: &[u8]) -> Result<()> {
        Err(EnvError::InvalidValue {
            field: "state",
            reason: format!("env `{}` cannot restore a state", self.spec().name),
        })
    }

    /// Hook: sets each world's step count within its running episode (shape [env_count], each below
    /// `max_episode_steps`), so the episode is truncated `max_episode_steps - steps[w]` steps from now unless
    /// it ends sooner. The trainer uses it to start the worlds' episodes out of phase (rsl_rl's
    /// `init_at_random_ep_len`). The default refuses: the env keeps no such counter.
    fn set_episode_steps(&mut self, _steps: &[u32]) -> Result<()> {
        Err(EnvError::InvalidValue {
            field: "episode_steps",
            reason: format!("env `{}` cannot set its episodes' step counts", self.spec().name),
        })
    }

    /// Checks `action`'s length against the spec; the trainer calls this once before rolling out.
    fn check_action_len(&self, len: usize) -> Result<()> {
        let spec = self.spec();
        let expected = spec.env_count * spec.action_dim();
        if len != expected {
            return Err(EnvError::Shape { field: "action", len, expected });
        }
        Ok(())
    }
}

/// Appends `sections` to `out`, each as its length in bytes (u64, little-endian) then its bytes: the framing of
/// the envs' saved states ([`Env::save_state`]).
pub fn frame_sections(out: &mut Vec<u8>, sections: &[&[u8]]) {
    for s in sections {
        out.extend_from_slice(&(s.len() as u64).to_le_bytes());
        out.extend_from_slice(s);
    }
}

/// The first `count` sections [`frame_sections`] wrote at the start of `bytes`, and how many bytes they took;
/// None where `bytes` ends before them.
pub fn split_sections(bytes: &[u8], count: usize) -> Option<(Vec<&[u8]>, usize)> {
    let mut at = 0usize;
    let mut sections = Vec::with_capacity(count);
    for _ in 0..count {
        let len = u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().unwrap()) as usize;
        at += 8;
        sections.push(bytes.get(at..at.checked_add(len)?)?);
        at += len;
    }
    Some((sections, at))
}

/// Checks a [`Env::set_episode_steps`] argument against `spec`: one count per world, each below the limit.
pub fn check_episode_steps(spec: &EnvSpec, steps: &[u32]) -> Result<()> {
    if steps.len() != spec.env_count {
        return Err(EnvError::Shape { field: "episode_steps", len: steps.len(), expected: spec.env_count });
    }
    if let Some((w, s)) = steps.iter().enumerate().find(|(_, s)| **s >= spec.max_episode_steps) {
        return Err(EnvError::InvalidValue {
            field: "episode_steps",
            reason: format!("world {w}: {s} steps, valid: below max_episode_steps = {}", spec.max_episode_steps),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Progress lands in its tenth, 1 in the last, out-of-range values clamp, NaN counts as 0; stage times add
    /// up under their names in first-seen order.
    #[test]
    fn profile_bins_progress_by_tenths_and_sums_stages() {
        let mut p = EnvProfile::default();
        for x in [0.0, 0.05, 0.1, 0.55, 0.999, 1.0, 1.5, -0.2, f32::NAN] {
            p.add_progress(x);
        }
        assert_eq!(p.progress_steps, [4, 1, 0, 0, 0, 1, 0, 0, 0, 3]);
        p.add_seconds("contacts", 0.5);
        p.add_seconds("solve", 0.25);
        p.add_seconds("contacts", 0.5);
        assert_eq!(p.stage_seconds, vec![("contacts", 1.0), ("solve", 0.25)]);
    }
}
