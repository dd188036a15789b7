// FrankaNutBolt's actions to the controller's targets on the device: nut_bolt.rs `action_targets`, one
// invocation per world, from the policy's actions and the articulation kernel's record of the fingertip
// pose (engine articulation/gpu.rs DynamicsLayout: position at 0, rotation at 4), into the controller
// kernel's inputs (`Input`, with `quat_mul`, from the controllers' task_space_input.wgsl, prepended).
// action_gpu.rs documents the layout.

struct ActionParams {
    world_count: u32,
    // Floats per world in the articulation record.
    stride: u32,
    // 1: the yaw action maps to -(a + 1) / 2 (clockwise only).
    unidirectional_rot: u32,
    _pad: u32,
    // The action scales (xyz) [m, rad, N, N m] and the fingers' targets [m].
    pos_scale: vec4<f32>,
    rot_scale: vec4<f32>,
    force_scale: vec4<f32>,
    torque_scale: vec4<f32>,
    gripper_q: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: ActionParams;
@group(1) @binding(0) var<storage, read> world_dynamics: array<f32>;
@group(1) @binding(1) var<storage, read> actions: array<f32>;
@group(2) @binding(0) var<storage, read_write> inputs: array<Input>;

fn act(w: u32, k: u32) -> f32 {
    return clamp(actions[w * 12u + k], -1.0, 1.0);
}

@compute @workgroup_size(64)
fn screw_targets(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= params.world_count) {
        return;
    }
    let b = w * params.stride;
    let pos = vec3<f32>(world_dynamics[b], world_dynamics[b + 1u], world_dynamics[b + 2u]);
    let quat = vec4<f32>(world_dynamics[b + 4u], world_dynamics[b + 5u], world_dynamics[b + 6u], world_dynamics[b + 7u]);
    let dp = vec3<f32>(act(w, 0u), act(w, 1u), act(w, 2u)) * params.pos_scale.xyz;
    let yaw = select(act(w, 5u), -(act(w, 5u) + 1.0) * 0.5, params.unidirectional_rot != 0u);
    let dr = vec3<f32>(act(w, 3u), act(w, 4u), yaw) * params.rot_scale.xyz;
    let angle = length(dr);
    var q = quat;
    if (angle > 1.0e-6) {
        // glam's Quat::from_axis_angle, then the turn applied in the world frame.
        let h = 0.5 * angle;
        q = quat_mul(vec4<f32>((dr / angle) * sin(h), cos(h)), quat);
    }
    var out: Input;
    out.target_pos = vec4<f32>(pos + dp, 0.0);
    out.target_quat = q;
    out.target_force = vec4<f32>(vec3<f32>(act(w, 6u), act(w, 7u), act(w, 8u)) * params.force_scale.xyz, 0.0);
    out.target_torque = vec4<f32>(vec3<f32>(act(w, 9u), act(w, 10u), act(w, 11u)) * params.torque_scale.xyz, 0.0);
    out.gripper_q = params.gripper_q;
    out.measured_force = vec4<f32>(0.0);
    out.measured_torque = vec4<f32>(0.0);
    inputs[w] = out;
}
