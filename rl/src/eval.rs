//! Evaluating an exported policy: deterministic actions (the Gaussian's mean, as rl_games' player and the
//! paper's tables), or sampled ones (`noise_seed`: the policy as it acts in training, whose episodes the
//! trainer's success rate counts; the two can differ a lot). Each world contributes the
//! same number of consecutive episodes (`episodes / env_count`, the remainder spread over the first worlds),
//! so short episodes (often the successful ones) are not over-counted as they would be by taking the first
//! `episodes` to end.
//!
//! The same loop runs the baselines a success rate is judged against ([`Actor`]; `factory-eval --baseline`,
//! [`crate::baseline`]): fixed actions per world (the zero action, a constant one), the env's scripted
//! controller, or an untrained network. Every report carries its 95% Wilson score interval and each episode's
//! outcome, so two reports on the same episodes compare episode by episode.

use burn::prelude::*;
use factory_envs::{EndCauses, Env, StepBuffers};

use crate::error::{Result, RlError};
use crate::model::{to_vec, ActorCritic};
use crate::normalizer::RunningMeanStd;
use crate::ppo::normal_tensor;
use factory_engine::rng::SplitMix64;

/// What acts in an evaluation.
pub enum Actor<'a> {
    /// A network: its mean action, or sampled with its sigma ([`EvalOptions::noise_seed`]).
    Policy {
        /// The network.
        model: &'a ActorCritic,
        /// Its observation normaliser (None: raw observations).
        norm: Option<&'a RunningMeanStd>,
        /// The clamp of normalised observations.
        clip: f32,
    },
    /// The same action at every step, per world: shape [env_count * action_dim], in the raw action space.
    Fixed(&'a [f32]),
    /// The env's scripted controller ([`factory_envs::Env::scripted_actions`]).
    Scripted,
}

/// How one episode ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpisodeRecord {
    /// The world it ran in.
    pub world: usize,
    /// Its end cause (`success`, `time_limit` or the env's failure cause).
    pub ended_by: String,
    /// Its env steps.
    pub steps: u32,
    /// Its undiscounted return.
    #[serde(rename = "return")]
    pub ret: f64,
}

/// Where a report came from, so that anyone re-runs it and gets the same numbers.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Provenance {
    /// The command line.
    pub command: String,
    /// The commit the binary was built from (`git describe --always --dirty` at build time; `unknown`
    /// outside a git checkout).
    pub commit: String,
    /// The policy file.
    pub policy: String,
    /// SHA-256 of the policy file's bytes (hex).
    pub policy_sha256: String,
    /// The seed of the env's draws (and of sampled actions and the untrained network's weights).
    pub seed: u64,
    /// Worlds stepped together.
    pub envs: usize,
    /// The env's config as evaluated, overrides applied.
    pub env_config: factory_envs::EnvConfig,
}

/// The columns of the paper's Tables IV and X-XII that an env reports.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct EvalReport {
    /// What acted: `policy`, or a baseline (`zero`, `constant`, `untrained`, `scripted`).
    pub actor: String,
    /// The constant action of the `constant` baseline (raw action space; empty otherwise).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub constant_action: Vec<f32>,
    /// Episodes evaluated.
    pub episodes: usize,
    /// Whether actions were sampled (`mean + sigma * noise`) instead of the mean.
    pub stochastic: bool,
    /// Fraction that ended in success.
    pub success_rate: f64,
    /// The success rate's 95% Wilson score interval.
    pub success_interval_95: [f64; 2],
    /// Mean env steps of the successful episodes (NaN when none succeeded).
    pub mean_steps_to_success: f64,
    /// Mean undiscounted return.
    pub mean_return: f64,
    /// Mean norm of the commanded arm joint torques over every step of every world [N m] (NaN when the env
    /// does not measure it).
    pub mean_joint_torque_norm: f64,
    /// How the episodes ended (`success`, `time_limit`, the env's failure causes).
    pub ended_by: EndCauses,
    /// Every world's first observation was the same (an env without reset randomisation). With the mean
    /// action the physics then plays one episode in every world (a world's physics does not depend on the
    /// batch), so the success rate can only be 0 or 1 up to the resets' own draws.
    pub identical_starts: bool,
    /// World-steps of the evaluation by task progress tenth ([`factory_envs::EnvProfile::progress_steps`]),
    /// every world counted until the last episode ended; absent for an env that reports no progress.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub progress_steps: Vec<u64>,
    /// The `constant` baseline's sweep, every candidate (empty otherwise).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub constant_sweep: Vec<crate::baseline::SweepPoint>,
    /// Every episode, in the order they ended.
    pub episode_records: Vec<EpisodeRecord>,
    /// Where the report came from (set by `factory-eval`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub provenance: Option<Provenance>,
}

