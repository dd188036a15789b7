// Contact generation on a many-body world's near pairs (see many_body/mod.rs): the work of
// contact/generate.wgsl (generate_core.wgsl) with the jobs taken from the near-pair list instead of a fixed
// list; the second reduction level is many_body/merge.wgsl. Prepended: contact/common.wgsl,
// many_body/many_body_common.wgsl; appended: generate_core, sdf_sample and the analytic SDFs.
//
// Layout: near pair e of world w is g = w * cap + e; its job k is g * jobs_per_pair + k, whose patches go
// to job_patches[(g * jobs_per_pair + k) * MAX_PATCHES..] and the pair's reduced patches to
// patches[g * MAX_PATCHES..] (merge.wgsl); counts go to many_body_meta (patch count, candidates, row offset).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<uniform> cp: ManyBodyParams;
@group(0) @binding(2) var<storage, read> tri_verts: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> sdf_values: array<u32>;
// Bounding sphere of job k of template t at [t * jobs_per_pair + k] (ManyBodyFlat::job_bounds).
@group(0) @binding(4) var<storage, read> job_bounds: array<vec4<f32>>;
@group(1) @binding(0) var<storage, read> body_q: array<Transform>;
@group(1) @binding(1) var<storage, read> many_body_pairs: array<Pair>;
@group(2) @binding(0) var<storage, read_write> job_patches: array<PatchOut>;
@group(2) @binding(1) var<storage, read_write> job_patch_count: array<u32>;
@group(2) @binding(2) var<storage, read_write> many_body_meta: array<atomic<u32>>;

var<workgroup> wg_count: u32;

// The world's near-pair count, uniform across the workgroup (it is read from a read-write buffer).
fn pair_count(lid: u32, w: u32) -> u32 {
    if (lid == 0u) {
        wg_count = atomicLoad(&many_body_meta[meta_base(w) + M_COUNT]);
    }
    return workgroupUniformLoad(&wg_count);
}

fn shape_pose(w: u32, body: u32, pos: vec4<f32>, rot: vec4<f32>) -> Transform {
    var t = Transform(vec4<f32>(0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0));
    if (body != NONE) {
        t = body_q[w * cp.body_count + body];
    }
    return xf_mul(t, Transform(pos, rot));
}

@compute @workgroup_size(WG)
fn many_body_generate(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let w = wid.z;
    let jobs = cp.jobs_per_pair;
    let e = wid.x;
    let k = wid.y;
    if (e >= pair_count(lid, w)) {
        return;
    }
    let g = w * cp.cap + e;
    let job = g * jobs + k;
    let pair = many_body_pairs[g];
    let world_a = shape_pose(w, pair.body_a, pair.a_pos, pair.a_rot);
    let world_b = shape_pose(w, pair.body_b, pair.b_pos, pair.b_rot);
    if (k >= pair.job_count || pair_far(pair, world_a, world_b)) {
        if (lid == 0u) {
            job_patch_count[job] = 0u;
        }
        return;
    }
    // Job cull (mod.rs job_far_cpu): one sample at the centre of the job's bounding sphere stands for all
    // its triangles' culls; most of a near pair's surface is far from the other shape. Two voxels of
    // slack for a grid: trilinear interpolation can be off by up to sqrt(3)/2 of a voxel either side.
    let bound = job_bounds[pair.many_body_template * jobs + k];
    sdf_bind(pair);
    let sc = sdf_sample(pair, xf_point(xf_mul(xf_inv(world_b), world_a), bound.xyz));
    let slack = select(2.0 * pair.sdf_origin.w, 0.0, pair.sdf_kind == 1u);
    if (bound.w < 0.0 || sc.d - bound.w - slack > pair.contact_offset) {
        if (lid == 0u) {
            job_patch_count[job] = 0u;
        }
        return;
    }
    let first = k * cp.chunk;
    let out = generate_job(lid, pair, pair.tri_first + first, min(cp.chunk, pair.tri_count - first), world_a, world_b, job * MAX_PATCHES, true);
    if (out.y > 0u) {
        atomicAdd(&many_body_meta[m_candidates(w) + e], out.y);
    }
    if (lid == 0u) {
        job_patch_count[job] = out.x;
    }
}

// One invocation per world: each pair's first patch in the world's row block (the solver's rows are laid
// out by patch), flagged when the patches exceed the budget.
@compute @workgroup_size(64)
fn many_body_alloc(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x;
    if (w >= cp.world_count) {
        return;
    }
    let n = atomicLoad(&many_body_meta[meta_base(w) + M_COUNT]);
    var total = 0u;
    for (var e = 0u; e < n; e++) {
        atomicStore(&many_body_meta[m_row_first(w) + e], total);
        total += atomicLoad(&many_body_meta[m_patch_count(w) + e]);
    }
    atomicStore(&many_body_meta[meta_base(w) + M_PATCHES], total);
    if (total > cp.patch_budget) {
        atomicOr(&many_body_meta[meta_base(w) + M_FLAGS], FLAG_PATCHES);
    }
}
