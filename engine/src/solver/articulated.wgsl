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
    // Loop passes of one dispatch's articulation work (articulated.rs), for the loop budget.
    art_passes: u32,
    // The substep this dispatch takes (a frame is one dispatch per substep, each with its own copy of
    // this uniform), and the substeps per frame.
    substep: u32,
    _pad0: u32,
    _pad1: u32,
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

// What a pass over one pair's rows reads once when a side is a link body: PairCtx, the link side's slot,
// and its sign (+1: the link is body a, which takes +d of an impulse along d; -1: it is b).
struct LinkCtx {
    c: PairCtx,
    ls: u32,
    sign: f32,
}

// The pass's K_{s, ls} for every slot s, at 4 s (linear <- force, linear <- torque, angular <- force,
// angular <- torque): copied out of kblk once per pass (link_ctx) and read at constant indices from then
// on. Kept out of LinkCtx: passed by value through the row functions, a context holding these 16 matrices
// makes each pass over a pair cost several times its rows on lavapipe.
var<private> lk: array<mat3x3<f32>, 16>;

fn link_ctx(c: PairCtx, ls: u32, sign: f32) -> LinkCtx {
    load_k_column(ls);
    return LinkCtx(c, ls, sign);
}

// lk = K_{s, ls} for every slot s, every read of kblk at a constant index (at a run-time index the
// 64-entry array is a chain of selects).
fn load_k_column(ls: u32) {
    if (ls == 0u) {
        lk[0] = kblk[0];
        lk[1] = kblk[1];
        lk[2] = kblk[2];
        lk[3] = kblk[3];
        if (SLOT_COUNT > 1u) {
            lk[4] = kblk[16];
            lk[5] = kblk[17];
            lk[6] = kblk[18];
            lk[7] = kblk[19];
        }
        if (SLOT_COUNT > 2u) {
            lk[8] = kblk[32];
            lk[9] = kblk[33];
            lk[10] = kblk[34];
            lk[11] = kblk[35];
        }
        if (SLOT_COUNT > 3u) {
            lk[12] = kblk[48];
            lk[13] = kblk[49];
            lk[14] = kblk[50];
            lk[15] = kblk[51];
        }
    }
    if (SLOT_COUNT > 1u && ls == 1u) {
        lk[0] = kblk[4];
        lk[1] = kblk[5];
        lk[2] = kblk[6];
        lk[3] = kblk[7];
        if (SLOT_COUNT > 1u) {
            lk[4] = kblk[20];
            lk[5] = kblk[21];
            lk[6] = kblk[22];
            lk[7] = kblk[23];
        }
        if (SLOT_COUNT > 2u) {
            lk[8] = kblk[36];
            lk[9] = kblk[37];
            lk[10] = kblk[38];
            lk[11] = kblk[39];
        }
        if (SLOT_COUNT > 3u) {
            lk[12] = kblk[52];
            lk[13] = kblk[53];
            lk[14] = kblk[54];
            lk[15] = kblk[55];
        }
    }
    if (SLOT_COUNT > 2u && ls == 2u) {
        lk[0] = kblk[8];
        lk[1] = kblk[9];
        lk[2] = kblk[10];
        lk[3] = kblk[11];
        if (SLOT_COUNT > 1u) {
            lk[4] = kblk[24];
            lk[5] = kblk[25];
            lk[6] = kblk[26];
            lk[7] = kblk[27];
        }
        if (SLOT_COUNT > 2u) {
            lk[8] = kblk[40];
            lk[9] = kblk[41];
            lk[10] = kblk[42];
            lk[11] = kblk[43];
        }
        if (SLOT_COUNT > 3u) {
            lk[12] = kblk[56];
            lk[13] = kblk[57];
            lk[14] = kblk[58];
            lk[15] = kblk[59];
        }
    }
    if (SLOT_COUNT > 3u && ls == 3u) {
        lk[0] = kblk[12];
        lk[1] = kblk[13];
        lk[2] = kblk[14];
        lk[3] = kblk[15];
        if (SLOT_COUNT > 1u) {
            lk[4] = kblk[28];
            lk[5] = kblk[29];
            lk[6] = kblk[30];
            lk[7] = kblk[31];
        }
        if (SLOT_COUNT > 2u) {
            lk[8] = kblk[44];
            lk[9] = kblk[45];
            lk[10] = kblk[46];
            lk[11] = kblk[47];
        }
        if (SLOT_COUNT > 3u) {
            lk[12] = kblk[60];
            lk[13] = kblk[61];
            lk[14] = kblk[62];
            lk[15] = kblk[63];
        }
    }
}

