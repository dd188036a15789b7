//! The task-space kernel's Rust-side GPU mirrors against naga's layout of the WGSL structs they mirror, in
//! the source the kernel compiles ([`TASK_SPACE_WGSL`]): the same size and every member at the same offset
//! ([`factory_engine::gpu::layout`]). No GPU needed.

use factory_controllers::task_space_gpu::{ControllerInputGpu, TaskParamsGpu, TASK_SPACE_WGSL};
use factory_engine::gpu::layout::assert_mirror;
use factory_engine::gpu_mirror;

/// `TaskParams` (the uniform) and `Input` (one world's targets, a storage element the env's action kernel
/// writes too).
#[test]
fn task_space_mirrors_match_their_wgsl_structs() {
    assert_mirror(
        TASK_SPACE_WGSL,
        "TaskParams",
        &gpu_mirror!(TaskParamsGpu { world_count, dof, arm_dof, stride, jacobian, mass_matrix, gravity_torque, flags }),
    );
    assert_mirror(
        TASK_SPACE_WGSL,
        "Input",
        &gpu_mirror!(ControllerInputGpu {
            target_pos,
            target_quat,
            target_force,
            target_torque,
            gripper_q,
            measured_force,
            measured_torque,
        }),
    );
}
