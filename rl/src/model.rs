//! The actor-critic network of the paper's Table IX: a shared MLP trunk (ELU), a linear head for the action
//! mean and one for the value, and a state-independent learned log standard deviation (rl_games'
//! `fixed_sigma: True`, initialised to `init_log_std`).
//!
//! Weights are drawn from the learner's own seeded generator (burn's Kaiming-uniform bound `1/sqrt(fan_in)`
//! for weights and biases) rather than burn's global one, so a run is reproducible from its seed and a
//! resumed run continues exactly.

use burn::module::{Module, Param, ParamId};
use burn::nn::Linear;
use burn::prelude::*;
use burn::tensor::activation::elu;
use factory_engine::rng::SplitMix64;

/// The policy and value network.
#[derive(Module, Debug)]
pub struct ActorCritic {
    /// Trunk layers, input first.
    pub trunk: Vec<Linear>,
    /// Action-mean head.
    pub mu: Linear,
    /// Value head (normalised units when the learner normalises values).
    pub value: Linear,
    /// Log standard deviation per action entry, shape [action_dim].
    pub log_std: Param<Tensor<1>>,
}

fn linear(d_in: usize, d_out: usize, rng: &mut SplitMix64, device: &Device) -> Linear {
    let bound = 1.0 / (d_in as f32).sqrt();
    let mut draw = |n: usize| (0..n).map(|_| (2.0 * rng.unit() - 1.0) * bound).collect::<Vec<f32>>();
    let w = draw(d_in * d_out);
    let b = draw(d_out);
    Linear {
        weight: Param::from_tensor(Tensor::<1>::from_floats(w.as_slice(), device).reshape([d_in, d_out])),
        bias: Some(Param::from_tensor(Tensor::<1>::from_floats(b.as_slice(), device))),
    }
}

impl ActorCritic {
    /// A network for `obs_dim` inputs and `action_dim` actions with the given hidden widths.
    pub fn new(
        obs_dim: usize,
        action_dim: usize,
        hidden: &[usize],
        init_log_std: f32,
        rng: &mut SplitMix64,
        device: &Device,
    ) -> Self {
        let mut trunk = Vec::with_capacity(hidden.len());
        let mut d = obs_dim;
        for &h in hidden {
            trunk.push(linear(d, h, rng, device));
            d = h;
        }
        let mu = linear(d, action_dim, rng, device);
        let value = linear(d, 1, rng, device);
        let log_std = Param::from_tensor(Tensor::<1>::full([action_dim], init_log_std, device));
        Self { trunk, mu, value, log_std }
    }

    /// Action means [batch, action_dim] and values [batch] for normalised observations [batch, obs_dim].
    pub fn forward(&self, obs: Tensor<2>) -> (Tensor<2>, Tensor<1>) {
        let mut x = obs;
        for layer in &self.trunk {
            x = elu(layer.forward(x), 1.0);
        }
        let mu = self.mu.forward(x.clone());
        let v = self.value.forward(x).flatten::<1>(0, 1);
        (mu, v)
    }

    /// Every parameter tensor as (id, shape, values), in a fixed order (for checkpoints and export).
    pub fn export(&self) -> Vec<(u64, Vec<usize>, Vec<f32>)> {
        fn entry<const D: usize>(p: &Param<Tensor<D>>) -> (u64, Vec<usize>, Vec<f32>) {
            let t = p.val();
            (p.id.val(), t.dims().to_vec(), to_vec(t))
        }
        let mut out = Vec::new();
        for l in self.trunk.iter().chain([&self.mu, &self.value]) {
            out.push(entry(&l.weight));
            out.push(entry(l.bias.as_ref().expect("our layers have biases")));
        }
        out.push(entry(&self.log_std));
        out
    }

    /// Replaces every parameter with `params` (as [`export`](Self::export) wrote them, ids kept so an
    /// optimizer state saved beside them applies), checking shapes.
    pub fn import(mut self, params: &[(u64, Vec<usize>, Vec<f32>)], device: &Device) -> Result<Self, String> {
        let expected = 2 * (self.trunk.len() + 2) + 1;
        if params.len() != expected {
            return Err(format!("{} parameter tensors, expected {expected}", params.len()));
        }
        fn param<const D: usize>(
            p: &(u64, Vec<usize>, Vec<f32>),
            want: [usize; D],
            device: &Device,
        ) -> Result<Param<Tensor<D>>, String> {
            let (id, shape, values) = p;
            if shape.as_slice() != want.as_slice() || values.len() != want.iter().product::<usize>() {
                return Err(format!("parameter {id}: shape {shape:?}, expected {want:?}"));
            }
            let t = Tensor::<1>::from_floats(values.as_slice(), device).reshape(want);
            let t = if device.is_autodiff() { t.require_grad() } else { t };
            Ok(Param::initialized(ParamId::from(*id), t))
        }
        let mut i = 0;
        let mut layers: Vec<&mut Linear> = self.trunk.iter_mut().collect();
        layers.push(&mut self.mu);
        layers.push(&mut self.value);
        for l in layers {
            let [d_in, d_out] = l.weight.val().dims();
            l.weight = param(&params[i], [d_in, d_out], device)?;
            l.bias = Some(param(&params[i + 1], [d_out], device)?);
            i += 2;
        }
        let [a] = self.log_std.val().dims();
        self.log_std = param(&params[i], [a], device)?;
        Ok(self)
    }
}

thread_local! {
    static READBACKS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

/// Device-to-host reads made through [`to_vec`] on this thread so far: the learner's one choke point for
/// readbacks, counted so a test can prove a device rollout reads nothing back per step (per thread, so tests
/// running beside it do not count).
pub fn readbacks() -> u64 {
    READBACKS.with(|c| c.get())
}

/// A tensor's values on the host (a readback when the tensor lives on a GPU; counted by [`readbacks`]).
pub fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    READBACKS.with(|c| c.set(c.get() + 1));
    t.into_data().try_into_vec::<f32>().expect("f32 tensor")
}
