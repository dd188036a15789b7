// Near pairs and their graph colouring for many-body worlds (see many_body/mod.rs for the method). Prepended:
// contact/common.wgsl and many_body/many_body_common.wgsl. Dispatches, in order, per frame: keep_keys, near_count,
// near_scan, near_emit, incidence, colour_round x ManyBodyConfig::colour_rounds, colour_sort.
//
// Many-body pairs: a near pair's record is its template's Pair with body_a, body_b filled in, and job_first
// holding its sort key for body b (body b's index; 0xffff0000 + s for static shape s), so that the list,
// sorted by (body_a, key), can be searched for a pair of bodies; many_body_template holds its template.

@group(0) @binding(0) var<uniform> cp: ManyBodyParams;
@group(0) @binding(1) var<storage, read> templates: array<Pair>;
// body_class [body_count], body_rule [class_count^2], static_rule [static_count * class_count].
@group(0) @binding(2) var<storage, read> rules: array<u32>;
@group(1) @binding(0) var<storage, read> body_q: array<Transform>;
// The solver scratch, read for the sleeping state only (solve.wgsl rest_index).
@group(1) @binding(1) var<storage, read> solver_scratch: array<vec4<f32>>;
@group(2) @binding(0) var<storage, read_write> many_body_pairs: array<Pair>;
@group(2) @binding(1) var<storage, read_write> many_body_meta: array<atomic<u32>>;
@group(2) @binding(2) var<storage, read_write> many_body_args: array<atomic<u32>>;
@group(3) @binding(0) var<uniform> pp: PassParams;

const STATIC_KEY: u32 = 0xffff0000u;
// Neighbour visits the serial completion of the colouring may make per world (mod.rs SERIAL_VISITS).
const SERIAL_VISITS: u32 = 24576u;

fn class_of(i: u32) -> u32 {
    return rules[i];
}

fn body_rule(ci: u32, cj: u32) -> u32 {
    return rules[cp.body_count + ci * cp.class_count + cj];
}

fn static_rule(s: u32, c: u32) -> u32 {
    return rules[cp.body_count + cp.class_count * cp.class_count + s * cp.class_count + c];
}

fn body_pose(w: u32, b: u32) -> Transform {
    if (b == NONE) {
        return Transform(vec4<f32>(0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0));
    }
    return body_q[w * cp.body_count + b];
}

fn near(t: u32, a: u32, b: u32, w: u32) -> bool {
    let p = templates[t];
    let wa = xf_mul(body_pose(w, a), Transform(p.a_pos, p.a_rot));
    let wb = xf_mul(body_pose(w, b), Transform(p.b_pos, p.b_rot));
    return !pair_far(p, wa, wb);
}

fn load(i: u32) -> u32 {
    return atomicLoad(&many_body_meta[i]);
}

fn store(i: u32, v: u32) {
    atomicStore(&many_body_meta[i], v);
}

// Last frame's sorted keys and row offsets, before the list is rebuilt.
@compute @workgroup_size(64)
fn keep_keys(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.y;
    let e = gid.x;
    if (e >= cp.cap) {
        return;
    }
    let n = load(meta_base(w) + M_COUNT);
    if (e == 0u) {
        store(meta_base(w) + M_OLD_COUNT, n);
    }
    if (e < n) {
        let g = w * cp.cap + e;
        store(m_old_a(w) + e, many_body_pairs[g].body_a);
        store(m_old_b(w) + e, many_body_pairs[g].job_first);
        store(m_old_row_first(w) + e, load(m_row_first(w) + e));
    }
}

// Per body i: its near pairs (i, j > i) and with static shapes (count_a), and (j < i, i) (count_b).
@compute @workgroup_size(64)
fn near_count(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let w = gid.y;
    if (i >= cp.body_count) {
        return;
    }
    var ca = 0u;
    var cb = 0u;
    for (var j = 0u; j < cp.body_count; j++) {
        let lo = min(i, j);
        let hi = max(i, j);
        let t = body_rule(class_of(lo), class_of(hi));
        if (j != i && t != NONE && near(t, lo, hi, w)) {
            if (j > i) {
                ca += 1u;
            } else {
                cb += 1u;
            }
        }
    }
    for (var s = 0u; s < cp.static_count; s++) {
        let t = static_rule(s, class_of(i));
        if (t != NONE && near(t, i, NONE, w)) {
            ca += 1u;
        }
    }
    store(m_count_a(w) + i, ca);
    store(m_count_b(w) + i, cb);
}

// Indirect dispatch arguments at slot a: x workgroups (the most any world needs) by world_count by 1.
fn set_args(a: u32, x: u32) {
    atomicMax(&many_body_args[a], x);
    atomicMax(&many_body_args[a + 1u], cp.world_count);
    atomicMax(&many_body_args[a + 2u], 1u);
}

