// Shared by generate.wgsl and merge.wgsl (the host concatenates this file in front of each).
// Contact reduction in workgroup memory (paper III-C, Algorithm 1): a batch of WG candidates lives in
// workgroup arrays; Assign bins them into existing patches by normal similarity, then FindDeepest /
// BinReduce / AddPatch open new patches until none is left; finally each patch keeps at most 4 contacts
// (deepest, farthest from it, farthest from their line, farthest on the other side: the largest area).
// Candidates are never written to global memory.

// The host appends reduce_plain.wgsl or, where the device has subgroup operations, reduce_subgroup.wgsl:
// lanes_init, best_patch and the combine_* helpers (same results either way).
//
// Workgroup size WG and candidates per invocation PER, substituted by the host (ContactConfig::workgroup_size:
// 32, 64, 128 or 256; ContactConfig::candidates_per_invocation: 1, 2 or 4); a batch holds BATCH = WG * PER
// candidates, invocation lid holding candidates lid * PER .. lid * PER + PER - 1 (the CPU twin cuts its
// batches to the same size).
//
// Why several candidates per invocation: lavapipe runs every workgroup-memory instruction lane by lane
// (below), so the reduction's cost is its memory instructions per lane. An invocation holding PER
// candidates reads the patch normals once for all of them in Assign, posts once per round, and in the slot
// rounds reads a patch's slots once for all its candidates in that patch (a loop over the distinct patches
// of its candidates; with PER > 1 the pipelines order each job's query triangles by normal so that
// consecutive ones tend to share a patch, model.rs normal_ordered: 1.07x at 256 worlds). Measured on
// lavapipe (docs/BENCHMARKS.md): PER 4 handles the M16 nut-bolt pair's contacts 1.3x faster than
// PER 1 at 64 invocations, 1.6x with 32. On a GPU it trades parallelism within a workgroup, which the worlds
// supply, for fewer barriers per candidate (not measured on a GPU).
//
// Loops: lavapipe (llvmpipe) gives each shader invocation ONE loop counter shared by all its loops,
// 65535 back edges in total (LP_MAX_TGSI_LOOP_ITERATIONS); past it every loop exits after one pass and
// the kernel silently skips work (a 180-batch job lost 90% of its candidates). So the per-batch loops are
// kept short (Assign unrolled by 4, no per-patch loop on one lane) and the host bounds the batches per
// workgroup from a worst-case count of these loops (ContactConfig::max_chunk_triangles,
// max_jobs_per_pair): keep that count in step with every loop added here.
// And llvmpipe tests a loop's exit only at its back edge: a loop whose exit test sits at the top of the body
// (every `for` and `while`) runs the whole body once more, every lane masked off, after its last pass (only
// memory accesses are skipped, lane by lane). The per-batch and per-triangle loops here therefore test at
// the end of the pass (do-while; the two SDF samples this saved per triangle of the nut-bolt pair and the
// batch loop's extra pass: contact handling about 1.1x faster, docs/BENCHMARKS.md).
const WG: u32 = WG_VALUE;
const PER: u32 = PER_VALUE;
const BATCH: u32 = WG_VALUE * PER_VALUE;
// Patch budget per pair, substituted by the host when the pipeline is built (16..256).
const MAX_PATCHES: u32 = MAX_PATCHES_VALUE;
const PATCH_CAP: u32 = MAX_PATCHES_VALUE + 1u; // + one temporary patch for AddPatch when full
const NONE: u32 = 0xffffffffu;
const UNASSIGNED: u32 = 0xfffffffeu;
const EMPTY: f32 = 3.0e38;   // depth of an empty slot / no candidate
const VALID_BELOW: f32 = 1.0e38;
const NEG_INF: f32 = -3.0e38;
const IDX_MASK: u32 = 0x3ffu;
// Slots 1-3 of a patch take no contact more than this fraction of the contact offset above both its
// deepest contact and the surface.
const DEPTH_BAND: f32 = 0.25;
// ... and no more than the deepest contact's distance from the surface, or this [m] if that is less
// (reduce.rs MIN_DEPTH_BAND: a peg standing on a table kept three slots on its chamfer's rim). A patch whose
// deepest contact is more than this above the surface is landing: no band (a tilted ring's far side).
const MIN_DEPTH_BAND: f32 = 1.0e-4;

