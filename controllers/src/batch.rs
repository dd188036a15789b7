//! The controllers' inputs: the robot's state per world ([`ArmBatch`]) and the targets ([`Targets`]).

use glam::{Quat, Vec3};

use crate::error::{ControllerError, Result};

/// What the controllers see of every world at one control step (world frame, SI units). Flat, world-major.
///
/// This crate computes nothing about the robot itself: the caller fills these from its articulation code
/// (forward kinematics, the fingertip Jacobian, the mass matrix with armature, gravity torques).
#[derive(Debug, Clone, PartialEq)]
pub struct ArmBatch {
    /// Number of worlds (parallel environments).
    pub world_count: usize,
    /// Degrees of freedom per world: the arm joints then the gripper fingers (9 for the Franka: 7 + 2).
    pub dof: usize,
    /// Arm joints: the first `arm_dof` of `dof`; the rest are gripper fingers.
    pub arm_dof: usize,
    /// Joint positions [rad, m], shape [world_count * dof].
    pub joint_q: Vec<f32>,
    /// Joint velocities [rad/s, m/s], shape [world_count * dof].
    pub joint_qd: Vec<f32>,
    /// Geometric Jacobian of the fingertip frame, rows (vx, vy, vz, wx, wy, wz), row-major 6 x dof per world,
    /// shape [world_count * 6 * dof]: `[v; ω] = J q̇`, v the fingertip origin's linear velocity [m/s], ω the
    /// angular velocity [rad/s], world frame. Only the first `arm_dof` columns are used.
    pub ee_jacobian: Vec<f32>,
    /// Joint-space mass matrix with armature [kg m², kg], row-major dof x dof per world, shape
    /// [world_count * dof * dof]. Only the arm block (first `arm_dof` rows and columns) is used.
    pub mass_matrix: Vec<f32>,
    /// Generalised gravity torques: the joint torques that hold the robot still against gravity [N m, N],
    /// shape [world_count * dof].
    pub gravity_torque: Vec<f32>,
    /// Fingertip position [m], shape [world_count].
    pub ee_pos: Vec<Vec3>,
    /// Fingertip orientation (unit quaternion), shape [world_count].
    pub ee_quat: Vec<Quat>,
    /// Fingertip linear velocity [m/s], shape [world_count].
    pub ee_linvel: Vec<Vec3>,
    /// Fingertip angular velocity [rad/s], world frame, shape [world_count].
    pub ee_angvel: Vec<Vec3>,
    /// Measured contact wrench the fingertips exert on the environment (force [N], torque [N m]), shape
    /// [world_count]; zeros when not measured. Factory's closed-loop force control measures
    /// `−(F_left + F_right)` of the finger contact forces (the force the fingers apply) and no torque.
    pub ee_wrench: Vec<[f32; 6]>,
}

impl ArmBatch {
    /// A batch with every buffer sized for `world_count` worlds, zeros everywhere, identity orientations.
    pub fn zeros(world_count: usize, dof: usize, arm_dof: usize) -> Self {
        ArmBatch {
            world_count,
            dof,
            arm_dof,
            joint_q: vec![0.0; world_count * dof],
            joint_qd: vec![0.0; world_count * dof],
            ee_jacobian: vec![0.0; world_count * 6 * dof],
            mass_matrix: vec![0.0; world_count * dof * dof],
            gravity_torque: vec![0.0; world_count * dof],
            ee_pos: vec![Vec3::ZERO; world_count],
            ee_quat: vec![Quat::IDENTITY; world_count],
            ee_linvel: vec![Vec3::ZERO; world_count],
            ee_angvel: vec![Vec3::ZERO; world_count],
            ee_wrench: vec![[0.0; 6]; world_count],
        }
    }

