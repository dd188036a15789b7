//! The task-space controllers on the device (`task_space.wgsl`): impedance, OSC, open- and closed-loop force
//! and hybrid force-motion, with the finger PD, gravity compensation and clamping, for every world in one
//! dispatch. The kernel reads what the engine's articulation kernel writes
//! ([`ArticulationGpu::world_dynamics`]: the fingertip frame's pose, twist and geometric Jacobian, M and g;
//! [`ArticulationGpu::joint_q`], [`ArticulationGpu::joint_qd`]) and writes [`ArticulationGpu::joint_tau`],
//! which the articulation's step reads: the control loop stays on the device, the first piece of a
//! device-resident Franka env (docs/ARCHITECTURE.md section 7). [`TaskSpaceController::compute`] is its CPU
//! reference, law for law and operation for operation (`tests/task_space_gpu.rs` checks the two on the Franka).
//!
//! [`TaskSpaceController::compute`]: crate::TaskSpaceController
//!
//! Layout: group 0 the controller (a [`TaskParamsGpu`] uniform, the gains as f32: kp, kd, motion axes,
//! force axes, kf (6 each), the finger PD's kp and kd (`dof - arm_dof` each), every joint's torque limit),
//! group 1 the state in (the articulation's record, `joint_q`, `joint_qd`, one [`ControllerInputGpu`] per
//! world: targets and measured wrench), group 2 the torques out. One invocation per world, 64 per
//! workgroup; a world's working set (the Jacobian block, a Cholesky factor, M^-1 J^T, the 6 x 6 task matrix:
//! about 1 KiB) lives in private arrays, which a GPU keeps in thread-local memory (cached in L1): the
//! arithmetic (~2.5k flops for OSC on the Franka) is latency-bound and needs many worlds to fill a GPU.
//!
//! Only the geometric Jacobian (Factory's default); an analytic-Jacobian controller is refused by
//! name.

use bytemuck::{Pod, Zeroable};
use factory_engine::articulation::gpu::ArticulationGpu;
use factory_engine::gpu::{dispatch_compute, Binding, ExplicitLayout, GpuContext};
use factory_engine::wgpu;

use crate::batch::{check_lens, Targets};
use crate::error::{ControllerError, Result};
use crate::linalg::MAX_N;
use crate::rotation::JacobianKind;
use crate::Controller;

/// The `Input` struct ([`ControllerInputGpu`]) and `quat_mul`, for kernels that write the controller's
/// inputs (prepend it to their source).
pub const CONTROLLER_INPUT_WGSL: &str = include_str!("task_space_input.wgsl");
pub const TASK_SPACE_WGSL: &str = concat!(include_str!("task_space_input.wgsl"), include_str!("task_space.wgsl"));

/// Worlds per workgroup (`@workgroup_size` of task_space.wgsl).
pub const TASK_SPACE_WG: u32 = 64;
/// Most finger joints (`ControllerInputGpu::gripper_q` is one vec4).
pub const MAX_FINGERS: usize = 4;
/// Most joints in all (the kernel's torque array; the engine's `MAX_DOFS`).
pub const MAX_DOF: usize = 16;

const FLAG_MOTION: u32 = 1;
const FLAG_INERTIAL: u32 = 2;
const FLAG_FORCE: u32 = 4;
const FLAG_CLOSED_LOOP: u32 = 8;
const FLAG_GRAVITY: u32 = 16;

/// `TaskParams` of task_space.wgsl (a uniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct TaskParamsGpu {
    pub world_count: u32,
    pub dof: u32,
    pub arm_dof: u32,
    /// The articulation record's floats per world and the offsets of J, M and g in it
    /// (`factory_engine::articulation::gpu::DynamicsLayout`).
    pub stride: u32,
    pub jacobian: u32,
    pub mass_matrix: u32,
    pub gravity_torque: u32,
    /// Which parts the law has (FLAG_*).
    pub flags: u32,
}