// Per slot, the twist change (linear [2 s], angular [2 s + 1]) of a unit impulse along the direction last
// given to link_response: K_{s, ls} u (an impulse on one finger moves the arm, so the other finger too).
var<private> dir_w: array<vec3<f32>, 8>;

// The link side's lever arm.
fn link_lever(l: LinkCtx, ra: vec3<f32>, rb: vec3<f32>) -> vec3<f32> {
    return select(rb, ra, l.sign > 0.0);
}

// Slot s's twist change for the spatial impulse u on the link side: K_{s, ls} u.
fn slot_response(s: u32, u: Sv) -> Sv {
    return Sv(lk[4u * s] * u.lin + lk[4u * s + 1u] * u.ang, lk[4u * s + 2u] * u.lin + lk[4u * s + 3u] * u.ang);
}

// Fills dir_w for direction d (not necessarily unit) and returns the link side's part of the inverse
// effective mass along d, u . K_{ls, ls} u with u its spatial impulse (solver/rows.rs SubstepInputs::eff).
fn link_response(l: LinkCtx, ra: vec3<f32>, rb: vec3<f32>, d: vec3<f32>) -> f32 {
    let u = Sv(l.sign * d, l.sign * cross(link_lever(l, ra, rb), d));
    var own = 0.0;
    if (SLOT_COUNT > 0u) {
        let w = slot_response(0u, u);
        dir_w[0] = w.lin;
        dir_w[1] = w.ang;
        own = select(own, sv_dot(u, w), l.ls == 0u);
    }
    if (SLOT_COUNT > 1u) {
        let w = slot_response(1u, u);
        dir_w[2] = w.lin;
        dir_w[3] = w.ang;
        own = select(own, sv_dot(u, w), l.ls == 1u);
    }
    if (SLOT_COUNT > 2u) {
        let w = slot_response(2u, u);
        dir_w[4] = w.lin;
        dir_w[5] = w.ang;
        own = select(own, sv_dot(u, w), l.ls == 2u);
    }
    if (SLOT_COUNT > 3u) {
        let w = slot_response(3u, u);
        dir_w[6] = w.lin;
        dir_w[7] = w.ang;
        own = select(own, sv_dot(u, w), l.ls == 3u);
    }
    return own;
}

// The link side's twist (read at constant indices, see LinkCtx).
fn link_twist(l: LinkCtx) -> Sv {
    var t = Sv(link_v[0], link_v[1]);
    if (SLOT_COUNT > 1u && l.ls == 1u) {
        t = Sv(link_v[2], link_v[3]);
    }
    if (SLOT_COUNT > 2u && l.ls == 2u) {
        t = Sv(link_v[4], link_v[5]);
    }
    if (SLOT_COUNT > 3u && l.ls == 3u) {
        t = Sv(link_v[6], link_v[7]);
    }
    return t;
}

