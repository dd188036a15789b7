// Shared by generate.wgsl and merge.wgsl (the host concatenates this file in front of each).
// Contact reduction in workgroup memory (paper III-C, Algorithm 1): a batch of WG candidates lives in
// workgroup arrays; Assign bins them into existing patches by normal similarity, then FindDeepest /
// BinReduce / AddPatch open new patches until none is left; finally each patch keeps at most 4 contacts
// (deepest, farthest from it, farthest from their line, farthest on the other side: the largest area).
// Candidates are never written to global memory.

const WG: u32 = 256u;
// Patch budget per pair, substituted by the host when the pipeline is built (16..256).
const MAX_PATCHES: u32 = MAX_PATCHES_VALUE;
const PATCH_CAP: u32 = MAX_PATCHES_VALUE + 1u; // + one temporary patch for AddPatch when full
const NONE: u32 = 0xffffffffu;
const UNASSIGNED: u32 = 0xfffffffeu;
const EMPTY: f32 = 3.0e38;   // depth of an empty slot / no candidate
const VALID_BELOW: f32 = 1.0e38;
const NEG_INF: f32 = -3.0e38;
const IDX_MASK: u32 = 0x3ffu;

struct Params {
    world_count: u32,
    body_count: u32,
    pair_count: u32,
    job_count: u32,
    normal_cos: f32,
    iterations: u32,
    world_offset: u32,
    _pad: u32,
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

// Order-preserving map of f32 to u32 (larger float -> larger integer), low bits cleared for an index.
fn ordered(f: f32) -> u32 {
    let b = bitcast<u32>(f);
    let m = select(0x80000000u, 0xffffffffu, (b & 0x80000000u) != 0u);
    return (b ^ m) & ~IDX_MASK;
}

var<workgroup> cand_pd: array<vec4<f32>, WG>;      // point xyz, depth w (EMPTY: no candidate)
var<workgroup> cand_n: array<vec4<f32>, WG>;       // unit normal xyz, area units w
var<workgroup> cand_patch: array<u32, WG>;         // patch index, UNASSIGNED or NONE
var<workgroup> patch_n: array<vec4<f32>, PATCH_CAP>;        // seed normal xyz
var<workgroup> patch_area: array<atomic<u32>, PATCH_CAP>;   // member area [area units]
var<workgroup> patch_slot: array<vec4<f32>, PATCH_CAP * 4u>;          // 4 per patch: point xyz, depth w
var<workgroup> patch_key: array<atomic<u32>, PATCH_CAP>;
var<workgroup> wg_best: atomic<u32>;
var<workgroup> wg_u32: u32;
var<workgroup> patch_count: u32;

fn reset_patches(lid: u32) {
    if (lid < PATCH_CAP) {
        atomicStore(&patch_area[lid], 0u);
        for (var s = 0u; s < 4u; s++) {
            patch_slot[lid * 4u + s] = vec4<f32>(0.0, 0.0, 0.0, EMPTY);
        }
    }
    if (lid == 0u) {
        patch_count = 0u;
    }
    workgroupBarrier();
}

// Metric that slot k maximises for a contact at x; NEG_INF when not eligible.
fn slot_metric(k: u32, p: u32, x: vec3<f32>, depth: f32, min_sep: f32) -> f32 {
    if (k == 0u) {
        return -depth;
    }
    let s0 = patch_slot[p * 4u];
    if (k == 1u) {
        let d = distance(x, s0.xyz);
        return select(NEG_INF, d, d > min_sep);
    }
    let s1 = patch_slot[p * 4u + 1u];
    if (s1.w >= VALID_BELOW) {
        return NEG_INF;
    }
    let dir = normalize(s1.xyz - s0.xyz);
    if (k == 2u) {
        let l = length(cross(x - s0.xyz, dir));
        return select(NEG_INF, l, l > min_sep);
    }
    let s2 = patch_slot[p * 4u + 2u];
    if (s2.w >= VALID_BELOW) {
        return NEG_INF;
    }
    let r = s2.xyz - s0.xyz;
    let perp = normalize(r - dot(r, dir) * dir);
    let m = -dot(x - s0.xyz, perp);
    return select(NEG_INF, m, m > min_sep);
}

fn measure(p: u32, offset: f32) -> f32 {
    return f32(atomicLoad(&patch_area[p])) * (offset - patch_slot[p * 4u].w);
}

// Reduces the batch in cand_* into the workgroup's patch list. Every invocation must call it.
fn reduce_batch(lid: u32, normal_cos: f32, offset: f32, min_sep: f32) {
    // Assign: the most similar existing patch above the threshold.
    let pc0 = workgroupUniformLoad(&patch_count);
    let my = cand_pd[lid];
    let my_n = cand_n[lid];
    let units = u32(my_n.w);
    if (my.w < VALID_BELOW) {
        var best = normal_cos;
        var assigned = UNASSIGNED;
        for (var p = 0u; p < pc0; p++) {
            let d = dot(my_n.xyz, patch_n[p].xyz);
            if (d >= best) {
                best = d;
                assigned = p;
            }
        }
        cand_patch[lid] = assigned;
        if (assigned != UNASSIGNED) {
            atomicAdd(&patch_area[assigned], units);
        }
    } else {
        cand_patch[lid] = NONE;
    }
    // New patches: FindDeepest, BinReduce, AddPatch until every candidate is binned.
    loop {
        if (lid == 0u) {
            atomicStore(&wg_best, 0u);
        }
        workgroupBarrier();
        if (cand_patch[lid] == UNASSIGNED) {
            atomicMax(&wg_best, ordered(-my.w) | (lid + 1u));
        }
        workgroupBarrier();
        if (lid == 0u) {
            wg_u32 = atomicLoad(&wg_best);
        }
        let best = workgroupUniformLoad(&wg_u32);
        if (best == 0u) {
            break;
        }
        let seed = (best & IDX_MASK) - 1u;
        let idx = min(workgroupUniformLoad(&patch_count), MAX_PATCHES);
        if (lid == 0u) {
            patch_n[idx] = vec4<f32>(cand_n[seed].xyz, 0.0);
            atomicStore(&patch_area[idx], 0u);
            patch_slot[idx * 4u] = cand_pd[seed];
            for (var s = 1u; s < 4u; s++) {
                patch_slot[idx * 4u + s] = vec4<f32>(0.0, 0.0, 0.0, EMPTY);
            }
        }
        workgroupBarrier();
        if (cand_patch[lid] == UNASSIGNED && dot(my_n.xyz, patch_n[idx].xyz) >= normal_cos) {
            cand_patch[lid] = idx;
            atomicAdd(&patch_area[idx], units);
        }
        workgroupBarrier();
        if (idx < MAX_PATCHES) {
            if (lid == 0u) {
                patch_count = idx + 1u;
            }
        } else {
            // Budget full: the new patch replaces the existing one of lowest measure if it measures more.
            if (lid == 0u) {
                var victim = 0u;
                var lowest = measure(0u, offset);
                for (var p = 1u; p < MAX_PATCHES; p++) {
                    let m = measure(p, offset);
                    if (m < lowest) {
                        lowest = m;
                        victim = p;
                    }
                }
                if (measure(MAX_PATCHES, offset) > lowest) {
                    patch_n[victim] = patch_n[MAX_PATCHES];
                    atomicStore(&patch_area[victim], atomicLoad(&patch_area[MAX_PATCHES]));
                    for (var s = 0u; s < 4u; s++) {
                        patch_slot[victim * 4u + s] = patch_slot[MAX_PATCHES * 4u + s];
                    }
                    wg_u32 = victim;
                } else {
                    wg_u32 = NONE;
                }
            }
            let victim = workgroupUniformLoad(&wg_u32);
            let c = cand_patch[lid];
            if (c == MAX_PATCHES) {
                cand_patch[lid] = victim;
            } else if (c == victim) {
                cand_patch[lid] = NONE;
            }
        }
        workgroupBarrier();
    }
    // Slots: 4 rounds, each an atomic arg-max per patch over the current slot and this batch's members.
    let pc = workgroupUniformLoad(&patch_count);
    for (var k = 0u; k < 4u; k++) {
        if (lid < pc) {
            let s = patch_slot[lid * 4u + k];
            var key0 = 0u;
            if (s.w < VALID_BELOW) {
                let m = slot_metric(k, lid, s.xyz, s.w, min_sep);
                if (m > NEG_INF) {
                    key0 = ordered(m);
                }
            }
            atomicStore(&patch_key[lid], key0);
        }
        workgroupBarrier();
        let c = cand_patch[lid];
        if (c < MAX_PATCHES) {
            let m = slot_metric(k, c, my.xyz, my.w, min_sep);
            if (m > NEG_INF) {
                atomicMax(&patch_key[c], ordered(m) | (lid + 1u));
            }
        }
        workgroupBarrier();
        if (lid < pc) {
            let code = atomicLoad(&patch_key[lid]) & IDX_MASK;
            if (code != 0u) {
                patch_slot[lid * 4u + k] = cand_pd[code - 1u];
            }
        }
        workgroupBarrier();
    }
}
