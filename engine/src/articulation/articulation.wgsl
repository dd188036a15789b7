// Articulation dynamics on the GPU: the WGSL twin of articulation/dynamics.rs (see gpu.rs for the algorithm,
// the references and the GPU-cost notes), its functions in articulation_core.wgsl (appended by gpu.rs). One
// invocation per world: a world's tree is walked serially (parent before child), and the worlds are
// independent.
//
// Entry points (one shared pipeline layout, gpu.rs):
// - `dynamics`: joint_q, joint_qd -> link_pose and the world's record in world_dynamics (frame pose and
//   twist, frame Jacobian, M with armature, g, c): dynamics.rs world_dynamics.
// - `step`: one frame of dynamics.rs step_world under joint_tau / joint_target_q, in place on joint_q and
//   joint_qd.
//
// Loops: llvmpipe (lavapipe) gives an invocation one budget of loop passes shared by all its loops and cuts
// every loop short past it (contact/common.wgsl); gpu.rs counts this file's passes (loop_passes) and refuses
// settings beyond the budget, so keep that count in step with every loop here. Loops whose body runs at
// least once (links: a model has a root; substeps >= 1) test their exit at the end of the pass, because
// llvmpipe runs a top-tested loop's body once more, masked, after its last pass; loops that may run zero
// times (dofs, the columns of a triangle) stay top-tested.

const NONE: u32 = 0xffffffffu;

struct Pose {
    p: vec4<f32>,
    q: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: ArtParams;
@group(0) @binding(1) var<storage, read> links: array<Link>;
@group(0) @binding(2) var<storage, read> dofs: array<Dof>;
@group(1) @binding(0) var<storage, read> joint_tau: array<f32>;
@group(1) @binding(1) var<storage, read> joint_target_q: array<f32>;
@group(2) @binding(0) var<storage, read_write> joint_q: array<f32>;
@group(2) @binding(1) var<storage, read_write> joint_qd: array<f32>;
@group(2) @binding(2) var<storage, read_write> link_pose: array<Pose>;
@group(2) @binding(3) var<storage, read_write> world_dynamics: array<f32>;

fn quat_rotate(r: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(r.xyz, v);
    return v + r.w * t + cross(r.xyz, t);
}

fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz), a.w * b.w - dot(a.xyz, b.xyz));
}


// The core's accessors of a world's control (articulation_core.wgsl).
fn tau_at(base: u32, d: u32) -> f32 {
    return joint_tau[base + d];
}

fn target_at(base: u32, d: u32) -> f32 {
    return joint_target_q[base + d];
}

fn load_joints(base: u32) {
    for (var d = 0u; d < params.dof_count; d++) {
        q[d] = joint_q[base + d];
        qd[d] = joint_qd[base + d];
    }
}

@compute @workgroup_size(64)
fn step(@builtin(global_invocation_id) gid: vec3<u32>) {
    let world = gid.x;
    if (world >= params.world_count) {
        return;
    }
    let base = world * params.dof_count;
    load_joints(base);
    let h = params.dt / f32(params.substeps);
    var sub = 0u;
    loop {
        forward_kinematics();
        if (free_velocity(base, h)) {
            integrate_positions(h);
        }
        sub += 1u;
        if (sub >= params.substeps) {
            break;
        }
    }
    for (var d = 0u; d < params.dof_count; d++) {
        joint_q[base + d] = q[d];
        joint_qd[base + d] = qd[d];
    }
}

@compute @workgroup_size(64)
fn dynamics(@builtin(global_invocation_id) gid: vec3<u32>) {
    let world = gid.x;
    if (world >= params.world_count) {
        return;
    }
    let n = params.dof_count;
    load_joints(world * n);
    forward_kinematics();
    var l = 0u;
    loop {
        link_pose[world * params.link_count + l] = Pose(vec4<f32>(pose_p[l], 0.0), pose_q[l]);
        l += 1u;
        if (l >= params.link_count) {
            break;
        }
    }
    let rec = world * params.dynamics_stride;
    let fl = params.frame_link;
    let fp = pose_p[fl] + quat_rotate(pose_q[fl], params.frame_p.xyz);
    let fq = quat_mul(pose_q[fl], params.frame_q);
    // The frame's Jacobian (dynamics.rs point_jacobian): zero, then the columns of the dofs moving it, from
    // the frame's link to the root; its twist J qd is summed along the same walk.
    let jac = rec + params.jacobian_offset;
    for (var i = 0u; i < 6u * n; i++) {
        world_dynamics[jac + i] = 0.0;
    }
    var lin = vec3<f32>(0.0);
    var ang = vec3<f32>(0.0);
    var a = fl;
    loop {
        let d = links[a].dof;
        if (d != NONE) {
            let axis = world_axis(a);
            var v = axis;
            var w = vec3<f32>(0.0);
            if (links[a].joint != JOINT_PRISMATIC) {
                v = cross(axis, fp - pose_p[a]);
                w = axis;
            }
            for (var k = 0u; k < 3u; k++) {
                world_dynamics[jac + k * n + d] = v[k];
                world_dynamics[jac + (3u + k) * n + d] = w[k];
            }
            lin += v * qd[d];
            ang += w * qd[d];
        }
        a = links[a].parent;
        if (a == NONE) {
            break;
        }
    }
    for (var k = 0u; k < 4u; k++) {
        world_dynamics[rec + k] = vec4<f32>(fp, 0.0)[k];
        world_dynamics[rec + 4u + k] = fq[k];
        world_dynamics[rec + 8u + k] = vec4<f32>(lin, 0.0)[k];
        world_dynamics[rec + 12u + k] = vec4<f32>(ang, 0.0)[k];
    }
    mass_matrix();
    let mo = rec + params.mass_offset;
    for (var i = 0u; i < n; i++) {
        for (var j = 0u; j <= i; j++) {
            let v = mass[i * n + j];
            world_dynamics[mo + i * n + j] = v;
            world_dynamics[mo + j * n + i] = v;
        }
    }
    inverse_dynamics(true, false);
    for (var d = 0u; d < n; d++) {
        world_dynamics[rec + params.gravity_offset + d] = bias[d];
    }
    inverse_dynamics(false, true);
    for (var d = 0u; d < n; d++) {
        world_dynamics[rec + params.coriolis_offset + d] = bias[d];
    }
}
