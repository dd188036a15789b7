// The articulation's dynamics functions (see gpu.rs for the algorithm and the GPU-cost notes), shared by
// articulation.wgsl (the articulation alone) and solver/articulated.wgsl (the articulation coupled with
// contacts). Each of those declares what is used here: `params` (ArtParams), `links` and `dofs` (indexable
// arrays of Link and Dof, storage or uniform), NONE, quat_rotate, quat_mul, and tau_at / target_at (a
// world's joint torque and drive target).

// Bounds of the private arrays below; gpu.rs refuses larger models (MAX_DOFS, MAX_LINKS there).
const MAX_DOFS: u32 = 16u;
const MAX_LINKS: u32 = 32u;
const JOINT_REVOLUTE: u32 = 1u;
const JOINT_PRISMATIC: u32 = 2u;
const TWO_PI: f32 = 6.283185307179586;

struct ArtParams {
    world_count: u32,
    link_count: u32,
    dof_count: u32,
    frame_link: u32,
    frame_p: vec4<f32>,
    frame_q: vec4<f32>,
    gravity: vec4<f32>,
    dt: f32,
    substeps: u32,
    // 1: the position drives act (a non-empty joint_target_q on the host), 0: effort only.
    drives: u32,
    dynamics_stride: u32,
    // Offsets [f32] in a world's dynamics record; the frame's pose and twist sit at 0..16.
    jacobian_offset: u32,
    mass_offset: u32,
    gravity_offset: u32,
    coriolis_offset: u32,
}

struct Link {
    origin_p: vec4<f32>,
    origin_q: vec4<f32>,
    axis: vec4<f32>,
    com_mass: vec4<f32>,
    inertia: mat3x3<f32>,
    parent: u32,
    joint: u32,
    dof: u32,
    _pad: u32,
}

struct Dof {
    lower: f32,
    upper: f32,
    velocity_limit: f32,
    effort_limit: f32,
    damping: f32,
    armature: f32,
    drive_stiffness: f32,
    drive_damping: f32,
}

// One world's working set, private to the invocation (see the GPU-cost notes in gpu.rs).
var<private> q: array<f32, MAX_DOFS>;
var<private> qd: array<f32, MAX_DOFS>;
var<private> pose_p: array<vec3<f32>, MAX_LINKS>;
var<private> pose_q: array<vec4<f32>, MAX_LINKS>;
// The mass matrix, then (step) the Cholesky factor of M + h (D + Kd) in its lower triangle.
var<private> mass: array<f32, 256>; // MAX_DOFS * MAX_DOFS
var<private> rhs: array<f32, MAX_DOFS>;
var<private> bias: array<f32, MAX_DOFS>;
// Recursive Newton-Euler per link: angular velocity, angular acceleration, origin acceleration, then the
// force and the moment about the origin its subtree needs.
var<private> rn_w: array<vec3<f32>, MAX_LINKS>;
var<private> rn_al: array<vec3<f32>, MAX_LINKS>;
var<private> rn_a: array<vec3<f32>, MAX_LINKS>;
var<private> rn_f: array<vec3<f32>, MAX_LINKS>;
var<private> rn_n: array<vec3<f32>, MAX_LINKS>;
// The columns of one link's centre-of-mass Jacobian (mass_matrix).
var<private> col_dof: array<u32, MAX_DOFS>;
var<private> col_v: array<vec3<f32>, MAX_DOFS>;
var<private> col_w: array<vec3<f32>, MAX_DOFS>;

// I_world x for link l at rotation r: R I R^T x without forming R (two rotations and a 3x3 product).
fn world_inertia_times(l: u32, r: vec4<f32>, x: vec3<f32>) -> vec3<f32> {
    let r_inv = vec4<f32>(-r.xyz, r.w);
    return quat_rotate(r, links[l].inertia * quat_rotate(r_inv, x));
}

// The joint axis of link l in the world.
fn world_axis(l: u32) -> vec3<f32> {
    return quat_rotate(pose_q[l], links[l].axis.xyz);
}

