//! `point_mass` as a [`DeviceEnv`]: the same dynamics, reward, episode logic and auto-reset as
//! [`PointMass`](crate::PointMass) (see its module docs), computed with tensor ops on the learner's device.
//! Resets draw start and goal for every world every step on the host, from the env's own seeded generator,
//! and upload them (one small upload per step, no readback); the step keeps them where an episode ended.
//! burn-flex 0.22's `Tensor::random` was tried first: its draws repeated across worlds, nearly value for
//! value, and PPO did not learn the task on them (4% of 1024 evaluation episodes vs 100% with these). The draws differ
//! from the host env's, so episodes are not the same draw for draw; the step matches the host env to
//! rounding (test below).

use burn::prelude::*;

use crate::device::{DeviceEnv, DeviceStep};
use crate::env::EnvSpec;
use crate::error::{EnvError, Result};
use crate::point_mass::{PointMass, PointMassConfig};

/// The device-resident point mass.
pub struct PointMassDevice {
    cfg: PointMassConfig,
    spec: EnvSpec,
    device: Device,
    /// Positions [m], shape [env_count, 2].
    world_p: Tensor<2>,
    /// Velocities [m/s], shape [env_count, 2].
    world_v: Tensor<2>,
    /// Goals [m], shape [env_count, 2].
    world_goal: Tensor<2>,
    /// Control steps taken in the current episode (whole numbers in f32), shape [env_count].
    world_steps: Tensor<1>,
    rng: factory_engine::rng::SplitMix64,
}

impl PointMassDevice {
    /// `env_count` worlds on `device`, whose generator `seed` seeds.
    pub fn new(cfg: &PointMassConfig, env_count: usize, seed: u64, device: &Device) -> Result<Self> {
        // The host env checks the config and names the spec; the device env shares both.
        let host = PointMass::new(cfg, env_count, seed)?;
        let zeros2 = Tensor::<2>::zeros([env_count, 2], device);
        Ok(Self {
            cfg: cfg.clone(),
            spec: crate::Env::spec(&host).clone(),
            device: device.clone(),
            world_p: zeros2.clone(),
            world_v: zeros2.clone(),
            world_goal: zeros2,
            world_steps: Tensor::zeros([env_count], device),
            rng: factory_engine::rng::SplitMix64(seed),
        })
    }

    /// Sets every world's state (for parity tests): positions, velocities and goals [env_count, 2], steps
    /// [env_count].
    pub fn set_state(&mut self, p: Tensor<2>, v: Tensor<2>, goal: Tensor<2>, steps: Tensor<1>) {
        (self.world_p, self.world_v, self.world_goal, self.world_steps) = (p, v, goal, steps);
    }

    fn draw(&mut self) -> Tensor<2> {
        let a = self.cfg.arena;
        let n = self.spec.env_count;
        let v: Vec<f32> = (0..2 * n).map(|_| (2.0 * self.rng.unit() - 1.0) * a).collect();
        self.upload(&v, 2)
    }

    fn upload(&self, v: &[f32], cols: usize) -> Tensor<2> {
        Tensor::<1>::from_floats(v, &self.device).reshape([self.spec.env_count, cols])
    }

    fn observe(&self) -> Tensor<2> {
        Tensor::cat(vec![self.world_goal.clone() - self.world_p.clone(), self.world_v.clone()], 1)
    }
}

impl DeviceEnv for PointMassDevice {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset(&mut self) -> DeviceStep {
        let n = self.spec.env_count;
        self.world_p = self.draw();
        self.world_goal = self.draw();
        self.world_v = Tensor::zeros([n, 2], &self.device);
        self.world_steps = Tensor::zeros([n], &self.device);
        let zeros = Tensor::<1>::zeros([n], &self.device);
        DeviceStep {
            observation: self.observe(),
            reward: zeros.clone(),
            terminated: zeros.clone(),
            truncated: zeros.clone(),
            success: zeros,
            failure: None,
        }
    }

