// The Gauss-Seidel step of a many-body world, one dispatch per colour (see many_body/mod.rs): the rows, warm
// start, patch passes and integration of solver/solver_core.wgsl, with the pairs of one colour (disjoint
// bodies) solved in parallel. Prepended: contact/common.wgsl, many_body/many_body_common.wgsl; appended:
// solver_core.wgsl, sdf_sample and the analytic SDFs. Per frame: many_body_build_rows, then per substep
// many_body_velocities, many_body_pass (warm start) per colour, many_body_pass per colour x pos_iters, many_body_positions,
// many_body_pass per colour x vel_iters; many_body_finish.
//
// solver_scratch: status per world, wrenches per body (as solver.wgsl), then two blocks of rows, used by
// alternate frames (frame & 1), each [world_count * patch_budget patches * 4 rows]: a frame's rows are
// built from last frame's, which stay in the other block; then the sleeping state, two vec4 per body
// (rest_index).
//
// Sleeping (many_body/mod.rs, 5.; compiled in only when ManyBodyConfig::sleep is on): many_body_wake before contact
// generation, many_body_sleep after the last substep.

@group(0) @binding(0) var<uniform> sp: SolverParams;
@group(0) @binding(1) var<uniform> cp: ManyBodyParams;
@group(0) @binding(2) var<storage, read> sdf_values: array<u32>;
@group(0) @binding(3) var<storage, read> bodies: array<Body>;
@group(1) @binding(0) var<storage, read> pairs: array<Pair>;
@group(1) @binding(1) var<storage, read> patches: array<PatchOut>;
@group(1) @binding(2) var<storage, read> many_body_meta: array<u32>;
@group(2) @binding(0) var<storage, read_write> body_q: array<Transform>;
@group(2) @binding(1) var<storage, read_write> body_qd: array<vec4<f32>>;
@group(2) @binding(2) var<storage, read_write> solver_scratch: array<vec4<f32>>;
@group(3) @binding(0) var<uniform> pp: PassParams;

override SLEEP: bool = false;

fn many_body_row(par: u32, w: u32, slot: u32) -> u32 {
    return rows_base() + ((par * sp.world_count + w) * cp.patch_budget + slot) * 4u * ROW;
}

// Sleeping state of global body g: [reference centre of mass (world, m), count], [reference rotation].
// count (a float): 0 no reference yet, 1 the reference was set this frame (the body moved), k + 1 still
// for k frames, above cp.sleep_frames asleep (RestState in many_body/mod.rs).
fn rest_index(g: u32) -> u32 {
    return cp.rest_base + 2u * g;
}

fn rest_count(g: u32) -> f32 {
    return solver_scratch[rest_index(g)].w;
}

// solver_core.wgsl's hook: a sleeping body takes no gravity and no impulses and is not integrated.
fn body_awake(g: u32) -> bool {
    return !SLEEP || rest_count(g) <= f32(cp.sleep_frames);
}

fn ready(w: u32) -> bool {
    return many_body_meta[meta_base(w) + M_FLAGS] == 0u;
}

fn frame_of(w: u32) -> u32 {
    return bitcast<u32>(solver_scratch[w].w) + 1u;
}

// Last frame's list index of the pair (a, key), NONE if it was not near then.
fn find_old(w: u32, a: u32, key: u32) -> u32 {
    let n = many_body_meta[meta_base(w) + M_OLD_COUNT];
    var lo = 0u;
    var hi = n;
    loop {
        if (lo >= hi) {
            break;
        }
        let mid = (lo + hi) / 2u;
        let ma = many_body_meta[m_old_a(w) + mid];
        let mk = many_body_meta[m_old_b(w) + mid];
        if (ma < a || (ma == a && mk < key)) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if (lo < n && many_body_meta[m_old_a(w) + lo] == a && many_body_meta[m_old_b(w) + lo] == key) {
        return lo;
    }
    return NONE;
}

@compute @workgroup_size(64)
fn many_body_build_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    let w = gid.y;
    if (e >= many_body_meta[meta_base(w) + M_COUNT] || !ready(w)) {
        return;
    }
    let frame = frame_of(w);
    let par = frame & 1u;
    let g = w * cp.cap + e;
    let pair = pairs[g];
    let count = many_body_meta[m_patch_count(w) + e];
    let first = many_body_meta[m_row_first(w) + e];
    let old = find_old(w, pair.body_a, pair.job_first);
    let va = view(w, pair.body_a);
    let vb = view(w, pair.body_b);
    for (var i = 0u; i < count; i++) {
        let g0 = many_body_row(par, w, first + i);
        var old0 = g0;
        var old_tag = NO_MATCH;
        if (old != NONE) {
            let oslot = many_body_meta[m_old_row_first(w) + old] + i;
            if (oslot < cp.patch_budget) {
                old0 = many_body_row(1u - par, w, oslot);
                old_tag = w * cp.cap + old;
            }
        }
        build_patch_rows(g0, old0, g, old_tag, pair, va, vb, patches[g * MAX_PATCHES + i], frame);
    }
}

