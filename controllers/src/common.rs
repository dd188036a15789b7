//! What every controller does around its law: the finger PD, gravity compensation, torque clamping, and the
//! per-world loads of the arm's Jacobian and mass-matrix blocks.

use crate::batch::{ArmBatch, Targets};
use crate::config::{CommonSettings, Gains};
use crate::error::{ControllerError, Result};
use crate::linalg::MAX_N;
use crate::rotation::{axis_angle_from_quat, axis_angle_rate_map_inverse, pose_error, JacobianKind};
use crate::MAX_ARM_DOF;

/// The shared part of a built controller.
#[derive(Debug, Clone)]
pub(crate) struct Common {
    pub dof: usize,
    pub arm_dof: usize,
    /// [N/m] per finger joint.
    pub gripper_kp: Vec<f32>,
    /// [N s/m] per finger joint.
    pub gripper_kd: Vec<f32>,
    /// The tighter of `torque_limit` and `effort_limit`, per joint [N m, N].
    pub limit: Vec<f32>,
    pub gravity: bool,
}

impl Common {
    pub fn new(s: &CommonSettings, dof: usize, arm_dof: usize) -> Result<Self> {
        check_dof(dof, arm_dof)?;
        let fd = dof - arm_dof;
        let gripper_kp = nonneg_gains(&s.gripper_kp, "gripper_kp", fd)?;
        let gripper_kd = nonneg_gains(&s.gripper_kd, "gripper_kd", fd)?;
        if !(s.torque_limit > 0.0) {
            return Err(ControllerError::InvalidValue {
                field: "torque_limit",
                reason: format!("must be positive, got {}", s.torque_limit),
            });
        }
        let mut limit = vec![s.torque_limit; dof];
        if let Some(eff) = &s.effort_limit {
            if eff.len() != dof {
                return Err(ControllerError::WrongLength { field: "effort_limit", len: eff.len(), expected: dof });
            }
            for (l, &e) in limit.iter_mut().zip(eff) {
                if !(e > 0.0) {
                    return Err(ControllerError::InvalidValue {
                        field: "effort_limit",
                        reason: format!("entries must be positive, got {e}"),
                    });
                }
                *l = l.min(e);
            }
        }
        Ok(Common { dof, arm_dof, gripper_kp, gripper_kd, limit, gravity: s.gravity_compensation })
    }

    /// Panics with the offending field if the batch does not match this controller or itself.
    pub fn check_call(&self, name: &str, arm: &ArmBatch, targets: &Targets, joint_tau: &[f32]) {
        assert!(
            arm.dof == self.dof && arm.arm_dof == self.arm_dof,
            "controller `{name}` was built for dof {}/{} but the batch has dof {}/{}",
            self.dof,
            self.arm_dof,
            arm.dof,
            arm.arm_dof
        );
        if let Err(e) = arm.check_shapes().and_then(|_| targets.check_shapes(arm)) {
            panic!("controller `{name}`: {e}");
        }
        assert_eq!(
            joint_tau.len(),
            arm.world_count * arm.dof,
            "controller `{name}`: joint_tau must have world_count * dof entries"
        );
    }

    /// Completes one world's torques: `tau` holds the arm law's torques in `[..arm_dof]`; adds g to them if
    /// enabled, writes the finger PD into `[arm_dof..]`, clamps everything.
    pub fn finish(&self, w: usize, arm: &ArmBatch, targets: &Targets, tau: &mut [f32]) {
        let (d, na) = (self.dof, self.arm_dof);
        let fd = d - na;
        if self.gravity {
            let g = &arm.gravity_torque[w * d..w * d + na];
            for (t, gi) in tau[..na].iter_mut().zip(g) {
                *t += gi;
            }
        }
        let q = &arm.joint_q[w * d..(w + 1) * d];
        let qd = &arm.joint_qd[w * d..(w + 1) * d];
        let qt = &targets.gripper_q[w * fd..(w + 1) * fd];
        for f in 0..fd {
            let j = na + f;
            tau[j] = self.gripper_kp[f] * (qt[f] - q[j]) - self.gripper_kd[f] * qd[j];
        }
        for (t, &l) in tau.iter_mut().zip(&self.limit) {
            *t = t.clamp(-l, l);
        }
    }
}

