// The Screw env's step on the device, around the engine's kernels (screw_step.rs documents the order and the
// layouts): `push_torque` hands the controller kernel's torques to the coupled solve, `pull_joints` hands
// the solve's joints back to the articulation kernel, `evaluate` is nut_bolt.rs's reward, outcome, time
// limit and masked reset (from a bank of start states), `observe` its observation. One invocation per
// world in each. The engine's orthonormal.wgsl (`any_orthonormal`) is appended.

struct ScrewParams {
    world_count: u32,
    // Bodies per world and the nut's index among them.
    body_count: u32,
    nut_body: u32,
    // Joints per world, of which the first arm_dof are the arm's (the fingers follow their drives).
    dof_count: u32,
    arm_dof: u32,
    // Floats per world in the articulation record (articulation/gpu.rs DynamicsLayout).
    stride: u32,
    // The solver's joints in its scratch buffer (solver/articulated.rs CouplingGpu): world 0's positions
    // at vec4 joint_base, then velocities, torques and targets each joint_plane vec4s further; joint_vec4s
    // vec4s per world.
    joint_base: u32,
    joint_plane: u32,
    joint_vec4s: u32,
    // Start states in the bank, each bank_stride vec4s: the world's body poses (2 vec4 per body), then
    // its joint positions (joint_vec4s vec4s).
    bank_count: u32,
    bank_stride: u32,
    max_episode_steps: u32,
    // Floats per observation; flags: bit 0 append the previous action, bit 1 the pads' forces on the nut.
    obs_dim: u32,
    flags: u32,
    // The solve's contact rows in its scratch (solver/articulated.rs RowsLayout) and the pads' pairs.
    rows_base: u32,
    rows_per_world: u32,
    rows_per_pair: u32,
    row_vec4: u32,
    pad_pair_left: u32,
    pad_pair_right: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    _pad3: u32,
    // The nut's centre of mass in its frame [m] (xyz).
    com_local: vec4<f32>,
    // Where the centre of mass is when seated [m] (xyz).
    seated: vec4<f32>,
    // Thread pitch, nut height, bolt diameter, height of the bolt's top [m].
    geometry: vec4<f32>,
    // Failure distance [m], success bonus, failure penalty, finger pad length [m].
    scoring: vec4<f32>,
    // Impulse to mean force over the last substep [1/s] (substeps / dt), and the sign that turns each pad
    // pair's impulse into the force on the nut (+1 where the nut is the pair's query side).
    forces: vec4<f32>,
}

// Keypoint segment length [m] (nut_bolt.rs KEYPOINT_AXIS).
const KEYPOINT_AXIS: f32 = 0.112071;

// Outcome codes of the step's `cause` plane.
const RUNNING: f32 = 0.0;
const SUCCESS: f32 = 1.0;
const FAR: f32 = 2.0;
const SLIPPED: f32 = 3.0;
const FALLEN: f32 = 4.0;
const DIVERGED: f32 = 5.0;

@group(0) @binding(0) var<uniform> params: ScrewParams;
@group(0) @binding(1) var<storage, read> bank: array<vec4<f32>>;

// push_torque
@group(1) @binding(0) var<storage, read> joint_tau: array<f32>;
@group(2) @binding(0) var<storage, read_write> scratch_out: array<vec4<f32>>;

// pull_joints
@group(1) @binding(0) var<storage, read> scratch_in: array<vec4<f32>>;
@group(2) @binding(0) var<storage, read_write> joint_q: array<f32>;
@group(2) @binding(1) var<storage, read_write> joint_qd: array<f32>;

// evaluate (world_dynamics also observe's)
@group(1) @binding(0) var<storage, read> world_dynamics: array<f32>;
@group(1) @binding(1) var<storage, read> actions: array<f32>;
@group(2) @binding(0) var<storage, read_write> body_q: array<vec4<f32>>;
@group(2) @binding(1) var<storage, read_write> body_qd: array<vec4<f32>>;
@group(2) @binding(2) var<storage, read_write> scratch: array<vec4<f32>>;
// Per world: vec4 (steps in the episode, episodes ended, 0, 0: whole numbers in f32), then 3 vec4 of the
// previous action.
@group(2) @binding(3) var<storage, read_write> env_state: array<vec4<f32>>;
// Planes of world_count floats: reward, terminated, truncated, success, cause.
@group(2) @binding(4) var<storage, read_write> step_out: array<f32>;

// observe
@group(1) @binding(1) var<storage, read> body_q_in: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> body_qd_in: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read> env_state_in: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read> rows_in: array<vec4<f32>>;
@group(2) @binding(0) var<storage, read_write> obs: array<f32>;

fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

fn joint_at(plane: u32, w: u32, k: u32) -> u32 {
    return params.joint_base + plane * params.joint_plane + w * params.joint_vec4s + k / 4u;
}