struct Params {
    world_count: u32,
    body_count: u32,
    pair_count: u32,
    job_count: u32,
    normal_cos: f32,
    iterations: u32,
    world_offset: u32,
    // The first job of a generate dispatch (generate.wgsl; the pipeline dispatches each run of jobs of one
    // SDF kind with its own pipeline); 0 elsewhere.
    job_base: u32,
}

struct Pair {
    a_pos: vec4<f32>,
    a_rot: vec4<f32>,
    b_pos: vec4<f32>,
    b_rot: vec4<f32>,
    sdf_origin: vec4<f32>,
    sdf_dims: vec4<u32>,
    body_a: u32,
    body_b: u32,
    tri_first: u32,
    tri_count: u32,
    sdf_kind: u32,
    job_first: u32,
    job_count: u32,
    sdf_scale: f32,
    contact_offset: f32,
    radius: f32,
    area_unit: f32,
    min_separation: f32,
    friction: f32,
    // A many_body pair's template (many_body/near.wgsl); unused elsewhere.
    many_body_template: u32,
    _pad2: f32,
    _pad3: f32,
    // Bounding spheres: the query shape's in its frame, the SDF shape's in its frame (w < 0: unbounded).
    a_bound: vec4<f32>,
    b_bound: vec4<f32>,
}

struct Transform {
    p: vec4<f32>,
    q: vec4<f32>,
}

struct PatchOut {
    normal: vec4<f32>,
    slots: array<vec4<f32>, 4>,
}

fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz), a.w * b.w - dot(a.xyz, b.xyz));
}

fn xf_mul(a: Transform, b: Transform) -> Transform {
    return Transform(vec4<f32>(a.p.xyz + quat_rotate(a.q, b.p.xyz), 0.0), quat_mul(a.q, b.q));
}

fn xf_inv(a: Transform) -> Transform {
    let qi = vec4<f32>(-a.q.xyz, a.q.w);
    return Transform(vec4<f32>(-quat_rotate(qi, a.p.xyz), 0.0), qi);
}

fn xf_point(a: Transform, v: vec3<f32>) -> vec3<f32> {
    return a.p.xyz + quat_rotate(a.q, v);
}

// Broad phase: whether no query triangle can come within the contact offset: the query shape's bounding
// sphere lies farther than the offset above a plane, or the pair's bounding spheres (shapes posed at world_a,
// world_b) are farther apart than it (twin: generate.rs pair_far_cpu).
fn pair_far(pair: Pair, world_a: Transform, world_b: Transform) -> bool {
    if (pair.sdf_kind == 1u) {
        let c = xf_point(xf_inv(world_b), xf_point(world_a, pair.a_bound.xyz));
        return c.z - pair.a_bound.w > pair.contact_offset;
    }
    if (pair.b_bound.w < 0.0) {
        return false;
    }
    let d = xf_point(world_a, pair.a_bound.xyz) - xf_point(world_b, pair.b_bound.xyz);
    let reach = pair.a_bound.w + pair.b_bound.w + pair.contact_offset;
    return dot(d, d) > reach * reach;
}

// Order-preserving map of f32 to u32 (larger float -> larger integer), low bits cleared for an index.
fn ordered(f: f32) -> u32 {
    let b = bitcast<u32>(f);
    let m = select(0x80000000u, 0xffffffffu, (b & 0x80000000u) != 0u);
    return (b ^ m) & ~IDX_MASK;
}

