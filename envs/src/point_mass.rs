//! `point_mass`: a planar point mass driven to a goal. The small task the learner is tested on: it has the same
//! [`Env`] interface, episode logic and auto-reset as the Franka tasks, and PPO solves it in a minute on a CPU.
//!
//! Dynamics per control step of `dt`: `v += dt (a_max a - c v)`, `p += dt v` (semi-implicit Euler, linear
//! damping `c`, so the top speed is `a_max / c`). Start and goal are drawn uniformly in the square
//! `[-arena, arena]^2`. Observation: goal minus position [m] and velocity [m/s]. Reward per step:
//! `-distance_weight * |g - p|`, plus `success_bonus` on the step that reaches the goal. Terminated (success)
//! when `|g - p| < goal_radius`; truncated after `max_episode_steps`.

use factory_engine::rng::SplitMix64;
use serde::{Deserialize, Serialize};

use crate::env::{Env, EnvSpec, StepBuffers};
use crate::error::{EnvError, Result};

/// `[env] type = "point_mass"`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PointMassConfig {
    /// Control step [s].
    pub dt: f32,
    /// Control steps after which an episode is truncated.
    pub max_episode_steps: u32,
    /// Half-width of the square in which start and goal are drawn [m].
    pub arena: f32,
    /// Distance to the goal that counts as reached [m].
    pub goal_radius: f32,
    /// Acceleration at action 1 [m/s^2].
    pub max_accel: f32,
    /// Linear damping [1/s].
    pub damping: f32,
    /// Reward per metre of distance per step [1/m].
    pub distance_weight: f32,
    /// Reward on the step that reaches the goal.
    pub success_bonus: f32,
}

impl Default for PointMassConfig {
    fn default() -> Self {
        Self {
            dt: 0.05,
            max_episode_steps: 100,
            arena: 1.0,
            goal_radius: 0.05,
            max_accel: 4.0,
            damping: 2.0,
            distance_weight: 1.0,
            success_bonus: 1.0,
        }
    }
}

impl PointMassConfig {
    fn check(&self) -> Result<()> {
        let positive =
            [("dt", self.dt), ("arena", self.arena), ("goal_radius", self.goal_radius), ("max_accel", self.max_accel)];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(EnvError::InvalidValue { field, reason: format!("{v} is not a finite number > 0") });
            }
        }
        let non_negative = [
            ("damping", self.damping),
            ("distance_weight", self.distance_weight),
            ("success_bonus", self.success_bonus),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(EnvError::InvalidValue { field, reason: format!("{v} is not a finite number >= 0") });
            }
        }
        if self.max_episode_steps == 0 {
            return Err(EnvError::InvalidValue { field: "max_episode_steps", reason: "must be at least 1".into() });
        }
        Ok(())
    }
}

/// The point-mass env (see the module docs).
pub struct PointMass {
    cfg: PointMassConfig,
    spec: EnvSpec,
    rng: SplitMix64,
    /// Positions [m], shape [env_count * 2].
    pub(crate) world_p: Vec<[f32; 2]>,
    /// Velocities [m/s], shape [env_count].
    pub(crate) world_v: Vec<[f32; 2]>,
    /// Goals [m], shape [env_count].
    pub(crate) world_goal: Vec<[f32; 2]>,
    /// Control steps taken in the current episode, shape [env_count].
    world_steps: Vec<u32>,
}

impl PointMass {
    /// `env_count` worlds drawn from `seed`.
    pub fn new(cfg: &PointMassConfig, env_count: usize, seed: u64) -> Result<Self> {
        cfg.check()?;
        if env_count == 0 {
            return Err(EnvError::InvalidValue { field: "env_count", reason: "must be at least 1".into() });
        }
        let spec = EnvSpec {
            name: "point_mass".into(),
            env_count,
            observation_names: ["goal_dx_m", "goal_dy_m", "vx_m_s", "vy_m_s"].map(String::from).to_vec(),
            action_names: ["accel_x", "accel_y"].map(String::from).to_vec(),
            max_episode_steps: cfg.max_episode_steps,
        };
        Ok(Self {
            cfg: cfg.clone(),
            spec,
            rng: SplitMix64(seed),
            world_p: vec![[0.0; 2]; env_count],
            world_v: vec![[0.0; 2]; env_count],
            world_goal: vec![[0.0; 2]; env_count],
            world_steps: vec![0; env_count],
        })
    }

