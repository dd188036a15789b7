//! What the controllers see, filled from the engine's articulation: per world the joint state, the
//! fingertip frame's pose, twist and geometric Jacobian, the mass matrix (armature included) and the
//! gravity torque, computed by the engine's CPU reference (`factory_engine::articulation::dynamics`).

use crate::batch::ArmBatch;
use factory_engine::articulation::dynamics::{world_dynamics, WorldDynamics};
use factory_engine::articulation::{ArticulationModel, ArticulationState, Frame};
use rayon::prelude::*;

impl ArmBatch {
    /// The batch for every world of `state`, with `frame` as the controlled frame (Factory: the
    /// fingertip-centred frame), `arm_dof` arm joints first (the rest fingers), and `ee_wrench` the
    /// measured wrench the fingertips exert per world (empty: zeros).
    pub fn from_articulation(
        model: &ArticulationModel,
        state: &ArticulationState,
        frame: &Frame,
        arm_dof: usize,
        ee_wrench: &[[f32; 6]],
    ) -> Self {
        let dof = model.dof_count();
        let worlds: Vec<_> = state
            .joint_q
            .par_chunks(dof)
            .zip(state.joint_qd.par_chunks(dof))
            .map(|(q, qd)| world_dynamics(model, q, qd, frame))
            .collect();
        Self::from_dynamics(&worlds, state, arm_dof, ee_wrench)
    }

    /// The batch from every world's dynamics `worlds` (the CPU reference's, or the device kernel's read back:
    /// `ArticulationGpu::read_dynamics`) at joint state `state`, as
    /// [`from_articulation`](Self::from_articulation).
    pub fn from_dynamics(
        worlds: &[WorldDynamics],
        state: &ArticulationState,
        arm_dof: usize,
        ee_wrench: &[[f32; 6]],
    ) -> Self {
        let world_count = worlds.len();
        let dof = state.joint_q.len() / world_count.max(1);
        let mut b = ArmBatch::zeros(world_count, dof, arm_dof);
        b.joint_q.copy_from_slice(&state.joint_q);
        b.joint_qd.copy_from_slice(&state.joint_qd);
        for (w, d) in worlds.iter().enumerate() {
            b.ee_jacobian[w * 6 * dof..(w + 1) * 6 * dof].copy_from_slice(&d.jacobian);
            b.mass_matrix[w * dof * dof..(w + 1) * dof * dof].copy_from_slice(&d.mass_matrix);
            b.gravity_torque[w * dof..(w + 1) * dof].copy_from_slice(&d.gravity_torque);
            b.ee_pos[w] = d.frame_pose.0;
            b.ee_quat[w] = d.frame_pose.1;
            b.ee_linvel[w] = d.frame_linvel;
            b.ee_angvel[w] = d.frame_angvel;
            b.ee_wrench[w] = ee_wrench.get(w).copied().unwrap_or([0.0; 6]);
        }
        b
    }
}