// The batch (stored by reduce_batch). Other invocations' entries are last read by AddPatch, before the barriers of
// the batch's last round, so the next batch may overwrite them at once.
var<workgroup> cand_pd: array<vec4<f32>, BATCH>;        // point xyz, depth w (EMPTY: no candidate)
var<workgroup> cand_n: array<vec4<f32>, BATCH>;         // unit normal xyz, area units w
// Patch p: seed normal xyz at patch_data[pd_normal(p)], slot k (point xyz, depth w) at pd_slot(p, k); member
// area [area units] at patch_ak[2p], slot 0's key (members post during Assign/AddPatch) at patch_ak[2p + 1].
// Interleaved so that one instruction moves or resets a whole patch: lavapipe runs every workgroup-memory
// instruction lane by lane (8 scalar accesses per component) whichever lanes take it, so lane-parallel
// copies cost a fifth of lane 0 copying field by field.
var<workgroup> patch_data: array<vec4<f32>, PATCH_CAP * 5u>;
var<workgroup> patch_ak: array<atomic<u32>, PATCH_CAP * 2u>;
// Slot k (1-3) of patch p: the arg-max key of its slot round at slot_keys[key_of(k, p)]; members post and
// reset them (see reduce_batch), so they are 0 between batches. Rounds 1 and 3 share a buffer: round 2
// resets round 1's keys before round 3 posts.
var<workgroup> slot_keys: array<atomic<u32>, PATCH_CAP * 2u>;
var<workgroup> wg_best: array<atomic<u32>, 2>;  // FindDeepest keys, double-buffered by loop parity
var<workgroup> wg_victim: atomic<u32>; // eviction arg-min key, NONE between evictions
// Per invocation (workgroup-uniform): FindDeepest rounds so far (wg_best's parity runs on across batches,
// so a batch's last round leaves the buffer of the next batch's first round zeroed).
var<private> red_round: u32;
// Set by reduce_batch when the budget is full and candidates are left: without eviction the job stops
// (generate.wgsl then hands it to its retry pass, which evicts); with eviction it says that the job evicted.
var<private> red_overflow: bool;

// Record of patch p: entry 0 its normal (pd_normal), entries 1-4 its slots (pd_slot); area and slot-0 key
// in patch_ak (ak_area, ak_key0).
fn pd_normal(p: u32) -> u32 {
    return p * 5u;
}

fn pd_slot(p: u32, k: u32) -> u32 {
    return p * 5u + 1u + k;
}

fn ak_area(p: u32) -> u32 {
    return 2u * p;
}

fn ak_key0(p: u32) -> u32 {
    return 2u * p + 1u;
}

fn key_of(k: u32, p: u32) -> u32 {
    return ((k - 1u) & 1u) * PATCH_CAP + p;
}

fn reset_patches(lid: u32) {
    lanes_init();
    for (var p = lid; p < PATCH_CAP; p += WG) {
        atomicStore(&patch_ak[ak_area(p)], 0u);
        atomicStore(&patch_ak[ak_key0(p)], 0u);
        atomicStore(&slot_keys[key_of(1u, p)], 0u);
        atomicStore(&slot_keys[key_of(2u, p)], 0u);
        for (var s = 0u; s < 4u; s++) {
            patch_data[pd_slot(p, s)] = vec4<f32>(0.0, 0.0, 0.0, EMPTY);
        }
    }
    if (lid == 0u) {
        atomicStore(&wg_best[0], 0u);
        atomicStore(&wg_best[1], 0u);
        atomicStore(&wg_victim, NONE);
    }
    workgroupBarrier();
}

// Metric that slot k maximises for a contact at x, given the patch's slots 0 to k - 1 (s0, s1, s2; those
// past k - 1 are not read); NEG_INF when not eligible.
// Slots 1-3 take no contact more than `band` above both the deepest one and the surface (every
// penetrating contact stays eligible): a patch's normal bin can hold
// points far from touching (a box face's far corners at a large contact offset), which would spread the
// patch over contacts that carry no load now (the paper's measure "prioritizes contacts with high
// penetration depth").
fn slot_metric(k: u32, s0: vec4<f32>, s1: vec4<f32>, s2: vec4<f32>, x: vec3<f32>, depth: f32, min_sep: f32, band: f32) -> f32 {
    if (s0.w <= MIN_DEPTH_BAND && depth > max(s0.w, 0.0) + min(band, max(abs(s0.w), MIN_DEPTH_BAND))) {
        return NEG_INF;
    }
    if (k == 1u) {
        let d = distance(x, s0.xyz);
        return select(NEG_INF, d, d > min_sep);
    }
    if (s1.w >= VALID_BELOW) {
        return NEG_INF;
    }
    let dir = normalize(s1.xyz - s0.xyz);
    if (k == 2u) {
        let l = length(cross(x - s0.xyz, dir));
        return select(NEG_INF, l, l > min_sep);
    }
    if (s2.w >= VALID_BELOW) {
        return NEG_INF;
    }
    let r = s2.xyz - s0.xyz;
    let perp = normalize(r - dot(r, dir) * dir);
    let m = -dot(x - s0.xyz, perp);
    return select(NEG_INF, m, m > min_sep);
}

