// Reduction helpers without subgroup operations (appended to common.wgsl by the host; the subgroup twin is
// reduce_subgroup.wgsl, with the same results).

fn lanes_init() {}

// The most similar patch of [0, pc0) to unit normal n with a dot product of at least `cos` (ties: the
// highest index), or UNASSIGNED. Unrolled by 4 (see the note on loops in common.wgsl).
fn best_patch(n: vec3<f32>, pc0: u32, cos: f32) -> u32 {
    var best = cos;
    var mine = UNASSIGNED;
    for (var p = 0u; p < pc0; p += 4u) {
        assign_step(p, pc0, n, &best, &mine);
        assign_step(p + 1u, pc0, n, &best, &mine);
        assign_step(p + 2u, pc0, n, &best, &mine);
        assign_step(p + 3u, pc0, n, &best, &mine);
    }
    return mine;
}

fn assign_step(p: u32, pc0: u32, n: vec3<f32>, best: ptr<function, f32>, mine: ptr<function, u32>) {
    if (p < pc0) {
        let d = dot(n, patch_data[pd_normal(p)].xyz);
        if (d >= *best) {
            *best = d;
            *mine = p;
        }
    }
}

// What this invocation posts to an atomic max / add / min that every invocation posts v to (0, 0, NONE:
// nothing): here v itself.
fn combine_max(v: u32) -> u32 {
    return v;
}

fn combine_add(v: u32) -> u32 {
    return v;
}

fn combine_min(v: u32) -> u32 {
    return v;
}