// Dispatched in contact handling, after the near pairs and before contact generation: a near pair wakes a
// sleeping body whose partner moved last frame; the woken body counts as one frame still (2), so it wakes
// its own neighbours only if it is then pushed out of its bounds. Pairs that wake the same body write the
// same value, and no pair reads a count this kernel changes into or out of "moved" (<= 1): the result does
// not depend on the order of the invocations. (near.wgsl's near_dormant then takes the jobs of pairs
// whose bodies all sleep.)
@compute @workgroup_size(64)
fn many_body_wake(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    let w = gid.y;
    if (!SLEEP || e >= min(many_body_meta[meta_base(w) + M_COUNT], cp.cap) || !ready(w)) {
        return;
    }
    let pair = pairs[w * cp.cap + e];
    if (pair.body_b == NONE) {
        return;
    }
    let ga = w * sp.body_count + pair.body_a;
    let gb = w * sp.body_count + pair.body_b;
    wake_by(ga, gb);
    wake_by(gb, ga);
}

fn wake_by(g: u32, other: u32) {
    if (!body_awake(g) && rest_count(other) <= 1.0) {
        solver_scratch[rest_index(g)].w = 2.0;
    }
}

// After the last substep: an awake dynamic or kinematic body within the bounds of its reference pose counts
// one more frame still (and falls asleep, its velocity zeroed, above cp.sleep_frames); otherwise its current
// pose becomes the reference.
@compute @workgroup_size(64)
fn many_body_sleep(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x;
    let w = gid.y;
    if (!SLEEP || b >= sp.body_count || !ready(w)) {
        return;
    }
    let kinematic = bodies[b].flags.x != 0u;
    if (bodies[b].com_inv_mass.w <= 0.0 && !kinematic) {
        return;
    }
    let g = w * sp.body_count + b;
    if (!body_awake(g)) {
        return;
    }
    let i = rest_index(g);
    let count = solver_scratch[i].w;
    let t = body_q[g];
    let com = t.p.xyz + quat_rotate(t.q, bodies[b].com_inv_mass.xyz);
    let still = length(com - solver_scratch[i].xyz) <= cp.sleep_distance
        && abs(dot(t.q, solver_scratch[i + 1u])) >= cp.sleep_half_cos;
    if (count > 0.0 && still) {
        // A kinematic body moves by the velocity it is given, so it never sleeps; standing still, it wakes
        // nobody.
        let next = select(count + 1.0, min(count + 1.0, f32(cp.sleep_frames)), kinematic);
        solver_scratch[i].w = next;
        if (next > f32(cp.sleep_frames)) {
            body_qd[2u * g] = vec4<f32>(0.0);
            body_qd[2u * g + 1u] = vec4<f32>(0.0);
        }
    } else {
        solver_scratch[i] = vec4<f32>(com, 1.0);
        solver_scratch[i + 1u] = t.q;
    }
}

@compute @workgroup_size(64)
fn many_body_velocities(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x;
    let w = gid.y;
    if (b < sp.body_count && ready(w)) {
        integrate_velocity(w * sp.body_count, b, sp.dt / f32(sp.substeps));
    }
}

@compute @workgroup_size(64)
fn many_body_positions(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x;
    let w = gid.y;
    if (b < sp.body_count && ready(w)) {
        integrate_position(w * sp.body_count, b, sp.dt / f32(sp.substeps));
    }
}

// One pass over the pairs of colour pp.index: the warm start or a Gauss-Seidel sweep, resampling each row's
// SDF first or not. One entry point per kind of pass (the host picks it by the phase's pp.warm and
// pp.resample): lavapipe runs both sides of every branch, so one kernel taking the flags at run time ran
// the warm start, the solve and the SDF sampling, masked, in every pass.
@compute @workgroup_size(64)
fn many_body_pass(@builtin(global_invocation_id) gid: vec3<u32>) {
    colour_pass(gid, false, false);
}

@compute @workgroup_size(64)
fn many_body_pass_resample(@builtin(global_invocation_id) gid: vec3<u32>) {
    colour_pass(gid, false, true);
}

@compute @workgroup_size(64)
fn many_body_pass_warm(@builtin(global_invocation_id) gid: vec3<u32>) {
    colour_pass(gid, true, false);
}

fn colour_pass(gid: vec3<u32>, warm: bool, resample: bool) {
    let k = gid.x;
    let w = gid.y;
    let c = pp.index;
    let start = many_body_meta[meta_base(w) + M_COLOUR_OFF + c];
    let end = many_body_meta[meta_base(w) + M_COLOUR_OFF + c + 1u];
    if (start + k >= end || !ready(w)) {
        return;
    }
    let e = many_body_meta[m_colour_list(w) + start + k];
    let count = many_body_meta[m_patch_count(w) + e];
    let first = many_body_meta[m_row_first(w) + e];
    let par = frame_of(w) & 1u;
    let h = sp.dt / f32(sp.substeps);
    pair_pass(w, w * cp.cap + e, many_body_row(par, w, first), count, h, pp.bias != 0u, warm, resample);
}

// Per world: status (x: 1 ok, 0 diverged or not stepped; y: near pairs; z: flags) and the frame counter.
@compute @workgroup_size(64)
fn many_body_finish(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= sp.world_count) {
        return;
    }
    let frame = frame_of(w);
    let flags = many_body_meta[meta_base(w) + M_FLAGS];
    var ok = select(0.0, 1.0, flags == 0u);
    for (var b = 0u; b < sp.body_count; b++) {
        if (!body_ok(w * sp.body_count + b)) {
            ok = 0.0;
        }
    }
    solver_scratch[w] = vec4<f32>(ok, f32(many_body_meta[meta_base(w) + M_COUNT]), f32(flags), bitcast<f32>(frame));
}