// Slot 0's key of contact s (its depth; code 0), 0 for an empty slot.
fn slot0_key(s: vec4<f32>) -> u32 {
    return select(0u, ordered(-s.w), s.w < VALID_BELOW);
}

fn measure(p: u32, offset: f32) -> f32 {
    return f32(atomicLoad(&patch_ak[ak_area(p)])) * (offset - patch_data[pd_slot(p, 0u)].w);
}

// Key that a valid candidate already binned by Assign posts to wg_best in the first round: below every
// FindDeepest key (those have ordered(-depth) >= ordered(-offset) > IDX_MASK), so it only tells the
// workgroup that the batch has members and needs the slot rounds.
const ASSIGNED_ONLY: u32 = 0x200u;

// An invocation's PER candidates, component j of each vector holding candidate lid * PER + j of the batch
// (components j >= PER: none). Point in the SDF shape's frame [m], depth [m] (EMPTY: no candidate), unit
// normal, area units. Vectors across candidates rather than an array of records: private values at
// constant indices stay in registers on lavapipe, and Assign's and AddPatch's tests run on all at once.
struct Cands {
    px: vec4<f32>,
    py: vec4<f32>,
    pz: vec4<f32>,
    depth: vec4<f32>,
    nx: vec4<f32>,
    ny: vec4<f32>,
    nz: vec4<f32>,
    units: vec4<f32>,
}

const LANES4: vec4<u32> = vec4<u32>(0u, 1u, 2u, 3u);

fn cands_empty() -> Cands {
    let z = vec4<f32>(0.0);
    return Cands(z, z, z, vec4<f32>(EMPTY), z, z, z, z);
}

// Candidate j (0..PER) of *c becomes (pd: point xyz, depth w; n: unit normal xyz, area units w).
fn cands_set(c: ptr<function, Cands>, j: u32, pd: vec4<f32>, n: vec4<f32>) {
    let m = LANES4 == vec4<u32>(j);
    (*c).px = select((*c).px, vec4<f32>(pd.x), m);
    (*c).py = select((*c).py, vec4<f32>(pd.y), m);
    (*c).pz = select((*c).pz, vec4<f32>(pd.z), m);
    (*c).depth = select((*c).depth, vec4<f32>(pd.w), m);
    (*c).nx = select((*c).nx, vec4<f32>(n.x), m);
    (*c).ny = select((*c).ny, vec4<f32>(n.y), m);
    (*c).nz = select((*c).nz, vec4<f32>(n.z), m);
    (*c).units = select((*c).units, vec4<f32>(n.w), m);
}

fn cands_pd(c: Cands, j: u32) -> vec4<f32> {
    return vec4<f32>(c.px[j], c.py[j], c.pz[j], c.depth[j]);
}

fn cands_n(c: Cands, j: u32) -> vec4<f32> {
    return vec4<f32>(c.nx[j], c.ny[j], c.nz[j], c.units[j]);
}

// dot(n, m) for each candidate's normal n: WGSL's dot, as with one candidate per invocation (a compiler may
// fuse dot's multiply-adds; written out as products and sums, the bins came out otherwise in the last bit).
fn dot4(c: Cands, m: vec3<f32>) -> vec4<f32> {
    return vec4<f32>(
        dot(vec3<f32>(c.nx.x, c.ny.x, c.nz.x), m),
        dot(vec3<f32>(c.nx.y, c.ny.y, c.nz.y), m),
        dot(vec3<f32>(c.nx.z, c.ny.z, c.nz.z), m),
        dot(vec3<f32>(c.nx.w, c.ny.w, c.nz.w), m),
    );
}

