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
// those of one pass with eviction. A frame where no job overflows (the nut-bolt pair alone: 55 patches of
// 64) dispatches no retry workgroup; the host clears the lists' counters before each frame.
//
// Sticky eviction: a job that overflowed keeps a flag (per job and world, kept across frames), and while
// it is set the first pass lists the job for the evicting pass at once instead of running it twice; the
// evicting pass clears the flag when the job evicted nothing. Both ways give the same patches, since an
// evicting run that never fills its budget does what the plain run does (reduce_batch). The Franka's nut,
// held in the hand on the thread, overflowed the 64 patches in ~121 of 128 worlds every frame (the
// bare nut-bolt scene's never does): the whole pair was generated twice.
//
// The evicting pass runs per SDF kind (RETRY_KIND, each pipeline compiled for its kind alone, as the first
// pass's runs are; lavapipe runs every compiled kind's sampling, masked, at every descent step), so the
// lists are per kind. `retry_jobs` layout (u32 words): [0, KINDS) each kind's listed-job count; then the
// flags, one per (world, job) at KINDS + world * job_count + job; then each kind's list of (job, world)
// pairs, kind k's from list_base(k), room for every job of every world. `retry_args`: the indirect
// dispatch size (x, y, z) of kind k's pass at words 3k..3k+2.

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
// The retry lists and the sticky flags (layout above).
@group(2) @binding(3) var<storage, read_write> retry_jobs: array<atomic<u32>>;
@group(2) @binding(4) var<storage, read_write> retry_args: array<atomic<u32>>;

const RETRY_ROW: u32 = 65535u; // the least max_compute_workgroups_per_dimension WebGPU allows
const KINDS: u32 = 4u; // SDF kinds (model.rs PairGpu::sdf_kind: grid, plane, thread, revolved)

// The SDF kind whose listed jobs a `generate_retry` pipeline redoes (generate.rs sets it per pipeline).
override RETRY_KIND: u32 = 0u;

fn flag_index(job_index: u32, world: u32) -> u32 {
    return KINDS + world * params.job_count + job_index;
}

fn list_base(kind: u32) -> u32 {
    return KINDS + params.world_count * params.job_count * (1u + 2u * kind);
}

// The first pass's workgroup-uniform copy of its job's flag.
var<workgroup> wg_flag: u32;

@compute @workgroup_size(WG)
fn generate(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let job_index = wid.x + params.job_base;
    let world = wid.y + params.world_offset;
    if (lid == 0u) {
        wg_flag = atomicLoad(&retry_jobs[flag_index(job_index, world)]);
    }
    // A flagged job goes straight to the evicting pass (uniform: the whole workgroup skips the plain run).
    if (workgroupUniformLoad(&wg_flag) == 0u) {
        if (run_job(lid, job_index, world, false)) {
            return;
        }
    }
    // Flagged or overflowed: list the job for its kind's evicting pass, and flag it for the next frame.
    if (lid == 0u) {
        let kind = pairs[jobs[job_index].pair].sdf_kind;
        atomicStore(&retry_jobs[flag_index(job_index, world)], 1u);
        let i = atomicAdd(&retry_jobs[kind], 1u);
        let at = list_base(kind) + 2u * i;
        atomicStore(&retry_jobs[at], job_index);
        atomicStore(&retry_jobs[at + 1u], world);
        atomicMax(&retry_args[3u * kind], min(i + 1u, RETRY_ROW));
        atomicMax(&retry_args[3u * kind + 1u], i / RETRY_ROW + 1u);
        atomicStore(&retry_args[3u * kind + 2u], 1u);
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
        if (i < atomicLoad(&retry_jobs[RETRY_KIND])) {
            let at = list_base(RETRY_KIND) + 2u * i;
            e = vec3<u32>(1u, atomicLoad(&retry_jobs[at]), atomicLoad(&retry_jobs[at + 1u]));
        }
        wg_retry = e;
    }
    let e = workgroupUniformLoad(&wg_retry);
    if (e.x == 0u) {
        return;
    }
    run_job(lid, e.y, e.z, true);
    // red_overflow (uniform): whether the job's budget filled and it evicted; if not, the plain pass will do
    // next frame.
    if (lid == 0u) {
        atomicStore(&retry_jobs[flag_index(e.y, e.z)], select(0u, 1u, red_overflow));
    }
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
