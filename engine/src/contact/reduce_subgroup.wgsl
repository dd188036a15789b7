// Reduction helpers with subgroup operations (appended to common.wgsl by the host where the device has
// wgpu::Features::SUBGROUP; the portable twin is reduce_plain.wgsl, with the same results). Call every one
// in uniform control flow.
//
// Why: lavapipe runs each workgroup-memory access lane by lane (one scalar access per lane and component,
// whichever lanes take it), so in Assign, where every invocation reads every patch normal, 8 lanes paid 8
// reads for one value. Here each of a subgroup's lanes reads a different patch and the subgroup shares
// them by shuffles: contact handling of the M16 nut-bolt pair at 64 worlds about 1.1x faster (2026-12-02,
// docs/BENCHMARKS.md). A subgroup also combines its posts to an atomic before one lane makes it; that is
// neutral on lavapipe and saves atomic contention on a GPU, as Assign's shuffles save shared-memory reads.

// This invocation's lane in its subgroup (counted as the active lanes are: every lane is active where
// lanes_init runs, at the top of reset_patches).
var<private> sg_lane: u32;

fn lanes_init() {
    sg_lane = subgroupExclusiveAdd(1u);
}

// The most similar patch of [0, pc0) to unit normal n with a dot product of at least `cos` (ties: the
// highest index), or UNASSIGNED. 8 patches per pass, read by lanes 0-7 (lavapipe's subgroup size; the host
// uses this file only where subgroups have at least 8 lanes; on wider ones the other lanes read copies),
// so the loop runs fewer passes than the portable one (see the note on loops in common.wgsl).
fn best_patch(n: vec3<f32>, pc0: u32, cos: f32) -> u32 {
    var best = cos;
    var mine = UNASSIGNED;
    for (var base = 0u; base < pc0; base += 8u) {
        let lane_n = patch_data[pd_normal(min(base + (sg_lane & 7u), PATCH_CAP - 1u))].xyz;
        shuffle_step(base, 0u, lane_n, pc0, n, &best, &mine);
        shuffle_step(base, 1u, lane_n, pc0, n, &best, &mine);
        shuffle_step(base, 2u, lane_n, pc0, n, &best, &mine);
        shuffle_step(base, 3u, lane_n, pc0, n, &best, &mine);
        shuffle_step(base, 4u, lane_n, pc0, n, &best, &mine);
        shuffle_step(base, 5u, lane_n, pc0, n, &best, &mine);
        shuffle_step(base, 6u, lane_n, pc0, n, &best, &mine);
        shuffle_step(base, 7u, lane_n, pc0, n, &best, &mine);
    }
    return mine;
}

// Patch base + j, read by lane j, against n.
fn shuffle_step(base: u32, j: u32, lane_n: vec3<f32>, pc0: u32, n: vec3<f32>, best: ptr<function, f32>, mine: ptr<function, u32>) {
    let d = dot(n, subgroupShuffle(lane_n, j));
    if (base + j < pc0 && d >= *best) {
        *best = d;
        *mine = base + j;
    }
}

// What this invocation posts to an atomic max / add / min that every invocation posts v to (0, 0, NONE:
// nothing): the subgroup's combined value from its first lane, nothing from the others, so one atomic per
// subgroup. (Helpers return values: naga takes no workgroup pointers as function arguments.)
fn combine_max(v: u32) -> u32 {
    return select(0u, subgroupMax(v), sg_lane == 0u);
}

fn combine_add(v: u32) -> u32 {
    return select(0u, subgroupAdd(v), sg_lane == 0u);
}

fn combine_min(v: u32) -> u32 {
    return select(NONE, subgroupMin(v), sg_lane == 0u);
}