fn ordered4(f: vec4<f32>) -> vec4<u32> {
    return vec4<u32>(ordered(f.x), ordered(f.y), ordered(f.z), ordered(f.w));
}

fn max4(v: vec4<u32>) -> u32 {
    return max(max(v.x, v.y), max(v.z, v.w));
}

fn sum4(v: vec4<u32>) -> u32 {
    return (v.x + v.y) + (v.z + v.w);
}

// The first j with v[j]; 3 if there is none.
fn first_of(v: vec4<bool>) -> u32 {
    return select(select(select(3u, 2u, v.z), 1u, v.y), 0u, v.x);
}

// One patch of an invocation's candidates: patch p and which candidates are in it.
struct Group {
    p: u32,
    sel: vec4<bool>,
}

// The patch of the first candidate still in *todo, with all of *todo's candidates in it, which leave *todo.
// Callers loop `loop { let g = next_group(&todo, mine); if (any(g.sel)) { ... } if (!any(todo)) { break; } }`:
// one pass per distinct patch of the invocation's candidates, at least one (counted in
// ContactConfig::reduce_batch_loops). The exit test ends the pass: lavapipe runs a loop's body once more,
// masked, after a pass that ends with the test at the top (see the note on loops above).
fn next_group(todo: ptr<function, vec4<bool>>, mine: vec4<u32>) -> Group {
    let t = *todo;
    let p = mine[first_of(t)];
    let sel = t & (mine == vec4<u32>(p));
    *todo = t & !sel;
    return Group(p, sel);
}

// FindDeepest of round *round of reduce_batch: every unbinned candidate posts its key (in round 0 a binned
// one posts ASSIGNED_ONLY), and the workgroup reads the largest (a barrier). Zeroes the next round's buffer,
// counts the round, and after round 0 sets *any_member (the batch has a candidate at all).
fn find_deepest(lid: u32, mine: vec4<u32>, key0: vec4<u32>, round: ptr<function, u32>, any_member: ptr<function, bool>) -> u32 {
    let b = red_round & 1u;
    red_round += 1u;
    let first = *round == 0u;
    let binned = select(vec4<bool>(false), mine != vec4<u32>(NONE), first);
    let each = select(select(vec4<u32>(0u), vec4<u32>(ASSIGNED_ONLY), binned), key0, mine == vec4<u32>(UNASSIGNED));
    let post = combine_max(max4(each));
    if (post != 0u) {
        atomicMax(&wg_best[b], post);
    }
    if (lid == 0u) {
        atomicStore(&wg_best[b ^ 1u], 0u);
    }
    let best = workgroupUniformLoad(&wg_best[b]);
    if (first) {
        *any_member = best != 0u;
    }
    *round += 1u;
    return best;
}

// AddPatch and BinReduce: opens patch idx seeded by the candidate of key `best` and bins this invocation's
// candidates into it if unbinned and their normals are similar (every invocation calls it).
fn add_patch(lid: u32, best: u32, idx: u32, c: Cands, units: vec4<u32>, key0: vec4<u32>, normal_cos: f32, mine: ptr<function, vec4<u32>>) {
    let seed = (best & IDX_MASK) - 1u;
    let seed_n = cand_n[seed].xyz;
    if (lid < 5u) {
        // Lane 0 the normal, lane 1 slot 0 (the seed), lanes 2-4 empty slots 1-3.
        var v = select(vec4<f32>(0.0, 0.0, 0.0, EMPTY), cand_pd[seed], lid == 1u);
        patch_data[pd_normal(idx) + lid] = select(v, vec4<f32>(seed_n, 0.0), lid == 0u);
    }
    let d = dot4(c, seed_n);
    let joins = (*mine == vec4<u32>(UNASSIGNED)) & (d >= vec4<f32>(normal_cos));
    *mine = select(*mine, vec4<u32>(idx), joins);
    let add = combine_add(sum4(select(vec4<u32>(0u), units, joins)));
    let key = combine_max(max4(select(vec4<u32>(0u), key0, joins)));
    if (add != 0u) {
        atomicAdd(&patch_ak[ak_area(idx)], add);
        atomicMax(&patch_ak[ak_key0(idx)], key);
    }
}