var<workgroup> scan_a: array<u32, 256>;
var<workgroup> scan_b: array<u32, 256>;

// One workgroup per world: exclusive prefix sums of the per-body counts (list offsets), the list's length
// (cut at cap, flagged), and the indirect dispatch sizes that follow from it.
@compute @workgroup_size(256)
fn near_scan(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let w = wid.x;
    let n = cp.body_count;
    let per = (n + 255u) / 256u;
    let first = lid * per;
    var sa = 0u;
    var sb = 0u;
    for (var k = 0u; k < per; k++) {
        let i = first + k;
        if (i < n) {
            sa += load(m_count_a(w) + i);
            sb += load(m_count_b(w) + i);
        }
    }
    scan_a[lid] = sa;
    scan_b[lid] = sb;
    workgroupBarrier();
    for (var d = 1u; d < 256u; d = d * 2u) {
        var va = scan_a[lid];
        var vb = scan_b[lid];
        if (lid >= d) {
            va += scan_a[lid - d];
            vb += scan_b[lid - d];
        }
        workgroupBarrier();
        scan_a[lid] = va;
        scan_b[lid] = vb;
        workgroupBarrier();
    }
    var oa = scan_a[lid] - sa;
    var ob = scan_b[lid] - sb;
    for (var k = 0u; k < per; k++) {
        let i = first + k;
        if (i < n) {
            store(m_off_a(w) + i, oa);
            store(m_off_b(w) + i, ob);
            oa += load(m_count_a(w) + i);
            ob += load(m_count_b(w) + i);
        }
    }
    if (lid == 255u) {
        let total = scan_a[255];
        let count = min(total, cp.cap);
        store(meta_base(w) + M_COUNT, count);
        store(meta_base(w) + M_FLAGS, select(0u, FLAG_PAIRS, total > cp.cap));
        set_args(A_PAIRS, (count + 63u) / 64u);
        // Generation: near pair x job x world.
        atomicMax(&many_body_args[A_GENERATE], count);
        atomicMax(&many_body_args[A_GENERATE + 1u], cp.jobs_per_pair);
        atomicMax(&many_body_args[A_GENERATE + 2u], cp.world_count);
        set_args(A_MERGE, count);
    }
}

fn emit(w: u32, k: u32, end: u32, t: u32, a: u32, b: u32, key: u32) {
    if (k < min(end, cp.cap)) {
        var p = templates[t];
        p.body_a = a;
        p.body_b = b;
        p.job_first = key;
        p.many_body_template = t;
        many_body_pairs[w * cp.cap + k] = p;
        store(m_colour(w) + k, UNCOLOURED);
        store(m_candidates(w) + k, 0u);
        store(m_patch_count(w) + k, 0u);
    }
}

// Per body i: writes its near pairs (i, j > i), then (i, static s), at its offset: the list is sorted by
// (body_a, key) whatever the order the invocations run in.
@compute @workgroup_size(64)
fn near_emit(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let w = gid.y;
    if (i >= cp.body_count) {
        return;
    }
    var k = load(m_off_a(w) + i);
    // The range near_count counted: the same test must give the same answer here, or the world is
    // flagged (never stepped with a gap in its list).
    let end = k + load(m_count_a(w) + i);
    let ci = class_of(i);
    for (var j = i + 1u; j < cp.body_count; j++) {
        let t = body_rule(ci, class_of(j));
        if (t != NONE && near(t, i, j, w)) {
            emit(w, k, end, t, i, j, j);
            k += 1u;
        }
    }
    for (var s = 0u; s < cp.static_count; s++) {
        let t = static_rule(s, ci);
        if (t != NONE && near(t, i, NONE, w)) {
            emit(w, k, end, t, i, NONE, STATIC_KEY + s);
            k += 1u;
        }
    }
    if (k != end) {
        atomicOr(&many_body_meta[meta_base(w) + M_FLAGS], FLAG_RECOUNT);
    }
}

// Sleeping (many_body/mod.rs, 5.; dispatched after solve.wgsl's many_body_wake): a near pair whose bodies all sleep
// (or whose one body sleeps beside a static shape) gets no jobs this frame, so no contacts and no rows: its
// bodies take no impulses anyway.
@compute @workgroup_size(64)
fn near_dormant(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    let w = gid.y;
    if (cp.sleep_frames == 0u || e >= min(load(meta_base(w) + M_COUNT), cp.cap)) {
        return;
    }
    let g = w * cp.cap + e;
    let a = many_body_pairs[g].body_a;
    let b = many_body_pairs[g].body_b;
    if (asleep(w, a) && (b == NONE || asleep(w, b))) {
        many_body_pairs[g].job_count = 0u;
    }
}