/// One world's targets and measured wrench as the kernel reads them (`Input` of task_space.wgsl); w
/// components unused.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ControllerInputGpu {
    /// Target fingertip position [m].
    pub target_pos: [f32; 4],
    /// Target fingertip orientation (x, y, z, w).
    pub target_quat: [f32; 4],
    /// Target wrench the fingertips apply: force [N], torque [N m].
    pub target_force: [f32; 4],
    pub target_torque: [f32; 4],
    /// Target finger openings [m], the first `dof - arm_dof` used.
    pub gripper_q: [f32; 4],
    /// Measured wrench the fingertips apply: force [N], torque [N m] (closed-loop force control).
    pub measured_force: [f32; 4],
    pub measured_torque: [f32; 4],
}

impl ControllerInputGpu {
    /// Every world's input from `targets` and the measured wrenches `measured` (empty: zeros), for
    /// `fingers` finger joints per world.
    pub fn from_targets(targets: &Targets, measured: &[[f32; 6]], fingers: usize) -> Vec<Self> {
        (0..targets.ee_pos.len())
            .map(|w| {
                let (ft, fc) = (targets.ee_wrench[w], measured.get(w).copied().unwrap_or([0.0; 6]));
                let mut gripper_q = [0.0; 4];
                gripper_q[..fingers].copy_from_slice(&targets.gripper_q[w * fingers..(w + 1) * fingers]);
                ControllerInputGpu {
                    target_pos: targets.ee_pos[w].extend(0.0).to_array(),
                    target_quat: targets.ee_quat[w].to_array(),
                    target_force: [ft[0], ft[1], ft[2], 0.0],
                    target_torque: [ft[3], ft[4], ft[5], 0.0],
                    gripper_q,
                    measured_force: [fc[0], fc[1], fc[2], 0.0],
                    measured_torque: [fc[3], fc[4], fc[5], 0.0],
                }
            })
            .collect()
    }
}

/// A [`TaskSpaceController`] bound to an [`ArticulationGpu`]'s buffers.
pub struct TaskSpaceGpu {
    pub world_count: u32,
    fingers: usize,
    /// One [`ControllerInputGpu`] per world, shape [world_count] ([`write_inputs`](Self::write_inputs)).
    pub inputs: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    groups: [wgpu::BindGroup; 3],
    _layout: ExplicitLayout,
}