// With the budget full, after add_patch opened patch MAX_PATCHES: of the existing patches and the new one,
// the one of least measure goes: one atomic arg-min over keys ordered(measure) | code, code p + 1 for an
// existing patch (the lowest index wins a tie) and 0 for the new one (it loses ties: it replaces a patch
// only when it measures more). Updates this invocation's `mine`.
fn evict(lid: u32, offset: f32, mine: ptr<function, vec4<u32>>) {
    workgroupBarrier(); // members' areas added
    var vkey = NONE;
    for (var p = lid; p <= MAX_PATCHES; p += WG) {
        vkey = min(vkey, ordered(measure(p, offset)) | select(p + 1u, 0u, p == MAX_PATCHES));
    }
    let post_v = combine_min(vkey);
    if (post_v != NONE) {
        atomicMin(&wg_victim, post_v);
    }
    let code = workgroupUniformLoad(&wg_victim) & IDX_MASK;
    let victim = select(NONE, code - 1u, code != 0u);
    // Lanes 0-4 move the patch's record, lanes 5-6 its area and slot-0 key, and zero the temporary patch's;
    // the next reads of the patch list follow the next round's barrier. The victim's own members' slot-0
    // keys go with it (they are no longer members).
    if (victim != NONE && lid < 5u) {
        patch_data[pd_normal(victim) + lid] = patch_data[pd_normal(MAX_PATCHES) + lid];
    }
    if (lid == 5u || lid == 6u) {
        let a = lid - 5u;
        let v = atomicExchange(&patch_ak[ak_area(MAX_PATCHES) + a], 0u);
        if (victim != NONE) {
            atomicStore(&patch_ak[ak_area(victim) + a], v);
        }
    }
    if (lid == 7u) {
        atomicStore(&wg_victim, NONE);
    }
    let m = *mine;
    *mine = select(select(m, vec4<u32>(NONE), m == vec4<u32>(victim)), vec4<u32>(victim), m == vec4<u32>(MAX_PATCHES));
}

