// Factory's task-space controllers on the device (paper appendix D4, eqs. 3-7): the law of task_space.rs
// (impedance, OSC, open- and closed-loop force, hybrid) and common.rs's finish (gravity compensation, the
// finger PD, clamping), one invocation per world, reading the articulation kernel's per-world record (the
// fingertip frame's pose, twist and geometric Jacobian, M, g: engine articulation/gpu.rs DynamicsLayout)
// and writing the joint torques the articulation's step reads. task_space_gpu.rs documents the layout;
// `Input` and `quat_mul` are in task_space_input.wgsl, prepended.

const MAX_N: u32 = 9u;      // linalg.rs MAX_N: the widest arm
const MAX_DOF: u32 = 16u;   // the engine's MAX_DOFS
const FLAG_MOTION: u32 = 1u;
const FLAG_INERTIAL: u32 = 2u;
const FLAG_FORCE: u32 = 4u;
const FLAG_CLOSED_LOOP: u32 = 8u;
const FLAG_GRAVITY: u32 = 16u;
// linalg.rs SPD6_REGULARISER.
const SPD6_REGULARISER: f32 = 1.0e-7;
// Offsets into `gains` (TaskSpaceGpu::gains): kp, kd, motion axes, force axes, kf (6 each), then the finger
// PD's kp and kd (dof - arm_dof each) and every joint's torque limit (dof).
const G_KP: u32 = 0u;
const G_KD: u32 = 6u;
const G_MOTION_AXES: u32 = 12u;
const G_FORCE_AXES: u32 = 18u;
const G_KF: u32 = 24u;
const G_FINGERS: u32 = 30u;

struct TaskParams {
    world_count: u32,
    dof: u32,
    arm_dof: u32,
    // The articulation record: floats per world and the offsets of J (6 x dof), M (dof x dof) and g (dof).
    stride: u32,
    jacobian: u32,
    mass_matrix: u32,
    gravity_torque: u32,
    flags: u32,
}

@group(0) @binding(0) var<uniform> params: TaskParams;
@group(0) @binding(1) var<storage, read> gains: array<f32>;
@group(1) @binding(0) var<storage, read> world_dynamics: array<f32>;
@group(1) @binding(1) var<storage, read> joint_q: array<f32>;
@group(1) @binding(2) var<storage, read> joint_qd: array<f32>;
@group(1) @binding(3) var<storage, read> inputs: array<Input>;
@group(2) @binding(0) var<storage, read_write> joint_tau: array<f32>;

// A world's working set: the arm's Jacobian block (6 x arm_dof, row-major), a Cholesky factor, M^-1 J^T by
// rows, the 6 x 6 task matrix, a right-hand side and the torques.
var<private> jac: array<f32, 54>;
var<private> lmat: array<f32, 81>;
var<private> xs: array<f32, 54>;
var<private> a6: array<f32, 36>;
var<private> rhs: array<f32, 9>;
var<private> tau: array<f32, 16>;

// The engine's rotation.rs axis_angle_from_quat: the rotation vector, shortest arc.
fn axis_angle_from_quat(q: vec4<f32>) -> vec3<f32> {
    var v = q.xyz;
    var w = q.w;
    if (w < 0.0) {
        v = -v;
        w = -w;
    }
    let s = length(v);
    if (s > 1.0e-6 * max(w, s)) {
        return v * (2.0 * atan2(s, w) / s);
    } else if (w > 0.0) {
        return v * (2.0 / w);
    }
    return vec3<f32>(0.0);
}

// The engine's dynamics.rs cholesky_factor on lmat (row-major n x n): L in the lower triangle, a pivot that
// is not positive floored at 1e-12 of the largest diagonal entry.
fn chol_factor(n: u32) {
    var scale = 0.0;
    for (var i = 0u; i < n; i++) {
        scale = max(scale, abs(lmat[i * n + i]));
    }
    let floor = select(1.0e-30, scale * 1.0e-12, scale > 0.0);
    for (var j = 0u; j < n; j++) {
        var d = lmat[j * n + j];
        for (var k = 0u; k < j; k++) {
            d -= lmat[j * n + k] * lmat[j * n + k];
        }
        if (!(d > floor)) {
            d = floor;
        }
        let ljj = sqrt(d);
        lmat[j * n + j] = ljj;
        for (var i = j + 1u; i < n; i++) {
            var s = lmat[i * n + j];
            for (var k = 0u; k < j; k++) {
                s -= lmat[i * n + k] * lmat[j * n + k];
            }
            lmat[i * n + j] = s / ljj;
        }
    }
}

// rhs <- (L L^T)^-1 rhs with lmat's factor (dynamics.rs cholesky_substitute).
fn chol_solve(n: u32) {
    for (var i = 0u; i < n; i++) {
        var s = rhs[i];
        for (var k = 0u; k < i; k++) {
            s -= lmat[i * n + k] * rhs[k];
        }
        rhs[i] = s / lmat[i * n + i];
    }
    for (var ii = 0u; ii < n; ii++) {
        let i = n - 1u - ii;
        var s = rhs[i];
        for (var k = i + 1u; k < n; k++) {
            s -= lmat[k * n + i] * rhs[k];
        }
        rhs[i] = s / lmat[i * n + i];
    }
}

