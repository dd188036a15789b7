//! Small dense linear algebra for the controllers: f32, row-major, fixed-capacity stack buffers.
//!
//! Written to be ported to WGSL as it is: no allocation, no pivoting tables, loops with bounds known up front
//! (`n <= MAX_N`), and iterative parts (the Jacobi SVD) run a bounded number of sweeps.
//!
//! - [`cholesky_factor`] / [`cholesky_solve_factored`] / [`solve_spd`]: SPD systems, `n <= MAX_N`.
//! - [`solve_spd6`] / [`inverse_spd6`]: 6x6 SPD systems with a tiny diagonal regulariser ([`SPD6_REGULARISER`]),
//!   for the task-space inertia `Λ = (J M⁻¹ Jᵀ)⁻¹` and damped least squares.
//! - [`svd_6xn`]: thin SVD of a 6 x n matrix (`n <= MAX_N`) by one-sided (Hestenes) Jacobi, and
//!   [`Svd6::solve`] / [`Svd6::pinv`]: the pseudoinverse from it with a singular-value cutoff.

/// Largest square system (and widest 6 x n matrix) these routines handle: the Franka's 7 arm joints plus its 2
/// fingers.
pub const MAX_N: usize = 9;

/// Relative diagonal regulariser for 6x6 SPD solves: `A + ε·(tr A / 6)·I` with ε = 1e-7 (about f32's ε). It
/// keeps the task-space inertia finite at kinematic singularities (where `J M⁻¹ Jᵀ` loses rank: Λ along the
/// lost direction is then bounded by ~1e7/(tr A/6) instead of being the inverse of a rounding error), while
/// perturbing a solve by no more than the rounding already in `A`'s entries (~ε·|A| each). A larger ε (1e-6
/// was tried) shows: on arms with cond(J M⁻¹ Jᵀ) ~ 1e3 it became the largest error in `J M⁻¹ τ`.
pub const SPD6_REGULARISER: f32 = 1e-7;

/// Most one-sided Jacobi sweeps. Each sweep rotates all 15 column pairs of a 6-column matrix; f32 converges in
/// 5-8 sweeps for the Jacobians here, so the bound only matters for NaN input.
pub const SVD_MAX_SWEEPS: usize = 30;

/// Cholesky factorisation `A = L Lᵀ` in place (row-major n x n, `n <= MAX_N`; the engine's
/// [`factory_engine::articulation::dynamics::cholesky_factor`]): the lower triangle of `a` holds L on return.
/// Returns false if a pivot was not positive; it is then floored so the factor stays usable.
pub fn cholesky_factor(a: &mut [f32], n: usize) -> bool {
    debug_assert!(n <= MAX_N && a.len() >= n * n);
    factory_engine::articulation::dynamics::cholesky_factor(n, a)
}

/// Solves `L Lᵀ x = b` in place (`b` becomes x) with the factor from [`cholesky_factor`].
pub fn cholesky_solve_factored(l: &[f32], n: usize, b: &mut [f32]) {
    debug_assert!(n <= MAX_N && l.len() >= n * n && b.len() >= n);
    factory_engine::articulation::dynamics::cholesky_substitute(n, l, b);
}

/// Solves `A x = b` in place for SPD `A` (row-major n x n, `n <= MAX_N`); returns [`cholesky_factor`]'s flag.
pub fn solve_spd(a: &[f32], n: usize, b: &mut [f32]) -> bool {
    let mut l = [0.0f32; MAX_N * MAX_N];
    l[..n * n].copy_from_slice(&a[..n * n]);
    let ok = cholesky_factor(&mut l, n);
    cholesky_solve_factored(&l, n, b);
    ok
}

/// Adds the [`SPD6_REGULARISER`] to a 6x6 matrix's diagonal and factors it in place.
fn factor_spd6_regularised(l: &mut [f32; 36]) -> bool {
    let mut tr = 0.0f32;
    for i in 0..6 {
        tr += l[i * 6 + i];
    }
    let eps = SPD6_REGULARISER * (tr.abs() / 6.0);
    for i in 0..6 {
        l[i * 6 + i] += eps;
    }
    cholesky_factor(l, 6)
}