/// The 95% Wilson score interval of `successes` in `n` trials ([0, 1] when `n` is 0).
pub fn wilson_interval(successes: usize, n: usize) -> [f64; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    const Z: f64 = 1.959964;
    let (k, n) = (successes as f64, n as f64);
    let p = k / n;
    let den = 1.0 + Z * Z / n;
    let mid = (p + Z * Z / (2.0 * n)) / den;
    let half = Z * (p * (1.0 - p) / n + Z * Z / (4.0 * n * n)).sqrt() / den;
    [(mid - half).max(0.0), (mid + half).min(1.0)]
}

/// The actor's name in a summary's title.
fn actor_words(actor: &str, stochastic: bool) -> String {
    let how = if stochastic { "sampled" } else { "mean" };
    match actor {
        "policy" | "" => format!("{how} actions"),
        "untrained" => format!("untrained network, {how} actions"),
        "zero" => "baseline: zero action".into(),
        "constant" => "baseline: best constant action".into(),
        "scripted" => "baseline: scripted controller".into(),
        other => other.to_string(),
    }
}

impl EvalReport {
    /// The report for a person: a title naming the env and how it acted, then one line per figure the env
    /// defines. Outcomes are the env's own end causes (`success`, `time_limit`, its failure causes); the
    /// joint-torque line appears only for an env that measures it.
    pub fn summary(&self, env: &str, worlds: usize) -> String {
        let actions = actor_words(&self.actor, self.stochastic);
        let mut rows: Vec<(&str, String)> = Vec::new();
        let successes = self.ended_by.0.get("success").copied().unwrap_or(0);
        let [lo, hi] = self.success_interval_95;
        rows.push((
            "success",
            format!(
                "{:.1}% ({successes} of {}), 95% interval {:.1}-{:.1}%",
                100.0 * self.success_rate,
                self.episodes,
                100.0 * lo,
                100.0 * hi
            ),
        ));
        if !self.constant_action.is_empty() {
            let a: Vec<String> = self.constant_action.iter().map(|x| format!("{x}")).collect();
            rows.push(("action", format!("[{}]", a.join(", "))));
        }
        if self.mean_steps_to_success.is_finite() {
            rows.push(("steps to success", format!("{:.1} mean", self.mean_steps_to_success)));
        }
        rows.push(("mean return", format!("{:.3}", self.mean_return)));
        if self.mean_joint_torque_norm.is_finite() {
            rows.push(("joint torque", format!("{:.2} N m mean norm", self.mean_joint_torque_norm)));
        }
        let ended: Vec<String> = self.ended_by.0.iter().map(|(cause, n)| format!("{cause} {n}")).collect();
        rows.push(("ended by", ended.join(", ")));
        let width = rows.iter().map(|(l, _)| l.len()).max().unwrap_or(0);
        let mut s = format!("{env} ({actions}): {} episodes over {worlds} worlds\n", self.episodes);
        for (label, value) in rows {
            s.push_str(&format!("  {label:<width$}  {value}\n"));
        }
        s
    }
}

