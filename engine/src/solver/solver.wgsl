// Rigid-body step on the GPU (WGSL twin of solver::step_cpu; see solver/mod.rs for the scheme): one
// invocation per world, because Gauss-Seidel is serial inside a world and the worlds are independent.
// Prepended by the host: contact/common.wgsl (Pair, Transform, PatchOut, quaternion helpers), and appended:
// contact/sdf_sample.wgsl and sdf/thread.wgsl (the SDF is re-sampled at every contact once per substep for
// the position sweeps and once for the velocity sweeps).
//
// On a GPU one invocation per world keeps a warp busy with 32 worlds: fine for the thousands of worlds of
// RL training, poor for one world with many contacts: that is many_body/solve.wgsl (graph-coloured pairs).

@group(0) @binding(0) var<uniform> sp: SolverParams;
@group(0) @binding(1) var<storage, read> pairs: array<Pair>;
@group(0) @binding(2) var<storage, read> sdf_values: array<u32>;
@group(0) @binding(3) var<storage, read> bodies: array<Body>;
@group(1) @binding(0) var<storage, read> patches: array<PatchOut>;
@group(1) @binding(1) var<storage, read> patch_counts: array<u32>;
@group(2) @binding(0) var<storage, read_write> body_q: array<Transform>;
@group(2) @binding(1) var<storage, read_write> body_qd: array<vec4<f32>>;  // [lin, ang] per body
// Laid out as control_index and rows_base say: status per world, wrenches per body, ROW * max_rows per world.
@group(2) @binding(2) var<storage, read_write> solver_scratch: array<vec4<f32>>;

// Whether global body g takes part in the dynamics (many_body/solve.wgsl: not asleep); every body here does.
fn body_awake(g: u32) -> bool {
    return true;
}

// solver_sweep.wgsl's hooks: every pair in order, and a pass over one pair's rows.
fn sweep_pair_count(world: u32) -> u32 {
    return sp.pair_count;
}

fn sweep_pair(world: u32, j: u32) -> u32 {
    return j;
}

fn pass_pair(world: u32, p: u32, first: u32, count: u32, h: f32, bias: bool, warm: bool) {
    pair_pass(world, p, first, count, h, bias, warm, false);
}

@compute @workgroup_size(64)
fn step(@builtin(global_invocation_id) gid: vec3<u32>) {
    let world = gid.x;
    if (world >= sp.world_count) {
        return;
    }
    let h = sp.dt / f32(sp.substeps);
    // Rows from the reduced contacts: the query element's point in body a's frame at the frame's start.
    let row0 = rows_base() + world * sp.max_rows * ROW;
    // The loop passes this frame takes (each loop of n passes counted n + 1, as llvmpipe does): on a
    // software adapter a world that would exceed the budget is flagged and left as it is, rather than have
    // its loops silently cut short. Patches are few in a pile of many pairs, so the count uses the real ones.
    var patches_used = 0u;
    for (var p = 0u; p < sp.pair_count; p++) {
        patches_used += patch_counts[world * sp.pair_count + p];
    }
    // (In f32: the product can pass 2^32 for absurd settings, and must then still exceed the budget.)
    let pairs_f = f32(sp.pair_count + 1u);
    let per_sweep = pairs_f + f32(patches_used) * f32(sp.patch_iters + 1u) + 2.0;
    let sweeps = f32(sp.pos_iters + sp.vel_iters + 1u);
    let resamples = 2.0 * (2.0 * pairs_f + f32(patches_used)); // resample_rows, twice
    let per_substep = sweeps * per_sweep + resamples + 2.0 * f32(sp.body_count + 1u) + 1.0;
    let passes = 2.0 * pairs_f + f32(patches_used) + f32(sp.substeps) * per_substep + f32(sp.body_count) + 2.0;
    let frame = bitcast<u32>(solver_scratch[world].w) + 1u;
    if (sp.loop_budget > 0u && passes > f32(sp.loop_budget)) {
        // x: diverged/not stepped, z: 1 = over the loop budget; w: the frame counter stays.
        solver_scratch[world] = vec4<f32>(0.0, 0.0, 1.0, solver_scratch[world].w);
        return;
    }
    let n_rows = build_rows(world, row0, frame);
    let first = world * sp.body_count;
    // Substeps (at least 1), bodies (at least 1) and sweeps loop with the exit test at the end of the pass
    // (see sweep): with tests at the top, lavapipe runs every substep's whole body once more, masked, and a
    // masked sweep after each run of sweeps (docs/BENCHMARKS.md).
    var sub = 0u;
    loop {
        integrate_bodies(first, h, false);
        sweep(world, row0, h, true, true);
        sweep_runs(world, row0, h, sp.pos_iters, true);
        integrate_bodies(first, h, true);
        sweep_runs(world, row0, h, sp.vel_iters, false);
        sub += 1u;
        if (sub >= sp.substeps) {
            break;
        }
    }
    // A world that went non-finite or faster than max_speed is flagged for the caller to reset.
    var ok = 1.0;
    for (var b = 0u; b < sp.body_count; b++) {
        if (!body_ok(first + b)) {
            ok = 0.0;
        }
    }
    solver_scratch[world] = vec4<f32>(ok, f32(n_rows), 0.0, bitcast<f32>(frame));
}