    fn draw(&mut self) -> [f32; 2] {
        let a = self.cfg.arena;
        [(2.0 * self.rng.unit() - 1.0) * a, (2.0 * self.rng.unit() - 1.0) * a]
    }

    fn reset_world(&mut self, w: usize) {
        self.world_p[w] = self.draw();
        self.world_goal[w] = self.draw();
        self.world_v[w] = [0.0; 2];
        self.world_steps[w] = 0;
    }

    fn distance(&self, w: usize) -> f32 {
        let (p, g) = (self.world_p[w], self.world_goal[w]);
        ((g[0] - p[0]).powi(2) + (g[1] - p[1]).powi(2)).sqrt()
    }

    fn observe(&self, w: usize, obs: &mut [f32]) {
        let (p, g, v) = (self.world_p[w], self.world_goal[w], self.world_v[w]);
        obs.copy_from_slice(&[g[0] - p[0], g[1] - p[1], v[0], v[1]]);
    }
}

impl Env for PointMass {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset(&mut self, out: &mut StepBuffers) {
        for w in 0..self.spec.env_count {
            self.reset_world(w);
            self.observe(w, &mut out.observation[w * 4..w * 4 + 4]);
            out.reward[w] = 0.0;
            out.terminated[w] = 0.0;
            out.truncated[w] = 0.0;
            out.success[w] = 0.0;
        }
    }

    fn set_episode_steps(&mut self, steps: &[u32]) -> Result<()> {
        crate::env::check_episode_steps(&self.spec, steps)?;
        self.world_steps.copy_from_slice(steps);
        Ok(())
    }

    fn save_state(&self) -> Option<Vec<u8>> {
        let mut b = self.rng.0.to_le_bytes().to_vec();
        for w in 0..self.spec.env_count {
            for x in self.world_p[w].iter().chain(&self.world_v[w]).chain(&self.world_goal[w]) {
                b.extend_from_slice(&x.to_le_bytes());
            }
            b.extend_from_slice(&self.world_steps[w].to_le_bytes());
        }
        Some(b)
    }

    fn load_state(&mut self, bytes: &[u8]) -> Result<()> {
        let n = self.spec.env_count;
        let expected = 8 + n * (6 * 4 + 4);
        if bytes.len() != expected {
            return Err(EnvError::Shape { field: "point_mass state", len: bytes.len(), expected });
        }
        let word = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
        self.rng.0 = u64::from_le_bytes(bytes[0..8].try_into().unwrap());
        for w in 0..n {
            let o = 8 + w * 28;
            let f = |k: usize| f32::from_bits(word(o + 4 * k));
            self.world_p[w] = [f(0), f(1)];
            self.world_v[w] = [f(2), f(3)];
            self.world_goal[w] = [f(4), f(5)];
            self.world_steps[w] = word(o + 24);
        }
        Ok(())
    }

    /// A PD law towards the goal, `a = (kp (g - p) - kd v) / a_max` clamped to [-1, 1], with kp = 16 s^-2 and
    /// kd = 8 s^-1: with the env's damping of 2 s^-1 a natural frequency of 4 rad/s, damping ratio 1.25, so
    /// the goal is reached well within the default 100 steps of 0.05 s.
    fn scripted_actions(&self) -> Option<Vec<f32>> {
        const KP: f32 = 16.0;
        const KD: f32 = 8.0;
        let mut action = Vec::with_capacity(2 * self.spec.env_count);
        for w in 0..self.spec.env_count {
            for k in 0..2 {
                let err = self.world_goal[w][k] - self.world_p[w][k];
                action.push(((KP * err - KD * self.world_v[w][k]) / self.cfg.max_accel).clamp(-1.0, 1.0));
            }
        }
        Some(action)
    }