/// How many of the episodes have ended, shown on stderr ([`EvalOptions::progress`]).
enum Progress {
    /// A bar on a terminal.
    Bar(indicatif::ProgressBar),
    /// A line each time another `every` episodes have ended, for logs.
    Lines { episodes: usize, every: usize, shown: std::cell::Cell<usize> },
}

impl Progress {
    fn new(episodes: usize) -> Self {
        use std::io::IsTerminal;
        if std::io::stderr().is_terminal() {
            let bar = indicatif::ProgressBar::new(episodes as u64);
            bar.set_style(
                indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} episodes  {msg}")
                    .expect("valid template")
                    .progress_chars("=> "),
            );
            Progress::Bar(bar)
        } else {
            Progress::Lines { episodes, every: episodes.div_ceil(16).max(1), shown: Default::default() }
        }
    }

    /// `done` episodes have ended, as `ended_by` counts them.
    fn update(&self, done: usize, ended_by: &EndCauses) {
        match self {
            Progress::Bar(bar) => {
                bar.set_position(done as u64);
                bar.set_message(ended_by.summary());
            }
            Progress::Lines { episodes, every, shown } => {
                if done / every > shown.get() / every {
                    shown.set(done);
                    eprintln!("eval: {done} of {episodes} episodes; ended: {}", ended_by.summary());
                }
            }
        }
    }

    fn finish(self) {
        if let Progress::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// Named values of world 0 at every evaluation step: its contact-force norms (the data of the paper's Fig.
/// S17) or its observation, action, reward and flags (what the policy saw and did).
#[derive(Clone, Debug, Default)]
pub struct Trace {
    /// Column names after `step` (`left_finger`, `bolt`, ...; `nut_pos_m_z`, `action_drot_z`, ...).
    pub names: Vec<String>,
    /// One row per step, in `names`' order.
    pub rows: Vec<Vec<f32>>,
}

/// What [`evaluate`] does besides the report.
#[derive(Debug, Default)]
pub struct EvalOptions<'a> {
    /// Sample actions with the policy's sigma, the noise drawn from this seed (None: the mean action).
    pub noise_seed: Option<u64>,
    /// Fills world 0's contact-force norms [N] per step (envs that measure them).
    pub forces: Option<&'a mut Trace>,
    /// Fills world 0's observation (the step's input), action (clipped to [-1, 1]), reward and
    /// terminated / truncated / success flags per step.
    pub steps: Option<&'a mut Trace>,
    /// Show the episodes that have ended and how (the env's end causes) on stderr: a progress bar on a
    /// terminal, else a line each time another sixteenth has ended, so that a log shows where a long
    /// evaluation is and an interrupted one leaves its counts.
    pub progress: bool,
}

impl Trace {
    /// The trace as CSV (`step,name,...`).
    pub fn to_csv(&self) -> String {
        let mut s = format!("step,{}\n", self.names.join(","));
        for (i, r) in self.rows.iter().enumerate() {
            let cols: Vec<String> = r.iter().map(|x| x.to_string()).collect();
            s.push_str(&format!("{i},{}\n", cols.join(",")));
        }
        s
    }
}

/// Runs `env` with the policy until every world has ended its quota of episodes: the mean action, or
/// actions sampled with the policy's sigma (`opts.noise_seed`).
pub fn evaluate(
    env: &mut dyn Env,
    model: &ActorCritic,
    norm: Option<&RunningMeanStd>,
    clip: f32,
    episodes: usize,
    device: &Device,
    opts: EvalOptions<'_>,
) -> EvalReport {
    evaluate_actor(env, Actor::Policy { model, norm, clip }, episodes, device, opts).expect("a network always acts")
}