impl TaskSpaceGpu {
    /// The kernel for `ctrl` on `art`'s worlds (every world's input zero until written). Refuses a
    /// controller without a device kernel (`type`: the joint-space ones), one built for another robot
    /// (`dof`), an analytic-Jacobian law (`jacobian`), and robots beyond the kernel's arrays (`dof`).
    pub fn new(gpu: &GpuContext, ctrl: &dyn Controller, art: &ArticulationGpu) -> Result<Self> {
        let Some(ctrl) = ctrl.as_task_space() else {
            return Err(ControllerError::InvalidValue {
                field: "type",
                reason: format!(
                    "`{}` has no device kernel; on the device: task_space_impedance, osc, open_loop_force, \
                     closed_loop_force, hybrid_force_motion",
                    ctrl.name()
                ),
            });
        };
        let (dof, arm_dof) = (ctrl.dof(), ctrl.arm_dof());
        if dof != art.dof_count as usize {
            return Err(ControllerError::InvalidValue {
                field: "dof",
                reason: format!("controller built for {dof} joints, the articulation has {}", art.dof_count),
            });
        }
        let fingers = dof - arm_dof;
        if dof > MAX_DOF || arm_dof > MAX_N || fingers > MAX_FINGERS {
            return Err(ControllerError::InvalidDof { dof, arm_dof, max: MAX_N });
        }
        let mut flags = 0;
        let mut gains = vec![0.0f32; 30];
        if let Some(m) = ctrl.motion() {
            if m.jacobian == JacobianKind::Analytic {
                return Err(ControllerError::InvalidValue {
                    field: "jacobian",
                    reason: "\"analytic\" runs on the host only; the device controller takes \"geometric\"".into(),
                });
            }
            flags |= FLAG_MOTION | if m.inertial { FLAG_INERTIAL } else { 0 };
            gains[0..6].copy_from_slice(&m.kp);
            gains[6..12].copy_from_slice(&m.kd);
            gains[12..18].copy_from_slice(&m.axes);
        }
        if let Some(f) = ctrl.force() {
            flags |= FLAG_FORCE;
            gains[18..24].copy_from_slice(&f.axes);
            if let Some(kf) = f.kf {
                flags |= FLAG_CLOSED_LOOP;
                gains[24..30].copy_from_slice(&kf);
            }
        }
        let common = ctrl.common();
        if common.gravity {
            flags |= FLAG_GRAVITY;
        }
        gains.extend(&common.gripper_kp);
        gains.extend(&common.gripper_kd);
        gains.extend(&common.limit);
        let lay = art.layout;
        let params = TaskParamsGpu {
            world_count: art.world_count,
            dof: dof as u32,
            arm_dof: arm_dof as u32,
            stride: lay.stride,
            jacobian: lay.jacobian,
            mass_matrix: lay.mass_matrix,
            gravity_torque: lay.gravity_torque,
            flags,
        };
        let uniform = gpu.uniform_buffer("task-space-params", bytemuck::bytes_of(&params));
        let gains = gpu.storage_buffer("task-space-gains", &gains, wgpu::BufferUsages::empty());
        let inputs = gpu.storage_buffer(
            "task-space-inputs",
            &vec![ControllerInputGpu::default(); art.world_count.max(1) as usize],
            wgpu::BufferUsages::empty(),
        );
        let ro = Binding::Storage { read_only: true };
        let layout = gpu.explicit_layout(
            "task-space",
            &[&[Binding::Uniform, ro], &[ro, ro, ro, ro], &[Binding::Storage { read_only: false }]],
        );
        let pipeline = gpu.pipeline_on(&layout, "task-space", TASK_SPACE_WGSL, "task_space");
        let groups = [
            gpu.bind_explicit(&layout, 0, &[&uniform, &gains], 0),
            gpu.bind_explicit(&layout, 1, &[&art.world_dynamics, &art.joint_q, &art.joint_qd, &inputs], 0),
            gpu.bind_explicit(&layout, 2, &[&art.joint_tau], 0),
        ];
        Ok(TaskSpaceGpu { world_count: art.world_count, fingers, inputs, pipeline, groups, _layout: layout })
    }

    /// Uploads every world's targets and measured fingertip wrench (`measured` empty: zeros), queued before
    /// the next submission. Refuses shapes that are not one entry per world.
    pub fn write_inputs(&self, gpu: &GpuContext, targets: &Targets, measured: &[[f32; 6]]) -> Result<()> {
        let n = self.world_count as usize;
        targets.check_shapes_for(n, self.fingers)?;
        if !measured.is_empty() {
            check_lens(&[("measured ee_wrench", measured.len(), n)])?;
        }
        let inputs = ControllerInputGpu::from_targets(targets, measured, self.fingers);
        gpu.queue.write_buffer(&self.inputs, 0, bytemuck::cast_slice(&inputs));
        Ok(())
    }

    /// Records the controller's dispatch: every world's torques into the articulation's `joint_tau`, from
    /// its record (encode the articulation's `dynamics` first).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("task-space"), timestamp_writes: None });
        dispatch_compute(
            &mut pass,
            &self.pipeline,
            self.groups.each_ref(),
            self.world_count.div_ceil(TASK_SPACE_WG),
            1,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::TASK_SPACE_WGSL;

    /// The kernel parses and validates with naga (no GPU needed), and the check can fail.
    #[test]
    fn task_space_shader_validates_with_naga() {
        let check = |src: &str| factory_engine::gpu::validate_wgsl(src, false);
        if let Err(e) = check(TASK_SPACE_WGSL) {
            panic!("task_space.wgsl:\n{e}");
        }
        assert!(check(&TASK_SPACE_WGSL.replace("tau[c] += s;", "tau[c] += 1u;")).is_err());
    }
}