// task_space.rs task_inertia_times: (J M^-1 J^T)^-1 f with the arm block of M at `m` in the record.
fn task_inertia_times(base: u32, f: array<f32, 6>) -> array<f32, 6> {
    let na = params.arm_dof;
    let n = params.dof;
    for (var r = 0u; r < na; r++) {
        for (var c = 0u; c < na; c++) {
            lmat[r * na + c] = world_dynamics[base + params.mass_matrix + r * n + c];
        }
    }
    chol_factor(na);
    for (var r = 0u; r < 6u; r++) {
        for (var k = 0u; k < na; k++) {
            rhs[k] = jac[r * na + k];
        }
        chol_solve(na);
        for (var k = 0u; k < na; k++) {
            xs[r * na + k] = rhs[k];
        }
    }
    for (var r = 0u; r < 6u; r++) {
        for (var c = 0u; c <= r; c++) {
            var s = 0.0;
            for (var k = 0u; k < na; k++) {
                s += jac[c * na + k] * xs[r * na + k];
            }
            a6[r * 6u + c] = s;
            a6[c * 6u + r] = s;
        }
    }
    // linalg.rs solve_spd6: A + eps (tr A / 6) I, factored and solved.
    var tr = 0.0;
    for (var i = 0u; i < 6u; i++) {
        tr += a6[i * 6u + i];
    }
    let eps = SPD6_REGULARISER * (abs(tr) / 6.0);
    for (var i = 0u; i < 36u; i++) {
        lmat[i] = a6[i];
    }
    for (var i = 0u; i < 6u; i++) {
        lmat[i * 6u + i] += eps;
    }
    chol_factor(6u);
    for (var i = 0u; i < 6u; i++) {
        rhs[i] = f[i];
    }
    chol_solve(6u);
    var y: array<f32, 6>;
    for (var i = 0u; i < 6u; i++) {
        y[i] = rhs[i];
    }
    return y;
}

// tau[..arm_dof] += J^T f.
fn add_jt(f: array<f32, 6>) {
    let na = params.arm_dof;
    for (var c = 0u; c < na; c++) {
        var s = 0.0;
        for (var r = 0u; r < 6u; r++) {
            s += jac[r * na + c] * f[r];
        }
        tau[c] += s;
    }
}

@compute @workgroup_size(64)
fn task_space(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= params.world_count) {
        return;
    }
    let na = params.arm_dof;
    let n = params.dof;
    let base = w * params.stride;
    let input = inputs[w];
    for (var r = 0u; r < 6u; r++) {
        for (var c = 0u; c < na; c++) {
            jac[r * na + c] = world_dynamics[base + params.jacobian + r * n + c];
        }
    }
    for (var i = 0u; i < n; i++) {
        tau[i] = 0.0;
    }
    if ((params.flags & FLAG_MOTION) != 0u) {
        // common.rs task_state with the geometric Jacobian: e = [p_t - p; axis-angle of q_t q^-1], the
        // velocity the measured twist.
        let pos = vec3<f32>(world_dynamics[base], world_dynamics[base + 1u], world_dynamics[base + 2u]);
        let quat = vec4<f32>(world_dynamics[base + 4u], world_dynamics[base + 5u], world_dynamics[base + 6u], world_dynamics[base + 7u]);
        let dp = input.target_pos.xyz - pos;
        let dr = axis_angle_from_quat(quat_mul(input.target_quat, vec4<f32>(-quat.xyz, quat.w)));
        let e = array<f32, 6>(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
        let xd = array<f32, 6>(
            world_dynamics[base + 8u], world_dynamics[base + 9u], world_dynamics[base + 10u],
            world_dynamics[base + 12u], world_dynamics[base + 13u], world_dynamics[base + 14u],
        );
        var f: array<f32, 6>;
        for (var i = 0u; i < 6u; i++) {
            f[i] = gains[G_KP + i] * e[i] - gains[G_KD + i] * xd[i];
        }
        if ((params.flags & FLAG_INERTIAL) != 0u) {
            f = task_inertia_times(base, f);
        }
        for (var i = 0u; i < 6u; i++) {
            f[i] *= gains[G_MOTION_AXES + i];
        }
        add_jt(f);
    }
    if ((params.flags & FLAG_FORCE) != 0u) {
        let ft = array<f32, 6>(input.target_force.x, input.target_force.y, input.target_force.z,
            input.target_torque.x, input.target_torque.y, input.target_torque.z);
        let fc = array<f32, 6>(input.measured_force.x, input.measured_force.y, input.measured_force.z,
            input.measured_torque.x, input.measured_torque.y, input.measured_torque.z);
        let closed = (params.flags & FLAG_CLOSED_LOOP) != 0u;
        var f: array<f32, 6>;
        for (var i = 0u; i < 6u; i++) {
            let fb = select(0.0, gains[G_KF + i] * (ft[i] - fc[i]), closed);
            f[i] = gains[G_FORCE_AXES + i] * (ft[i] + fb);
        }
        add_jt(f);
    }
    // common.rs finish.
    if ((params.flags & FLAG_GRAVITY) != 0u) {
        for (var i = 0u; i < na; i++) {
            tau[i] += world_dynamics[base + params.gravity_torque + i];
        }
    }
    let fingers = n - na;
    for (var f = 0u; f < fingers; f++) {
        let j = na + f;
        tau[j] = gains[G_FINGERS + f] * (input.gripper_q[f] - joint_q[w * n + j]) - gains[G_FINGERS + fingers + f] * joint_qd[w * n + j];
    }
    for (var i = 0u; i < n; i++) {
        let l = gains[G_FINGERS + 2u * fingers + i];
        joint_tau[w * n + i] = clamp(tau[i], -l, l);
    }
}
