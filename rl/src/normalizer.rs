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

/// The running statistics on a few vectors, against values worked out by hand (the arithmetic is in the
/// comments), and the batch-by-batch merge against one pass over the concatenation.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::to_vec;
    use crate::test_support::assert_close;

    fn rows(v: &[[f32; 2]]) -> Tensor<2> {
        let flat: Vec<f32> = v.iter().flatten().copied().collect();
        Tensor::<1>::from_floats(flat.as_slice(), &Device::flex()).reshape([v.len(), 2])
    }

    /// The two batches of the tests: columns (1, 2, 3 | 5, 7) and (10, 20, 60 | 0, 40).
    const FIRST: [[f32; 2]; 3] = [[1.0, 10.0], [2.0, 20.0], [3.0, 60.0]];
    const SECOND: [[f32; 2]; 2] = [[5.0, 0.0], [7.0, 40.0]];

    #[test]
    fn the_first_batch_replaces_the_prior() {
        let mut s = RunningMeanStd::new(2, &Device::flex());
        s.update(rows(&FIRST));
        // Column 0: mean (1 + 2 + 3) / 3 = 2, variance (1 + 0 + 1) / 3 = 2/3.
        // Column 1: mean (10 + 20 + 60) / 3 = 30, variance (400 + 100 + 900) / 3 = 1400/3.
        // The prior (mean 0, variance 1) has count 0 and so weight 0.
        assert_close("mean", &to_vec(s.mean.clone()), &[2.0, 30.0]);
        assert_close("var", &to_vec(s.var.clone()), &[0.666_666_7, 466.666_67]);
        assert_eq!(s.count, 3.0);
    }

    /// Two batches merged one after the other give the statistics of one pass over the concatenation.
    #[test]
    fn two_batches_merge_to_the_statistics_of_their_concatenation() {
        let mut s = RunningMeanStd::new(2, &Device::flex());
        s.update(rows(&FIRST));
        s.update(rows(&SECOND));
        // The merge, column 0: batch mean 6, variance 1, d = 6 - 2 = 4;
        //   mean = 2 + 4 * 2/5 = 3.6; M2 = (2/3) 3 + 1 * 2 + 4^2 * 3 * 2 / 5 = 2 + 2 + 19.2 = 23.2; var 23.2 / 5 = 4.64.
        // Column 1: batch mean 20, variance 400, d = -10;
        //   mean = 30 - 10 * 2/5 = 26; M2 = 1400 + 800 + 100 * 6/5 = 2320; var 2320 / 5 = 464.
        // One pass over (1, 2, 3, 5, 7): mean 18 / 5 = 3.6, var 88 / 5 - 3.6^2 = 17.6 - 12.96 = 4.64;
        // over (10, 20, 60, 0, 40): mean 130 / 5 = 26, var 5700 / 5 - 26^2 = 1140 - 676 = 464.
        assert_close("mean", &to_vec(s.mean.clone()), &[3.6, 26.0]);
        assert_close("var", &to_vec(s.var.clone()), &[4.64, 464.0]);
        assert_eq!(s.count, 5.0);

        let mut once = RunningMeanStd::new(2, &Device::flex());
        once.update(rows(&[FIRST[0], FIRST[1], FIRST[2], SECOND[0], SECOND[1]]));
        assert_close("one pass mean", &to_vec(once.mean.clone()), &to_vec(s.mean.clone()));
        assert_close("one pass var", &to_vec(once.var.clone()), &to_vec(s.var.clone()));
        assert_eq!(once.count, s.count);
    }

    #[test]
    fn an_empty_batch_changes_nothing() {
        let mut s = RunningMeanStd::new(2, &Device::flex());
        s.update(rows(&FIRST));
        s.update(rows(&[]));
        assert_close("mean", &to_vec(s.mean.clone()), &[2.0, 30.0]);
        assert_eq!(s.count, 3.0);
    }

    /// `(x - mean) / sqrt(var + 1e-5)`, clamped; a zero variance divides by sqrt(1e-5) = 0.0031623.
    #[test]
    fn normalize_scales_guards_a_zero_variance_and_clamps() {
        let device = Device::flex();
        let s = RunningMeanStd {
            mean: Tensor::from_floats([1.0, -2.0], &device),
            var: Tensor::from_floats([4.0, 0.0], &device),
            count: 10.0,
        };
        let x = rows(&[[3.0, -2.0], [101.0, 1.0], [-99.0, -5.0]]);
        // Column 0: (3 - 1) / sqrt(4.00001) = 2 / 2.0000025 = 0.99999875; (101 - 1) / 2.0000025 = 49.99994;
        //           (-99 - 1) / 2.0000025 = -49.99994.
        // Column 1: 0 / 0.0031623 = 0; 3 / 0.0031623 = 948.6833; -3 / 0.0031623 = -948.6833.
        let raw = to_vec(s.normalize(x.clone(), None));
        assert_close("normalised", &raw, &[0.999_998_75, 0.0, 49.999_94, 948.683_3, -49.999_94, -948.683_3]);
        let clipped = to_vec(s.normalize(x, Some(5.0)));
        assert_close("clipped at 5", &clipped, &[0.999_998_75, 0.0, 5.0, 5.0, -5.0, -5.0]);
    }

    /// The scalar forms used for the values: normalise and back.
    #[test]
    fn normalize_1d_and_denormalize_1d_are_inverse() {
        let device = Device::flex();
        let s = RunningMeanStd {
            mean: Tensor::from_floats([2.0], &device),
            var: Tensor::from_floats([1.0], &device),
            count: 4.0,
        };
        // sqrt(1 + 1e-5) = 1.000005: (4 - 2) / 1.000005 = 1.99999; 1.5 * 1.000005 + 2 = 3.5000075.
        let n = s.normalize_1d(Tensor::from_floats([4.0, 2.0], &device));
        assert_close("normalised", &to_vec(n.clone()), &[1.99999, 0.0]);
        assert_close("denormalised", &to_vec(s.denormalize_1d(Tensor::from_floats([1.5], &device))), &[3.500_007_5]);
        assert_close("round trip", &to_vec(s.denormalize_1d(n)), &[4.0, 2.0]);
    }
}