pub(crate) fn check_dof(dof: usize, arm_dof: usize) -> Result<()> {
    if arm_dof == 0 || arm_dof > MAX_ARM_DOF || arm_dof > dof {
        return Err(ControllerError::InvalidDof { dof, arm_dof, max: MAX_ARM_DOF });
    }
    Ok(())
}

/// Resolves a gain vector and checks its entries are finite and >= 0 (a negative gain would destabilise the
/// loop silently).
pub(crate) fn nonneg_gains(g: &Gains, field: &'static str, len: usize) -> Result<Vec<f32>> {
    let v = g.resolve(field, len)?;
    if let Some(x) = v.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
        return Err(ControllerError::InvalidValue { field, reason: format!("gains must be finite and >= 0, got {x}") });
    }
    Ok(v)
}

/// As [`nonneg_gains`] for exactly 6 task-space values.
pub(crate) fn task_gains(g: &Gains, field: &'static str) -> Result<[f32; 6]> {
    Ok(nonneg_gains(g, field, 6)?.try_into().expect("length checked"))
}

/// A 6-flag selection vector: every entry 0 or 1 (the paper's Boolean selection matrices).
pub(crate) fn axes(g: &Gains, field: &'static str) -> Result<[f32; 6]> {
    let v = g.resolve(field, 6)?;
    if let Some(x) = v.iter().find(|x| **x != 0.0 && **x != 1.0) {
        return Err(ControllerError::InvalidValue { field, reason: format!("axis flags must be 0 or 1, got {x}") });
    }
    Ok(v.try_into().expect("length checked"))
}

/// The arm block (first `arm_dof` columns) of world `w`'s 6 x dof Jacobian, row-major 6 x arm_dof.
pub(crate) fn arm_jacobian(arm: &ArmBatch, w: usize) -> [f32; 6 * MAX_N] {
    let (d, na) = (arm.dof, arm.arm_dof);
    let src = &arm.ee_jacobian[w * 6 * d..(w + 1) * 6 * d];
    let mut j = [0.0f32; 6 * MAX_N];
    for r in 0..6 {
        j[r * na..(r + 1) * na].copy_from_slice(&src[r * d..r * d + na]);
    }
    j
}

/// The arm block of world `w`'s mass matrix, row-major arm_dof x arm_dof.
pub(crate) fn arm_mass(arm: &ArmBatch, w: usize) -> [f32; MAX_N * MAX_N] {
    let (d, na) = (arm.dof, arm.arm_dof);
    let src = &arm.mass_matrix[w * d * d..(w + 1) * d * d];
    let mut m = [0.0f32; MAX_N * MAX_N];
    for r in 0..na {
        m[r * na..(r + 1) * na].copy_from_slice(&src[r * d..r * d + na]);
    }
    m
}

/// World `w`'s task error e, task velocity ẋ and, for the analytic kind, the Jacobian turned into
/// `J_a = blockdiag(I, E(φ)⁻¹) J_g` in place (`j`: 6 x na).
///
/// The velocity is the measured fingertip twist, mapped to axis-angle rates in the analytic case
/// (`ẋ = [v; E⁻¹ω]`, which is `J_a q̇` when the twist is `J_g q̇`); IsaacGymEnvs uses the measured twist too.
pub(crate) fn task_state(
    arm: &ArmBatch,
    targets: &Targets,
    w: usize,
    kind: JacobianKind,
    j: &mut [f32; 6 * MAX_N],
) -> ([f32; 6], [f32; 6]) {
    let na = arm.arm_dof;
    let e = pose_error(targets.ee_pos[w], targets.ee_quat[w], arm.ee_pos[w], arm.ee_quat[w], kind);
    let (v, mut om) = (arm.ee_linvel[w], arm.ee_angvel[w]);
    if kind == JacobianKind::Analytic {
        let einv = axis_angle_rate_map_inverse(axis_angle_from_quat(arm.ee_quat[w]));
        om = einv * om;
        // Rows 3..6 ← E⁻¹ · rows 3..6 (glam is column-major: einv.col(c)[r] = E⁻¹[r][c]).
        for c in 0..na {
            let col = glam::Vec3::new(j[3 * na + c], j[4 * na + c], j[5 * na + c]);
            let out = einv * col;
            j[3 * na + c] = out.x;
            j[4 * na + c] = out.y;
            j[5 * na + c] = out.z;
        }
    }
    (e, [v.x, v.y, v.z, om.x, om.y, om.z])
}
