//! Orientation errors and the axis-angle rate map behind the analytic Jacobian.
//!
//! Conventions follow IsaacGymEnvs' `factory_control.get_pose_error` (the code Factory's controllers were
//! written in): the error is `target − current` for position and, with the geometric Jacobian, the axis-angle
//! of `q_target · q_current⁻¹` (the rotation that takes the current orientation to the target, expressed in
//! the world frame, so it pairs with the world-frame angular velocity rows of the geometric Jacobian). With
//! the analytic Jacobian the orientation state is itself the axis-angle vector φ of the current orientation,
//! and the error is `φ_target − φ_current` (paper appendix D4: "⊖ simply computes the difference").
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

/// Which Jacobian the task-space laws use (paper appendix D4, eq. 3: "J is the geometric or analytic
/// Jacobian").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JacobianKind {
    /// Rows `[v; ω]`: the orientation error is the axis-angle of `q_t · q_c⁻¹`, the velocity is ω.
    #[default]
    Geometric,
    /// Rows `[v; φ̇]`: `J_a = blockdiag(I, E(φ)⁻¹) J_g`, the orientation error is `φ_t − φ_c`, the velocity
    /// `E(φ)⁻¹ ω`.
    Analytic,
}

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

/// World-frame orientation error for the geometric Jacobian: the axis-angle of `target · current⁻¹`, shortest
/// arc (so q and −q give the same error).
pub fn orientation_error(target: Quat, current: Quat) -> Vec3 {
    axis_angle_from_quat(target * current.conjugate())
}

/// The 6-D task-space pose error `[p_t − p; rotation error]` (see the module docs for the two kinds).
pub fn pose_error(target_pos: Vec3, target_quat: Quat, pos: Vec3, quat: Quat, kind: JacobianKind) -> [f32; 6] {
    let dp = target_pos - pos;
    let dr = match kind {
        JacobianKind::Geometric => orientation_error(target_quat, quat),
        JacobianKind::Analytic => axis_angle_from_quat(target_quat) - axis_angle_from_quat(quat),
    };
    [dp.x, dp.y, dp.z, dr.x, dr.y, dr.z]
}

fn skew(p: Vec3) -> Mat3 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::tests::Rng;
    use std::f32::consts::{FRAC_PI_6, PI};

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).abs().max_element() <= tol
    }

    #[test]
    fn thirty_degrees_about_z() {
        // (0, 0, π/6) = (0, 0, 0.5236).
        let e = orientation_error(Quat::from_rotation_z(30f32.to_radians()), Quat::IDENTITY);
        assert!(close(e, Vec3::new(0.0, 0.0, FRAC_PI_6), 1e-4), "{e}");
        // The error is relative: the same 30° step from any current orientation, in the world frame.
        let cur = Quat::from_rotation_x(0.7) * Quat::from_rotation_y(-0.3);
        let e = orientation_error(Quat::from_rotation_z(30f32.to_radians()) * cur, cur);
        assert!(close(e, Vec3::new(0.0, 0.0, FRAC_PI_6), 1e-4), "{e}");
        let full = pose_error(Vec3::X, Quat::from_rotation_z(0.5), Vec3::ZERO, Quat::IDENTITY, JacobianKind::Geometric);
        assert!((full[0] - 1.0).abs() < 1e-6 && (full[5] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn quaternion_sign_gives_the_short_way() {
        let q = Quat::from_rotation_z(30f32.to_radians());
        let neg = Quat::from_xyzw(-q.x, -q.y, -q.z, -q.w);
        let e = orientation_error(neg, Quat::IDENTITY);
        assert!(close(e, Vec3::new(0.0, 0.0, FRAC_PI_6), 1e-4), "{e}");
        // 350° about z is −10° the short way.
        let e = orientation_error(Quat::from_rotation_z(350f32.to_radians()), Quat::IDENTITY);
        assert!(close(e, Vec3::new(0.0, 0.0, -10f32.to_radians()), 1e-4), "{e}");
        // Analytic error uses the shortest-arc rotation vector of each side.
        let e = pose_error(Vec3::ZERO, neg, Vec3::ZERO, Quat::IDENTITY, JacobianKind::Analytic);
        assert!(close(Vec3::new(e[3], e[4], e[5]), Vec3::new(0.0, 0.0, FRAC_PI_6), 1e-4));
    }

    #[test]
    fn axis_angle_round_trips() {
        let mut rng = Rng::new(21);
        for _ in 0..100 {
            let axis = Vec3::new(rng.next(), rng.next(), rng.next()).normalize();
            let angle = (rng.next() * 0.5 + 0.5) * PI * 0.999;
            let phi = axis_angle_from_quat(Quat::from_axis_angle(axis, angle));
            assert!(close(phi, axis * angle, 1e-5), "{phi} vs {}", axis * angle);
        }
        let tiny = axis_angle_from_quat(Quat::from_axis_angle(Vec3::Y, 1e-8));
        assert!(close(tiny, Vec3::new(0.0, 1e-8, 0.0), 1e-12));
    }

    /// φ(t) = log(exp(tω)·R(φ₀)) for world-frame ω: the central difference of φ at t = 0 must be E(φ₀)⁻¹ ω.
    #[test]
    fn rate_map_inverse_matches_finite_differences() {
        let mut rng = Rng::new(42);
        let mut worst_gap = 0.0f32;
        for i in 0..200 {
            let axis = Vec3::new(rng.next(), rng.next(), rng.next()).normalize();
            // Angles across (0, π), including the small-angle series branch and close to π.
            let angle = match i % 4 {
                0 => 0.01 + 0.03 * (rng.next() + 1.0),
                1 => 3.0 + 0.1 * rng.next().abs(),
                _ => 0.1 + 2.8 * 0.5 * (rng.next() + 1.0),
            };
            let phi0 = axis * angle;
            let q0 = Quat::from_scaled_axis(phi0);
            let w = Vec3::new(rng.next(), rng.next(), rng.next());
            let h = 2e-3;
            let plus = axis_angle_from_quat(Quat::from_scaled_axis(w * h) * q0);
            let minus = axis_angle_from_quat(Quat::from_scaled_axis(-w * h) * q0);
            let fd = (plus - minus) / (2.0 * h);
            let an = axis_angle_rate_map_inverse(phi0) * w;
            assert!(close(fd, an, 2e-3 * (1.0 + an.length())), "θ {angle}: fd {fd} vs E⁻¹ω {an}");
            // E really is not the identity here (so the test could fail): track the largest gap.
            worst_gap = worst_gap.max((an - w).length());
            // E·E⁻¹ = I
            let prod = axis_angle_rate_map(phi0) * axis_angle_rate_map_inverse(phi0);
            assert!(prod.abs_diff_eq(Mat3::IDENTITY, 1e-5), "θ {angle}: E E⁻¹ = {prod}");
        }
        assert!(worst_gap > 0.5, "test angles too small to tell E⁻¹ from I: {worst_gap}");
    }

    #[test]
    fn rate_map_inverse_is_finite_at_pi() {
        let m = axis_angle_rate_map_inverse(Vec3::Z * PI);
        assert!(m.is_finite());
        // At θ = π about z: E⁻¹ = I − ½[φ]× + (1/π²)[φ]×², and [φ]×² = π²(zzᵀ − I).
        let expect = Mat3::from_cols(Vec3::new(0.0, -PI / 2.0, 0.0), Vec3::new(PI / 2.0, 0.0, 0.0), Vec3::Z);
        assert!(m.abs_diff_eq(expect, 1e-5), "{m}");
    }
}