fn asleep(w: u32, b: u32) -> bool {
    return solver_scratch[cp.rest_base + 2u * (w * cp.body_count + b)].w > f32(cp.sleep_frames);
}

// The list index of pair (i, j) (i < j), NONE if it was cut off.
fn find_pair(w: u32, i: u32, j: u32) -> u32 {
    let n = load(meta_base(w) + M_COUNT);
    var lo = load(m_off_a(w) + i);
    var hi = min(lo + load(m_count_a(w) + i), n);
    loop {
        if (lo >= hi) {
            break;
        }
        let mid = (lo + hi) / 2u;
        if (many_body_pairs[w * cp.cap + mid].job_first < j) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if (lo < n && many_body_pairs[w * cp.cap + lo].body_a == i && many_body_pairs[w * cp.cap + lo].job_first == j) {
        return lo;
    }
    return NONE;
}

// Per body j: the list indices of its pairs (i < j, j), for the colouring's neighbour search.
@compute @workgroup_size(64)
fn incidence(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = gid.x;
    let w = gid.y;
    if (j >= cp.body_count) {
        return;
    }
    var k = load(m_off_b(w) + j);
    let end = k + load(m_count_b(w) + j);
    let cj = class_of(j);
    for (var i = 0u; i < j; i++) {
        let t = body_rule(class_of(i), cj);
        if (t != NONE && near(t, i, j, w)) {
            let e = find_pair(w, i, j);
            if (k < min(end, cp.cap) && e != NONE) {
                store(m_blist(w) + k, e);
            }
            k += 1u;
        }
    }
    if (k != end) {
        atomicOr(&many_body_meta[meta_base(w) + M_FLAGS], FLAG_RECOUNT);
    }
}

// Colouring priority of a pair of bodies (mod.rs `priority`).
fn pcg(v: u32) -> u32 {
    let s = v * 747796405u + 2891336453u;
    let x = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    return (x >> 22u) ^ x;
}

fn priority(a: u32, b: u32) -> u32 {
    return pcg(a ^ pcg(b));
}

// Neighbour f of pair e in round r: x = 1 if f, uncoloured at the round's start, outranks e; else y = the
// bit of f's colour (0 if f is uncoloured or found none). r = NONE: the serial completion, where only
// colours count.
fn neighbour(w: u32, f: u32, e: u32, pe: u32, r: u32) -> vec2<u32> {
    let v = load(m_colour(w) + f);
    if (r == NONE && v == UNCOLOURED) {
        return vec2<u32>(0u, 0u); // the serial completion (colour_sort): uncoloured neighbours block nothing
    }
    if (v == UNCOLOURED || (v >> 8u) == r) {
        let g = w * cp.cap + f;
        let pf = priority(many_body_pairs[g].body_a, many_body_pairs[g].body_b);
        return vec2<u32>(select(0u, 1u, pf > pe || (pf == pe && f > e)), 0u);
    }
    let c = v & 0xffu;
    return vec2<u32>(0u, select(0u, 1u << c, c < 32u));
}

// The pairs sharing body x with pair e: whether one outranks e (x), and their colours' bits (y).
fn scan_body(w: u32, x: u32, e: u32, pe: u32, r: u32) -> vec2<u32> {
    let n = load(meta_base(w) + M_COUNT);
    var used = 0u;
    let first = load(m_off_a(w) + x);
    let end = min(first + load(m_count_a(w) + x), n);
    for (var f = first; f < end; f++) {
        if (f != e) {
            let s = neighbour(w, f, e, pe, r);
            if (s.x != 0u) {
                return vec2<u32>(1u, 0u);
            }
            used |= s.y;
        }
    }
    let fb = load(m_off_b(w) + x);
    let nb = load(m_count_b(w) + x);
    for (var q = 0u; q < nb; q++) {
        if (fb + q >= cp.cap) {
            break;
        }
        let f = load(m_blist(w) + fb + q);
        if (f != e && f < n) {
            let s = neighbour(w, f, e, pe, r);
            if (s.x != 0u) {
                return vec2<u32>(1u, 0u);
            }
            used |= s.y;
        }
    }
    return vec2<u32>(0u, used);
}

// One Jones-Plassmann round (pp.index = the round): an uncoloured pair that outranks every uncoloured
// neighbour takes the lowest colour its neighbours leave free. The colour word carries the round, so a
// neighbour coloured in this very round still counts as uncoloured: the result does not depend on timing.
@compute @workgroup_size(64)
fn colour_round(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    let w = gid.y;
    let r = pp.index;
    let n = load(meta_base(w) + M_COUNT);
    if (e >= n || (load(meta_base(w) + M_FLAGS) & FLAG_PAIRS) != 0u || load(m_colour(w) + e) != UNCOLOURED) {
        return;
    }
    let g = w * cp.cap + e;
    let a = many_body_pairs[g].body_a;
    let b = many_body_pairs[g].body_b;
    let pe = priority(a, b);
    let sa = scan_body(w, a, e, pe, r);
    if (sa.x != 0u) {
        return;
    }
    var used = sa.y;
    if (b != NONE) {
        let sb = scan_body(w, b, e, pe, r);
        if (sb.x != 0u) {
            return;
        }
        used |= sb.y;
    }
    let c = countTrailingZeros(~used);
    if (c >= cp.max_colours) {
        atomicOr(&many_body_meta[meta_base(w) + M_FLAGS], FLAG_COLOURS);
        store(m_colour(w) + e, (r << 8u) | COLOUR_NONE);
    } else {
        store(m_colour(w) + e, (r << 8u) | c);
    }
}

// One invocation per world: the pairs listed by colour (list order within a colour), each colour's start,
// the colours in use, the solver's dispatch sizes per colour; flags pairs left uncoloured.
@compute @workgroup_size(64)
fn colour_sort(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= cp.world_count) {
        return;
    }
    let n = load(meta_base(w) + M_COUNT);
    // Pairs the rounds left uncoloured are coloured here one after another in list order (greedy: the
    // lowest colour their neighbours leave free), within a budget of neighbour visits (lavapipe's loop
    // passes); the CPU twin does the same.
    if ((load(meta_base(w) + M_FLAGS) & FLAG_PAIRS) == 0u) {
        var visits = 0u;
        for (var e = 0u; e < n; e++) {
            if (load(m_colour(w) + e) != UNCOLOURED) {
                continue;
            }
            let g = w * cp.cap + e;
            let a = many_body_pairs[g].body_a;
            let b = many_body_pairs[g].body_b;
            // Its neighbours, plus the 4 loop exits of its two scans.
            var cost = 4u + load(m_count_a(w) + a) + load(m_count_b(w) + a);
            if (b != NONE) {
                cost += load(m_count_a(w) + b) + load(m_count_b(w) + b);
            }
            if (visits + cost > SERIAL_VISITS) {
                break;
            }
            visits += cost;
            var used = scan_body(w, a, e, 0u, NONE).y;
            if (b != NONE) {
                used |= scan_body(w, b, e, 0u, NONE).y;
            }
            let c = countTrailingZeros(~used);
            if (c >= cp.max_colours) {
                atomicOr(&many_body_meta[meta_base(w) + M_FLAGS], FLAG_COLOURS);
                store(m_colour(w) + e, COLOUR_NONE);
            } else {
                store(m_colour(w) + e, c);
            }
        }
    }
    var cnt: array<u32, 32>;
    var incomplete = false;
    for (var e = 0u; e < n; e++) {
        let v = load(m_colour(w) + e);
        let c = v & 0xffu;
        if (v == UNCOLOURED) {
            incomplete = true;
        } else if (c < cp.max_colours) {
            cnt[c] += 1u;
        }
    }
    var off = 0u;
    var used = 0u;
    for (var c = 0u; c < 32u; c++) {
        store(meta_base(w) + M_COLOUR_OFF + c, off);
        let k = cnt[c];
        if (k > 0u) {
            used = c + 1u;
            set_args(A_COLOUR + 3u * c, (k + 63u) / 64u);
        }
        cnt[c] = off;
        off += k;
    }
    store(meta_base(w) + M_COLOUR_OFF + 32u, off);
    for (var e = 0u; e < n; e++) {
        let v = load(m_colour(w) + e);
        let c = v & 0xffu;
        if (v != UNCOLOURED && c < cp.max_colours) {
            store(m_colour_list(w) + cnt[c], e);
            cnt[c] += 1u;
        }
    }
    store(meta_base(w) + M_COLOURS, used);
    // The flags the CPU twin raises, in its order: an overfull list is not coloured (so not flagged for
    // rounds), and the patch budget counts only for a world coloured in full.
    let flags = load(meta_base(w) + M_FLAGS);
    var out = flags | select(0u, FLAG_ROUNDS, incomplete && (flags & FLAG_PAIRS) == 0u);
    if ((out & (FLAG_PAIRS | FLAG_COLOURS | FLAG_ROUNDS)) != 0u) {
        out &= ~FLAG_PATCHES;
    }
    store(meta_base(w) + M_FLAGS, out);
}