// Reduces a batch into the workgroup's patch list: this invocation's candidates are `c` (Cands; depth EMPTY:
// none); `pc0` is the patch count before the batch (workgroup-uniform; the caller keeps it) and the count
// after it is returned. Every invocation must call it. The caller must barrier before reading the patch list.
//
// Barriers serialise warps on a GPU, so each step is placed to need as few as possible (a batch that opens
// no patch costs 9: 2 for its one FindDeepest round, 2 per slot round and 1 after the last). On lavapipe
// they cost next to nothing (measured: what costs there is every memory instruction, run lane by
// lane, and every branch's body, run masked whether taken or not; see docs/BENCHMARKS.md):
// - no barrier at entry: Assign reads only this invocation's candidates and the patch normals and slot 0s,
//   which the previous batch last wrote before a barrier; candidates of other invocations are read only
//   after the first round's workgroupUniformLoad;
// - the seed's normal is read from cand_n (stable during the batch), so binning needs no barrier after
//   AddPatch writes the patch; a fresh patch index's area and slot-0 key are still 0 from reset_patches
//   (the temporary patch MAX_PATCHES is zeroed after each use), so members can add to them at once;
// - slot 0 (the deepest member) is an arg-max whose keys members post as soon as they know their patch
//   (Assign, AddPatch), into patch_ak, so it needs no round of its own; the slot's current contact
//   enters the arg-max when the key is read (max is order-free);
// - wg_best is double-buffered: the buffer of round i+1 is zeroed during round i, before the barrier that
//   ends every read of it from round i-1, so a round costs one workgroupUniformLoad (2 barriers), plus 3
//   when the budget is full and a victim must be chosen (one atomic arg-min over the patches, `evict`);
// - the slot rounds are the members' work, each invocation on the patches of its candidates (2 barriers
//   per round, one at the end), and a batch whose invocations have no candidate skips them (on a GPU;
//   lavapipe runs them masked).
//
// `evicting`, a constant at every call site (lavapipe and GPU compilers inline the call and drop the other
// branch): false leaves out the eviction rounds, whose code lavapipe would otherwise run, masked, in every
// batch (15% of the nut-bolt pair's contact handling, which never fills its budget); such a batch sets
// red_overflow and stops where a patch would have to go.
fn reduce_batch(lid: u32, c: Cands, pc0: u32, normal_cos: f32, offset: f32, min_sep: f32, evicting: bool) -> u32 {
    // Others read these (AddPatch) only after the first round's barrier; this invocation uses its own from
    // registers.
    let first = lid * PER;
    var j = 0u;
    loop {
        cand_pd[first + j] = cands_pd(c, j);
        cand_n[first + j] = cands_n(c, j);
        j += 1u;
        if (j >= PER) {
            break;
        }
    }
    let valid = c.depth < vec4<f32>(VALID_BELOW);
    let units = vec4<u32>(c.units);
    let code = vec4<u32>(first + 1u) + LANES4;
    let key0 = ordered4(-c.depth) | code;
    // Assign: the most similar existing patch above the threshold.
    let found = best_patch(c, pc0, normal_cos); // every invocation: best_patch may use subgroups
    var mine = select(vec4<u32>(NONE), found, valid);
    // Slot 0's arg-max over its current contact (code 0) and the members (see the slot rounds), per patch.
    var todo = valid & (mine != vec4<u32>(UNASSIGNED));
    loop {
        let g = next_group(&todo, mine);
        if (any(g.sel)) {
            atomicAdd(&patch_ak[ak_area(g.p)], sum4(select(vec4<u32>(0u), units, g.sel)));
            atomicMax(&patch_ak[ak_key0(g.p)], max(max4(select(vec4<u32>(0u), key0, g.sel)), slot0_key(patch_data[pd_slot(g.p, 0u)])));
        }
        if (!any(todo)) {
            break;
        }
    }
    // New patches: FindDeepest, BinReduce, AddPatch until every candidate is binned. `mine` holds these
    // candidates' patch indices, UNASSIGNED or NONE; only this invocation needs it. Two loops: rounds while
    // the budget has room, then rounds that evict: lavapipe runs a loop's body, masked, at least once, and
    // every branch's body, so with the eviction in the one loop every round paid for it.
    var pc = pc0;
    var round = 0u;
    var best = 0u;
    var any_member = false;
    loop {
        best = find_deepest(lid, mine, key0, &round, &any_member);
        if (best <= IDX_MASK || pc >= MAX_PATCHES) {
            break;
        }
        add_patch(lid, best, pc, c, units, key0, normal_cos, &mine);
        pc += 1u;
    }
    // Budget full and candidates left: each new patch goes to index MAX_PATCHES; of the existing patches
    // and the new one, the one of least measure goes.
    if (best > IDX_MASK) {
        red_overflow = true;
        if (!evicting) {
            return pc;
        }
        loop {
            add_patch(lid, best, MAX_PATCHES, c, units, key0, normal_cos, &mine);
            evict(lid, offset, &mine);
            best = find_deepest(lid, mine, key0, &round, &any_member);
            if (best <= IDX_MASK) {
                break;
            }
        }
    }
    if (!any_member) {
        return pc; // no candidate in the batch: the slot rounds would change nothing
    }
    // Slots: the arg-max per patch over the current slot and this batch's members, slot by slot (each
    // slot's metric depends on the slots before it). Only patches with members can change (the others'
    // slots were chosen against the same slots before them), so the members do all the work: each posts
    // the larger of its own key and the current contact's (code 0: keep it), and the winner writes its
    // point. The patches written above and every slot-0 post are visible: the last workgroupUniformLoad
    // of the loops was a barrier.
    let member = mine < vec4<u32>(MAX_PATCHES);
    todo = member;
    loop {
        let g = next_group(&todo, mine);
        if (any(g.sel)) {
            let hit = g.sel & (code == vec4<u32>(atomicLoad(&patch_ak[ak_key0(g.p)]) & IDX_MASK));
            if (any(hit)) {
                patch_data[pd_slot(g.p, 0u)] = cands_pd(c, first_of(hit));
            }
        }
        if (!any(todo)) {
            break;
        }
    }
    // Written out with a constant k each: lavapipe runs both sides of every branch, so slot_metric with a
    // loop's k paid for every slot's reads.
    let band = DEPTH_BAND * offset;
    slot_round(1u, mine, c, code, min_sep, band);
    slot_round(2u, mine, c, code, min_sep, band);
    slot_round(3u, mine, c, code, min_sep, band);
    workgroupBarrier(); // every member has read slot 3's key
    todo = member;
    loop {
        let g = next_group(&todo, mine);
        if (any(g.sel)) {
            atomicStore(&slot_keys[key_of(3u, g.p)], 0u);
        }
        if (!any(todo)) {
            break;
        }
    }
    return pc;
}

