// Contact generation (paper III-A; Macklin et al. 2020, "Local optimization for robust signed distance
// field collision") fused with the first level of contact reduction. One workgroup per (job, world): a job
// is a run of up to `chunk` query triangles of one shape pair. Each invocation takes one triangle per
// batch, moves the triangle's point of least signed distance (in the SDF shape's frame) by projected
// gradient descent on the triangle with an adaptive step, and keeps it as a candidate when it lies within
// the contact offset. The batch is then reduced into patches in workgroup memory (common.wgsl); only the
// job's patches reach global memory, for merge.wgsl to combine per pair.
//
// Two entry points: `generate` runs every job without the reduction's eviction rounds (see reduce_batch)
// and lists the jobs whose patch budget overflows in `retry_jobs`, sizing the indirect dispatch of
// `generate_retry` in `retry_args`; `generate_retry` redoes those jobs with eviction. The results are
// those of one pass with eviction. A frame where no job overflows (the nut-bolt pair: 55 patches of 64)
// dispatches no retry workgroup; the host clears both buffers' counters before each frame.

struct Job {
    pair: u32,
    tri_first: u32,
    tri_count: u32,
    slot: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> pairs: array<Pair>;
@group(0) @binding(2) var<storage, read> jobs: array<Job>;
@group(0) @binding(3) var<storage, read> tri_verts: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> sdf_values: array<u32>;  // i16 pairs, see model.rs
@group(1) @binding(0) var<storage, read> body_q: array<Transform>;
@group(2) @binding(0) var<storage, read_write> job_patches: array<PatchOut>;
@group(2) @binding(1) var<storage, read_write> job_patch_count: array<u32>;
@group(2) @binding(2) var<storage, read_write> pair_candidates: array<atomic<u32>>;
// Word 0: jobs listed; then (job, world) per listed job.
@group(2) @binding(3) var<storage, read_write> retry_jobs: array<atomic<u32>>;
// Indirect dispatch size of generate_retry (x, y, z workgroups): rows of RETRY_ROW jobs.
@group(2) @binding(4) var<storage, read_write> retry_args: array<atomic<u32>>;

const RETRY_ROW: u32 = 65535u; // the least max_compute_workgroups_per_dimension WebGPU allows

@compute @workgroup_size(WG)
fn generate(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let job_index = wid.x + params.job_base;
    let world = wid.y + params.world_offset;
    if (run_job(lid, job_index, world, false)) {
        return;
    }
    // Overflow: list the job for the retry pass.
    if (lid == 0u) {
        let i = atomicAdd(&retry_jobs[0], 1u);
        atomicStore(&retry_jobs[1u + 2u * i], job_index);
        atomicStore(&retry_jobs[2u + 2u * i], world);
        atomicMax(&retry_args[0], min(i + 1u, RETRY_ROW));
        atomicMax(&retry_args[1], i / RETRY_ROW + 1u);
        atomicStore(&retry_args[2], 1u);
    }
}

// The retry pass's job: (1, job, world), or x = 0 in the last row's padding; through workgroup memory, so
// that the workgroup's control flow is uniform.
var<workgroup> wg_retry: vec3<u32>;

@compute @workgroup_size(WG)
fn generate_retry(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    if (lid == 0u) {
        let i = wid.y * RETRY_ROW + wid.x;
        var e = vec3<u32>(0u);
        if (i < atomicLoad(&retry_jobs[0])) {
            e = vec3<u32>(1u, atomicLoad(&retry_jobs[1u + 2u * i]), atomicLoad(&retry_jobs[2u + 2u * i]));
        }
        wg_retry = e;
    }
    let e = workgroupUniformLoad(&wg_retry);
    if (e.x == 0u) {
        return;
    }
    run_job(lid, e.y, e.z, true);
}

// Job `job_index` in world `world`; false (and nothing written) where `evicting` is false and the patch budget
// overflows.
fn run_job(lid: u32, job_index: u32, world: u32, evicting: bool) -> bool {
    let job = jobs[job_index];
    let pair = pairs[job.pair];
    // Poses: query shape A and SDF shape B in the world; work in B's frame.
    var body_a = Transform(vec4<f32>(0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0));
    var body_b = body_a;
    if (pair.body_a != NONE) {
        body_a = body_q[world * params.body_count + pair.body_a];
    }
    if (pair.body_b != NONE) {
        body_b = body_q[world * params.body_count + pair.body_b];
    }
    let world_a = xf_mul(body_a, Transform(pair.a_pos, pair.a_rot));
    let world_b = xf_mul(body_b, Transform(pair.b_pos, pair.b_rot));
    // Broad phase: far apart, the job has nothing (uniform: every input is read at a uniform index).
    if (pair_far(pair, world_a, world_b)) {
        if (lid == 0u) {
            job_patch_count[world * params.job_count + job_index] = 0u;
        }
        return true;
    }
    sdf_bind(pair);
    let out = generate_job(lid, pair, job.tri_first, job.tri_count, world_a, world_b, (world * params.job_count + job_index) * MAX_PATCHES, evicting);
    if (out.x == NONE) {
        return false;
    }
    if (out.y > 0u) {
        atomicAdd(&pair_candidates[world * params.pair_count + job.pair], out.y);
    }
    if (lid == 0u) {
        job_patch_count[world * params.job_count + job_index] = out.x;
    }
    return true;
}