@compute @workgroup_size(64)
fn push_torque(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= params.world_count) {
        return;
    }
    // The fingers' torques stay zero: their drives hold them closed (nut_bolt.rs FrankaNutBolt::step).
    for (var v = 0u; v < params.joint_vec4s; v++) {
        var t = vec4<f32>(0.0);
        for (var c = 0u; c < 4u; c++) {
            let k = 4u * v + c;
            if (k < params.arm_dof) {
                t[c] = joint_tau[w * params.dof_count + k];
            }
        }
        scratch_out[joint_at(2u, w, 4u * v)] = t;
    }
}

@compute @workgroup_size(64)
fn pull_joints(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= params.world_count) {
        return;
    }
    for (var k = 0u; k < params.dof_count; k++) {
        joint_q[w * params.dof_count + k] = scratch_in[joint_at(0u, w, k)][k % 4u];
        joint_qd[w * params.dof_count + k] = scratch_in[joint_at(1u, w, k)][k % 4u];
    }
}

fn record_v3(w: u32, at: u32) -> vec3<f32> {
    let b = w * params.stride + at;
    return vec3<f32>(world_dynamics[b], world_dynamics[b + 1u], world_dynamics[b + 2u]);
}

fn record_quat(w: u32) -> vec4<f32> {
    let b = w * params.stride + 4u;
    return vec4<f32>(world_dynamics[b], world_dynamics[b + 1u], world_dynamics[b + 2u], world_dynamics[b + 3u]);
}

// The pads' midpoint (nut_bolt.rs pad_midpoint): half a pad up the fingers from the fingertip.
fn pad_midpoint(tip: vec3<f32>, q: vec4<f32>) -> vec3<f32> {
    return tip + rotate(q, vec3<f32>(0.0, 0.0, -1.0)) * (0.5 * params.scoring.w);
}

// Sum of the distances between the 4 keypoints of the segments from a along da and from b along db.
fn keypoint_distance(a: vec3<f32>, da: vec3<f32>, b: vec3<f32>, db: vec3<f32>) -> f32 {
    var d = 0.0;
    for (var i = 0u; i < 4u; i++) {
        let t = f32(i) / 3.0 * KEYPOINT_AXIS;
        d += distance(a + da * t, b + db * t);
    }
    return d;
}

// A hash of (world, episode) to pick a start state: the same sequence for every run of a seed-free bank.
fn pick(w: u32, episode: u32) -> u32 {
    var h = w * 0x9E3779B9u ^ (episode + 0x7F4A7C15u) * 0x85EBCA6Bu;
    h ^= h >> 16u;
    h *= 0x7FEB352Du;
    h ^= h >> 15u;
    return h % params.bank_count;
}

@compute @workgroup_size(64)
fn evaluate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= params.world_count) {
        return;
    }
    let tip = record_v3(w, 0u);
    let tip_q = record_quat(w);
    let nb = w * params.body_count + params.nut_body;
    let nut_p = body_q[2u * nb].xyz;
    let nut_q = body_q[2u * nb + 1u];
    let com = nut_p + rotate(nut_q, params.com_local.xyz);
    let status = scratch[w];
    // The solve's verdict (articulated.wgsl): x is 1 for a world that stayed finite and under the bound.
    let diverged = status.x != 1.0;
    let pads = pad_midpoint(tip, tip_q);
    let to_target = distance(com, params.seated.xyz);
    let pitch = params.geometry.x;
    let nut_height = params.geometry.y;
    var cause = RUNNING;
    // nut_bolt.rs Screw::outcome, in its order.
    if (diverged) {
        cause = DIVERGED;
    } else if (to_target < pitch) {
        cause = SUCCESS;
    } else if (length(com.xy) > 0.5 * params.geometry.z && com.z < params.geometry.w + 0.5 * nut_height) {
        cause = FALLEN;
    } else if (distance(com, pads) > 0.5 * params.scoring.w + 0.5 * nut_height) {
        cause = SLIPPED;
    } else if (to_target > params.scoring.x) {
        cause = FAR;
    }
    let up = vec3<f32>(0.0, 0.0, 1.0);
    let nut_axis = rotate(nut_q, up);
    let shaped = -(keypoint_distance(com, nut_axis, params.seated.xyz, up)
        + keypoint_distance(com, nut_axis, pads, rotate(tip_q, -up)));
    var reward = select(shaped, 0.0, diverged);
    if (cause == SUCCESS) {
        reward += params.scoring.y;
    } else if (cause != RUNNING) {
        reward -= params.scoring.z;
    }
    var counters = env_state[4u * w];
    let steps = counters.x + 1.0;
    let timed_out = cause == RUNNING && steps >= f32(params.max_episode_steps);
    let n = params.world_count;
    step_out[w] = reward;
    step_out[n + w] = select(0.0, 1.0, cause != RUNNING);
    step_out[2u * n + w] = select(0.0, 1.0, timed_out);
    step_out[3u * n + w] = select(0.0, 1.0, cause == SUCCESS);
    step_out[4u * n + w] = cause;
    let done = cause != RUNNING || timed_out;
    for (var k = 0u; k < 3u; k++) {
        let b = w * 12u + 4u * k;
        let a = clamp(vec4<f32>(actions[b], actions[b + 1u], actions[b + 2u], actions[b + 3u]), vec4<f32>(-1.0), vec4<f32>(1.0));
        env_state[4u * w + 1u + k] = select(a, vec4<f32>(0.0), done);
    }
    if (!done) {
        counters.x = steps;
        env_state[4u * w] = counters;
        return;
    }
    // Masked reset (nut_bolt.rs NutBoltScene::reset_world): the bank's bodies and joints, every body and
    // joint at rest (the host zeroes the nut's and the joints' velocities; the link bodies' twists follow
    // from the joints at the step's end, and zeroing them too clears a diverged world's), and a cold warm
    // start: the solver matches only rows stamped with the frame before (solver_core.wgsl match_old), so
    // skipping a frame number forgets every row of this world.
    let episode = u32(counters.y);
    let e = pick(w, episode) * params.bank_stride;
    for (var b = 0u; b < params.body_count; b++) {
        let at = 2u * (w * params.body_count + b);
        body_q[at] = bank[e + 2u * b];
        body_q[at + 1u] = bank[e + 2u * b + 1u];
        body_qd[at] = vec4<f32>(0.0);
        body_qd[at + 1u] = vec4<f32>(0.0);
    }
    for (var v = 0u; v < params.joint_vec4s; v++) {
        scratch[joint_at(0u, w, 4u * v)] = bank[e + 2u * params.body_count + v];
        scratch[joint_at(1u, w, 4u * v)] = vec4<f32>(0.0);
    }
    scratch[w] = vec4<f32>(status.x, 0.0, 0.0, bitcast<f32>(bitcast<u32>(status.w) + 1u));
    env_state[4u * w] = vec4<f32>(0.0, counters.y + 1.0, 0.0, 0.0);
}

