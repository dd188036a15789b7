// Second level of contact reduction on a many-body world's near pairs (contact/merge.wgsl's work,
// merge_core.wgsl, on the near-pair list; layout as in many_body/contacts.wgsl). A module of its own because the
// job counts, written by the generate kernel, must be read-only here: the reduction's barriers need the
// loop bounds derived from them to be uniform. Prepended: contact/common.wgsl, many_body/many_body_common.wgsl;
// appended: merge_core.wgsl.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<uniform> cp: ManyBodyParams;
@group(1) @binding(0) var<storage, read> many_body_pairs: array<Pair>;
@group(1) @binding(1) var<storage, read> job_patches: array<PatchOut>;
@group(1) @binding(2) var<storage, read> job_patch_count: array<u32>;
@group(2) @binding(0) var<storage, read_write> many_body_meta: array<atomic<u32>>;
@group(2) @binding(1) var<storage, read_write> patches: array<PatchOut>;

var<workgroup> wg_count: u32;

// The world's near-pair count, uniform across the workgroup (it is read from a read-write buffer).
fn pair_count(lid: u32, w: u32) -> u32 {
    if (lid == 0u) {
        wg_count = atomicLoad(&many_body_meta[meta_base(w) + M_COUNT]);
    }
    return workgroupUniformLoad(&wg_count);
}

@compute @workgroup_size(WG)
fn many_body_merge(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let w = wid.y;
    let e = wid.x;
    if (e >= pair_count(lid, w)) {
        return;
    }
    let g = w * cp.cap + e;
    let pair = many_body_pairs[g];
    let pc = merge_jobs(lid, pair, g * cp.jobs_per_pair, pair.job_count, g * MAX_PATCHES);
    if (lid == 0u) {
        atomicStore(&many_body_meta[m_patch_count(w) + e], pc);
    }
}