    /// Checks that every buffer has the length `world_count`, `dof` and `arm_dof` imply.
    pub fn check_shapes(&self) -> Result<()> {
        let (w, d) = (self.world_count, self.dof);
        if self.arm_dof > d {
            return Err(ControllerError::InvalidDof { dof: d, arm_dof: self.arm_dof, max: crate::MAX_ARM_DOF });
        }
        let lens = [
            ("ArmBatch.joint_q", self.joint_q.len(), w * d),
            ("ArmBatch.joint_qd", self.joint_qd.len(), w * d),
            ("ArmBatch.ee_jacobian", self.ee_jacobian.len(), w * 6 * d),
            ("ArmBatch.mass_matrix", self.mass_matrix.len(), w * d * d),
            ("ArmBatch.gravity_torque", self.gravity_torque.len(), w * d),
            ("ArmBatch.ee_pos", self.ee_pos.len(), w),
            ("ArmBatch.ee_quat", self.ee_quat.len(), w),
            ("ArmBatch.ee_linvel", self.ee_linvel.len(), w),
            ("ArmBatch.ee_angvel", self.ee_angvel.len(), w),
            ("ArmBatch.ee_wrench", self.ee_wrench.len(), w),
        ];
        check_lens(&lens)
    }
}

/// Per-world targets, written by a task or a policy.
#[derive(Debug, Clone, PartialEq)]
pub struct Targets {
    /// Target fingertip position [m], shape [world_count].
    pub ee_pos: Vec<Vec3>,
    /// Target fingertip orientation (unit quaternion), shape [world_count].
    pub ee_quat: Vec<Quat>,
    /// Target wrench the fingertips should apply to the environment (force [N], torque [N m]), shape
    /// [world_count]. Read only by controllers that do force control.
    pub ee_wrench: Vec<[f32; 6]>,
    /// Target finger joint positions [m] (each finger's opening), shape [world_count * (dof - arm_dof)].
    pub gripper_q: Vec<f32>,
}

impl Targets {
    /// Targets for `world_count` worlds: origin, identity orientation, zero wrench, fingers at 0 (closed).
    pub fn zeros(world_count: usize, finger_dof: usize) -> Self {
        Targets {
            ee_pos: vec![Vec3::ZERO; world_count],
            ee_quat: vec![Quat::IDENTITY; world_count],
            ee_wrench: vec![[0.0; 6]; world_count],
            gripper_q: vec![0.0; world_count * finger_dof],
        }
    }

    /// Targets that hold every world where `arm` is now (fingers included), with zero wrench.
    pub fn hold(arm: &ArmBatch) -> Self {
        let fd = arm.dof - arm.arm_dof;
        let mut gripper_q = Vec::with_capacity(arm.world_count * fd);
        for w in 0..arm.world_count {
            gripper_q.extend_from_slice(&arm.joint_q[w * arm.dof + arm.arm_dof..(w + 1) * arm.dof]);
        }
        Targets {
            ee_pos: arm.ee_pos.clone(),
            ee_quat: arm.ee_quat.clone(),
            ee_wrench: vec![[0.0; 6]; arm.world_count],
            gripper_q,
        }
    }

    /// Checks the buffers' lengths against the batch they go with.
    pub fn check_shapes(&self, arm: &ArmBatch) -> Result<()> {
        self.check_shapes_for(arm.world_count, arm.dof.saturating_sub(arm.arm_dof))
    }

    /// [`check_shapes`](Self::check_shapes) for `world_count` worlds of `fingers` finger joints each.
    pub fn check_shapes_for(&self, world_count: usize, fingers: usize) -> Result<()> {
        let w = world_count;
        let lens = [
            ("Targets.ee_pos", self.ee_pos.len(), w),
            ("Targets.ee_quat", self.ee_quat.len(), w),
            ("Targets.ee_wrench", self.ee_wrench.len(), w),
            ("Targets.gripper_q", self.gripper_q.len(), w * fingers),
        ];
        check_lens(&lens)
    }
}

pub(crate) fn check_lens(lens: &[(&'static str, usize, usize)]) -> Result<()> {
    for &(field, len, expected) in lens {
        if len != expected {
            return Err(ControllerError::Shape { field, len, expected });
        }
    }
    Ok(())
}