// Link poses from q (dynamics.rs forward_kinematics).
fn forward_kinematics() {
    var l = 0u;
    loop {
        let link = links[l];
        var lp = link.origin_p.xyz;
        var lq = link.origin_q;
        if (link.dof != NONE) {
            let x = q[link.dof];
            if (link.joint == JOINT_REVOLUTE) {
                // The half angle reduced to [-pi, pi], where WGSL's sin and cos are accurate (GPUs' fast
                // sin loses digits beyond it); a continuous joint turning a nut passes many turns. A no-op
                // (bitwise) for |q| <= 2 pi, so parity with the host's sin_cos is unaffected.
                var half_angle = 0.5 * x;
                half_angle -= TWO_PI * round(half_angle / TWO_PI);
                lq = quat_mul(lq, vec4<f32>(link.axis.xyz * sin(half_angle), cos(half_angle)));
            } else if (link.joint == JOINT_PRISMATIC) {
                lp = lp + quat_rotate(lq, link.axis.xyz * x);
            }
        }
        if (link.parent == NONE) {
            pose_p[l] = lp;
            pose_q[l] = lq;
        } else {
            let pq = pose_q[link.parent];
            pose_p[l] = pose_p[link.parent] + quat_rotate(pq, lp);
            pose_q[l] = normalize(quat_mul(pq, lq));
        }
        l += 1u;
        if (l >= params.link_count) {
            break;
        }
    }
}

// M = sum over links of m Jc^T Jc + Jw^T I Jw, plus the armature on the diagonal (dynamics.rs
// mass_matrix). Only the lower triangle (row >= column) is accumulated: the Cholesky factor reads no other,
// and `dynamics` mirrors it; that halves the pair loop.
fn mass_matrix() {
    let n = params.dof_count;
    for (var i = 0u; i < n * n; i++) {
        mass[i] = 0.0;
    }
    var l = 0u;
    loop {
        let m = links[l].com_mass.w;
        if (m > 0.0) {
            let r = pose_q[l];
            let c = pose_p[l] + quat_rotate(r, links[l].com_mass.xyz);
            var k = 0u;
            var a = l;
            loop {
                let d = links[a].dof;
                if (d != NONE) {
                    let axis = world_axis(a);
                    col_dof[k] = d;
                    if (links[a].joint == JOINT_PRISMATIC) {
                        col_v[k] = axis;
                        col_w[k] = vec3<f32>(0.0);
                    } else {
                        col_v[k] = cross(axis, c - pose_p[a]);
                        col_w[k] = axis;
                    }
                    k += 1u;
                }
                a = links[a].parent;
                if (a == NONE) {
                    break;
                }
            }
            for (var i = 0u; i < k; i++) {
                let iwi = world_inertia_times(l, r, col_w[i]);
                let di = col_dof[i];
                for (var j = i; j < k; j++) {
                    let dj = col_dof[j];
                    let idx = max(di, dj) * n + min(di, dj);
                    mass[idx] += m * dot(col_v[i], col_v[j]) + dot(iwi, col_w[j]);
                }
            }
        }
        l += 1u;
        if (l >= params.link_count) {
            break;
        }
    }
    for (var d = 0u; d < n; d++) {
        mass[d * n + d] += dofs[d].armature;
    }
}

// bias = c(q, qd) [+ g(q)] by the recursive Newton-Euler algorithm with qdd = 0 (dynamics.rs
// inverse_dynamics): with_velocity false takes qd = 0. Both flags are constants at every call site, so the
// untaken terms compile out after inlining.
fn inverse_dynamics(with_gravity: bool, with_velocity: bool) {
    var base_acc = vec3<f32>(0.0);
    if (with_gravity) {
        base_acc = -params.gravity.xyz;
    }
    var l = 0u;
    loop {
        let link = links[l];
        var wp = vec3<f32>(0.0);
        var alp = vec3<f32>(0.0);
        var ap = base_acc;
        var op = pose_p[l];
        if (link.parent != NONE) {
            wp = rn_w[link.parent];
            alp = rn_al[link.parent];
            ap = rn_a[link.parent];
            op = pose_p[link.parent];
        }
        let rel = pose_p[l] - op;
        var wl = wp;
        var alc = alp;
        var acc = ap + cross(alp, rel) + cross(wp, cross(wp, rel));
        if (link.dof != NONE && with_velocity) {
            let axis_v = world_axis(l) * qd[link.dof];
            if (link.joint == JOINT_REVOLUTE) {
                wl = wp + axis_v;
                alc = alp + cross(wp, axis_v);
            } else if (link.joint == JOINT_PRISMATIC) {
                acc += 2.0 * cross(wp, axis_v);
            }
        }
        rn_w[l] = wl;
        rn_al[l] = alc;
        rn_a[l] = acc;
        rn_f[l] = vec3<f32>(0.0);
        rn_n[l] = vec3<f32>(0.0);
        l += 1u;
        if (l >= params.link_count) {
            break;
        }
    }
    // Children come after their parents, so walking backwards every child has added its subtree's force
    // to its parent before the parent is visited.
    l = params.link_count;
    loop {
        l -= 1u;
        let link = links[l];
        let m = link.com_mass.w;
        if (m > 0.0) {
            let r = pose_q[l];
            let rc = quat_rotate(r, link.com_mass.xyz);
            let w = rn_w[l];
            let al = rn_al[l];
            let ac = rn_a[l] + cross(al, rc) + cross(w, cross(w, rc));
            let fc = m * ac;
            rn_f[l] += fc;
            rn_n[l] += world_inertia_times(l, r, al) + cross(w, world_inertia_times(l, r, w)) + cross(rc, fc);
        }
        if (link.parent != NONE) {
            let p = link.parent;
            rn_f[p] += rn_f[l];
            rn_n[p] += rn_n[l] + cross(pose_p[l] - pose_p[p], rn_f[l]);
        }
        if (link.dof != NONE) {
            let axis = world_axis(l);
            if (link.joint == JOINT_PRISMATIC) {
                bias[link.dof] = dot(axis, rn_f[l]);
            } else {
                bias[link.dof] = dot(axis, rn_n[l]);
            }
        }
        if (l == 0u) {
            break;
        }
    }
}