    fn step(&mut self, action: &[f32], out: &mut StepBuffers) {
        let c = &self.cfg;
        let (dt, a_max, damping) = (c.dt, c.max_accel, c.damping);
        for w in 0..self.spec.env_count {
            let a = [action[2 * w].clamp(-1.0, 1.0), action[2 * w + 1].clamp(-1.0, 1.0)];
            for k in 0..2 {
                self.world_v[w][k] += dt * (a_max * a[k] - damping * self.world_v[w][k]);
                self.world_p[w][k] += dt * self.world_v[w][k];
            }
            self.world_steps[w] += 1;
            let d = self.distance(w);
            let reached = d < self.cfg.goal_radius;
            let timed_out = !reached && self.world_steps[w] >= self.cfg.max_episode_steps;
            out.reward[w] = -self.cfg.distance_weight * d + if reached { self.cfg.success_bonus } else { 0.0 };
            out.terminated[w] = reached as u8 as f32;
            out.truncated[w] = timed_out as u8 as f32;
            out.success[w] = reached as u8 as f32;
            if reached || timed_out {
                self.reset_world(w);
            }
            self.observe(w, &mut out.observation[w * 4..w * 4 + 4]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(n: usize) -> (PointMass, StepBuffers) {
        let e = PointMass::new(&PointMassConfig::default(), n, 3).unwrap();
        let b = StepBuffers::new(e.spec());
        (e, b)
    }

    #[test]
    fn steering_at_the_goal_reaches_it_and_resets_that_world_only() {
        let (mut e, mut b) = env(2);
        e.reset(&mut b);
        let first_goal_1 = e.world_goal[1];
        let mut reached_at = None;
        for t in 0..200 {
            // World 0: a proportional-derivative steer towards the goal; world 1 idles.
            let o = &b.observation[0..4];
            let a = [(4.0 * o[0] - 1.0 * o[2]).clamp(-1.0, 1.0), (4.0 * o[1] - 1.0 * o[3]).clamp(-1.0, 1.0), 0.0, 0.0];
            e.step(&a, &mut b);
            if b.success[0] == 1.0 {
                reached_at = Some(t);
                assert_eq!(b.terminated[0], 1.0);
                assert_eq!(e.world_steps[0], 0, "the world that succeeded starts a new episode");
                break;
            }
        }
        let t = reached_at.expect("a PD steer reaches the goal");
        assert!(t < 100, "reached at step {t}, within the episode");
        // The idle world did not succeed and was not reset (its goal is the same unless it timed out).
        if t + 1 < 100 {
            assert_eq!(e.world_goal[1], first_goal_1);
            assert_eq!(b.truncated[1], 0.0);
        }
    }

    #[test]
    fn idle_world_is_truncated_at_the_time_limit_not_terminated() {
        let (mut e, mut b) = env(1);
        e.reset(&mut b);
        // Start far from the goal so idling cannot succeed.
        e.world_p[0] = [-1.0, -1.0];
        e.world_goal[0] = [1.0, 1.0];
        for t in 1..=100 {
            e.step(&[0.0, 0.0], &mut b);
            assert_eq!(b.truncated[0] == 1.0, t == 100, "step {t}");
            assert_eq!(b.terminated[0], 0.0);
        }
        assert_eq!(e.world_steps[0], 0);
    }

    #[test]
    fn same_seed_same_episodes() {
        let (mut a, mut ba) = env(8);
        let (mut b, mut bb) = env(8);
        a.reset(&mut ba);
        b.reset(&mut bb);
        let act: Vec<f32> = (0..16).map(|i| ((i * 7) % 5) as f32 / 2.0 - 1.0).collect();
        for _ in 0..150 {
            a.step(&act, &mut ba);
            b.step(&act, &mut bb);
        }
        assert_eq!(ba.observation, bb.observation);
        assert_eq!(ba.reward, bb.reward);
    }

    #[test]
    fn saved_state_resumes_exactly() {
        let (mut a, mut ba) = env(5);
        a.reset(&mut ba);
        let act: Vec<f32> = (0..10).map(|i| (i as f32 * 0.37).sin()).collect();
        for _ in 0..40 {
            a.step(&act, &mut ba);
        }
        let saved = a.save_state().unwrap();
        let (mut b, mut bb) = env(5);
        b.load_state(&saved).unwrap();
        for _ in 0..120 {
            a.step(&act, &mut ba);
            b.step(&act, &mut bb);
        }
        assert_eq!(ba.observation, bb.observation);
        assert!(b.load_state(&saved[1..]).is_err());
    }

    #[test]
    fn bad_values_are_refused_by_name() {
        let cfg = PointMassConfig { goal_radius: -1.0, ..Default::default() };
        let err = PointMass::new(&cfg, 4, 0).err().unwrap().to_string();
        assert!(err.contains("goal_radius"), "{err}");
    }
}