// Velocity along d of the row's point on a relative to b (the link side through its twist, the rigid side
// through the velocity the pass carries).
fn link_rel(l: LinkCtx, vla: Vel, vlb: Vel, ra: vec3<f32>, rb: vec3<f32>, d: vec3<f32>) -> f32 {
    let t = link_twist(l);
    let vl = t.lin + cross(t.ang, link_lever(l, ra, rb));
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
    let f = (l.sign * x) * d;
    let m = (l.sign * x) * cross(link_lever(l, ra, rb), d);
    if (SLOT_COUNT > 0u) {
        link_v[0] += dir_w[0] * x;
        link_v[1] += dir_w[1] * x;
        if (l.ls == 0u) {
            link_phi[0] += f;
            link_phi[1] += m;
        }
    }
    if (SLOT_COUNT > 1u) {
        link_v[2] += dir_w[2] * x;
        link_v[3] += dir_w[3] * x;
        if (l.ls == 1u) {
            link_phi[2] += f;
            link_phi[3] += m;
        }
    }
    if (SLOT_COUNT > 2u) {
        link_v[4] += dir_w[4] * x;
        link_v[5] += dir_w[5] * x;
        if (l.ls == 2u) {
            link_phi[4] += f;
            link_phi[5] += m;
        }
    }
    if (SLOT_COUNT > 3u) {
        link_v[6] += dir_w[6] * x;
        link_v[7] += dir_w[7] * x;
        if (l.ls == 3u) {
            link_phi[6] += f;
            link_phi[7] += m;
        }
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
    let arms = row_arms(va, vb, va.pos + quat_rotate(va.rot, anchor.xyz), l.c.pair.radius, n);
    let ra = arms.ra;
    let rb = arms.rb;
    let k = eff_mass(l.c.da, l.c.db, ra, rb, n) + link_response(l, ra, rb, n);
    if (k <= 0.0) {
        return;
    }
    let new_n = max(lambda.x + (normal_goal(s, h, bias) - link_rel(l, *vla, *vlb, ra, rb, n)) / k, 0.0);
    link_apply(l, vla, vlb, ra, rb, n, new_n - lambda.x);
    lambda.x = new_n;
    let mu = lambda.w;
    if (mu > 0.0) {
        let t1 = any_orthonormal(n);
        let t2 = cross(n, t1);
        let limit = friction_limit(mu, g0, ri, lambda.x);
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
    let arms = row_arms(va, vb, va.pos + quat_rotate(va.rot, anchor.xyz), l.c.pair.radius, n);
    let ra = arms.ra;
    let rb = arms.rb;
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
    let l = link_ctx(c, select(sb, sa, sa != NONE), select(-1.0, 1.0, sa != NONE));
    var vla = vel_load(c.da);
    var vlb = vel_load(c.db);
    // One loop over (patch, pass), not a loop of passes inside a loop of patches: lavapipe runs a loop's
    // body at least once under a lane mask, so an inner loop would run all its passes, masked, for pairs
    // without patches, and for every rigid pair (whose pass runs this function masked).
    let per_patch = select(LINK_PATCH_ITERS, 1u, warm);
    let total = count * per_patch;
    var it = 0u;
    loop {
        let g0 = first + (it / per_patch) * 4u * ROW;
        if (warm) {
            link_warm_row(l, &vla, &vlb, g0);
            link_warm_row(l, &vla, &vlb, g0 + ROW);
            link_warm_row(l, &vla, &vlb, g0 + 2u * ROW);
            link_warm_row(l, &vla, &vlb, g0 + 3u * ROW);
        } else {
            link_solve_row(l, &vla, &vlb, g0, g0, h, bias);
            link_solve_row(l, &vla, &vlb, g0, g0 + ROW, h, bias);
            link_solve_row(l, &vla, &vlb, g0, g0 + 2u * ROW, h, bias);
            link_solve_row(l, &vla, &vlb, g0, g0 + 3u * ROW, h, bias);
        }
        it += 1u;
        if (it >= total) {
            break;
        }
    }
    vel_store(c.da, vla);
    vel_store(c.db, vlb);
}

// The world's pairs with patches this frame, in pair order (set at each dispatch's start): the sweeps
// visit only these. On lavapipe a pass over a pair without patches still runs its rows once, masked, and
// runs both the rigid and the link pass (a branch runs both sides), the link one several times the cost
// of a rigid one; most pairs are empty most of the time (the pads and the table, the nut and the table once
// it is picked).
var<private> active_pairs: array<u32, MAX_PAIRS>;
var<private> active_count: u32;

// Pairs per world articulated.rs accepts (the bound of active_pairs).
const MAX_PAIRS: u32 = 64u;

fn find_active_pairs(world: u32) {
    active_count = 0u;
    for (var p = 0u; p < sp.pair_count; p++) {
        if (patch_counts[world * sp.pair_count + p] > 0u) {
            active_pairs[active_count] = p;
            active_count += 1u;
        }
    }
}

// solver_sweep.wgsl's hooks.
fn sweep_pair_count(world: u32) -> u32 {
    return active_count;
}

fn sweep_pair(world: u32, j: u32) -> u32 {
    return active_pairs[j];
}

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

// Slot s's twist J_s qd.
fn slot_twist(s: u32) -> Sv {
    var lin = vec3<f32>(0.0);
    var ang = vec3<f32>(0.0);
    for (var d = 0u; d < params.dof_count; d++) {
        lin += slot_jl[s * MAX_DOFS + d] * qd[d];
        ang += slot_ja[s * MAX_DOFS + d] * qd[d];
    }
    return Sv(lin, ang);
}

// The link bodies' twists J_s qd. link_v and link_phi are read and written at constant indices only (the
// slots written out): so they stay in registers, where one access at a run-time index anywhere would put
// every access of the rows' hot path in memory.
fn link_twists() {
    if (SLOT_COUNT > 0u) {
        let t = slot_twist(0u);
        link_v[0] = t.lin;
        link_v[1] = t.ang;
    }
    if (SLOT_COUNT > 1u) {
        let t = slot_twist(1u);
        link_v[2] = t.lin;
        link_v[3] = t.ang;
    }
    if (SLOT_COUNT > 2u) {
        let t = slot_twist(2u);
        link_v[4] = t.lin;
        link_v[5] = t.ang;
    }
    if (SLOT_COUNT > 3u) {
        let t = slot_twist(3u);
        link_v[6] = t.lin;
        link_v[7] = t.ang;
    }
}

// qd += Y_s phi_s for spatial impulse phi_s (force, torque) on slot s.
fn slot_take(s: u32, f: vec3<f32>, m: vec3<f32>) {
    for (var d = 0u; d < params.dof_count; d++) {
        qd[d] += dot(slot_yl[s * MAX_DOFS + d], f) + dot(slot_ya[s * MAX_DOFS + d], m);
    }
}

// qd += sum_t Y_t phi_t, and the tallies cleared (dynamics.rs ContactResponse::apply_impulses).
fn joints_take_impulses() {
    if (SLOT_COUNT > 0u) {
        slot_take(0u, link_phi[0], link_phi[1]);
        link_phi[0] = vec3<f32>(0.0);
        link_phi[1] = vec3<f32>(0.0);
    }
    if (SLOT_COUNT > 1u) {
        slot_take(1u, link_phi[2], link_phi[3]);
        link_phi[2] = vec3<f32>(0.0);
        link_phi[3] = vec3<f32>(0.0);
    }
    if (SLOT_COUNT > 2u) {
        slot_take(2u, link_phi[4], link_phi[5]);
        link_phi[4] = vec3<f32>(0.0);
        link_phi[5] = vec3<f32>(0.0);
    }
    if (SLOT_COUNT > 3u) {
        slot_take(3u, link_phi[6], link_phi[7]);
        link_phi[6] = vec3<f32>(0.0);
        link_phi[7] = vec3<f32>(0.0);
    }
}

// Slot s's twist into its body's velocity.
fn store_slot_twist(first: u32, s: u32, lin: vec3<f32>, ang: vec3<f32>) {
    let g = first + coupling.slot_body[s];
    body_qd[2u * g] = vec4<f32>(lin, 0.0);
    body_qd[2u * g + 1u] = vec4<f32>(ang, 0.0);
}

// One substep per dispatch (the host dispatches sp.substeps per frame, coupling.substep = 0, 1, ...): lavapipe
// budgets loop passes per invocation, and a frame of 4 substeps of 32 sweeps with the articulation passes
// it once the nut's thread is in contact (the world would then be skipped, frozen). The first substep builds the
// frame's rows; between dispatches the state waits in storage (joints in solver_scratch, bodies in body_q
// and body_qd, impulses in the rows), and everything a substep derives (link Jacobians, K, the links'
// twists) it derives afresh, as the host does.
@compute @workgroup_size(64)
fn step(@builtin(global_invocation_id) gid: vec3<u32>) {
    let world = gid.x;
    if (world >= sp.world_count) {
        return;
    }
    let first_substep = coupling.substep == 0u;
    let last_substep = coupling.substep + 1u >= sp.substeps;
    if (!first_substep && solver_scratch[world].z == 1.0) {
        return; // skipped this frame for the loop budget
    }
    let h = sp.dt / f32(sp.substeps);
    let row0 = rows_base() + world * sp.max_rows * ROW;
    // The loop budget (solver.wgsl) of this dispatch: its rows' passes, link patches at LINK_PATCH_ITERS,
    // and the articulation's (counted on the host).
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
    let substep_passes = sweeps * per_sweep + resamples + 2.0 * f32(sp.body_count + 1u) + 1.0;
    var passes = 2.0 * pairs_f + substep_passes + f32(sp.body_count) + f32(coupling.art_passes) + 2.0;
    if (first_substep) {
        passes += 2.0 * pairs_f + f32(patches_used + link_patches);
    }
    if (sp.loop_budget > 0u && passes > f32(sp.loop_budget)) {
        solver_scratch[world] = vec4<f32>(0.0, 0.0, 1.0, solver_scratch[world].w);
        return;
    }
    find_active_pairs(world);
    let jb = joint_block(world);
    let n = params.dof_count;
    for (var d = 0u; d < n; d++) {
        q[d] = joint_get(jb, d);
        qd[d] = joint_get(jb + coupling.joint_plane, d);
    }
    forward_kinematics();
    if (first_substep) {
        // The frame's rows at the link poses the joints give.
        place_link_bodies(world);
        let frame = bitcast<u32>(solver_scratch[world].w) + 1u;
        let n_rows = build_rows(world, row0, frame);
        // x: ok so far (a later substep clears it), y: rows, z: 0 (stepped), w: the frame.
        solver_scratch[world] = vec4<f32>(1.0, f32(n_rows), 0.0, bitcast<f32>(frame));
    }
    let first = world * sp.body_count;
    var ok = solver_scratch[world].x;
    // The substep (step_cpu_articulated's loop body).
    if (free_velocity(jb, h)) {
        build_response();
    } else {
        ok = 0.0;
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
    for (var d = 0u; d < n; d++) {
        joint_set(jb, d, q[d]);
        joint_set(jb + coupling.joint_plane, d, qd[d]);
    }
    if (SLOT_COUNT > 0u) {
        store_slot_twist(first, 0u, link_v[0], link_v[1]);
    }
    if (SLOT_COUNT > 1u) {
        store_slot_twist(first, 1u, link_v[2], link_v[3]);
    }
    if (SLOT_COUNT > 2u) {
        store_slot_twist(first, 2u, link_v[4], link_v[5]);
    }
    if (SLOT_COUNT > 3u) {
        store_slot_twist(first, 3u, link_v[6], link_v[7]);
    }
    if (last_substep) {
        // A world that went non-finite or faster than max_speed (joints included) is flagged for the caller
        // to reset.
        for (var d = 0u; d < n; d++) {
            let bits = bitcast<u32>(q[d] + qd[d]) & 0x7f800000u;
            if (bits == 0x7f800000u || abs(qd[d]) > sp.max_speed) {
                ok = 0.0;
            }
        }
        for (var b = 0u; b < sp.body_count; b++) {
            if (!body_ok(first + b)) {
                ok = 0.0;
            }
        }
    }
    solver_scratch[world].x = ok;
}