/// Solves `(A + ε·tr(A)/6·I) x = b` in place for SPD 6x6 `A` (see [`SPD6_REGULARISER`]).
pub fn solve_spd6(a: &[f32; 36], b: &mut [f32; 6]) -> bool {
    let mut l = *a;
    let ok = factor_spd6_regularised(&mut l);
    cholesky_solve_factored(&l, 6, b);
    ok
}

/// Inverse of the regularised SPD 6x6 `A` (see [`solve_spd6`]), row-major.
pub fn inverse_spd6(a: &[f32; 36]) -> [f32; 36] {
    let mut l = *a;
    factor_spd6_regularised(&mut l);
    let mut inv = [0.0f32; 36];
    for c in 0..6 {
        let mut col = [0.0f32; 6];
        col[c] = 1.0;
        cholesky_solve_factored(&l, 6, &mut col);
        for r in 0..6 {
            inv[r * 6 + c] = col[r];
        }
    }
    inv
}

/// Thin SVD `A = U diag(s) Vᵀ` of a 6 x n matrix.
#[derive(Debug, Clone, Copy)]
pub struct Svd6 {
    /// Columns of A: the right singular vectors' length.
    pub n: usize,
    /// Left singular vectors, row-major 6x6: column k is `u_k`.
    pub u: [f32; 36],
    /// Singular values, descending, all >= 0.
    pub s: [f32; 6],
    /// Right singular vectors, row-major n x 6 (stride 6): column k is `v_k`. Columns for zero singular values
    /// (and, when n < 6, the ones past the rank) are zero.
    pub v: [f32; MAX_N * 6],
}

/// Thin SVD of the 6 x n row-major matrix `a` (`n <= MAX_N`) by one-sided Jacobi.
///
/// Works on `B = Aᵀ` (n x 6): plane rotations `V_B` orthogonalise B's six columns, `B V_B = W`, so
/// `Aᵀ = (W Σ⁻¹) Σ V_Bᵀ` and `A = V_B Σ (W Σ⁻¹)ᵀ`: A's left singular vectors are `V_B`, its singular values B's
/// column norms, its right singular vectors B's normalised columns. Orthogonalising the short side (6 columns
/// rather than n rows) keeps every rotation on vectors of length n <= 9. Hestenes (1958); Demmel & Veselić
/// (1992) for the stopping test `|b_p·b_q| <= tol·|b_p||b_q|`.
pub fn svd_6xn(a: &[f32], n: usize) -> Svd6 {
    debug_assert!(n <= MAX_N && a.len() >= 6 * n);
    // Column-major B = Aᵀ: b[k][i] = B[i][k] = A[k][i].
    let mut b = [[0.0f32; MAX_N]; 6];
    for k in 0..6 {
        for i in 0..n {
            b[k][i] = a[k * n + i];
        }
    }
    // Column-major V_B: vb[k][r] = V_B[r][k].
    let mut vb = [[0.0f32; 6]; 6];
    for (k, col) in vb.iter_mut().enumerate() {
        col[k] = 1.0;
    }
    // f32 dot products of length-9 vectors carry ~n·ε relative error, so asking for tighter orthogonality would
    // only spin.
    let tol = 2e-7 * n.max(6) as f32;
    for _ in 0..SVD_MAX_SWEEPS {
        let mut rotated = false;
        for p in 0..5 {
            for q in p + 1..6 {
                let (mut alpha, mut beta, mut gamma) = (0.0f32, 0.0f32, 0.0f32);
                for i in 0..n {
                    alpha += b[p][i] * b[p][i];
                    beta += b[q][i] * b[q][i];
                    gamma += b[p][i] * b[q][i];
                }
                if gamma.abs() <= tol * (alpha * beta).sqrt() || gamma == 0.0 {
                    continue;
                }
                rotated = true;
                // The rotation angle that zeroes the pair's inner product; the smaller root of
                // t² + 2ζt − 1 = 0 keeps |θ| <= π/4, which is what makes the sweeps converge.
                let zeta = (beta - alpha) / (2.0 * gamma);
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                for i in 0..n {
                    let (bp, bq) = (b[p][i], b[q][i]);
                    b[p][i] = c * bp - s * bq;
                    b[q][i] = s * bp + c * bq;
                }
                for r in 0..6 {
                    let (vp, vq) = (vb[p][r], vb[q][r]);
                    vb[p][r] = c * vp - s * vq;
                    vb[q][r] = s * vp + c * vq;
                }
            }
        }
        if !rotated {
            break;
        }
    }
    let mut norms = [0.0f32; 6];
    for k in 0..6 {
        let mut s2 = 0.0f32;
        for i in 0..n {
            s2 += b[k][i] * b[k][i];
        }
        norms[k] = s2.sqrt();
    }
    // Selection sort of 6 indices by descending norm (branchy but tiny, and WGSL-friendly).
    let mut order = [0usize, 1, 2, 3, 4, 5];
    for i in 0..6 {
        let mut best = i;
        for j in i + 1..6 {
            if norms[order[j]] > norms[order[best]] {
                best = j;
            }
        }
        order.swap(i, best);
    }
    let smax = norms[order[0]];
    let mut out = Svd6 { n, u: [0.0; 36], s: [0.0; 6], v: [0.0; MAX_N * 6] };
    for (k, &src) in order.iter().enumerate() {
        let sk = norms[src];
        out.s[k] = sk;
        for r in 0..6 {
            out.u[r * 6 + k] = vb[src][r];
        }
        // A right singular vector is only defined for a non-zero singular value; below ~ε·σmax the normalised
        // column is rounding noise, and every consumer drops such σ anyway.
        if sk > smax * 1e-30 && sk > 0.0 {
            for i in 0..n {
                out.v[i * 6 + k] = b[src][i] / sk;
            }
        }
    }
    out
}