/// The actions of `actor` for the observations in `buf`, clipped to [-1, 1]; `noise` samples a network's.
fn act(
    actor: &Actor<'_>,
    env: &dyn Env,
    obs: &[f32],
    noise: Option<&mut (SplitMix64, Tensor<2>)>,
    device: &Device,
) -> Result<Vec<f32>> {
    let spec = env.spec();
    let (n, d, a_dim) = (spec.env_count, spec.observation_dim(), spec.action_dim());
    let raw = match actor {
        Actor::Policy { model, norm, clip } => {
            let o = Tensor::<1>::from_floats(obs, device).reshape([n, d]);
            let o = match norm {
                Some(nm) => nm.normalize(o, Some(*clip)),
                None => o,
            };
            let (mu, _) = model.forward(o);
            let mu = match noise {
                Some((rng, std)) => mu + normal_tensor(rng, n, a_dim, device) * std.clone(),
                None => mu,
            };
            return Ok(to_vec(mu.clamp(-1.0, 1.0)));
        }
        Actor::Fixed(a) => a.to_vec(),
        Actor::Scripted => env.scripted_actions().ok_or_else(|| RlError::InvalidValue {
            field: "--baseline".into(),
            reason: format!("env `{}` has no scripted controller", spec.name),
        })?,
    };
    if raw.len() != n * a_dim {
        return Err(RlError::InvalidValue {
            field: "--baseline".into(),
            reason: format!("{} actions for {n} worlds x {a_dim} action entries", raw.len()),
        });
    }
    Ok(raw.into_iter().map(|x| x.clamp(-1.0, 1.0)).collect())
}

