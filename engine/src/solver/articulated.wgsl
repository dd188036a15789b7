// Rigid bodies and an articulation stepped together on the GPU: the WGSL twin of
// solver::step_cpu_articulated (see solver/mod.rs for the contact scheme and articulation/dynamics.rs
// ContactResponse for the coupling). One invocation per world, as solver.wgsl.
//
// Per substep of length h: forward kinematics; the joints' velocity before contact (free_velocity, which
// leaves the Cholesky factor of A = M + h (D + Kd) in `mass`); each link body's twist Jacobian J_s at its
// centre of mass, Y_s = A^-1 J_s^T, and the blocks K_st = J_s Y_t (how link s's twist answers a spatial
// impulse on link t); the link bodies' twists J_s qd. The rows then see a link body through K: an impulse
// u on link t changes every link's twist by K_st u and is summed into link_phi[t]. After the position
// sweeps the joints take the impulses (qd += sum_t Y_t phi_t), integrate and move the link bodies by
// forward kinematics; the velocity sweeps follow, and the joints take their impulses too.
//
// Prepended by the host: contact/common.wgsl; appended: solver_sweep.wgsl, solver_core.wgsl,
// articulation/articulation_core.wgsl, contact/sdf_sample.wgsl and the analytic SDFs.
//
// Bindings: the 8 storage buffers of solver.wgsl (the joint state and control live in solver_scratch
// behind the rows), and the articulation model as uniforms (uniform buffers do not count against the 8
// storage buffers a stage may bind; on a GPU they are also read through the constant cache).

@group(0) @binding(0) var<uniform> sp: SolverParams;
@group(0) @binding(1) var<storage, read> pairs: array<Pair>;
@group(0) @binding(2) var<storage, read> sdf_values: array<u32>;
@group(0) @binding(3) var<storage, read> bodies: array<Body>;
@group(0) @binding(4) var<uniform> params: ArtParams;
@group(0) @binding(5) var<uniform> links: array<Link, MAX_LINKS>;
@group(0) @binding(6) var<uniform> dofs: array<Dof, MAX_DOFS>;
@group(0) @binding(7) var<uniform> coupling: Coupling;
@group(1) @binding(0) var<storage, read> patches: array<PatchOut>;
@group(1) @binding(1) var<storage, read> patch_counts: array<u32>;
@group(2) @binding(0) var<storage, read_write> body_q: array<Transform>;
@group(2) @binding(1) var<storage, read_write> body_qd: array<vec4<f32>>;
// Status per world, wrenches per body, rows (solver_core.wgsl), then the joints (Coupling.joint_base).
@group(2) @binding(2) var<storage, read_write> solver_scratch: array<vec4<f32>>;

// Link bodies (slots) a world may have (articulated.rs MAX_SLOTS).
const MAX_SLOTS: u32 = 4u;

