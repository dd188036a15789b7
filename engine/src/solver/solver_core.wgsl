// The rigid-body solver's row and body operations (see solver/mod.rs for the scheme), shared by the
// one-invocation-per-world step (solver.wgsl) and the graph-coloured step of many-body worlds
// (many_body/solve.wgsl). Each of those declares the bindings used here: sp, pairs, sdf_values, bodies, body_q,
// body_qd and solver_scratch (laid out as control_index and rows_base say).

struct SolverParams {
    world_count: u32,
    body_count: u32,
    pair_count: u32,
    max_rows: u32,
    dt: f32,
    substeps: u32,
    pos_iters: u32,
    vel_iters: u32,
    max_depenetration_velocity: f32,
    rest_offset: f32,
    max_speed: f32,
    patch_iters: u32,
    gravity: vec4<f32>,
    // Loop passes one invocation may make (llvmpipe's budget, see GpuSolver::new); 0: unlimited.
    loop_budget: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct Body {
    // Inverse inertia about the COM in body axes, columns [1/(kg m^2)].
    inv_inertia: mat3x3<f32>,
    // COM in the body frame xyz [m], inverse mass w [1/kg].
    com_inv_mass: vec4<f32>,
    // x: 1 for a kinematic body (moved by its velocity, no gravity, no impulses).
    flags: vec4<u32>,
}

// A contact row: anchor (query element point in body a's frame) xyz + pair index (bits) w; accumulated
// impulses of the current substep (normal, tangent 1, tangent 2) xyz and friction coefficient w; the normal
// and separation of the last SDF sample (zero normal: none yet); the contact point in body b's frame at the
// frame's start xyz (for matching the row next frame) and the frame it was built in w (u32 bits; rows of
// patch slots unused since are older and never matched).
struct Row {
    anchor: vec4<f32>,
    lambda: vec4<f32>,
    normal: vec4<f32>,
    point_b: vec4<f32>,
}

// Coulomb's cone on each patch's total normal impulse (SolverConfig::friction_per_patch), set when the
// pipeline is built: lavapipe runs both sides of every branch, so as a uniform flag the per-patch share's
// 8 storage reads would run, masked, in every row update.
override FRICTION_PER_PATCH: bool = false;
// SolverConfig::patch_iters (also in sp.patch_iters for the loop budget), a constant of the pipeline: with
// a run-time bound, lavapipe runs the re-sweep loop's body (four rows), masked, once per patch even where
// patch_iters is 1 (a loop's body runs once more after its last pass; contact/common.wgsl), which makes a
// sweep cost about twice its rows (docs/BENCHMARKS.md).
override PATCH_ITERS: u32 = 1u;

// vec4s per row in solver_scratch (solver/gpu.rs ROW_VEC4).
const ROW: u32 = 4u;

// solver_scratch holds, in order: a status vec4 per world (x: 1 ok, 0 diverged; y: rows used), the external
// wrench per body (Control::body_f: force xyz, then torque xyz; written by the host, read here), then each
// world's rows. The wrench lives here because the stage already binds the 8 storage buffers WebGPU allows.
fn control_index(g: u32) -> u32 {
    return sp.world_count + 2u * g;
}

fn rows_base() -> u32 {
    return sp.world_count * (1u + 2u * sp.body_count);
}
// Warm-start match: anchor and point within this fraction of the pair's contact offset, normals within
// acos(WARM_COS) (see the row building in step).
const WARM_DISTANCE: f32 = 0.1;
const WARM_COS: f32 = 0.985;
// A pair tag no row carries (build_patch_rows: no rows of last frame to match).
const NO_MATCH: u32 = 0xfffffffeu;

fn quat_to_mat3(q: vec4<f32>) -> mat3x3<f32> {
    let x = q.x;
    let y = q.y;
    let z = q.z;
    let w = q.w;
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        vec3<f32>(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        vec3<f32>(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    );
}

// any_orthonormal: orthonormal.wgsl (included beside this file).

// A body's pose, for building rows and sampling the SDF at them.
struct BodyView {
    pos: vec3<f32>,
    rot: vec4<f32>,
    com: vec3<f32>,
}

fn view(world: u32, b: u32) -> BodyView {
    if (b == NONE) {
        return BodyView(vec3<f32>(0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0), vec3<f32>(0.0));
    }
    let t = body_q[world * sp.body_count + b];
    return BodyView(t.p.xyz, t.q, bodies[b].com_inv_mass.xyz);
}

// World-frame inverse inertia [1/(kg m^2)] of global body g (index b in its world) at its current pose.
fn world_inv_inertia(g: u32, b: u32) -> mat3x3<f32> {
    let r = quat_to_mat3(body_q[g].q);
    return r * bodies[b].inv_inertia * transpose(r);
}

// A body's response to impulses: global index (NONE: the static world), inverse mass [1/kg] and world
// inverse inertia [1/(kg m^2)] (zero for static and kinematic bodies).
struct Dyn {
    index: u32,
    inv_mass: f32,
    inv_i: mat3x3<f32>,
}

fn dyn_of(world: u32, b: u32) -> Dyn {
    if (b == NONE) {
        return Dyn(NONE, 0.0, mat3x3<f32>());
    }
    let g = world * sp.body_count + b;
    // A sleeping body (many_body/solve.wgsl) responds as a static one.
    let inv_mass = select(0.0, bodies[b].com_inv_mass.w, body_awake(g));
    var inv_i = mat3x3<f32>();
    if (inv_mass > 0.0) {
        inv_i = world_inv_inertia(g, b);
    }
    return Dyn(g, inv_mass, inv_i);
}

// A body's velocity (linear [m/s], angular [rad/s]), held in registers while a pass goes over a pair's
// rows (pair_pass).
struct Vel {
    lin: vec3<f32>,
    ang: vec3<f32>,
}

fn vel_load(d: Dyn) -> Vel {
    if (d.index == NONE) {
        return Vel(vec3<f32>(0.0), vec3<f32>(0.0));
    }
    return Vel(body_qd[2u * d.index].xyz, body_qd[2u * d.index + 1u].xyz);
}

// Writes back a velocity that impulses may have changed (static and kinematic bodies take none).
fn vel_store(d: Dyn, v: Vel) {
    if (d.index == NONE || d.inv_mass == 0.0) {
        return;
    }
    body_qd[2u * d.index] = vec4<f32>(v.lin, 0.0);
    body_qd[2u * d.index + 1u] = vec4<f32>(v.ang, 0.0);
}

// Velocity of the point at lever arm r.
fn vel_at(v: Vel, r: vec3<f32>) -> vec3<f32> {
    return v.lin + cross(v.ang, r);
}

// v after impulse `imp` [N s] at lever arm r (sign -1: its opposite).
fn vel_apply(d: Dyn, v: Vel, r: vec3<f32>, imp: vec3<f32>, sign: f32) -> Vel {
    if (d.index == NONE || d.inv_mass == 0.0) {
        return v;
    }
    return Vel(v.lin + sign * d.inv_mass * imp, v.ang + sign * (d.inv_i * cross(r, imp)));
}

fn eff_mass(da: Dyn, db: Dyn, ra: vec3<f32>, rb: vec3<f32>, d: vec3<f32>) -> f32 {
    let ca = cross(ra, d);
    let cb = cross(rb, d);
    return da.inv_mass + db.inv_mass + dot(ca, da.inv_i * ca) + dot(cb, db.inv_i * cb);
}

// One tangential row (effective mass kt) on the velocities va, vb: returns the new accumulated impulse,
// clamped to the friction cone's box.
fn friction_row(da: Dyn, db: Dyn, va: ptr<function, Vel>, vb: ptr<function, Vel>, ra: vec3<f32>, rb: vec3<f32>, t: vec3<f32>, kt: f32, old: f32, limit: f32) -> f32 {
    if (kt <= 0.0) {
        return old;
    }
    let vt = dot(vel_at(*va, ra) - vel_at(*vb, rb), t);
    let new_t = clamp(old - vt / kt, -limit, limit);
    *va = vel_apply(da, *va, ra, t * (new_t - old), 1.0);
    *vb = vel_apply(db, *vb, rb, t * (new_t - old), -1.0);
    return new_t;
}

// What a pass over one pair's rows reads once: the pair, its bodies' poses, responses and velocities (the
// velocities are carried from row to row in registers and written back at the end of the pass). The
// poses stand still during a sweep, so this is bitwise what reading them at every row would give: on a
// software adapter every storage access is a bounds-checked gather, and re-reading these is where a
// solver's time goes. On the M16 nut-bolt at 256 worlds, reading them once per pass makes the solve about
// 3.5 times faster than re-reading them at every row and impulse, and 2.5 times faster than keeping only
// the velocities in registers per row; caching each row's lever arms and effective masses and each body's
// world inertia in the scratch buffer is slower still: loads, not arithmetic, are what cost
// (docs/BENCHMARKS.md).
struct PairCtx {
    pair: Pair,
    va: BodyView,
    vb: BodyView,
    da: Dyn,
    db: Dyn,
}

// Samples pair's SDF at the contact point x (world) of row ri, shape b posed by vb, and stores the row's
// normal (world, out of b) and separation [m] in its scratch; zero where the SDF has no gradient.
// Returns what it stored. The caller has bound the pair's SDF (sdf_bind).
fn resample_row(pair: Pair, vb: BodyView, x: vec3<f32>, ri: u32) -> vec4<f32> {
    let shape_b = xf_mul(Transform(vec4<f32>(vb.pos, 0.0), vb.rot), Transform(pair.b_pos, pair.b_rot));
    let s0 = sdf_sample(pair, xf_point(xf_inv(shape_b), x));
    let glen = length(s0.g);
    var ns = vec4<f32>(0.0);
    if (glen > 0.0) {
        ns = vec4<f32>(quat_rotate(shape_b.q, s0.g / glen), s0.d - pair.radius - sp.rest_offset);
    }
    solver_scratch[ri + 2u] = ns;
    return ns;
}

// resample_row for every row of pair p's `count` patches from row `first`, at the poses of world `world`:
// what a sweep with `resample` does before it solves, without the solve.
fn resample_pair(world: u32, p: u32, first: u32, count: u32) {
    if (count == 0u) {
        return;
    }
    let pair = pairs[p];
    sdf_bind(pair);
    let va = view(world, pair.body_a);
    let vb = view(world, pair.body_b);
    // Exit test at the end of the pass (count >= 1 here): see pair_pass.
    var i = 0u;
    loop {
        let g0 = first + i * 4u * ROW;
        resample_slot(pair, va, vb, g0);
        resample_slot(pair, va, vb, g0 + ROW);
        resample_slot(pair, va, vb, g0 + 2u * ROW);
        resample_slot(pair, va, vb, g0 + 3u * ROW);
        i += 1u;
        if (i >= count) {
            break;
        }
    }
}

fn resample_slot(pair: Pair, va: BodyView, vb: BodyView, ri: u32) {
    let anchor = solver_scratch[ri];
    if (bitcast<u32>(anchor.w) != NONE) {
        _ = resample_row(pair, vb, va.pos + quat_rotate(va.rot, anchor.xyz), ri);
    }
}

// Lever arms [m] from the centres of mass of a and b (posed by va, vb) to a row's contact point on a's
// surface: the query element's point x (world) less the pair's radius along the normal n.
struct Arms {
    ra: vec3<f32>,
    rb: vec3<f32>,
}

fn row_arms(va: BodyView, vb: BodyView, x: vec3<f32>, radius: f32, n: vec3<f32>) -> Arms {
    let xa = x - radius * n;
    return Arms(xa - (va.pos + quat_rotate(va.rot, va.com)), xa - (vb.pos + quat_rotate(vb.rot, vb.com)));
}

// Coulomb's bound on a row's accumulated tangential impulses for normal impulse lambda_n: mu times its own
// normal impulse, or with friction per patch its share of the patch's (patch_normal_share).
fn friction_limit(mu: f32, g0: u32, ri: u32, lambda_n: f32) -> f32 {
    if (FRICTION_PER_PATCH) {
        return mu * patch_normal_share(g0, ri, lambda_n);
    }
    return mu * lambda_n;
}

// The normal velocity a row drives to at separation s [m]: speculative when separated (approach at most
// the gap), a bounded depenetration when penetrating in the position sweeps (bias), 0 otherwise.
fn normal_goal(s: f32, h: f32, bias: bool) -> f32 {
    var goal = 0.0;
    if (s > 0.0) {
        goal = -s / h;
    } else if (bias) {
        goal = min(-s / h, sp.max_depenetration_velocity);
    }
    return goal;
}

// One Gauss-Seidel update of row ri (of the patch at g0) of pair c on the velocities vla, vlb.
fn solve_row(c: PairCtx, vla: ptr<function, Vel>, vlb: ptr<function, Vel>, g0: u32, ri: u32, h: f32, bias: bool, resample: bool) {
    let anchor = solver_scratch[ri];
    if (bitcast<u32>(anchor.w) == NONE) {
        return; // an empty slot of its patch
    }
    var lambda = solver_scratch[ri + 1u];
    let pair = c.pair;
    let va = c.va;
    let vb = c.vb;
    let x = va.pos + quat_rotate(va.rot, anchor.xyz);
    var ns: vec4<f32>;
    if (resample) {
        ns = resample_row(pair, vb, x, ri);
    } else {
        ns = solver_scratch[ri + 2u];
    }
    if (all(ns.xyz == vec3<f32>(0.0))) {
        return; // no gradient at the contact
    }
    let n = ns.xyz;
    let s = ns.w;
    let arms = row_arms(va, vb, x, pair.radius, n);
    let ra = arms.ra;
    let rb = arms.rb;
    let k = eff_mass(c.da, c.db, ra, rb, n);
    if (k <= 0.0) {
        return;
    }
    let goal = normal_goal(s, h, bias);
    let vn = dot(vel_at(*vla, ra) - vel_at(*vlb, rb), n);
    let new_n = max(lambda.x + (goal - vn) / k, 0.0);
    let dn = new_n - lambda.x;
    lambda.x = new_n;
    *vla = vel_apply(c.da, *vla, ra, n * dn, 1.0);
    *vlb = vel_apply(c.db, *vlb, rb, n * dn, -1.0);
    let mu = lambda.w;
    if (mu > 0.0) {
        let t1 = any_orthonormal(n);
        let t2 = cross(n, t1);
        let limit = friction_limit(mu, g0, ri, lambda.x);
        // Written out (not a loop): lavapipe counts every loop pass against one budget per invocation.
        lambda.y = friction_row(c.da, c.db, vla, vlb, ra, rb, t1, eff_mass(c.da, c.db, ra, rb, t1), lambda.y, limit);
        lambda.z = friction_row(c.da, c.db, vla, vlb, ra, rb, t2, eff_mass(c.da, c.db, ra, rb, t2), lambda.z, limit);
    }
    solver_scratch[ri + 1u] = lambda;
}

// The patch's normal impulse per contact: its rows' impulses (row ri's own being `own`, not yet stored)
// summed and divided by its contacts (friction per patch: each contact may carry an equal share of
// mu times the patch's normal impulse, so the patch as a whole obeys Coulomb's cone). Written out: no loop.
fn patch_normal_share(g0: u32, ri: u32, own: f32) -> f32 {
    var sum = 0.0;
    var n = 0.0;
    let r0 = select(solver_scratch[g0 + 1u].x, own, ri == g0);
    let r1 = select(solver_scratch[g0 + ROW + 1u].x, own, ri == g0 + ROW);
    let r2 = select(solver_scratch[g0 + 2u * ROW + 1u].x, own, ri == g0 + 2u * ROW);
    let r3 = select(solver_scratch[g0 + 3u * ROW + 1u].x, own, ri == g0 + 3u * ROW);
    if (bitcast<u32>(solver_scratch[g0].w) != NONE) { sum += r0; n += 1.0; }
    if (bitcast<u32>(solver_scratch[g0 + ROW].w) != NONE) { sum += r1; n += 1.0; }
    if (bitcast<u32>(solver_scratch[g0 + 2u * ROW].w) != NONE) { sum += r2; n += 1.0; }
    if (bitcast<u32>(solver_scratch[g0 + 3u * ROW].w) != NONE) { sum += r3; n += 1.0; }
    return sum / max(n, 1.0);
}

// Warm start of one row at the start of a substep: re-applies the impulses of the previous substep (or of
// the matching row last frame) along the normal they were solved with (the anchor moved with body a since).
fn warm_row(c: PairCtx, vla: ptr<function, Vel>, vlb: ptr<function, Vel>, ri: u32) {
    let anchor = solver_scratch[ri];
    let nw = solver_scratch[ri + 2u];
    let lambda = solver_scratch[ri + 1u];
    if (bitcast<u32>(anchor.w) == NONE || all(nw.xyz == vec3<f32>(0.0)) || all(lambda.xyz == vec3<f32>(0.0))) {
        return;
    }
    let va = c.va;
    let vb = c.vb;
    let n = nw.xyz;
    let arms = row_arms(va, vb, va.pos + quat_rotate(va.rot, anchor.xyz), c.pair.radius, n);
    let ra = arms.ra;
    let rb = arms.rb;
    let t1 = any_orthonormal(n);
    let t2 = cross(n, t1);
    let imp = lambda.x * n + lambda.y * t1 + lambda.z * t2;
    *vla = vel_apply(c.da, *vla, ra, imp, 1.0);
    *vlb = vel_apply(c.db, *vlb, rb, imp, -1.0);
}

// Builds the 4 rows of a patch at g0 (tagged with pair index p) from the reduced contacts. Warm start across frames: a row takes
// over the impulses of the closest of its patch's rows last frame that was the same contact (anchor on a
// and point on b within WARM_DISTANCE of the contact offset, normal within acos(WARM_COS)). The reduction
// is deterministic, so resting contacts come back in the same patch, though not always in the same slot
// (the deepest of four equally deep corners changes with rounding).
// Last frame's rows of the patch are read at old0 and were tagged old_p (the same place and tag when the
// pair list is fixed; NO_MATCH: the pair is new).
fn build_patch_rows(g0: u32, old0: u32, p: u32, old_p: u32, pair: Pair, va: BodyView, vb: BodyView, pt: PatchOut, frame: u32) -> u32 {
    // Written out, not looped: lavapipe counts every loop pass against the invocation's budget, and this
    // runs for every patch of the world (ROW vec4s per row).
    let old = array<Row, 4>(old_row(old0), old_row(old0 + ROW), old_row(old0 + 2u * ROW), old_row(old0 + 3u * ROW));
    var built = build_row(g0, pt.slots[0], old, p, old_p, pair, va, vb, pt.normal.xyz, frame);
    built += build_row(g0 + ROW, pt.slots[1], old, p, old_p, pair, va, vb, pt.normal.xyz, frame);
    built += build_row(g0 + 2u * ROW, pt.slots[2], old, p, old_p, pair, va, vb, pt.normal.xyz, frame);
    built += build_row(g0 + 3u * ROW, pt.slots[3], old, p, old_p, pair, va, vb, pt.normal.xyz, frame);
    return built;
}

// A row of last frame, read before its patch's rows are rebuilt in place.
fn old_row(r: u32) -> Row {
    return Row(solver_scratch[r], solver_scratch[r + 1u], solver_scratch[r + 2u], solver_scratch[r + 3u]);
}

// The warm-start match so far: the distance of the best old row, whether one matched, its impulses and
// normal.
struct Match {
    best: f32,
    found: bool,
    lambda: vec4<f32>,
    normal: vec4<f32>,
}

// Whether old row `o` was the same contact (see build_patch_rows), and the closer one of it and `m`.
fn match_old(m: Match, o: Row, p: u32, n: vec3<f32>, local: vec3<f32>, pb: vec3<f32>, tol: f32, friction: f32, frame: u32) -> Match {
    // Only last frame's rows (stamp frame - 1): a patch slot unused last frame holds older rows.
    let last_frame = bitcast<u32>(o.point_b.w) + 1u == frame;
    if (last_frame && bitcast<u32>(o.anchor.w) == p && any(o.normal.xyz != vec3<f32>(0.0)) && dot(o.normal.xyz, n) >= WARM_COS) {
        let d = distance(o.anchor.xyz, local);
        if (d <= tol && distance(o.point_b.xyz, pb) <= tol && (!m.found || d < m.best)) {
            return Match(d, true, vec4<f32>(o.lambda.xyz, friction), o.normal);
        }
    }
    return m;
}

// Builds the row at rk from patch slot c (empty: a NONE row); returns 1 if it is a contact.
fn build_row(rk: u32, c: vec4<f32>, old: array<Row, 4>, p: u32, old_p: u32, pair: Pair, va: BodyView, vb: BodyView, n: vec3<f32>, frame: u32) -> u32 {
    if (c.w >= VALID_BELOW) {
        solver_scratch[rk] = vec4<f32>(0.0, 0.0, 0.0, bitcast<f32>(NONE));
        solver_scratch[rk + 3u] = vec4<f32>(0.0, 0.0, 0.0, bitcast<f32>(frame));
        return 0u;
    }
    let local = quat_rotate(vec4<f32>(-va.rot.xyz, va.rot.w), c.xyz + pair.radius * n - va.pos);
    let pb = quat_rotate(vec4<f32>(-vb.rot.xyz, vb.rot.w), c.xyz - vb.pos);
    let tol = WARM_DISTANCE * pair.contact_offset;
    var m = Match(tol, false, vec4<f32>(0.0, 0.0, 0.0, pair.friction), vec4<f32>(0.0));
    m = match_old(m, old[0], old_p, n, local, pb, tol, pair.friction, frame);
    m = match_old(m, old[1], old_p, n, local, pb, tol, pair.friction, frame);
    m = match_old(m, old[2], old_p, n, local, pb, tol, pair.friction, frame);
    m = match_old(m, old[3], old_p, n, local, pb, tol, pair.friction, frame);
    solver_scratch[rk] = vec4<f32>(local, bitcast<f32>(p));
    solver_scratch[rk + 1u] = m.lambda;
    solver_scratch[rk + 2u] = m.normal;
    solver_scratch[rk + 3u] = vec4<f32>(pb, bitcast<f32>(frame));
    return 1u;
}


// One pass over the `count` patches of pair `p` (index into pairs), whose rows start at `first`, 4 per
// patch: for each patch the warm start (warm) or a Gauss-Seidel update of each of its rows, then
// SolverConfig::patch_iters - 1 more passes over this patch alone on the sampled geometry.
fn pair_pass(world: u32, p: u32, first: u32, count: u32, h: f32, bias: bool, warm: bool, resample: bool) {
    if (count == 0u) {
        return;
    }
    let pair = pairs[p];
    if (resample) {
        sdf_bind(pair); // for solve_row's samples
    }
    let c = PairCtx(pair, view(world, pair.body_a), view(world, pair.body_b), dyn_of(world, pair.body_a), dyn_of(world, pair.body_b));
    var vla = vel_load(c.da);
    var vlb = vel_load(c.db);
    // Exit test at the end of the pass (count >= 1 here): lavapipe runs a loop's body once more, masked,
    // after a last pass that ends with the test at the top (contact/common.wgsl on loops).
    var i = 0u;
    loop {
        let g0 = first + i * 4u * ROW;
        if (warm) {
            warm_row(c, &vla, &vlb, g0);
            warm_row(c, &vla, &vlb, g0 + ROW);
            warm_row(c, &vla, &vlb, g0 + 2u * ROW);
            warm_row(c, &vla, &vlb, g0 + 3u * ROW);
        } else {
            solve_row(c, &vla, &vlb, g0, g0, h, bias, resample);
            solve_row(c, &vla, &vlb, g0, g0 + ROW, h, bias, resample);
            solve_row(c, &vla, &vlb, g0, g0 + 2u * ROW, h, bias, resample);
            solve_row(c, &vla, &vlb, g0, g0 + 3u * ROW, h, bias, resample);
            if (PATCH_ITERS > 1u) {
                var inner = 1u;
                loop {
                    solve_row(c, &vla, &vlb, g0, g0, h, bias, false);
                    solve_row(c, &vla, &vlb, g0, g0 + ROW, h, bias, false);
                    solve_row(c, &vla, &vlb, g0, g0 + 2u * ROW, h, bias, false);
                    solve_row(c, &vla, &vlb, g0, g0 + 3u * ROW, h, bias, false);
                    inner += 1u;
                    if (inner >= PATCH_ITERS) {
                        break;
                    }
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

// Velocity update of body b (global index first + b) over a substep h: gravity and the external wrench.
fn integrate_velocity(first: u32, b: u32, h: f32) {
    let m = bodies[b];
    let g = first + b;
    if (m.com_inv_mass.w > 0.0 && body_awake(g)) {
        // External wrench (Control::body_f): force through the COM, torque about it, world frame.
        let f = solver_scratch[control_index(g)].xyz;
        let tau = solver_scratch[control_index(g) + 1u].xyz;
        body_qd[2u * g] = vec4<f32>(body_qd[2u * g].xyz + (sp.gravity.xyz + m.com_inv_mass.w * f) * h, 0.0);
        // The world inverse inertia only where a torque acts (most bodies have none).
        if (any(tau != vec3<f32>(0.0))) {
            body_qd[2u * g + 1u] = vec4<f32>(body_qd[2u * g + 1u].xyz + (world_inv_inertia(g, b) * tau) * h, 0.0);
        }
    }
}

// Position update of body b over a substep h (dynamic and kinematic bodies; the COM moves with the
// velocity, the rotation by the angular velocity's quaternion derivative).
fn integrate_position(first: u32, b: u32, h: f32) {
    let m = bodies[b];
    let g = first + b;
    if ((m.com_inv_mass.w > 0.0 && body_awake(g)) || m.flags.x != 0u) {
        let t = body_q[g];
        let c = t.p.xyz + quat_rotate(t.q, m.com_inv_mass.xyz) + body_qd[2u * g].xyz * h;
        let w = body_qd[2u * g + 1u].xyz;
        let dq = quat_mul(vec4<f32>(w, 0.0), t.q) * (0.5 * h);
        let q2 = normalize(t.q + dq);
        body_q[g] = Transform(vec4<f32>(c - quat_rotate(q2, m.com_inv_mass.xyz), 0.0), q2);
    }
}

// Whether global body g is finite and no faster than max_speed (else its world is flagged as diverged).
fn body_ok(g: u32) -> bool {
    let v = body_qd[2u * g].xyz;
    let sum = vec4<f32>(body_q[g].p.xyz, 0.0) + body_q[g].q + vec4<f32>(v + body_qd[2u * g + 1u].xyz, 0.0);
    // Exponent bits all set = NaN or inf (checked on the bits: WGSL lets compilers assume finite math,
    // so float comparisons cannot be trusted to see a NaN).
    let bits = bitcast<vec4<u32>>(sum) & vec4<u32>(0x7f800000u);
    let finite = !any(bits == vec4<u32>(0x7f800000u));
    return finite && length(v) <= sp.max_speed;
}