// The largest slot-k key of the candidates of `sel` (all in one patch with slots s0, s1, s2), 0 if none is
// eligible.
fn member_key(k: u32, s0: vec4<f32>, s1: vec4<f32>, s2: vec4<f32>, c: Cands, code: vec4<u32>, sel: vec4<bool>, min_sep: f32, band: f32) -> u32 {
    var key = 0u;
    var j = 0u;
    loop {
        let pd = cands_pd(c, j);
        let m = slot_metric(k, s0, s1, s2, pd.xyz, pd.w, min_sep, band);
        if (sel[j] && m > NEG_INF) {
            key = max(key, ordered(m) | code[j]);
        }
        j += 1u;
        if (j >= PER) {
            break;
        }
    }
    return key;
}

// Slot round k (1-3) of reduce_batch: the members of each patch post their metric for slot k and the
// current contact's, then the winner writes its point (or, when neither it nor any member is eligible, the
// slot empties). Also resets the previous slot's key, which every member has read. Each invocation works
// once per distinct patch of its candidates.
fn slot_round(k: u32, mine: vec4<u32>, c: Cands, code: vec4<u32>, min_sep: f32, band: f32) {
    workgroupBarrier(); // slot k - 1 written
    let member = mine < vec4<u32>(MAX_PATCHES);
    var todo = member;
    loop {
        let g = next_group(&todo, mine);
        if (any(g.sel)) {
            if (k == 1u) {
                atomicStore(&patch_ak[ak_key0(g.p)], 0u);
            } else {
                atomicStore(&slot_keys[key_of(k - 1u, g.p)], 0u);
            }
            let s0 = patch_data[pd_slot(g.p, 0u)];
            var s1 = vec4<f32>(0.0);
            var s2 = vec4<f32>(0.0);
            if (k >= 2u) {
                s1 = patch_data[pd_slot(g.p, 1u)];
            }
            if (k >= 3u) {
                s2 = patch_data[pd_slot(g.p, 2u)];
            }
            let cur = patch_data[pd_slot(g.p, k)];
            var key = member_key(k, s0, s1, s2, c, code, g.sel, min_sep, band);
            if (cur.w < VALID_BELOW) {
                let mc = slot_metric(k, s0, s1, s2, cur.xyz, cur.w, min_sep, band);
                if (mc > NEG_INF) {
                    key = max(key, ordered(mc));
                }
            }
            if (key != 0u) {
                atomicMax(&slot_keys[key_of(k, g.p)], key);
            }
        }
        if (!any(todo)) {
            break;
        }
    }
    workgroupBarrier();
    todo = member;
    loop {
        let g = next_group(&todo, mine);
        if (any(g.sel)) {
            // The winner writes its point; where neither the current contact (no longer eligible: too close
            // to or far above the new deepest) nor a member qualifies, the slot empties (every invocation with
            // members writes the same value). One store: lavapipe runs each store instruction lane by lane,
            // taken or not.
            let key = atomicLoad(&slot_keys[key_of(k, g.p)]);
            let hit = g.sel & (code == vec4<u32>(key & IDX_MASK));
            let own = any(hit);
            if (own || key == 0u) {
                patch_data[pd_slot(g.p, k)] = select(vec4<f32>(0.0, 0.0, 0.0, EMPTY), cands_pd(c, first_of(hit)), own);
            }
        }
        if (!any(todo)) {
            break;
        }
    }
}
