//! Rotation vectors (axis-angle) and the rate map E(phi) between their derivative and the angular velocity,
//! behind the analytic Jacobian ([`super::dynamics::analytic_jacobian`]) and the controllers' analytic mode.
//!
//! # The rate map E(φ) (own derivation)
//!
//! Let `R(t) = exp([φ(t)]×)` with φ = θ·a the rotation vector, and ω the world-frame angular velocity,
//! `Ṙ Rᵀ = [ω]×`. Differentiating the exponential series term by term and collecting with Rodrigues'
//! formula gives `ω = E(φ) φ̇` with
//!
//! ```text
//! E(φ)   = I + (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×²
//! E(φ)⁻¹ = I − ½[φ]× + c(θ) [φ]×²,   c(θ) = 1/θ² − (1 + cos θ)/(2θ sin θ) = (1 − (θ/2)·cot(θ/2)) / θ²
//! ```
//!
//! (the "left Jacobian of SO(3)" and its inverse; Barfoot, *State Estimation for Robotics*, 2017, sec. 7.1.3;
//! the same E_r⁻¹ for rotation vectors is in the ETH Zürich *Robot Dynamics* lecture notes, 2017, eq. 2.107,
//! and the general analytic/geometric Jacobian relation `J_a = T_A(φ)⁻¹ J_g` in Siciliano et al., *Robotics:
//! Modelling, Planning and Control*, 2009, sec. 3.6). The inverse is checked by multiplying out: `[φ]×³ =
//! −θ²[φ]×`, so `E·E⁻¹` reduces to I exactly when c(θ) has the form above.
//!
//! Numerics: `cot(θ/2)` is `w/|v|` for the unit quaternion (w, v) of φ with w >= 0, so E⁻¹ is finite on the
//! whole shortest-arc range θ ∈ [0, π] (c(π) = 1/π²; E itself is singular only at θ = 2π, which a shortest-arc
//! rotation vector never reaches). Near θ = 0 the difference in c(θ) cancels, so a Taylor series is used.
//! The analytic orientation state still jumps where the current orientation crosses θ = π (φ flips to −φ):
//! that is inherent to the representation, as in IsaacGymEnvs.

use glam::{Mat3, Quat, Vec3};

/// Axis-angle (rotation vector) of a quaternion, shortest arc: the sign of q is chosen so that w >= 0, giving
/// an angle in [0, π]. q need not be unit length (the angle and axis are scale-invariant); zero gives zero.
pub fn axis_angle_from_quat(q: Quat) -> Vec3 {
    let (mut v, mut w) = (Vec3::new(q.x, q.y, q.z), q.w);
    if w < 0.0 {
        v = -v;
        w = -w;
    }
    let s = v.length();
    if s > 1e-6 * w.max(s) {
        v * (2.0 * s.atan2(w) / s)
    } else if w > 0.0 {
        // θ = 2·atan(s/w) ≈ 2s/w: the same limit without dividing by a tiny s.
        v * (2.0 / w)
    } else {
        Vec3::ZERO
    }
}

/// The cross-product matrix [p]x (p x v = [p]x v).
pub fn skew(p: Vec3) -> Mat3 {
    // glam matrices are column-major: these are the columns of [p]×.
    Mat3::from_cols(Vec3::new(0.0, p.z, -p.y), Vec3::new(-p.z, 0.0, p.x), Vec3::new(p.y, -p.x, 0.0))
}

/// `E(φ)`: maps axis-angle rates to world-frame angular velocity, `ω = E(φ) φ̇` (module docs).
pub fn axis_angle_rate_map(phi: Vec3) -> Mat3 {
    let th = phi.length();
    let (a, b) = if th < 0.05 {
        // (1 − cos θ)/θ² and (θ − sin θ)/θ³ to O(θ⁶).
        let t2 = th * th;
        (0.5 - t2 / 24.0 + t2 * t2 / 720.0, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0)
    } else {
        ((1.0 - th.cos()) / (th * th), (th - th.sin()) / (th * th * th))
    };
    let k = skew(phi);
    Mat3::IDENTITY + k * a + k * k * b
}

/// `E(φ)⁻¹`: maps world-frame angular velocity to axis-angle rates, `φ̇ = E(φ)⁻¹ ω` (module docs).
pub fn axis_angle_rate_map_inverse(phi: Vec3) -> Mat3 {
    let th = phi.length();
    let c = if th < 0.05 {
        let t2 = th * th;
        1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    } else {
        let half = 0.5 * th;
        // cot(θ/2) via cos/sin of the half angle: finite at θ = π, unlike (1 + cos θ)/sin θ.
        (1.0 - half * half.cos() / half.sin()) / (th * th)
    };
    let k = skew(phi);
    Mat3::IDENTITY - k * 0.5 + k * k * c
}
