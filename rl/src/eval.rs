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
    /// Print a line to stderr each time another sixteenth of the episodes has ended (episodes, seated, how
    /// they ended so far): a long evaluation shows where it is, and an interrupted one leaves its counts.
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
    let report_every = episodes.div_ceil(16).max(1);
    let spec = env.spec().clone();
    if let Some(t) = steps.as_deref_mut() {
        t.names = spec.observation_names.clone();
        t.names.extend(spec.action_names.iter().map(|a| format!("action_{a}")));
        t.names.extend(["reward", "terminated", "truncated", "success"].map(String::from));
    }
    let (n, d, a_dim) = (spec.env_count, spec.observation_dim(), spec.action_dim());
    let mut buf = StepBuffers::new(&spec);
    env.reset(&mut buf);
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
        let done_before = done;
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
        if progress && done / report_every > done_before / report_every {
            eprintln!("eval: {done} of {episodes} episodes, {succ} seated; ended: {}", ended_by.summary());
        }
    }
    EvalReport {
        episodes: done,
        stochastic: noise_seed.is_some(),
        success_rate: succ as f64 / done as f64,
        mean_steps_to_success: if succ > 0 { steps_succ as f64 / succ as f64 } else { f64::NAN },
        mean_return: ret_sum / done as f64,
        mean_joint_torque_norm: if torque_count > 0 { torque_sum / torque_count as f64 } else { f64::NAN },
        ended_by,
        identical_starts,
    }
}
