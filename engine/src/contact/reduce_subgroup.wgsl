// Reduction helpers with subgroup operations (appended to common.wgsl by the host where the device has
// wgpu::Features::SUBGROUP; the portable twin is reduce_plain.wgsl, with the same results). Call every one
// in uniform control flow.
//
// Why: lavapipe runs each workgroup-memory access lane by lane (one scalar access per lane and component,
// whichever lanes take it), so in Assign, where every invocation reads every patch normal, 8 lanes would pay 8
// reads for one value. Here each of a subgroup's lanes reads a different patch and the subgroup shares
// them by shuffles: contact handling of the M16 nut-bolt pair at 64 worlds about 1.1x faster
// (docs/BENCHMARKS.md). A subgroup also combines its posts to an atomic before one lane makes it; that is
// neutral on lavapipe and saves atomic contention on a GPU, as Assign's shuffles save shared-memory reads.

// This invocation's lane in its subgroup (counted as the active lanes are: every lane is active where
// lanes_init runs, at the top of reset_patches).
var<private> sg_lane: u32;

fn lanes_init() {
    sg_lane = subgroupExclusiveAdd(1u);
}

// Per candidate of c: the most similar patch of [0, pc0) to its unit normal with a dot product of at least
// `cos` (ties: the highest index), or UNASSIGNED. 8 patches per pass, read by lanes 0-7 (lavapipe's subgroup
// size; the host uses this file only where subgroups have at least 8 lanes; on wider ones the other lanes
// read copies), so the loop runs fewer passes than the portable one (see the note on loops in common.wgsl).
fn best_patch(c: Cands, pc0: u32, cos: f32) -> vec4<u32> {
    var best = vec4<f32>(cos);
    var mine = vec4<u32>(UNASSIGNED);
    // Exit test at the end of the pass (see the note on loops in common.wgsl); with no patches the one pass
    // changes nothing.
    var base = 0u;
    loop {
        let lane_n = patch_data[pd_normal(min(base + (sg_lane & 7u), PATCH_CAP - 1u))].xyz;
        shuffle_step(base, 0u, lane_n, pc0, c, &best, &mine);
        shuffle_step(base, 1u, lane_n, pc0, c, &best, &mine);
        shuffle_step(base, 2u, lane_n, pc0, c, &best, &mine);
        shuffle_step(base, 3u, lane_n, pc0, c, &best, &mine);
        shuffle_step(base, 4u, lane_n, pc0, c, &best, &mine);
        shuffle_step(base, 5u, lane_n, pc0, c, &best, &mine);
        shuffle_step(base, 6u, lane_n, pc0, c, &best, &mine);
        shuffle_step(base, 7u, lane_n, pc0, c, &best, &mine);
        base += 8u;
        if (base >= pc0) {
            break;
        }
    }
    return mine;
}

// Patch base + j, read by lane j, against the candidates' normals.
fn shuffle_step(base: u32, j: u32, lane_n: vec3<f32>, pc0: u32, c: Cands, best: ptr<function, vec4<f32>>, mine: ptr<function, vec4<u32>>) {
    let m = subgroupShuffle(lane_n, j);
    let d = dot4(c, m);
    let better = (d >= *best) & vec4<bool>(base + j < pc0);
    *best = select(*best, d, better);
    *mine = select(*mine, vec4<u32>(base + j), better);
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
