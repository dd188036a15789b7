// Reduction helpers without subgroup operations (appended to common.wgsl by the host; the subgroup twin is
// reduce_subgroup.wgsl, with the same results).

fn lanes_init() {}

// Per candidate of c: the most similar patch of [0, pc0) to its unit normal with a dot product of at least
// `cos` (ties: the highest index), or UNASSIGNED. Unrolled by 4 (see the note on loops in common.wgsl).
fn best_patch(c: Cands, pc0: u32, cos: f32) -> vec4<u32> {
    var best = vec4<f32>(cos);
    var mine = vec4<u32>(UNASSIGNED);
    // Exit test at the end of the pass (see the note on loops in common.wgsl); with no patches the one pass
    // changes nothing.
    var p = 0u;
    loop {
        assign_step(p, pc0, c, &best, &mine);
        assign_step(p + 1u, pc0, c, &best, &mine);
        assign_step(p + 2u, pc0, c, &best, &mine);
        assign_step(p + 3u, pc0, c, &best, &mine);
        p += 4u;
        if (p >= pc0) {
            break;
        }
    }
    return mine;
}

fn assign_step(p: u32, pc0: u32, c: Cands, best: ptr<function, vec4<f32>>, mine: ptr<function, vec4<u32>>) {
    if (p < pc0) {
        let m = patch_data[pd_normal(p)].xyz;
        let d = dot4(c, m);
        let better = d >= *best;
        *best = select(*best, d, better);
        *mine = select(*mine, vec4<u32>(p), better);
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