// The summed impulse [N s] of pair `pair`'s rows of the world's last frame (GpuArticulatedSolver::pair_impulse
// on the device: the same rows in the same order).
fn pair_impulse(w: u32, pair: u32) -> vec3<f32> {
    let frame = bitcast<u32>(rows_in[w].w);
    let first = params.rows_base + (w * params.rows_per_world + pair * params.rows_per_pair) * params.row_vec4;
    var sum = vec3<f32>(0.0);
    for (var k = 0u; k < params.rows_per_pair; k++) {
        let r = first + k * params.row_vec4;
        let n = rows_in[r + 2u].xyz;
        if (bitcast<u32>(rows_in[r].w) == pair && bitcast<u32>(rows_in[r + 3u].w) == frame && any(n != vec3<f32>(0.0))) {
            let t1 = any_orthonormal(n);
            let i = rows_in[r + 1u];
            sum += i.x * n + i.y * t1 + i.z * cross(n, t1);
        }
    }
    return sum;
}

@compute @workgroup_size(64)
fn observe(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= params.world_count) {
        return;
    }
    let o = w * params.obs_dim;
    let tip = record_v3(w, 0u);
    let tip_q = record_quat(w);
    let tip_v = record_v3(w, 8u);
    let tip_omega = record_v3(w, 12u);
    let nb = w * params.body_count + params.nut_body;
    let nut_p = body_q_in[2u * nb].xyz;
    let nut_q = body_q_in[2u * nb + 1u];
    let com = nut_p + rotate(nut_q, params.com_local.xyz);
    let nut_v = body_qd_in[2u * nb].xyz;
    let nut_omega = body_qd_in[2u * nb + 1u].xyz;
    // nut_bolt.rs FrankaNutBolt::observe's order.
    let head = array<f32, 26>(
        tip.x, tip.y, tip.z, tip_q.x, tip_q.y, tip_q.z, tip_q.w, tip_v.x, tip_v.y, tip_v.z,
        tip_omega.x, tip_omega.y, tip_omega.z,
        com.x, com.y, com.z, nut_q.x, nut_q.y, nut_q.z, nut_q.w, nut_v.x, nut_v.y, nut_v.z,
        nut_omega.x, nut_omega.y, nut_omega.z,
    );
    for (var k = 0u; k < 26u; k++) {
        obs[o + k] = head[k];
    }
    var at = o + 26u;
    if ((params.flags & 2u) != 0u) {
        let left = pair_impulse(w, params.pad_pair_left) * (params.forces.x * params.forces.y);
        let right = pair_impulse(w, params.pad_pair_right) * (params.forces.x * params.forces.z);
        let f = array<f32, 6>(left.x, left.y, left.z, right.x, right.y, right.z);
        for (var k = 0u; k < 6u; k++) {
            obs[at + k] = f[k];
        }
        at += 6u;
    }
    if ((params.flags & 1u) != 0u) {
        for (var k = 0u; k < 3u; k++) {
            let a = env_state_in[4u * w + 1u + k];
            obs[at + 4u * k] = a.x;
            obs[at + 4u * k + 1u] = a.y;
            obs[at + 4u * k + 2u] = a.z;
            obs[at + 4u * k + 3u] = a.w;
        }
    }
}
