//! Orientation errors and the axis-angle rate map behind the analytic Jacobian.
//!
//! Conventions follow IsaacGymEnvs' `factory_control.get_pose_error` (the code Factory's controllers were
//! written in): the error is `target − current` for position and, with the geometric Jacobian, the axis-angle
//! of `q_target · q_current⁻¹` (the rotation that takes the current orientation to the target, expressed in
//! the world frame, so it pairs with the world-frame angular velocity rows of the geometric Jacobian). With
//! the analytic Jacobian the orientation state is itself the axis-angle vector φ of the current orientation,
//! and the error is `φ_target − φ_current` (paper appendix D4: "⊖ simply computes the difference").
//!
//! The rate map E(φ) and the rotation vector live in the engine
//! (`factory_engine::articulation::rotation`, with their derivation), re-exported here.

pub use factory_engine::articulation::rotation::{
    axis_angle_from_quat, axis_angle_rate_map, axis_angle_rate_map_inverse, skew,
};
use glam::{Quat, Vec3};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::tests::Rng;
    use glam::Mat3;
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