impl Svd6 {
    /// The cutoff `torch.linalg.pinv`/`numpy.linalg.pinv` use by default: `max(m, n)·ε·σmax`.
    pub fn default_pinv_cutoff(&self) -> f32 {
        self.n.max(6) as f32 * f32::EPSILON * self.s[0]
    }

    /// `x = A⁺ b` (length n) with singular values `<= cutoff` dropped (treated as zero, not inverted).
    pub fn solve(&self, b: &[f32; 6], cutoff: f32) -> [f32; MAX_N] {
        let mut x = [0.0f32; MAX_N];
        for k in 0..6 {
            let sk = self.s[k];
            if !(sk > cutoff) {
                continue;
            }
            let mut utb = 0.0f32;
            for r in 0..6 {
                utb += self.u[r * 6 + k] * b[r];
            }
            let c = utb / sk;
            for i in 0..self.n {
                x[i] += self.v[i * 6 + k] * c;
            }
        }
        x
    }

    /// The pseudoinverse `A⁺ = V diag(1/s) Uᵀ`, row-major n x 6, singular values `<= cutoff` dropped.
    pub fn pinv(&self, cutoff: f32) -> [f32; MAX_N * 6] {
        let mut p = [0.0f32; MAX_N * 6];
        for k in 0..6 {
            let sk = self.s[k];
            if !(sk > cutoff) {
                continue;
            }
            for i in 0..self.n {
                let vik = self.v[i * 6 + k] / sk;
                for j in 0..6 {
                    p[i * 6 + j] += vik * self.u[j * 6 + k];
                }
            }
        }
        p
    }
}

/// `y = A x`, A row-major m x n.
pub fn mat_vec(a: &[f32], m: usize, n: usize, x: &[f32], y: &mut [f32]) {
    for r in 0..m {
        let mut s = 0.0f32;
        for c in 0..n {
            s += a[r * n + c] * x[c];
        }
        y[r] = s;
    }
}