struct Coupling {
    // Link bodies per world.
    slot_count: u32,
    // vec4 index in solver_scratch of world 0's joint positions; the velocities, torques and drive
    // targets follow, joint_plane vec4s apart, each world's vector joint_vec4s (ceil(dof_count / 4)) long.
    joint_base: u32,
    joint_plane: u32,
    joint_vec4s: u32,
    // Per slot: its body and its link.
    slot_body: vec4<u32>,
    slot_link: vec4<u32>,
    // Loop passes of a frame's articulation work (articulated.rs), for the loop budget.
    art_passes: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Slots, a constant of the pipeline: the per-impulse response over the slots is written out for each,
// not looped (lavapipe counts every loop pass of an invocation against one budget).
override SLOT_COUNT: u32 = 2u;
// Gauss-Seidel passes per sweep over a patch that touches a link (max of SolverConfig::patch_iters and
// link_patch_iters).
override LINK_PATCH_ITERS: u32 = 1u;

// The link bodies' twists (centre-of-mass velocity, angular velocity) during the sweeps, and the spatial
// impulses (force [N s], torque about the centre of mass [N m s]) applied to each since the joints last
// took them; [2 s] linear, [2 s + 1] angular.
var<private> link_v: array<vec3<f32>, 8>;
var<private> link_phi: array<vec3<f32>, 8>;
// Per slot s and dof d at s MAX_DOFS + d: column d of J_s (the twist Jacobian at the link's centre of
// mass: linear, angular) and row d of Y_s = A^-1 J_s^T (force, torque parts).
var<private> slot_jl: array<vec3<f32>, 64>;
var<private> slot_ja: array<vec3<f32>, 64>;
var<private> slot_yl: array<vec3<f32>, 64>;
var<private> slot_ya: array<vec3<f32>, 64>;
// K_st for slots s, t at 4 (s MAX_SLOTS + t): the blocks (linear <- force, linear <- torque,
// angular <- force, angular <- torque).
var<private> kblk: array<mat3x3<f32>, 64>;

fn body_awake(g: u32) -> bool {
    return true;
}

// The slot of body b (NONE: not a link body, or the static world).
fn slot_of(b: u32) -> u32 {
    if (b == NONE) {
        return NONE;
    }
    let f = bodies[b].flags.y;
    return select(NONE, f - 1u, f != 0u);
}

// World w's joint positions in solver_scratch (its velocities, torques and targets a plane, two and three
// planes on).
fn joint_block(world: u32) -> u32 {
    return coupling.joint_base + world * coupling.joint_vec4s;
}

fn joint_get(at: u32, d: u32) -> f32 {
    return solver_scratch[at + d / 4u][d % 4u];
}

fn joint_set(at: u32, d: u32, x: f32) {
    solver_scratch[at + d / 4u][d % 4u] = x;
}

// articulation_core.wgsl's accessors: `base` is the world's joint block.
fn tau_at(base: u32, d: u32) -> f32 {
    return joint_get(base + 2u * coupling.joint_plane, d);
}

fn target_at(base: u32, d: u32) -> f32 {
    return joint_get(base + 3u * coupling.joint_plane, d);
}

// A spatial vector: linear and angular parts.
struct Sv {
    lin: vec3<f32>,
    ang: vec3<f32>,
}

fn sv_dot(a: Sv, b: Sv) -> f32 {
    return dot(a.lin, b.lin) + dot(a.ang, b.ang);
}

// K_st u.
fn k_times(s: u32, t: u32, u: Sv) -> Sv {
    let i = 4u * (s * MAX_SLOTS + t);
    return Sv(kblk[i] * u.lin + kblk[i + 1u] * u.ang, kblk[i + 2u] * u.lin + kblk[i + 3u] * u.ang);
}

// What a pass over one pair's rows reads once when a side is a link body: PairCtx, the link side's slot,
// and its sign (+1: the link is body a, which takes +d of an impulse along d; -1: it is b).
struct LinkCtx {
    c: PairCtx,
    ls: u32,
    sign: f32,
}

// Per slot, the twist change (linear [2 s], angular [2 s + 1]) of a unit impulse along the direction last
// given to link_response: K_{s, ls} u (an impulse on one finger moves the arm, so the other finger too).
var<private> dir_w: array<vec3<f32>, 8>;

// The link side's lever arm.
fn link_lever(l: LinkCtx, ra: vec3<f32>, rb: vec3<f32>) -> vec3<f32> {
    return select(rb, ra, l.sign > 0.0);
}

// Fills dir_w for direction d (not necessarily unit) and returns the link side's part of the inverse
// effective mass along d, u . K_{ls, ls} u with u its spatial impulse (solver/mod.rs Step::eff).
fn link_response(l: LinkCtx, ra: vec3<f32>, rb: vec3<f32>, d: vec3<f32>) -> f32 {
    let u = Sv(l.sign * d, l.sign * cross(link_lever(l, ra, rb), d));
    if (SLOT_COUNT > 0u) {
        let w = k_times(0u, l.ls, u);
        dir_w[0] = w.lin;
        dir_w[1] = w.ang;
    }
    if (SLOT_COUNT > 1u) {
        let w = k_times(1u, l.ls, u);
        dir_w[2] = w.lin;
        dir_w[3] = w.ang;
    }
    if (SLOT_COUNT > 2u) {
        let w = k_times(2u, l.ls, u);
        dir_w[4] = w.lin;
        dir_w[5] = w.ang;
    }
    if (SLOT_COUNT > 3u) {
        let w = k_times(3u, l.ls, u);
        dir_w[6] = w.lin;
        dir_w[7] = w.ang;
    }
    return sv_dot(u, Sv(dir_w[2u * l.ls], dir_w[2u * l.ls + 1u]));
}

// Velocity along d of the row's point on a relative to b (the link side through its twist, the rigid side
// through the velocity the pass carries).
fn link_rel(l: LinkCtx, vla: Vel, vlb: Vel, ra: vec3<f32>, rb: vec3<f32>, d: vec3<f32>) -> f32 {
    let rl = link_lever(l, ra, rb);
    let vl = link_v[2u * l.ls] + cross(link_v[2u * l.ls + 1u], rl);
    let va = select(vel_at(vla, ra), vl, l.sign > 0.0);
    let vb = select(vl, vel_at(vlb, rb), l.sign > 0.0);
    return dot(va - vb, d);
}

// Applies x times the impulse d at the row's point (+d to a, -d to b), d the direction link_response was
// last given: the rigid side through its mass and inertia (vel_apply leaves the link body's zero-mass
// Dyn alone), every slot through dir_w, and the link's impulse tally.
fn link_apply(l: LinkCtx, vla: ptr<function, Vel>, vlb: ptr<function, Vel>, ra: vec3<f32>, rb: vec3<f32>, d: vec3<f32>, x: f32) {
    *vla = vel_apply(l.c.da, *vla, ra, d * x, 1.0);
    *vlb = vel_apply(l.c.db, *vlb, rb, d * x, -1.0);
    link_phi[2u * l.ls] += (l.sign * x) * d;
    link_phi[2u * l.ls + 1u] += (l.sign * x) * cross(link_lever(l, ra, rb), d);
    if (SLOT_COUNT > 0u) {
        link_v[0] += dir_w[0] * x;
        link_v[1] += dir_w[1] * x;
    }
    if (SLOT_COUNT > 1u) {
        link_v[2] += dir_w[2] * x;
        link_v[3] += dir_w[3] * x;
    }
    if (SLOT_COUNT > 2u) {
        link_v[4] += dir_w[4] * x;
        link_v[5] += dir_w[5] * x;
    }
    if (SLOT_COUNT > 3u) {
        link_v[6] += dir_w[6] * x;
        link_v[7] += dir_w[7] * x;
    }
}

// One tangential row along t with a link side: the new accumulated impulse.
fn link_friction_row(l: LinkCtx, vla: ptr<function, Vel>, vlb: ptr<function, Vel>, ra: vec3<f32>, rb: vec3<f32>, t: vec3<f32>, old: f32, limit: f32) -> f32 {
    let kt = eff_mass(l.c.da, l.c.db, ra, rb, t) + link_response(l, ra, rb, t);
    if (kt <= 0.0) {
        return old;
    }
    let new_t = clamp(old - link_rel(l, *vla, *vlb, ra, rb, t) / kt, -limit, limit);
    link_apply(l, vla, vlb, ra, rb, t, new_t - old);
    return new_t;
}

// solver_core.wgsl's solve_row for a pair with a link side, on the sampled normal and separation.
fn link_solve_row(l: LinkCtx, vla: ptr<function, Vel>, vlb: ptr<function, Vel>, g0: u32, ri: u32, h: f32, bias: bool) {
    let anchor = solver_scratch[ri];
    if (bitcast<u32>(anchor.w) == NONE) {
        return;
    }
    let ns = solver_scratch[ri + 2u];
    if (all(ns.xyz == vec3<f32>(0.0))) {
        return;
    }
    var lambda = solver_scratch[ri + 1u];
    let va = l.c.va;
    let vb = l.c.vb;
    let n = ns.xyz;
    let s = ns.w;
    let xa = va.pos + quat_rotate(va.rot, anchor.xyz) - l.c.pair.radius * n;
    let ra = xa - (va.pos + quat_rotate(va.rot, va.com));
    let rb = xa - (vb.pos + quat_rotate(vb.rot, vb.com));
    let k = eff_mass(l.c.da, l.c.db, ra, rb, n) + link_response(l, ra, rb, n);
    if (k <= 0.0) {
        return;
    }
    var goal = 0.0;
    if (s > 0.0) {
        goal = -s / h;
    } else if (bias) {
        goal = min(-s / h, sp.max_depenetration_velocity);
    }
    let new_n = max(lambda.x + (goal - link_rel(l, *vla, *vlb, ra, rb, n)) / k, 0.0);
    link_apply(l, vla, vlb, ra, rb, n, new_n - lambda.x);
    lambda.x = new_n;
    let mu = lambda.w;
    if (mu > 0.0) {
        let t1 = any_orthonormal(n);
        let t2 = cross(n, t1);
        var limit = mu * lambda.x;
        if (FRICTION_PER_PATCH) {
            limit = mu * patch_normal_share(g0, ri, lambda.x);
        }
        lambda.y = link_friction_row(l, vla, vlb, ra, rb, t1, lambda.y, limit);
        lambda.z = link_friction_row(l, vla, vlb, ra, rb, t2, lambda.z, limit);
    }
    solver_scratch[ri + 1u] = lambda;
}

// solver_core.wgsl's warm_row for a pair with a link side.
fn link_warm_row(l: LinkCtx, vla: ptr<function, Vel>, vlb: ptr<function, Vel>, ri: u32) {
    let anchor = solver_scratch[ri];
    let nw = solver_scratch[ri + 2u];
    let lambda = solver_scratch[ri + 1u];
    if (bitcast<u32>(anchor.w) == NONE || all(nw.xyz == vec3<f32>(0.0)) || all(lambda.xyz == vec3<f32>(0.0))) {
        return;
    }
    let va = l.c.va;
    let vb = l.c.vb;
    let n = nw.xyz;
    let xa = va.pos + quat_rotate(va.rot, anchor.xyz) - l.c.pair.radius * n;
    let ra = xa - (va.pos + quat_rotate(va.rot, va.com));
    let rb = xa - (vb.pos + quat_rotate(vb.rot, vb.com));
    let t1 = any_orthonormal(n);
    let imp = lambda.x * n + lambda.y * t1 + lambda.z * cross(n, t1);
    _ = link_response(l, ra, rb, imp);
    link_apply(l, vla, vlb, ra, rb, imp, 1.0);
}

// pair_pass for a pair with a link side: LINK_PATCH_ITERS Gauss-Seidel passes per patch.
fn link_pair_pass(world: u32, p: u32, first: u32, count: u32, h: f32, bias: bool, warm: bool, sa: u32, sb: u32) {
    let pair = pairs[p];
    let c = PairCtx(pair, view(world, pair.body_a), view(world, pair.body_b), dyn_of(world, pair.body_a), dyn_of(world, pair.body_b));
    // One side is a link (articulated.rs refuses pairs of two link bodies).
    let l = LinkCtx(c, select(sb, sa, sa != NONE), select(-1.0, 1.0, sa != NONE));
    var vla = vel_load(c.da);
    var vlb = vel_load(c.db);
    var i = 0u;
    loop {
        let g0 = first + i * 4u * ROW;
        if (warm) {
            link_warm_row(l, &vla, &vlb, g0);
            link_warm_row(l, &vla, &vlb, g0 + ROW);
            link_warm_row(l, &vla, &vlb, g0 + 2u * ROW);
            link_warm_row(l, &vla, &vlb, g0 + 3u * ROW);
        } else {
            var sweep_pass = 0u;
            loop {
                link_solve_row(l, &vla, &vlb, g0, g0, h, bias);
                link_solve_row(l, &vla, &vlb, g0, g0 + ROW, h, bias);
                link_solve_row(l, &vla, &vlb, g0, g0 + 2u * ROW, h, bias);
                link_solve_row(l, &vla, &vlb, g0, g0 + 3u * ROW, h, bias);
                sweep_pass += 1u;
                if (sweep_pass >= LINK_PATCH_ITERS) {
                    break;
                }
            }
        }
        i += 1u;
        if (i >= count) {
            break;
        }
    }
    vel_store(c.da, vla);
    vel_store(c.db, vlb);
}

// solver_sweep.wgsl's hook.
fn pass_pair(world: u32, p: u32, first: u32, count: u32, h: f32, bias: bool, warm: bool) {
    if (count == 0u) {
        return;
    }
    let pair = pairs[p];
    let sa = slot_of(pair.body_a);
    let sb = slot_of(pair.body_b);
    if (sa == NONE && sb == NONE) {
        pair_pass(world, p, first, count, h, bias, warm, false);
    } else {
        link_pair_pass(world, p, first, count, h, bias, warm, sa, sb);
    }
}

// Puts each link body where the joints put its link (forward kinematics done).
fn place_link_bodies(world: u32) {
    for (var s = 0u; s < coupling.slot_count; s++) {
        let l = coupling.slot_link[s];
        body_q[world * sp.body_count + coupling.slot_body[s]] = Transform(vec4<f32>(pose_p[l], 0.0), pose_q[l]);
    }
}

// J_s, Y_s and K_st of every slot at the current link poses, with A's Cholesky factor in `mass`
// (dynamics.rs ContactResponse::new).
fn build_response() {
    let n = params.dof_count;
    for (var s = 0u; s < coupling.slot_count; s++) {
        let l = coupling.slot_link[s];
        let c = pose_p[l] + quat_rotate(pose_q[l], links[l].com_mass.xyz);
        let js = s * MAX_DOFS;
        for (var d = 0u; d < n; d++) {
            slot_jl[js + d] = vec3<f32>(0.0);
            slot_ja[js + d] = vec3<f32>(0.0);
        }
        // The point Jacobian at the link's centre of mass (dynamics.rs point_jacobian).
        var a = l;
        loop {
            let d = links[a].dof;
            if (d != NONE) {
                let axis = world_axis(a);
                if (links[a].joint == JOINT_PRISMATIC) {
                    slot_jl[js + d] = axis;
                } else {
                    slot_jl[js + d] = cross(axis, c - pose_p[a]);
                    slot_ja[js + d] = axis;
                }
            }
            a = links[a].parent;
            if (a == NONE) {
                break;
            }
        }
        // Column k of Y_s = A^-1 (row k of J_s).
        for (var k = 0u; k < 6u; k++) {
            for (var d = 0u; d < n; d++) {
                rhs[d] = select(slot_ja[js + d][k % 3u], slot_jl[js + d][k % 3u], k < 3u);
            }
            cholesky_substitute();
            for (var d = 0u; d < n; d++) {
                if (k < 3u) {
                    slot_yl[js + d][k] = rhs[d];
                } else {
                    slot_ya[js + d][k - 3u] = rhs[d];
                }
            }
        }
    }
    for (var s = 0u; s < coupling.slot_count; s++) {
        for (var t = 0u; t < coupling.slot_count; t++) {
            // K_st = sum over dofs of (column d of J_s) (row d of Y_t), in four 3 x 3 blocks.
            var ll = mat3x3<f32>();
            var la = mat3x3<f32>();
            var al = mat3x3<f32>();
            var aa = mat3x3<f32>();
            for (var d = 0u; d < n; d++) {
                let jl = slot_jl[s * MAX_DOFS + d];
                let ja = slot_ja[s * MAX_DOFS + d];
                let yl = slot_yl[t * MAX_DOFS + d];
                let ya = slot_ya[t * MAX_DOFS + d];
                ll += mat3x3<f32>(jl * yl.x, jl * yl.y, jl * yl.z);
                la += mat3x3<f32>(jl * ya.x, jl * ya.y, jl * ya.z);
                al += mat3x3<f32>(ja * yl.x, ja * yl.y, ja * yl.z);
                aa += mat3x3<f32>(ja * ya.x, ja * ya.y, ja * ya.z);
            }
            let b = 4u * (s * MAX_SLOTS + t);
            kblk[b] = ll;
            kblk[b + 1u] = la;
            kblk[b + 2u] = al;
            kblk[b + 3u] = aa;
        }
    }
}

// The link bodies' twists J_s qd.
fn link_twists() {
    let n = params.dof_count;
    for (var s = 0u; s < coupling.slot_count; s++) {
        var lin = vec3<f32>(0.0);
        var ang = vec3<f32>(0.0);
        for (var d = 0u; d < n; d++) {
            lin += slot_jl[s * MAX_DOFS + d] * qd[d];
            ang += slot_ja[s * MAX_DOFS + d] * qd[d];
        }
        link_v[2u * s] = lin;
        link_v[2u * s + 1u] = ang;
    }
}

// qd += sum_t Y_t phi_t, and the tallies cleared (dynamics.rs ContactResponse::apply_impulses).
fn joints_take_impulses() {
    let n = params.dof_count;
    for (var t = 0u; t < coupling.slot_count; t++) {
        let f = link_phi[2u * t];
        let m = link_phi[2u * t + 1u];
        for (var d = 0u; d < n; d++) {
            qd[d] += dot(slot_yl[t * MAX_DOFS + d], f) + dot(slot_ya[t * MAX_DOFS + d], m);
        }
        link_phi[2u * t] = vec3<f32>(0.0);
        link_phi[2u * t + 1u] = vec3<f32>(0.0);
    }
}

@compute @workgroup_size(64)
fn step(@builtin(global_invocation_id) gid: vec3<u32>) {
    let world = gid.x;
    if (world >= sp.world_count) {
        return;
    }
    let h = sp.dt / f32(sp.substeps);
    let row0 = rows_base() + world * sp.max_rows * ROW;
    // The loop budget (solver.wgsl): the rows' passes, link patches at LINK_PATCH_ITERS, and the
    // articulation's (counted on the host).
    var patches_used = 0u;
    var link_patches = 0u;
    for (var p = 0u; p < sp.pair_count; p++) {
        let count = patch_counts[world * sp.pair_count + p];
        if (slot_of(pairs[p].body_a) == NONE && slot_of(pairs[p].body_b) == NONE) {
            patches_used += count;
        } else {
            link_patches += count;
        }
    }
    let pairs_f = f32(sp.pair_count + 1u);
    let per_sweep = pairs_f + f32(patches_used) * f32(sp.patch_iters + 1u) + f32(link_patches) * f32(LINK_PATCH_ITERS + 2u) + 2.0;
    let sweeps = f32(sp.pos_iters + sp.vel_iters + 1u);
    let resamples = 2.0 * (2.0 * pairs_f + f32(patches_used + link_patches));
    let per_substep = sweeps * per_sweep + resamples + 2.0 * f32(sp.body_count + 1u) + 1.0;
    let passes = 3.0 * pairs_f + f32(patches_used + link_patches) + f32(sp.substeps) * per_substep + f32(sp.body_count) + f32(coupling.art_passes) + 2.0;
    let frame = bitcast<u32>(solver_scratch[world].w) + 1u;
    if (sp.loop_budget > 0u && passes > f32(sp.loop_budget)) {
        solver_scratch[world] = vec4<f32>(0.0, 0.0, 1.0, solver_scratch[world].w);
        return;
    }
    let jb = joint_block(world);
    let n = params.dof_count;
    for (var d = 0u; d < n; d++) {
        q[d] = joint_get(jb, d);
        qd[d] = joint_get(jb + coupling.joint_plane, d);
    }
    // The frame's rows at the link poses the joints give.
    forward_kinematics();
    place_link_bodies(world);
    var n_rows = 0u;
    for (var p = 0u; p < sp.pair_count; p++) {
        let pw = world * sp.pair_count + p;
        let count = patch_counts[pw];
        if (count == 0u) {
            continue;
        }
        let pair = pairs[p];
        let va = view(world, pair.body_a);
        let vb = view(world, pair.body_b);
        for (var i = 0u; i < count; i++) {
            let g0 = row_index(row0, p, i, 0u);
            n_rows += build_patch_rows(g0, g0, p, p, pair, va, vb, patches[pw * MAX_PATCHES + i], frame);
        }
    }
    let first = world * sp.body_count;
    var art_ok = true;
    var sub = 0u;
    loop {
        forward_kinematics();
        if (free_velocity(jb, h)) {
            build_response();
        } else {
            art_ok = false;
        }
        link_twists();
        integrate_bodies(first, h, false);
        sweep(world, row0, h, true, true);
        sweep_runs(world, row0, h, sp.pos_iters, true);
        integrate_bodies(first, h, true);
        joints_take_impulses();
        integrate_positions(h);
        forward_kinematics();
        place_link_bodies(world);
        // The substep's Jacobians serve the velocity sweeps too (step_cpu_articulated alike).
        link_twists();
        sweep_runs(world, row0, h, sp.vel_iters, false);
        joints_take_impulses();
        link_twists();
        sub += 1u;
        if (sub >= sp.substeps) {
            break;
        }
    }
    var ok = select(0.0, 1.0, art_ok);
    for (var d = 0u; d < n; d++) {
        joint_set(jb, d, q[d]);
        joint_set(jb + coupling.joint_plane, d, qd[d]);
        let bits = bitcast<u32>(q[d] + qd[d]) & 0x7f800000u;
        if (bits == 0x7f800000u || abs(qd[d]) > sp.max_speed) {
            ok = 0.0;
        }
    }
    for (var s = 0u; s < coupling.slot_count; s++) {
        let g = first + coupling.slot_body[s];
        body_qd[2u * g] = vec4<f32>(link_v[2u * s], 0.0);
        body_qd[2u * g + 1u] = vec4<f32>(link_v[2u * s + 1u], 0.0);
    }
    for (var b = 0u; b < sp.body_count; b++) {
        if (!body_ok(first + b)) {
            ok = 0.0;
        }
    }
    solver_scratch[world] = vec4<f32>(ok, f32(n_rows), 0.0, bitcast<f32>(frame));
}
