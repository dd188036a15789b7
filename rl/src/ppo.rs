//! Proximal policy optimisation (Schulman et al. 2017) as the paper trains Factory's policies (Table IX,
//! rl_games' `a2c_continuous`): clipped surrogate, clipped value loss weighted `0.5 * critic_coef`, bounds
//! loss on the action means, GAE (Schulman et al. 2016) with value bootstrap on truncation, running
//! observation and value normalisation, advantage normalisation over the rollout, Adam with a fixed rate.
//!
//! Data flow: the env writes one flat observation buffer per step; it becomes one tensor (one bulk copy), the
//! policy runs on the learner's device, the sampled actions come back in one copy for the env. Everything
//! else (the rollout buffer, GAE, losses) stays in tensors on the learner's device; the host reads back only
//! the per-update logging summary. Exploration noise and minibatch order come from the learner's own seeded
//! generator (drawn on the host and uploaded), so a run is reproducible and a resumed run continues exactly.

use burn::grad_clipping::GradientClippingConfig;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use factory_engine::rng::SplitMix64;
use factory_envs::{DeviceEnv, DeviceStep, EndCauses, Env, StepBuffers};

use crate::config::PpoConfig;
use crate::model::{to_vec, ActorCritic};
use crate::normalizer::RunningMeanStd;

const LN_2PI: f32 = 1.837_877_1;
/// rl_games' soft bound on action means for the bounds loss.
const SOFT_BOUND: f32 = 1.1;