/// `y = Aᵀ x`, A row-major m x n (so y has length n).
pub fn mat_t_vec(a: &[f32], m: usize, n: usize, x: &[f32], y: &mut [f32]) {
    for c in 0..n {
        let mut s = 0.0f32;
        for r in 0..m {
            s += a[r * n + c] * x[r];
        }
        y[c] = s;
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// xorshift64*: deterministic test matrices without a rand dependency.
    pub(crate) struct Rng(u64);
    impl Rng {
        pub(crate) fn new(seed: u64) -> Self {
            Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
        }
        /// Uniform in [-1, 1).
        pub(crate) fn next(&mut self) -> f32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
            ((x >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        }
        pub(crate) fn fill(&mut self, a: &mut [f32]) {
            for x in a {
                *x = self.next();
            }
        }
    }

    /// Random SPD matrix `B Bᵀ + n·I`, row-major.
    pub(crate) fn random_spd(rng: &mut Rng, n: usize) -> Vec<f32> {
        let mut b = vec![0.0; n * n];
        rng.fill(&mut b);
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let mut s = 0.0;
                for k in 0..n {
                    s += b[i * n + k] * b[j * n + k];
                }
                a[i * n + j] = s + if i == j { n as f32 } else { 0.0 };
            }
        }
        a
    }

    pub(crate) fn matmul(a: &[f32], b: &[f32], m: usize, k: usize, n: usize) -> Vec<f32> {
        let mut c = vec![0.0; m * n];
        for i in 0..m {
            for j in 0..n {
                let mut s = 0.0;
                for l in 0..k {
                    s += a[i * k + l] * b[l * n + j];
                }
                c[i * n + j] = s;
            }
        }
        c
    }

    fn max_abs_diff(a: &[f32], b: &[f32]) -> f32 {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
    }

    #[test]
    fn cholesky_solves_known_system() {
        // A = L Lᵀ with a chosen integer L, b = A x for a chosen x: the solve must return x.
        let l = [2.0, 0.0, 0.0, 1.0, 3.0, 0.0, -1.0, 0.5, 1.5];
        let mut lt = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                lt[i * 3 + j] = l[j * 3 + i];
            }
        }
        let a = matmul(&l, &lt, 3, 3, 3);
        let x = [1.0, -2.0, 0.25];
        let mut b = [0.0; 3];
        mat_vec(&a, 3, 3, &x, &mut b);
        assert!(solve_spd(&a, 3, &mut b));
        assert!(max_abs_diff(&b, &x) < 1e-5, "{b:?}");

        // And a random 9x9 system.
        let mut rng = Rng::new(7);
        let a = random_spd(&mut rng, 9);
        let mut x = [0.0; 9];
        rng.fill(&mut x);
        let mut b = [0.0; 9];
        mat_vec(&a, 9, 9, &x, &mut b);
        assert!(solve_spd(&a, 9, &mut b));
        assert!(max_abs_diff(&b, &x) < 1e-4, "{b:?} vs {x:?}");
    }

    #[test]
    fn cholesky_flags_indefinite_matrix() {
        let a = [1.0, 2.0, 2.0, 1.0]; // eigenvalues 3 and -1
        let mut b = [1.0, 1.0];
        assert!(!solve_spd(&a, 2, &mut b));
        assert!(b.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn spd6_inverse_is_inverse() {
        let mut rng = Rng::new(3);
        let a: [f32; 36] = random_spd(&mut rng, 6).try_into().unwrap();
        let inv = inverse_spd6(&a);
        let prod = matmul(&a, &inv, 6, 6, 6);
        let mut eye = [0.0; 36];
        for i in 0..6 {
            eye[i * 6 + i] = 1.0;
        }
        // The regulariser perturbs by ~1e-6 relative.
        assert!(max_abs_diff(&prod, &eye) < 1e-4, "{prod:?}");
        let mut x = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let mut b = [0.0; 6];
        mat_vec(&a, 6, 6, &x, &mut b);
        solve_spd6(&a, &mut b);
        assert!(max_abs_diff(&b, &x) < 1e-4);
        // A singular matrix still gives finite output.
        x = [1.0; 6];
        let mut sing = [0.0; 36];
        for i in 0..6 {
            for j in 0..6 {
                sing[i * 6 + j] = 1.0; // rank 1
            }
        }
        solve_spd6(&sing, &mut x);
        assert!(x.iter().all(|v| v.is_finite()));
    }

    fn check_svd(a: &[f32], n: usize, tol: f32) -> Svd6 {
        let svd = svd_6xn(a, n);
        // U S Vᵀ = A
        let mut rec = vec![0.0; 6 * n];
        for r in 0..6 {
            for c in 0..n {
                let mut s = 0.0;
                for k in 0..6 {
                    s += svd.u[r * 6 + k] * svd.s[k] * svd.v[c * 6 + k];
                }
                rec[r * n + c] = s;
            }
        }
        let scale = a.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        assert!(max_abs_diff(&rec, &a[..6 * n]) < tol * scale, "reconstruction {rec:?} vs {a:?}");
        // UᵀU = I, VᵀV = I (on the non-zero singular values), s descending and non-negative.
        for p in 0..6 {
            for q in 0..6 {
                let uu: f32 = (0..6).map(|r| svd.u[r * 6 + p] * svd.u[r * 6 + q]).sum();
                assert!((uu - if p == q { 1.0 } else { 0.0 }).abs() < 1e-5, "UᵀU[{p}][{q}] = {uu}");
                if svd.s[p] > 1e-3 && svd.s[q] > 1e-3 {
                    let vv: f32 = (0..n).map(|i| svd.v[i * 6 + p] * svd.v[i * 6 + q]).sum();
                    assert!((vv - if p == q { 1.0 } else { 0.0 }).abs() < 1e-5, "VᵀV[{p}][{q}] = {vv}");
                }
            }
        }
        for k in 0..5 {
            assert!(svd.s[k] >= svd.s[k + 1] && svd.s[k + 1] >= 0.0, "{:?}", svd.s);
        }
        svd
    }

    #[test]
    fn svd_reconstructs_random_6x7_with_orthonormal_factors() {
        let mut rng = Rng::new(11);
        for _ in 0..50 {
            let mut a = [0.0f32; 42];
            rng.fill(&mut a);
            check_svd(&a, 7, 1e-5);
        }
        // Other widths, including n < 6 (rank-deficient rows) and n = 9.
        for n in [3, 6, 9] {
            let mut a = vec![0.0f32; 6 * n];
            rng.fill(&mut a);
            check_svd(&a, n, 1e-5);
        }
    }

    #[test]
    fn svd_of_known_diagonal_matrix() {
        // A = diag(3, 1, 4, 1, 5, 9) padded with a zero column: singular values are the sorted |diagonal|.
        let d = [3.0, -1.0, 4.0, 1.0, 5.0, 9.0];
        let mut a = [0.0f32; 42];
        for i in 0..6 {
            a[i * 7 + i] = d[i];
        }
        let svd = check_svd(&a, 7, 1e-6);
        assert_eq!(svd.s, [9.0, 5.0, 4.0, 3.0, 1.0, 1.0]);
    }

    #[test]
    fn pinv_satisfies_penrose_identity() {
        let mut rng = Rng::new(5);
        for _ in 0..20 {
            let mut a = [0.0f32; 42];
            rng.fill(&mut a);
            let svd = svd_6xn(&a, 7);
            let p = svd.pinv(svd.default_pinv_cutoff());
            // A A⁺ A = A and A⁺ A A⁺ = A⁺
            let apa = matmul(&matmul(&a, &p[..42], 6, 7, 6), &a, 6, 6, 7);
            assert!(max_abs_diff(&apa, &a) < 1e-5, "A A+ A != A");
            let pap = matmul(&matmul(&p[..42], &a, 7, 6, 7), &p[..42], 7, 7, 6);
            assert!(max_abs_diff(&pap, &p[..42]) < 1e-4, "A+ A A+ != A+");
            // solve agrees with pinv · b
            let b = [0.3, -0.1, 0.7, 0.2, -0.5, 0.9];
            let x = svd.solve(&b, svd.default_pinv_cutoff());
            let mut y = [0.0; 7];
            mat_vec(&p[..42], 7, 6, &b, &mut y);
            assert!(max_abs_diff(&x[..7], &y) < 1e-5);
        }
        // Rank-deficient: two equal rows.
        let mut a = [0.0f32; 42];
        rng.fill(&mut a);
        let row: [f32; 7] = a[..7].try_into().unwrap();
        a[7..14].copy_from_slice(&row);
        let svd = svd_6xn(&a, 7);
        assert!(svd.s[5] < 1e-5, "{:?}", svd.s);
        let p = svd.pinv(1e-4);
        let apa = matmul(&matmul(&a, &p[..42], 6, 7, 6), &a, 6, 6, 7);
        assert!(max_abs_diff(&apa, &a) < 1e-5);
    }
}