/// Runs `env` with `actor` until every world has ended its quota of episodes. Sampling
/// (`opts.noise_seed`) applies to a network only. Fails only for a scripted actor on an env without a
/// script, or fixed actions of the wrong length.
pub fn evaluate_actor(
    env: &mut dyn Env,
    actor: Actor<'_>,
    episodes: usize,
    device: &Device,
    opts: EvalOptions<'_>,
) -> Result<EvalReport> {
    let EvalOptions { noise_seed, mut forces, mut steps, progress } = opts;
    let noise_seed = if let Actor::Policy { .. } = actor { noise_seed } else { None };
    let bar = progress.then(|| Progress::new(episodes));
    let spec = env.spec().clone();
    if let Some(t) = steps.as_deref_mut() {
        t.names = spec.observation_names.clone();
        t.names.extend(spec.action_names.iter().map(|a| format!("action_{a}")));
        t.names.extend(["reward", "terminated", "truncated", "success"].map(String::from));
    }
    let (n, d, a_dim) = (spec.env_count, spec.observation_dim(), spec.action_dim());
    let mut buf = StepBuffers::new(&spec);
    env.reset(&mut buf);
    let profile_before = env.profile();
    let identical_starts = buf.observation.chunks(d).all(|o| o == &buf.observation[..d]);
    let mut ret = vec![0.0f64; n];
    let mut len = vec![0u32; n];
    let quota: Vec<usize> = (0..n).map(|w| episodes / n + (w < episodes % n) as usize).collect();
    let mut ended = vec![0usize; n];
    let (mut done, mut succ, mut steps_succ, mut ret_sum) = (0usize, 0usize, 0u64, 0.0f64);
    let (mut torque_sum, mut torque_count) = (0.0f64, 0u64);
    let mut ended_by = EndCauses::default();
    let mut noise = match (&actor, noise_seed) {
        (Actor::Policy { model, .. }, Some(seed)) => {
            Some((SplitMix64(seed), model.log_std.val().exp().unsqueeze_dim::<2>(0)))
        }
        _ => None,
    };
    let mut records = Vec::with_capacity(episodes);
    while done < episodes {
        let action = act(&actor, &*env, &buf.observation, noise.as_mut(), device)?;
        let row = steps.is_some().then(|| [&buf.observation[..d], &action[..a_dim]].concat());
        env.step(&action, &mut buf);
        if let (Some(t), Some(mut r)) = (steps.as_deref_mut(), row) {
            r.extend([buf.reward[0], buf.terminated[0], buf.truncated[0], buf.success[0]]);
            t.rows.push(r);
        }
        if let Some(d) = env.diagnostics() {
            torque_sum += d.joint_torque_norm.iter().map(|&t| t as f64).sum::<f64>();
            torque_count += d.joint_torque_norm.len() as u64;
            if let Some(trace) = forces.as_deref_mut() {
                if trace.names.is_empty() {
                    trace.names = d.contact_force_norms.iter().map(|(n, _)| n.clone()).collect();
                }
                trace.rows.push(d.contact_force_norms.iter().map(|(_, v)| v[0]).collect());
            }
        }
        for w in 0..n {
            ret[w] += buf.reward[w] as f64;
            len[w] += 1;
            if buf.done(w) {
                if ended[w] < quota[w] {
                    ended[w] += 1;
                    done += 1;
                    ended_by.record(&buf, w);
                    let cause = buf.end_cause(w).unwrap_or("unknown").to_string();
                    records.push(EpisodeRecord { world: w, ended_by: cause, steps: len[w], ret: ret[w] });
                    ret_sum += ret[w];
                    if buf.success[w] != 0.0 {
                        succ += 1;
                        steps_succ += len[w] as u64;
                    }
                }
                ret[w] = 0.0;
                len[w] = 0;
            }
        }
        if let Some(b) = &bar {
            b.update(done, &ended_by);
        }
    }
    if let Some(b) = bar {
        b.finish();
    }
    let progress_steps = match (env.profile(), profile_before) {
        (Some(a), Some(b)) => a.progress_steps.iter().zip(&b.progress_steps).map(|(x, y)| x - y).collect(),
        _ => Vec::new(),
    };
    let actor_name = match actor {
        Actor::Policy { .. } => "policy",
        Actor::Fixed(_) => "fixed",
        Actor::Scripted => "scripted",
    };
    Ok(EvalReport {
        actor: actor_name.into(),
        constant_action: Vec::new(),
        episodes: done,
        stochastic: noise_seed.is_some(),
        success_rate: succ as f64 / done as f64,
        success_interval_95: wilson_interval(succ, done),
        mean_steps_to_success: if succ > 0 { steps_succ as f64 / succ as f64 } else { f64::NAN },
        mean_return: ret_sum / done as f64,
        mean_joint_torque_norm: if torque_count > 0 { torque_sum / torque_count as f64 } else { f64::NAN },
        ended_by,
        identical_starts,
        progress_steps,
        constant_sweep: Vec::new(),
        episode_records: records,
        provenance: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(torque: f64) -> EvalReport {
        let mut ended_by = EndCauses::default();
        ended_by.add("success", 3);
        ended_by.add("time_limit", 1);
        EvalReport {
            episodes: 4,
            success_rate: 0.75,
            mean_steps_to_success: 12.0,
            mean_return: 1.5,
            mean_joint_torque_norm: torque,
            success_interval_95: wilson_interval(3, 4),
            ended_by,
            ..Default::default()
        }
    }

    #[test]
    fn summary_names_only_what_the_env_defines() {
        let s = report(f64::NAN).summary("point_mass", 2);
        assert_eq!(
            s,
            "point_mass (mean actions): 4 episodes over 2 worlds\n  success           75.0% (3 of 4), 95% interval \
             30.1-95.4%\n  steps to success  12.0 mean\n  mean return       1.500\n  ended by          success 3, time_limit 1\n"
        );
        assert!(!s.contains("torque") && !s.contains("NaN"), "{s}");
        let s = report(4.25).summary("franka_nut_bolt", 2);
        assert!(s.contains("joint torque      4.25 N m mean norm"), "{s}");
    }

    #[test]
    fn summary_leaves_out_steps_to_success_when_none_succeeded() {
        let r = EvalReport { success_rate: 0.0, mean_steps_to_success: f64::NAN, ..report(f64::NAN) };
        assert!(!r.summary("point_mass", 1).contains("steps to success"));
    }
}