// In-place Cholesky factorisation of `mass` (lower triangle); false if not positive definite (dynamics.rs
// cholesky_factor).
fn cholesky_factor() -> bool {
    let n = params.dof_count;
    for (var j = 0u; j < n; j++) {
        var s = mass[j * n + j];
        for (var k = 0u; k < j; k++) {
            s -= mass[j * n + k] * mass[j * n + k];
        }
        if (!(s > 0.0)) {
            return false;
        }
        let d = sqrt(s);
        mass[j * n + j] = d;
        for (var i = j + 1u; i < n; i++) {
            var t = mass[i * n + j];
            for (var k = 0u; k < j; k++) {
                t -= mass[i * n + k] * mass[j * n + k];
            }
            mass[i * n + j] = t / d;
        }
    }
    return true;
}

// rhs <- (L L^T)^-1 rhs with the factor in `mass` (dynamics.rs cholesky_substitute).
fn cholesky_substitute() {
    let n = params.dof_count;
    for (var i = 0u; i < n; i++) {
        var s = rhs[i];
        for (var k = 0u; k < i; k++) {
            s -= mass[i * n + k] * rhs[k];
        }
        rhs[i] = s / mass[i * n + i];
    }
    for (var ii = 0u; ii < n; ii++) {
        let i = n - 1u - ii;
        var s = rhs[i];
        for (var k = i + 1u; k < n; k++) {
            s -= mass[k * n + i] * rhs[k];
        }
        rhs[i] = s / mass[i * n + i];
    }
}

// The first half of a substep (dynamics.rs free_velocity): qd += h (M + h (D + Kd))^-1 (clamped actuator
// - c - g - D qd). False (qd untouched) when the matrix is not positive definite.
fn free_velocity(base: u32, h: f32) -> bool {
    let n = params.dof_count;
    mass_matrix();
    inverse_dynamics(true, true);
    let driven = params.drives != 0u;
    for (var d = 0u; d < n; d++) {
        let dof = dofs[d];
        var actuator = tau_at(base, d);
        var implicit_damping = dof.damping;
        if (driven) {
            actuator += dof.drive_stiffness * (target_at(base, d) - q[d]) - dof.drive_damping * qd[d];
            implicit_damping += dof.drive_damping;
        }
        let limit = dof.effort_limit;
        rhs[d] = clamp(actuator, -limit, limit) - bias[d] - dof.damping * qd[d];
        mass[d * n + d] += h * implicit_damping;
    }
    if (!cholesky_factor()) {
        return false;
    }
    cholesky_substitute();
    for (var d = 0u; d < n; d++) {
        qd[d] += h * rhs[d];
    }
    return true;
}

// The second half of a substep (dynamics.rs integrate_positions): velocity limit, q += h qd, position limits.
fn integrate_positions(h: f32) {
    for (var d = 0u; d < params.dof_count; d++) {
        let dof = dofs[d];
        let v = clamp(qd[d], -dof.velocity_limit, dof.velocity_limit);
        var x = q[d] + h * v;
        var vel = v;
        if (x < dof.lower) {
            x = dof.lower;
            vel = max(vel, 0.0);
        } else if (x > dof.upper) {
            x = dof.upper;
            vel = min(vel, 0.0);
        }
        q[d] = x;
        qd[d] = vel;
    }
}