/// Standard normal draws (Box-Muller on SplitMix64).
pub fn normal(rng: &mut SplitMix64, n: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(n + 1);
    while out.len() < n {
        let u1 = ((rng.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        let u2 = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        let r = (-2.0 * u1.ln()).sqrt();
        let t = std::f64::consts::TAU * u2;
        out.push((r * t.cos()) as f32);
        out.push((r * t.sin()) as f32);
    }
    out.truncate(n);
    out
}

/// A [rows, cols] tensor of [`normal`] draws on `device` (the exploration noise of a step's actions).
pub fn normal_tensor(rng: &mut SplitMix64, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    Tensor::<1>::from_floats(normal(rng, rows * cols).as_slice(), device).reshape([rows, cols])
}

/// Episode bookkeeping on the host (the env is stepped from the host, so its flags are already here).
#[derive(Clone, Debug, Default)]
pub struct EpisodeTracker {
    /// Undiscounted return of each world's running episode.
    pub running_return: Vec<f32>,
    /// Steps of each world's running episode.
    pub running_length: Vec<u32>,
    /// Episodes finished since the last [`take`](Self::take): (return, length, success).
    pub finished: Vec<(f32, u32, bool)>,
    /// How they ended.
    pub ended_by: EndCauses,
}

impl EpisodeTracker {
    /// For `env_count` worlds.
    pub fn new(env_count: usize) -> Self {
        Self {
            running_return: vec![0.0; env_count],
            running_length: vec![0; env_count],
            finished: Vec::new(),
            ended_by: EndCauses::default(),
        }
    }

    /// Records one step's results.
    pub fn record(&mut self, buf: &StepBuffers) {
        for w in 0..self.running_return.len() {
            self.running_return[w] += buf.reward[w];
            self.running_length[w] += 1;
            if buf.done(w) {
                self.finished.push((self.running_return[w], self.running_length[w], buf.success[w] != 0.0));
                self.ended_by.record(buf, w);
                self.running_return[w] = 0.0;
                self.running_length[w] = 0;
            }
        }
    }

    /// The episodes finished since the last call, and how they ended.
    pub fn take(&mut self) -> (Vec<(f32, u32, bool)>, EndCauses) {
        (std::mem::take(&mut self.finished), std::mem::take(&mut self.ended_by))
    }
}

/// Episode tallies of a device rollout, kept on the device and read with the update's summary.
#[derive(Clone, Debug)]
pub struct DeviceEpisodes {
    /// Undiscounted return of each world's running episode, [N].
    pub running_return: Tensor<1>,
    /// Steps of each world's running episode, [N].
    pub running_length: Tensor<1>,
    /// Since the last [`take`](Self::take): [episodes ended, succeeded, sum of their returns, sum of their
    /// lengths, truncated, then one count per failure cause the env names], [5 + causes].
    pub totals: Tensor<1>,
    /// Failure causes the env names ([`DeviceEnv::failure_causes`]).
    causes: usize,
}

impl DeviceEpisodes {
    /// For `env_count` worlds on `device`, an env that names no failure causes.
    pub fn new(env_count: usize, device: &Device) -> Self {
        Self::with_causes(env_count, 0, device)
    }

    /// For `env_count` worlds on `device`, counting each of `causes` failure causes apart.
    pub fn with_causes(env_count: usize, causes: usize, device: &Device) -> Self {
        Self {
            running_return: Tensor::zeros([env_count], device),
            running_length: Tensor::zeros([env_count], device),
            totals: Tensor::zeros([5 + causes], device),
            causes,
        }
    }

    /// Records one step's results (tensor ops only).
    pub fn record(&mut self, out: &DeviceStep) {
        let ret = self.running_return.clone() + out.reward.clone();
        let len = self.running_length.clone().add_scalar(1.0);
        let done = (out.terminated.clone() + out.truncated.clone()).clamp(0.0, 1.0);
        let mut counts = vec![
            done.clone().sum(),
            (out.success.clone() * done.clone()).sum(),
            (ret.clone() * done.clone()).sum(),
            (len.clone() * done.clone()).sum(),
            out.truncated.clone().sum(),
        ];
        for c in 1..=self.causes {
            counts.push(match &out.failure {
                Some(f) => f.clone().equal_elem(c as f32).float().sum(),
                None => Tensor::zeros([1], &done.device()),
            });
        }
        self.totals = self.totals.clone() + Tensor::cat(counts, 0);
        let keep = done.neg().add_scalar(1.0);
        self.running_return = ret * keep.clone();
        self.running_length = len * keep;
    }

    /// The totals since the last call (still on the device), and zeroes them.
    pub fn take(&mut self) -> Tensor<1> {
        let device = self.totals.device();
        std::mem::replace(&mut self.totals, Tensor::zeros([5 + self.causes], &device))
    }

    /// How the episodes of read-back [`totals`](Self::totals) ended: `success`, `time_limit`, each of the env's
    /// named `causes` (in the order of [`DeviceEnv::failure_causes`]) and, for any rest, `failure`.
    pub fn ended_by(totals: &[f32], causes: &[&str]) -> EndCauses {
        let (ended, succeeded, truncated) =
            (totals[0].round() as usize, totals[1].round() as usize, totals[4].round() as usize);
        let mut out = EndCauses::default();
        out.add("success", succeeded);
        out.add("time_limit", truncated);
        let mut named = 0;
        for (name, &count) in causes.iter().zip(totals.get(5..).unwrap_or(&[])) {
            out.add(name, count.round() as usize);
            named += count.round() as usize;
        }
        out.add("failure", ended.saturating_sub(succeeded + truncated + named));
        out
    }
}

/// What a rollout accumulates per step before it is stacked.
#[derive(Default)]
struct Steps {
    obs: Vec<Tensor<2>>,
    raw: Vec<Tensor<2>>,
    action: Vec<Tensor<2>>,
    logp: Vec<Tensor<1>>,
    value: Vec<Tensor<1>>,
    reward: Vec<Tensor<1>>,
    terminated: Vec<Tensor<1>>,
    truncated: Vec<Tensor<1>>,
}

/// One rollout on the learner's device: `horizon` steps of `env_count` worlds.
pub struct Rollout {
    /// Normalised observations as the policy saw them, [T, N, obs_dim].
    pub obs: Tensor<3>,
    /// Sampled (unclipped) actions, [T, N, action_dim].
    pub action: Tensor<3>,
    /// Log-probabilities of the actions, [T, N].
    pub logp: Tensor<2>,
    /// Value estimates in return units, [T, N].
    pub value: Tensor<2>,
    /// Rewards, [T, N].
    pub reward: Tensor<2>,
    /// Terminated flags, [T, N].
    pub terminated: Tensor<2>,
    /// Truncated flags, [T, N].
    pub truncated: Tensor<2>,
    /// Value of the observation after the last step, in return units, [N].
    pub last_value: Tensor<1>,
}

/// What one update reports (read back once per update).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct UpdateStats {
    /// Mean clipped-surrogate loss over the update's minibatches.
    pub actor_loss: f32,
    /// Mean value loss (normalised units).
    pub critic_loss: f32,
    /// Mean bounds loss.
    pub bounds_loss: f32,
    /// Mean reward per step in the rollout.
    pub mean_reward: f32,
    /// Mean policy standard deviation.
    pub sigma: f32,
}

/// The learner: network, optimizer, normalisers and generator.
pub struct Ppo {
    /// Hyperparameters.
    pub cfg: PpoConfig,
    /// Device for data (no autodiff).
    pub device: Device,
    /// The same device with autodiff, where the network trains.
    pub train_device: Device,
    /// The network (on `train_device`).
    pub model: ActorCritic,
    /// Adam.
    pub optim: ModuleOptimizer,
    /// Observation statistics.
    pub obs_norm: RunningMeanStd,
    /// Return statistics (value normalisation).
    pub value_norm: RunningMeanStd,
    /// Noise and minibatch order.
    pub rng: SplitMix64,
    /// Worlds per rollout.
    pub env_count: usize,
    /// Observation entries.
    pub obs_dim: usize,
    /// Action entries.
    pub action_dim: usize,
    /// Wall time of the host rollouts' acting so far [s]: the observation's upload, the forward pass and
    /// the action's readback (the `policy` stage of an update's report).
    pub act_seconds: f64,
}

/// The network a run with `seed` starts from, and the generator that then draws its noise: what the
/// learner trains, and the `untrained` baseline of `factory-eval`.
pub fn initial_model(
    cfg: &PpoConfig,
    obs_dim: usize,
    action_dim: usize,
    seed: u64,
    device: &Device,
) -> (ActorCritic, SplitMix64) {
    let mut rng = SplitMix64(seed ^ 0x5EED_0F_9A0);
    let model = ActorCritic::new(obs_dim, action_dim, &cfg.hidden, cfg.init_log_std, &mut rng, device);
    (model, rng)
}

impl Ppo {
    /// A fresh learner for an env of this shape; `seed` draws the weights and the noise.
    pub fn new(
        cfg: &PpoConfig,
        env_count: usize,
        obs_dim: usize,
        action_dim: usize,
        seed: u64,
        device: Device,
    ) -> Self {
        let train_device = device.clone().autodiff();
        let (model, rng) = initial_model(cfg, obs_dim, action_dim, seed, &train_device);
        let mut adam = AdamConfig::new().with_epsilon(1e-8);
        if cfg.max_grad_norm > 0.0 {
            adam = adam.with_grad_clipping(Some(GradientClippingConfig::Norm(cfg.max_grad_norm)));
        }
        Self {
            cfg: cfg.clone(),
            obs_norm: RunningMeanStd::new(obs_dim, &device),
            value_norm: RunningMeanStd::new(1, &device),
            device,
            train_device,
            model,
            optim: adam.init(),
            rng,
            env_count,
            obs_dim,
            action_dim,
            act_seconds: 0.0,
        }
    }

    fn normalize_obs(&self, obs: Tensor<2>) -> Tensor<2> {
        if self.cfg.normalize_observation {
            self.obs_norm.normalize(obs, Some(self.cfg.observation_clip))
        } else {
            obs
        }
    }

    fn value_to_returns(&self, v: Tensor<1>) -> Tensor<1> {
        if self.cfg.normalize_value {
            self.value_norm.denormalize_1d(v)
        } else {
            v
        }
    }

    /// The deterministic action (the mean, clipped to [-1, 1]) for raw observations on the host; for
    /// evaluation.
    pub fn act_deterministic(&self, model: &ActorCritic, obs: &[f32]) -> Vec<f32> {
        let n = obs.len() / self.obs_dim;
        let o = Tensor::<1>::from_floats(obs, &self.device).reshape([n, self.obs_dim]);
        let (mu, _) = model.forward(self.normalize_obs(o));
        to_vec(mu.clamp(-1.0, 1.0))
    }

    /// Steps `env` for `horizon` steps from the observations in `buf` (which it leaves holding the last),
    /// recording episodes in `episodes`. A host env: one upload of the observations and one download of the
    /// actions per step.
    pub fn collect(&mut self, env: &mut dyn Env, buf: &mut StepBuffers, episodes: &mut EpisodeTracker) -> Rollout {
        let n = self.env_count;
        let policy = self.model.valid();
        let gaussian = self.gaussian(&policy);
        let flags = |v: &[f32], dev: &Device| Tensor::<1>::from_floats(v, dev);
        let mut steps = Steps::default();
        for _ in 0..self.cfg.horizon {
            let started = std::time::Instant::now();
            let raw = Tensor::<1>::from_floats(buf.observation.as_slice(), &self.device).reshape([n, self.obs_dim]);
            let action = self.act(&policy, &gaussian, raw, &mut steps);
            // The one readback per step on a host env: the actions it must apply.
            let action = to_vec(action);
            self.act_seconds += started.elapsed().as_secs_f64();
            env.step(&action, buf);
            episodes.record(buf);
            steps.reward.push(flags(&buf.reward, &self.device));
            steps.terminated.push(flags(&buf.terminated, &self.device));
            steps.truncated.push(flags(&buf.truncated, &self.device));
        }
        let raw_last = Tensor::<1>::from_floats(buf.observation.as_slice(), &self.device).reshape([n, self.obs_dim]);
        self.finish(&policy, raw_last, steps)
    }

    /// As [`collect`](Self::collect) for a device env: from the observations `obs` (left holding the last),
    /// everything stays on the device; episodes are tallied in `episodes` and read with the update's summary.
    /// The host uploads the exploration noise and reads nothing back.
    pub fn collect_device(
        &mut self,
        env: &mut dyn DeviceEnv,
        obs: &mut Tensor<2>,
        episodes: &mut DeviceEpisodes,
    ) -> Rollout {
        let policy = self.model.valid();
        let gaussian = self.gaussian(&policy);
        let mut steps = Steps::default();
        for _ in 0..self.cfg.horizon {
            let action = self.act(&policy, &gaussian, obs.clone(), &mut steps);
            let out = env.step(action);
            episodes.record(&out);
            *obs = out.observation;
            steps.reward.push(out.reward);
            steps.terminated.push(out.terminated);
            steps.truncated.push(out.truncated);
        }
        self.finish(&policy, obs.clone(), steps)
    }

    /// The policy's sigma [1, A] and its log-density constant `-sum(log sigma) - A/2 ln(2 pi)` [1], for a
    /// rollout (tensors: reading them would be a readback).
    fn gaussian(&self, policy: &ActorCritic) -> (Tensor<2>, Tensor<1>) {
        let log_std = policy.log_std.val();
        let std = log_std.clone().exp().unsqueeze_dim::<2>(0);
        let logp_const = log_std.sum().neg().sub_scalar(0.5 * self.action_dim as f32 * LN_2PI);
        (std, logp_const)
    }

    /// One acting step from raw observations [N, O]: records the normalised observations, the sampled action,
    /// its log-probability and the value in `steps`, and returns the action (unclipped) [N, A].
    fn act(
        &mut self,
        policy: &ActorCritic,
        gaussian: &(Tensor<2>, Tensor<1>),
        raw: Tensor<2>,
        steps: &mut Steps,
    ) -> Tensor<2> {
        let n = self.env_count;
        let obs = self.normalize_obs(raw.clone());
        let (mu, v) = policy.forward(obs.clone());
        let eps = normal_tensor(&mut self.rng, n, self.action_dim, &self.device);
        let action = mu + eps.clone() * gaussian.0.clone();
        let logp = eps.powi_scalar(2).sum_dim(1).flatten::<1>(0, 1).mul_scalar(-0.5) + gaussian.1.clone().expand([n]);
        steps.obs.push(obs);
        steps.raw.push(raw);
        steps.action.push(action.clone());
        steps.logp.push(logp);
        steps.value.push(self.value_to_returns(v));
        action
    }

    /// The rollout from its steps and the observations after the last one.
    fn finish(&mut self, policy: &ActorCritic, raw_last: Tensor<2>, steps: Steps) -> Rollout {
        let (_, v_last) = policy.forward(self.normalize_obs(raw_last));
        let last_value = self.value_to_returns(v_last);
        if self.cfg.normalize_observation {
            // After the rollout, so the stored observations and log-probabilities stay consistent.
            self.obs_norm.update(Tensor::cat(steps.raw, 0));
        }
        Rollout {
            obs: Tensor::stack(steps.obs, 0),
            action: Tensor::stack(steps.action, 0),
            logp: Tensor::stack(steps.logp, 0),
            value: Tensor::stack(steps.value, 0),
            reward: Tensor::stack(steps.reward, 0),
            terminated: Tensor::stack(steps.terminated, 0),
            truncated: Tensor::stack(steps.truncated, 0),
            last_value,
        }
    }

    /// Generalised advantage estimates [T, N] (tensor ops, backward over time).
    pub fn gae(&self, r: &Rollout) -> Tensor<2> {
        let [t_len, n] = r.reward.dims();
        let (gamma, lambda) = (self.cfg.gamma, self.cfg.gae_lambda);
        let mut reward = r.reward.clone();
        if self.cfg.value_bootstrap {
            // rl_games: a truncated step's reward gets gamma V(s_t), the value of the state it was taken in.
            reward = reward + r.value.clone().mul_scalar(gamma) * r.truncated.clone();
        }
        let not_done = (r.terminated.clone() + r.truncated.clone()).clamp(0.0, 1.0).neg().add_scalar(1.0);
        let row = |x: &Tensor<2>, t: usize| x.clone().slice([t..t + 1, 0..n]).flatten::<1>(0, 1);
        let mut adv_next = Tensor::<1>::zeros([n], &self.device);
        let mut out = vec![adv_next.clone(); t_len];
        for t in (0..t_len).rev() {
            let next_v = if t + 1 == t_len { r.last_value.clone() } else { row(&r.value, t + 1) };
            let nd = row(&not_done, t);
            let delta = row(&reward, t) + next_v.mul_scalar(gamma) * nd.clone() - row(&r.value, t);
            adv_next = delta + adv_next * nd.mul_scalar(gamma * lambda);
            out[t] = adv_next.clone();
        }
        Tensor::stack(out, 0)
    }

    /// One PPO update on `rollout`: `epochs` passes of shuffled minibatches.
    pub fn update(&mut self, rollout: Rollout) -> UpdateStats {
        self.update_with(rollout, None).0
    }

    /// As [`update`](Self::update), reading `extra` (a device rollout's episode tallies) back in the same
    /// transfer as the summary; returns its values too.
    pub fn update_with(&mut self, rollout: Rollout, extra: Option<Tensor<1>>) -> (UpdateStats, Vec<f32>) {
        let [t_len, n] = rollout.reward.dims();
        let batch = t_len * n;
        let adv = self.gae(&rollout).reshape([batch]);
        let values = rollout.value.clone().reshape([batch]);
        let returns = adv.clone() + values.clone();
        let (old_v, ret) = if self.cfg.normalize_value {
            self.value_norm.update(returns.clone().reshape([batch, 1]));
            (self.value_norm.normalize_1d(values), self.value_norm.normalize_1d(returns))
        } else {
            (values, returns)
        };
        let adv = if self.cfg.normalize_advantage {
            let mean = adv.clone().mean();
            let centred = adv - mean;
            let std = centred.clone().powi_scalar(2).mean().sqrt().add_scalar(1e-8);
            centred / std
        } else {
            adv
        };
        let obs = rollout.obs.reshape([batch, self.obs_dim]);
        let act = rollout.action.reshape([batch, self.action_dim]);
        let logp_old = rollout.logp.reshape([batch]);
        let mean_reward = rollout.reward.mean();

        let mb = self.cfg.minibatch_size;
        let c = self.cfg.clone();
        let clip = c.clip_ratio;
        let mut sums: Vec<Tensor<1>> = Vec::new();
        for _ in 0..c.epochs {
            let perm = self.permutation(batch);
            for chunk in perm.chunks_exact(mb) {
                let idx = Tensor::<1, Int>::from_ints(chunk, &self.device);
                let o = obs.clone().select(0, idx.clone());
                let a = act.clone().select(0, idx.clone());
                let lp_old = logp_old.clone().select(0, idx.clone());
                let ad = adv.clone().select(0, idx.clone());
                let v_old = old_v.clone().select(0, idx.clone());
                let r = ret.clone().select(0, idx);

                let (mu, v) = self.model.forward(o);
                let log_std = self.model.log_std.val();
                let z = (a - mu.clone()) / log_std.clone().exp().unsqueeze_dim(0);
                let logp = z.powi_scalar(2).sum_dim(1).flatten::<1>(0, 1).mul_scalar(-0.5)
                    - log_std.clone().sum()
                    - 0.5 * self.action_dim as f32 * LN_2PI;
                let ratio = (logp - lp_old).exp();
                let surr = (ratio.clone() * ad.clone()).min_pair(ratio.clamp(1.0 - clip, 1.0 + clip) * ad);
                let actor_loss = surr.mean().neg();
                let v_err = (v.clone() - r.clone()).powi_scalar(2);
                let critic_loss = if c.clip_value {
                    let v_clipped = v_old.clone() + (v - v_old).clamp(-clip, clip);
                    v_err.max_pair((v_clipped - r).powi_scalar(2)).mean()
                } else {
                    v_err.mean()
                };
                let high = (mu.clone() - SOFT_BOUND).clamp_min(0.0).powi_scalar(2);
                let low = (mu + SOFT_BOUND).clamp_max(0.0).powi_scalar(2);
                let bounds_loss = (high + low).sum_dim(1).mean();
                let mut loss = actor_loss.clone()
                    + critic_loss.clone().mul_scalar(0.5 * c.critic_coef)
                    + bounds_loss.clone().mul_scalar(c.bounds_loss_coef);
                if c.entropy_coef > 0.0 {
                    // A Gaussian's entropy: sum(log sigma) + d/2 ln(2 pi e).
                    let entropy = log_std.sum().add_scalar(0.5 * self.action_dim as f32 * (LN_2PI + 1.0));
                    loss = loss - entropy.mul_scalar(c.entropy_coef);
                }
                let grads = GradientsParams::from_grads(loss.backward(), &self.model);
                let model = self.model.clone();
                self.model = self.optim.step(c.learning_rate, model, grads);
                sums.push(Tensor::cat(
                    vec![actor_loss.without_autodiff(), critic_loss.without_autodiff(), bounds_loss.without_autodiff()],
                    0,
                ));
            }
        }
        // The logging summary: the one readback of the update.
        let sigma = self.model.log_std.val().without_autodiff().exp().mean();
        let mut parts = vec![Tensor::stack::<2>(sums, 0).mean_dim(0).flatten::<1>(0, 1), mean_reward, sigma];
        parts.extend(extra);
        let summary = to_vec(Tensor::cat(parts, 0));
        let stats = UpdateStats {
            actor_loss: summary[0],
            critic_loss: summary[1],
            bounds_loss: summary[2],
            mean_reward: summary[3],
            sigma: summary[4],
        };
        (stats, summary[5..].to_vec())
    }

    /// A Fisher-Yates permutation of 0..n from the learner's generator.
    fn permutation(&mut self, n: usize) -> Vec<i32> {
        let mut p: Vec<i32> = (0..n as i32).collect();
        for i in (1..n).rev() {
            let j = (self.rng.next_u64() % (i as u64 + 1)) as usize;
            p.swap(i, j);
        }
        p
    }
}

/// The PPO maths on rollouts of a few steps, against values worked out by hand (the arithmetic is in the
/// comments): GAE with its episode ends and truncation bootstrap, the clipped surrogate, the clipped value
/// loss, the bounds loss, advantage normalisation and the return statistics of value normalisation. The
/// networks have no hidden layer and hand-set weights, so the action means and values are known; the losses
/// are the ones [`Ppo::update`] reports: with one epoch of one minibatch, those of the network before its
/// step.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::assert_close;

    /// A learner on burn-flex with observations and actions of `action_dim` entries per world and no hidden
    /// layer, after `tweak` sets its config.
    fn learner(env_count: usize, action_dim: usize, tweak: impl FnOnce(&mut PpoConfig)) -> Ppo {
        let mut cfg = PpoConfig { hidden: Vec::new(), max_grad_norm: 0.0, ..PpoConfig::default() };
        tweak(&mut cfg);
        Ppo::new(&cfg, env_count, 1, action_dim, 7, Device::flex())
    }

    /// Sets the network to `mu = obs * mu_w + mu_b` (mu_w [action_dim], one observation entry),
    /// `v = obs * v_w + v_b` and the log standard deviations.
    fn set_network(ppo: &mut Ppo, mu_w: &[f32], mu_b: &[f32], v: [f32; 2], log_std: &[f32]) {
        let mut params = ppo.model.export();
        let values: [&[f32]; 5] = [mu_w, mu_b, &v[..1], &v[1..], log_std];
        for (p, new) in params.iter_mut().zip(values) {
            assert_eq!(p.2.len(), new.len(), "parameter shape {:?}", p.1);
            p.2 = new.to_vec();
        }
        ppo.model = ppo.model.clone().import(&params, &ppo.train_device).unwrap();
    }

    /// A rollout's data, time-major ([t][world] flattened), for [`Rollout`].
    struct Data {
        t: usize,
        n: usize,
        obs: Vec<f32>,
        action: Vec<f32>,
        logp: Vec<f32>,
        value: Vec<f32>,
        reward: Vec<f32>,
        terminated: Vec<f32>,
        truncated: Vec<f32>,
        last_value: Vec<f32>,
    }

    impl Data {
        /// Zeros for `t` steps of `n` worlds with one observation and `action_dim` action entries.
        fn zeros(t: usize, n: usize, action_dim: usize) -> Self {
            let z = |k: usize| vec![0.0; k];
            Self {
                t,
                n,
                obs: z(t * n),
                action: z(t * n * action_dim),
                logp: z(t * n),
                value: z(t * n),
                reward: z(t * n),
                terminated: z(t * n),
                truncated: z(t * n),
                last_value: z(n),
            }
        }

        fn rollout(&self, device: &Device) -> Rollout {
            let (t, n) = (self.t, self.n);
            let grid = |v: &[f32]| Tensor::<1>::from_floats(v, device).reshape([t, n]);
            let a = self.action.len() / (t * n);
            Rollout {
                obs: Tensor::<1>::from_floats(self.obs.as_slice(), device).reshape([t, n, 1]),
                action: Tensor::<1>::from_floats(self.action.as_slice(), device).reshape([t, n, a]),
                logp: grid(&self.logp),
                value: grid(&self.value),
                reward: grid(&self.reward),
                terminated: grid(&self.terminated),
                truncated: grid(&self.truncated),
                last_value: Tensor::from_floats(self.last_value.as_slice(), device),
            }
        }
    }

    /// gamma 0.5 and lambda 0.75 (gamma lambda = 0.375): exact in binary, and apart, so a swap shows.
    fn gae_learner(n: usize, value_bootstrap: bool) -> Ppo {
        learner(n, 1, |c| {
            c.gamma = 0.5;
            c.gae_lambda = 0.75;
            c.value_bootstrap = value_bootstrap;
        })
    }

    /// One world, three steps: r = [1, 2, 3], V = [0.5, 1, 1.5], the given end flags on the middle step, and
    /// V = 2 after the last.
    fn three_steps(terminated: f32, truncated: f32) -> Data {
        Data {
            reward: vec![1.0, 2.0, 3.0],
            value: vec![0.5, 1.0, 1.5],
            terminated: vec![0.0, terminated, 0.0],
            truncated: vec![0.0, truncated, 0.0],
            last_value: vec![2.0],
            ..Data::zeros(3, 1, 1)
        }
    }

    /// No episode ends: the last step bootstraps from the value of the observation after the rollout.
    #[test]
    fn gae_runs_through_the_rollout_and_bootstraps_from_the_last_value() {
        let ppo = gae_learner(1, true);
        let adv = to_vec(ppo.gae(&three_steps(0.0, 0.0).rollout(&ppo.device)));
        // delta_t = r_t + gamma V_{t+1} - V_t, A_t = delta_t + gamma lambda A_{t+1}:
        // t=2: 3 + 0.5 * 2 (last_value) - 1.5 = 2.5;   A = 2.5
        // t=1: 2 + 0.5 * 1.5 - 1 = 1.75;               A = 1.75 + 0.375 * 2.5 = 2.6875
        // t=0: 1 + 0.5 * 1 - 0.5 = 1;                  A = 1 + 0.375 * 2.6875 = 2.0078125
        assert_close("advantages", &adv, &[2.007_812_5, 2.6875, 2.5]);
    }

    /// A terminated step in the middle: no bootstrap across it, and no advantage carried back over it.
    #[test]
    fn gae_stops_at_a_terminated_step() {
        let ppo = gae_learner(1, true);
        let adv = to_vec(ppo.gae(&three_steps(1.0, 0.0).rollout(&ppo.device)));
        // t=2 (the next episode's first step): 3 + 0.5 * 2 - 1.5 = 2.5
        // t=1 (terminated): 2 + 0 - 1 = 1;            A = 1 (nothing from t=2)
        // t=0: 1 + 0.5 * 1 - 0.5 = 1;                 A = 1 + 0.375 * 1 = 1.375
        assert_close("advantages", &adv, &[1.375, 1.0, 2.5]);
    }

    /// A truncated step in the middle with `value_bootstrap`: the env has already reset the world, so the
    /// episode's last observation is gone; as in rl_games the step's reward gets gamma V(s_t), the value of
    /// the state the step was taken in, and nothing crosses into the next episode.
    #[test]
    fn gae_bootstraps_a_truncated_step_from_its_own_value() {
        let ppo = gae_learner(1, true);
        let adv = to_vec(ppo.gae(&three_steps(0.0, 1.0).rollout(&ppo.device)));
        // t=2: 2.5 as above
        // t=1 (truncated): r = 2 + 0.5 * V_1 = 2 + 0.5 * 1 = 2.5; delta = 2.5 - 1 = 1.5;   A = 1.5
        // t=0: 1 + 0.5 * 1 - 0.5 = 1;                 A = 1 + 0.375 * 1.5 = 1.5625
        assert_close("advantages", &adv, &[1.5625, 1.5, 2.5]);
        // Without value_bootstrap a truncation is an end like termination: [1.375, 1, 2.5].
        let plain = gae_learner(1, false);
        let adv = to_vec(plain.gae(&three_steps(0.0, 1.0).rollout(&plain.device)));
        assert_close("advantages without value_bootstrap", &adv, &[1.375, 1.0, 2.5]);
    }

    /// Episodes that end on the rollout's last step never read `last_value` (the value of the next
    /// episode's first observation), whether truncated (world 0) or terminated (world 1).
    #[test]
    fn gae_ignores_the_last_value_after_an_end_on_the_last_step() {
        let ppo = gae_learner(2, true);
        let data = Data {
            // [t][world]: r = [1, 2] and V = [0.5, 1] in both worlds.
            reward: vec![1.0, 1.0, 2.0, 2.0],
            value: vec![0.5, 0.5, 1.0, 1.0],
            truncated: vec![0.0, 0.0, 1.0, 0.0],
            terminated: vec![0.0, 0.0, 0.0, 1.0],
            last_value: vec![100.0, 100.0],
            ..Data::zeros(2, 2, 1)
        };
        let adv = to_vec(ppo.gae(&data.rollout(&ppo.device)));
        // World 0, t=1 (truncated): 2 + 0.5 * 1 - 1 = 1.5;   t=0: 1 + 0.5 * 1 - 0.5 = 1, A = 1 + 0.375 * 1.5 = 1.5625
        // World 1, t=1 (terminated): 2 - 1 = 1;             t=0: 1, A = 1 + 0.375 * 1 = 1.375
        assert_close("advantages", &adv, &[1.5625, 1.375, 1.5, 1.0]);
    }

    /// Two worlds, an episode boundary in the middle of world 0's rollout only: each world's advantages are
    /// its own.
    #[test]
    fn gae_keeps_worlds_apart_across_an_episode_boundary() {
        let ppo = gae_learner(2, true);
        let data = Data {
            // [t][world]: world 0 r = [1, 2, 3], V = [0.5, 1, 1.5]; world 1 r = [0, 1, -1], V = [0, 0.5, 0.25].
            reward: vec![1.0, 0.0, 2.0, 1.0, 3.0, -1.0],
            value: vec![0.5, 0.0, 1.0, 0.5, 1.5, 0.25],
            terminated: vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            last_value: vec![2.0, 1.0],
            ..Data::zeros(3, 2, 1)
        };
        let adv = to_vec(ppo.gae(&data.rollout(&ppo.device)));
        // World 0: t=2 2.5 and t=1 2.6875 (as without ends); t=0 terminated: 1 - 0.5 = 0.5.
        // World 1: t=2: -1 + 0.5 * 1 - 0.25 = -0.75
        //          t=1: 1 + 0.5 * 0.25 - 0.5 = 0.625;   A = 0.625 + 0.375 * -0.75 = 0.34375
        //          t=0: 0 + 0.5 * 0.5 - 0 = 0.25;       A = 0.25 + 0.375 * 0.34375 = 0.37890625
        assert_close("advantages", &adv, &[0.5, 0.378_906_25, 2.6875, 0.343_75, 2.5, -0.75]);
    }

    /// gamma 0 (so an advantage is r - V and a return is r), one epoch of one minibatch of the whole
    /// rollout, no normalisation: the reported losses are the network's before its step.
    fn loss_learner(batch: usize, action_dim: usize, tweak: impl FnOnce(&mut PpoConfig)) -> Ppo {
        learner(batch, action_dim, |c| {
            c.gamma = 0.0;
            c.epochs = 1;
            c.minibatch_size = batch;
            c.normalize_value = false;
            c.normalize_advantage = false;
            c.clip_ratio = 0.2;
            tweak(c);
        })
    }

    /// log N(0; 0, 1) = -ln(2 pi) / 2: the log-density of an action at the mean with sigma 1.
    const LOGP_AT_MEAN: f32 = -0.918_938_5;

    /// The clipped surrogate with the ratio inside and outside [0.8, 1.2] on both sides, for positive and
    /// negative advantages: min(ratio A, clip(ratio) A) takes the clipped term only where it is the smaller.
    #[test]
    fn clipped_surrogate_takes_the_pessimistic_term() {
        let mut ppo = loss_learner(5, 1, |_| {});
        // mu = 0, sigma = 1, V = 0: each action 0 has log-probability LOGP_AT_MEAN now.
        set_network(&mut ppo, &[0.0], &[0.0], [0.0, 0.0], &[0.0]);
        // Old log-probabilities LOGP_AT_MEAN - ln(ratio): ln 1.5 = 0.4054651, ln 0.5 = -0.6931472,
        // ln 1.1 = 0.0953102. The advantages are the rewards (gamma 0, V = 0).
        let data = Data {
            logp: vec![-1.324_403_6, -0.225_791_35, -1.324_403_6, -0.225_791_35, -1.014_248_7],
            reward: vec![1.0, 1.0, -1.0, -1.0, 2.0],
            ..Data::zeros(5, 1, 1)
        };
        let stats = ppo.update(data.rollout(&ppo.device));
        // ratio 1.5, A = +1: min(1.5, 1.2) = 1.2     (clipped above)
        // ratio 0.5, A = +1: min(0.5, 0.8) = 0.5     (unclipped below)
        // ratio 1.5, A = -1: min(-1.5, -1.2) = -1.5  (unclipped above)
        // ratio 0.5, A = -1: min(-0.5, -0.8) = -0.8  (clipped below)
        // ratio 1.1, A = +2: 2.2                     (inside the range)
        // actor loss = -(1.2 + 0.5 - 1.5 - 0.8 + 2.2) / 5 = -1.6 / 5 = -0.32
        assert_close("actor loss", &[stats.actor_loss], &[-0.32]);
        // Value loss (V = 0 = old V, so clipping changes nothing): (1 + 1 + 1 + 1 + 4) / 5 = 1.6.
        assert_close("critic loss", &[stats.critic_loss], &[1.6]);
        assert_close("bounds loss", &[stats.bounds_loss], &[0.0]);
        assert_close("mean reward", &[stats.mean_reward], &[0.4]);
    }

    /// The clipped value loss: max((V - R)^2, (V_old + clip(V - V_old, -0.2, 0.2) - R)^2), with the new
    /// value V = 1 moved past the clip range above and below the rollout's values; and without `clip_value`
    /// the plain squared error.
    #[test]
    fn clipped_value_loss_takes_the_larger_error() {
        // V_old (the rollout's values) and R (= the rewards with gamma 0):
        let data = Data {
            value: vec![1.0, 0.5, 0.5, 1.5, 1.5],
            reward: vec![0.0, 0.5, 2.0, 1.0, 2.0],
            logp: vec![LOGP_AT_MEAN; 5],
            ..Data::zeros(5, 1, 1)
        };
        let mut ppo = loss_learner(5, 1, |_| {});
        set_network(&mut ppo, &[0.0], &[0.0], [0.0, 1.0], &[0.0]);
        let stats = ppo.update(data.rollout(&ppo.device));
        // V_old 1.0, R 0:   V - V_old = 0 inside;         max(1, 1) = 1
        // V_old 0.5, R 0.5: clipped V 0.7;                max(0.25, 0.04) = 0.25
        // V_old 0.5, R 2:   clipped V 0.7;                max(1, 1.69) = 1.69
        // V_old 1.5, R 1:   clipped V 1.3;                max(0, 0.09) = 0.09
        // V_old 1.5, R 2:   clipped V 1.3;                max(1, 0.49) = 1
        // mean: (1 + 0.25 + 1.69 + 0.09 + 1) / 5 = 4.03 / 5 = 0.806
        assert_close("clipped critic loss", &[stats.critic_loss], &[0.806]);
        // Ratio 1 everywhere: the actor loss is -mean(A) = -mean(R - V_old) = -(-1 + 0 + 1.5 - 0.5 + 0.5) / 5.
        assert_close("actor loss", &[stats.actor_loss], &[-0.1]);

        let mut plain = loss_learner(5, 1, |c| c.clip_value = false);
        set_network(&mut plain, &[0.0], &[0.0], [0.0, 1.0], &[0.0]);
        let stats = plain.update(data.rollout(&plain.device));
        // (1 + 0.25 + 1 + 0 + 1) / 5 = 3.25 / 5 = 0.65
        assert_close("unclipped critic loss", &[stats.critic_loss], &[0.65]);
    }

    /// The bounds loss: per sample the sum over action entries of (mu - 1.1)^2 above 1.1 and
    /// (mu + 1.1)^2 below -1.1, averaged over the minibatch.
    #[test]
    fn bounds_loss_penalises_means_beyond_the_soft_bound() {
        let mut ppo = loss_learner(4, 2, |_| {});
        // mu = (obs, -obs), V = 0.
        set_network(&mut ppo, &[1.0, -1.0], &[0.0, 0.0], [0.0, 0.0], &[0.0, 0.0]);
        let data = Data { obs: vec![0.5, 1.5, -2.0, 1.1], ..Data::zeros(4, 1, 2) };
        let stats = ppo.update(data.rollout(&ppo.device));
        // obs 0.5:  mu (0.5, -0.5) inside:                  0
        // obs 1.5:  mu (1.5, -1.5): 0.4^2 + (-0.4)^2 =      0.32
        // obs -2:   mu (-2, 2): (-0.9)^2 + 0.9^2 =          1.62
        // obs 1.1:  mu (1.1, -1.1) on the bound:            0
        // mean: (0 + 0.32 + 1.62 + 0) / 4 = 1.94 / 4 = 0.485
        assert_close("bounds loss", &[stats.bounds_loss], &[0.485]);
        assert_close("critic loss", &[stats.critic_loss], &[0.0]);
    }

    /// Advantage normalisation over the rollout: A = (3, 1) becomes ((3 - 2) / 1, (1 - 2) / 1) = (1, -1)
    /// (population standard deviation sqrt(((1)^2 + (-1)^2) / 2) = 1, plus 1e-8), then clipped at ratio 1.5.
    #[test]
    fn advantages_are_normalised_over_the_rollout() {
        let mut ppo = loss_learner(2, 1, |c| c.normalize_advantage = true);
        set_network(&mut ppo, &[0.0], &[0.0], [0.0, 0.0], &[0.0]);
        // Both at ratio 1.5 (old log-probability LOGP_AT_MEAN - ln 1.5).
        let data = Data { logp: vec![-1.324_403_6; 2], reward: vec![3.0, 1.0], ..Data::zeros(2, 1, 1) };
        let stats = ppo.update(data.rollout(&ppo.device));
        // A = +1: min(1.5, 1.2) = 1.2;  A = -1: min(-1.5, -1.2) = -1.5;  loss = -(1.2 - 1.5) / 2 = 0.15
        // (unnormalised it would be -(3.6 + 1.2) / 2 = -2.4).
        assert_close("actor loss", &[stats.actor_loss], &[0.15]);
    }

    /// Value normalisation: the return statistics take in this rollout's returns (advantage + value) before
    /// the value loss, which is then in normalised units.
    #[test]
    fn value_normalisation_merges_the_returns_then_scores_in_normalised_units() {
        let mut ppo = loss_learner(2, 1, |c| c.normalize_value = true);
        set_network(&mut ppo, &[0.0], &[0.0], [0.0, 0.0], &[0.0]);
        // V_old = 0, returns R = r = (1, 3).
        let data = Data { logp: vec![LOGP_AT_MEAN; 2], reward: vec![1.0, 3.0], ..Data::zeros(2, 1, 1) };
        let stats = ppo.update(data.rollout(&ppo.device));
        // Returns merged into the fresh statistics: mean (1 + 3) / 2 = 2, variance ((-1)^2 + 1^2) / 2 = 1.
        assert_close("return mean", &to_vec(ppo.value_norm.mean.clone()), &[2.0]);
        assert_close("return variance", &to_vec(ppo.value_norm.var.clone()), &[1.0]);
        assert_eq!(ppo.value_norm.count, 2.0);
        // With s = sqrt(1 + 1e-5) = 1.000005: R_n = (-1, 1) / s = -+0.999995, V_old,n = -2 / s = -1.99999,
        // V = 0 (moved 1.99999 from V_old,n, clipped to +0.2: -1.79999).
        // Sample R_n -0.999995: max(0.99999, (-1.79999 + 0.999995)^2 = 0.639992) = 0.99999
        // Sample R_n +0.999995: max(0.99999, (-1.79999 - 0.999995)^2 = 7.839916) = 7.839916
        // mean: (0.99999 + 7.839916) / 2 = 4.419953
        assert_close("critic loss", &[stats.critic_loss], &[4.419_953]);
    }
}