    fn step(&mut self, action: Tensor<2>) -> DeviceStep {
        let c = &self.cfg;
        let a = action.clamp(-1.0, 1.0);
        let v = self.world_v.clone();
        let v = v.clone() + (a.mul_scalar(c.max_accel) - v.mul_scalar(c.damping)).mul_scalar(c.dt);
        let p = self.world_p.clone() + v.clone().mul_scalar(c.dt);
        let steps = self.world_steps.clone().add_scalar(1.0);
        let d = (self.world_goal.clone() - p.clone()).powi_scalar(2).sum_dim(1).sqrt().flatten::<1>(0, 1);
        let reached = d.clone().lower_elem(c.goal_radius).float();
        let timed_out = steps.clone().greater_equal_elem(c.max_episode_steps as f32).float()
            * reached.clone().neg().add_scalar(1.0);
        let reward = d.mul_scalar(-c.distance_weight) + reached.clone().mul_scalar(c.success_bonus);
        let done = reached.clone() + timed_out.clone();
        let keep = done.clone().neg().add_scalar(1.0);
        let (keep2, done2) = (keep.clone().unsqueeze_dim::<2>(1), done.unsqueeze_dim::<2>(1));
        // Masked reset: a fresh draw for every world, kept where the episode ended.
        self.world_p = p * keep2.clone() + self.draw() * done2.clone();
        self.world_goal = self.world_goal.clone() * keep2.clone() + self.draw() * done2;
        self.world_v = v * keep2;
        self.world_steps = steps * keep;
        DeviceStep {
            observation: self.observe(),
            reward,
            terminated: reached.clone(),
            truncated: timed_out,
            success: reached,
            failure: None,
        }
    }

    /// Positions, velocities, goals and step counts as little-endian f32, then the generator's state.
    fn save_state(&self) -> Option<Vec<u8>> {
        let mut b = Vec::new();
        for t in [&self.world_p, &self.world_v, &self.world_goal] {
            let v = t.clone().into_data().try_into_vec::<f32>().ok()?;
            b.extend(v.iter().flat_map(|x| x.to_le_bytes()));
        }
        let steps = self.world_steps.clone().into_data().try_into_vec::<f32>().ok()?;
        b.extend(steps.iter().flat_map(|x| x.to_le_bytes()));
        b.extend(self.rng.0.to_le_bytes());
        Some(b)
    }

    fn load_state(&mut self, bytes: &[u8]) -> Result<()> {
        let n = self.spec.env_count;
        if bytes.len() != 4 * 7 * n + 8 {
            return Err(EnvError::InvalidValue {
                field: "state",
                reason: format!(
                    "point_mass (device): {} bytes, expected {} for {n} worlds",
                    bytes.len(),
                    4 * 7 * n + 8
                ),
            });
        }
        let f: Vec<f32> = bytes[..28 * n].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
        self.world_p = self.upload(&f[..2 * n], 2);
        self.world_v = self.upload(&f[2 * n..4 * n], 2);
        self.world_goal = self.upload(&f[4 * n..6 * n], 2);
        self.world_steps = Tensor::<1>::from_floats(&f[6 * n..], &self.device);
        self.rng.0 = u64::from_le_bytes(bytes[28 * n..].try_into().unwrap());
        Ok(())
    }

    fn set_episode_steps(&mut self, steps: &[u32]) -> Result<()> {
        crate::env::check_episode_steps(&self.spec, steps)?;
        let v: Vec<f32> = steps.iter().map(|&s| s as f32).collect();
        self.world_steps = Tensor::<1>::from_floats(v.as_slice(), &self.device);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Env, StepBuffers};

