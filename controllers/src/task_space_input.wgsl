// What a task-space controller kernel reads per world (task_space_gpu.rs ControllerInputGpu), shared by the
// controller (task_space.wgsl) and the kernels that write it (the env's action.wgsl): prepended to both.

// A world's targets and measured wrench; w components unused.
struct Input {
    target_pos: vec4<f32>,
    target_quat: vec4<f32>,
    target_force: vec4<f32>,
    target_torque: vec4<f32>,
    gripper_q: vec4<f32>,
    measured_force: vec4<f32>,
    measured_torque: vec4<f32>,
}

// Hamilton product a b of (x, y, z, w) quaternions (glam's).
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz), a.w * b.w - dot(a.xyz, b.xyz));
}
