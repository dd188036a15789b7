//! Running mean and variance of a stream of vectors (rl_games' `RunningMeanStd`), kept as tensors on the
//! learner's device and merged batch by batch with Chan, Golub and LeVeque's parallel update (1979,
//! "Updating formulae and a pairwise algorithm for computing sample variances"): for the batch's mean `m_b`,
//! variance `v_b` and count `n_b`, `d = m_b - m`, `m += d n_b / n`, `M2 = v n_a + v_b n_b + d^2 n_a n_b / n`.

use burn::prelude::*;

/// Guard against division by a zero variance (rl_games uses 1e-5).
pub const EPSILON: f32 = 1e-5;

/// Running statistics of `dim`-vectors.
#[derive(Clone, Debug)]
pub struct RunningMeanStd {
    /// Mean, shape [dim].
    pub mean: Tensor<1>,
    /// Population variance, shape [dim].
    pub var: Tensor<1>,
    /// Samples merged so far (a host scalar: it depends only on batch sizes, never read from the device).
    pub count: f64,
}

impl RunningMeanStd {
    /// Zero mean, unit variance, no samples.
    pub fn new(dim: usize, device: &Device) -> Self {
        Self { mean: Tensor::zeros([dim], device), var: Tensor::ones([dim], device), count: 0.0 }
    }

    /// Merges a batch [n, dim].
    pub fn update(&mut self, x: Tensor<2>) {
        let [n, _] = x.dims();
        if n == 0 {
            return;
        }
        let batch_mean = x.clone().mean_dim(0).flatten::<1>(0, 1);
        let batch_var = (x - batch_mean.clone().unsqueeze_dim(0)).powi_scalar(2).mean_dim(0).flatten::<1>(0, 1);
        let (na, nb) = (self.count, n as f64);
        let total = na + nb;
        let delta = batch_mean - self.mean.clone();
        self.mean = self.mean.clone() + delta.clone().mul_scalar(nb / total);
        let m2 = self.var.clone().mul_scalar(na)
            + batch_var.mul_scalar(nb)
            + delta.powi_scalar(2).mul_scalar(na * nb / total);
        self.var = m2.div_scalar(total);
        self.count = total;
    }

    /// `(x - mean) / sqrt(var + eps)` for x [n, dim], clamped to +-`clip` when given.
    pub fn normalize(&self, x: Tensor<2>, clip: Option<f32>) -> Tensor<2> {
        let y = (x - self.mean.clone().unsqueeze_dim(0)) / self.var.clone().add_scalar(EPSILON).sqrt().unsqueeze_dim(0);
        match clip {
            Some(c) => y.clamp(-c, c),
            None => y,
        }
    }

    /// `(x - mean) / sqrt(var + eps)` for scalars x [n] (dim 1).
    pub fn normalize_1d(&self, x: Tensor<1>) -> Tensor<1> {
        (x - self.mean.clone()) / self.var.clone().add_scalar(EPSILON).sqrt()
    }

    /// `y sqrt(var + eps) + mean` for scalars y [n] (dim 1).
    pub fn denormalize_1d(&self, y: Tensor<1>) -> Tensor<1> {
        y * self.var.clone().add_scalar(EPSILON).sqrt() + self.mean.clone()
    }
}
