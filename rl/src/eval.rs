//! Evaluating an exported policy: deterministic actions (the Gaussian's mean, as rl_games' player and the
//! paper's tables), or sampled ones (`noise_seed`: the policy as it acts in training, whose episodes the
//! trainer's success rate counts; the two can differ a lot). Each world contributes the
//! same number of consecutive episodes (`episodes / env_count`, the remainder spread over the first worlds),
//! so short episodes (often the successful ones) are not over-counted as they would be by taking the first
//! `episodes` to end.

use burn::prelude::*;
use factory_envs::{EndCauses, Env, StepBuffers};

use crate::model::{to_vec, ActorCritic};
use crate::normalizer::RunningMeanStd;
use crate::ppo::normal_tensor;
use factory_engine::rng::SplitMix64;

/// The columns of the paper's Tables IV and X-XII that an env reports.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct EvalReport {
    /// Episodes evaluated.
    pub episodes: usize,
    /// Whether actions were sampled (`mean + sigma * noise`) instead of the mean.
    pub stochastic: bool,
    /// Fraction that ended in success.
    pub success_rate: f64,
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
}

impl EvalReport {
    /// The report for a person: a title naming the env and how it acted, then one line per figure the env
    /// defines. Outcomes are the env's own end causes (`success`, `time_limit`, its failure causes); the
    /// joint-torque line appears only for an env that measures it.
    pub fn summary(&self, env: &str, worlds: usize) -> String {
        let actions = if self.stochastic { "sampled" } else { "mean" };
        let mut rows: Vec<(&str, String)> = Vec::new();
        let successes = self.ended_by.0.get("success").copied().unwrap_or(0);
        rows.push(("success", format!("{:.1}% ({successes} of {})", 100.0 * self.success_rate, self.episodes)));
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
        let mut s = format!("{env} ({actions} actions): {} episodes over {worlds} worlds\n", self.episodes);
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
    let EvalOptions { noise_seed, mut forces, mut steps, progress } = opts;
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
    let mut noise = noise_seed.map(|seed| (SplitMix64(seed), model.log_std.val().exp().unsqueeze_dim::<2>(0)));
    while done < episodes {
        let o = Tensor::<1>::from_floats(buf.observation.as_slice(), device).reshape([n, d]);
        let o = match norm {
            Some(nm) => nm.normalize(o, Some(clip)),
            None => o,
        };
        let (mu, _) = model.forward(o);
        let mu = match noise.as_mut() {
            Some((rng, std)) => mu + normal_tensor(rng, n, a_dim, device) * std.clone(),
            None => mu,
        };
        let action = to_vec(mu.clamp(-1.0, 1.0));
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
    EvalReport {
        episodes: done,
        stochastic: noise_seed.is_some(),
        success_rate: succ as f64 / done as f64,
        mean_steps_to_success: if succ > 0 { steps_succ as f64 / succ as f64 } else { f64::NAN },
        mean_return: ret_sum / done as f64,
        mean_joint_torque_norm: if torque_count > 0 { torque_sum / torque_count as f64 } else { f64::NAN },
        ended_by,
        identical_starts,
        progress_steps,
    }
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
            ended_by,
            ..Default::default()
        }
    }

    #[test]
    fn summary_names_only_what_the_env_defines() {
        let s = report(f64::NAN).summary("point_mass", 2);
        assert_eq!(
            s,
            "point_mass (mean actions): 4 episodes over 2 worlds\n  success           75.0% (3 of 4)\n  steps to \
             success  12.0 mean\n  mean return       1.500\n  ended by          success 3, time_limit 1\n"
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