    fn host_values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
        t.into_data().try_into_vec::<f32>().unwrap()
    }

    /// From the host env's state, the device env steps to the same observations and rewards (to rounding), and
    /// ends the same episodes with the same flags.
    #[test]
    fn steps_as_the_host_point_mass() {
        let device = Device::flex();
        let cfg = PointMassConfig { max_episode_steps: 30, goal_radius: 0.3, ..Default::default() };
        let n = 16;
        let mut host = PointMass::new(&cfg, n, 5).unwrap();
        let mut buf = StepBuffers::new(host.spec());
        host.reset(&mut buf);
        let mut dev = PointMassDevice::new(&cfg, n, 5, &device).unwrap();
        let flat = |f: &dyn Fn(usize) -> [f32; 2]| -> Tensor<2> {
            let v: Vec<f32> = (0..n).flat_map(f).collect();
            Tensor::<1>::from_floats(v.as_slice(), &device).reshape([n, 2])
        };
        dev.set_state(
            flat(&|w| host.world_p[w]),
            flat(&|w| host.world_v[w]),
            flat(&|w| host.world_goal[w]),
            Tensor::zeros([n], &device),
        );
        let mut rng = factory_engine::rng::SplitMix64(9);
        let mut ended = 0;
        for _ in 0..40 {
            let action: Vec<f32> = (0..2 * n).map(|_| 2.4 * rng.unit() - 1.2).collect();
            host.step(&action, &mut buf);
            let out = dev.step(Tensor::<1>::from_floats(action.as_slice(), &device).reshape([n, 2]));
            let (term, trunc) = (host_values(out.terminated), host_values(out.truncated));
            let (reward, obs) = (host_values(out.reward), host_values(out.observation));
            for w in 0..n {
                assert_eq!((term[w], trunc[w]), (buf.terminated[w], buf.truncated[w]), "world {w}");
                assert!((reward[w] - buf.reward[w]).abs() < 1e-5, "world {w}: {} vs {}", reward[w], buf.reward[w]);
                if buf.done(w) {
                    ended += 1;
                    // Both reset the world; the draws differ, so copy the host's into the device env.
                    let mut p = host_values(dev.world_p.clone());
                    let mut g = host_values(dev.world_goal.clone());
                    p[2 * w..2 * w + 2].copy_from_slice(&host.world_p[w]);
                    g[2 * w..2 * w + 2].copy_from_slice(&host.world_goal[w]);
                    dev.world_p = Tensor::<1>::from_floats(p.as_slice(), &device).reshape([n, 2]);
                    dev.world_goal = Tensor::<1>::from_floats(g.as_slice(), &device).reshape([n, 2]);
                } else {
                    for k in 0..4 {
                        let h = buf.observation[4 * w + k];
                        assert!((obs[4 * w + k] - h).abs() < 1e-5, "world {w} obs {k}: {} vs {h}", obs[4 * w + k]);
                    }
                }
            }
        }
        assert!(ended >= n, "episodes ended, by success and by the time limit: {ended}");
        // Its own resets draw start and goal inside the arena, at rest, at step 0.
        dev.reset();
        let (p, g) = (host_values(dev.world_p.clone()), host_values(dev.world_goal.clone()));
        assert!(p.iter().chain(&g).all(|x| x.abs() <= cfg.arena) && p != g);
        assert!(host_values(dev.world_v.clone())
            .iter()
            .chain(&host_values(dev.world_steps.clone()))
            .all(|x| *x == 0.0));
    }

    /// A saved state restored into a fresh env continues the same episodes step for step; set episode steps
    /// truncate where they say.
    #[test]
    fn saved_state_continues_and_episode_steps_truncate() {
        let device = Device::flex();
        let cfg = PointMassConfig { max_episode_steps: 30, ..Default::default() };
        let n = 8;
        let mut a = PointMassDevice::new(&cfg, n, 3, &device).unwrap();
        a.reset();
        let act = |k: usize| {
            let v: Vec<f32> = (0..2 * n).map(|i| ((i + k) % 5) as f32 * 0.4 - 0.8).collect();
            Tensor::<1>::from_floats(v.as_slice(), &device).reshape([n, 2])
        };
        for k in 0..7 {
            a.step(act(k));
        }
        let mut b = PointMassDevice::new(&cfg, n, 99, &device).unwrap();
        b.reset();
        b.load_state(&a.save_state().unwrap()).unwrap();
        for k in 7..50 {
            let (x, y) = (a.step(act(k)), b.step(act(k)));
            assert_eq!(host_values(x.observation), host_values(y.observation), "step {k}");
            assert_eq!(host_values(x.truncated), host_values(y.truncated), "step {k}");
        }
        assert!(b.load_state(&[0u8; 5]).unwrap_err().to_string().contains("expected"));

        let mut c = PointMassDevice::new(&PointMassConfig { goal_radius: 1e-6, ..cfg.clone() }, n, 3, &device).unwrap();
        c.reset();
        let steps: Vec<u32> = (0..n as u32).map(|w| 29 - w).collect();
        c.set_episode_steps(&steps).unwrap();
        for k in 0..n {
            let trunc = host_values(c.step(act(k)).truncated);
            assert_eq!(trunc[k], 1.0, "world {k} truncated after {} steps", k + 1);
            assert_eq!(trunc.iter().sum::<f32>(), 1.0, "step {}", k + 1);
        }
        assert!(c.set_episode_steps(&[30; 8]).is_err());
    }
}
