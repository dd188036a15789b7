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
    let pc = merge_jobs(lid, pair, world * params.job_count + pair.job_first, pair.job_count, (world * params.pair_count + pair_index) * MAX_PATCHES);
    if (lid == 0u) {
        patch_counts[world * params.pair_count + pair_index] = pc;
    }
}
