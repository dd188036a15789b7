// Second level of contact reduction: one workgroup per (pair, world) reads the patches that
// generate.wgsl wrote for the pair's jobs, treats their contacts as candidates (with the patch normal and
// an equal share of its area), and runs the same reduction (common.wgsl) into at most MAX_PATCHES patches.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> pairs: array<Pair>;
@group(1) @binding(0) var<storage, read> job_patches: array<PatchOut>;
@group(1) @binding(1) var<storage, read> job_patch_count: array<u32>;
@group(2) @binding(0) var<storage, read_write> patches: array<PatchOut>;
@group(2) @binding(1) var<storage, read_write> patch_counts: array<u32>;

@compute @workgroup_size(WG)
fn merge(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let pair_index = wid.x;
    let world = wid.y + params.world_offset;
    let pair = pairs[pair_index];
    reset_patches(lid);
    var pc = 0u;
    // The jobs' slots form one stream (job by job, 4 slots per patch), cut into batches of WG: most jobs
    // hold far fewer than WG slots, and a batch costs the same (its barriers and slot rounds) however few
    // candidates it holds.
    let job_base = world * params.job_count + pair.job_first;
    var total = 0u;
    for (var j = 0u; j < pair.job_count; j++) {
        total += job_patch_count[job_base + j] * 4u;
    }
    var first_job = 0u; // the job holding stream index `base`, and its first index
    var first_off = 0u;
    for (var base = 0u; base < total; base += WG) {
        loop {
            let n = job_patch_count[job_base + first_job] * 4u;
            if (first_off + n > base) {
                break;
            }
            first_off += n;
            first_job++;
        }
        var cand = vec4<f32>(0.0, 0.0, 0.0, EMPTY);
        var normal = vec4<f32>(0.0);
        let i = base + lid;
        if (i < total) {
            var j = first_job;
            var off = first_off;
            loop {
                let n = job_patch_count[job_base + j] * 4u;
                if (i < off + n) {
                    break;
                }
                off += n;
                j++;
            }
            let k = i - off;
            let p = job_patches[(job_base + j) * MAX_PATCHES + k / 4u];
            let sl = p.slots[k % 4u];
            if (sl.w < VALID_BELOW) {
                var used = 0u;
                for (var s = 0u; s < 4u; s++) {
                    used += select(0u, 1u, p.slots[s].w < VALID_BELOW);
                }
                cand = sl;
                let units = p.normal.w / (f32(used) * pair.area_unit);
                normal = vec4<f32>(p.normal.xyz, f32(max(1u, u32(round(units)))));
            }
        }
        put_candidate(lid, cand, normal);
        pc = reduce_batch(lid, pc, params.normal_cos, pair.contact_offset, pair.min_separation);
    }
    workgroupBarrier(); // the last batch's slot writes
    let out_base = (world * params.pair_count + pair_index) * MAX_PATCHES;
    for (var p = lid; p < pc; p += WG) {
        var o: PatchOut;
        o.normal = vec4<f32>(patch_n[p].xyz, f32(atomicLoad(&patch_area[p])) * pair.area_unit);
        for (var s = 0u; s < 4u; s++) {
            o.slots[s] = patch_slot[p * 4u + s];
        }
        patches[out_base + p] = o;
    }
    if (lid == 0u) {
        patch_counts[world * params.pair_count + pair_index] = pc;
    }
}
