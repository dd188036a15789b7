// The rigid-body solver's passes over a world's rows (see solver/mod.rs for the scheme), shared by the
// one-invocation-per-world steps: solver.wgsl (rigid bodies) and articulated.wgsl (rigid bodies and an
// articulation). Each of those declares solver_core.wgsl's bindings, `pass_pair` (one pass over one
// pair's rows: warm start or Gauss-Seidel update), and the pairs a sweep visits in order: the j-th of
// `sweep_pair_count(world)` is `sweep_pair(world, j)`.

// Row of slot k of patch i of pair p: rows keep their patch slots (an empty slot is a row with pair NONE),
// so a contact can look for itself among its patch's rows of last frame.
fn row_index(row0: u32, p: u32, i: u32, k: u32) -> u32 {
    return row0 + ROW * ((p * MAX_PATCHES + i) * 4u + k);
}


// One pass over the world's rows in order (pair, patch, slot), four rows (one patch) per loop pass
// (lavapipe budgets loop passes): a Gauss-Seidel sweep (warm = false) or the warm start (warm = true), on the
// normals and separations resample_rows stored.
fn sweep(world: u32, row0: u32, h: f32, bias: bool, warm: bool) {
    let n = sweep_pair_count(world);
    if (n == 0u) {
        return;
    }
    // The loops here test for exit at the end of the pass: lavapipe runs a loop's body once more, masked,
    // after a last pass that ends with the test at the top (contact/common.wgsl on loops).
    var j = 0u;
    loop {
        let p = sweep_pair(world, j);
        let count = patch_counts[world * sp.pair_count + p];
        pass_pair(world, p, row_index(row0, p, 0u, 0u), count, h, bias, warm);
        j += 1u;
        if (j >= n) {
            break;
        }
    }
}

// Samples every row's SDF at the world's current poses. The poses stand still during the sweeps that
// follow, so this is what their first sweep did in-line, bitwise; done apart, the sweeps' flags are
// constants: lavapipe runs both sides of every branch, so a sweep that took a run-time resample flag would
// run the sampling code, masked, in every one of its 20 iterations (and each sweep would inline it).
fn resample_rows(world: u32, row0: u32) {
    let n = sweep_pair_count(world);
    if (n == 0u) {
        return;
    }
    var j = 0u;
    loop {
        let p = sweep_pair(world, j);
        resample_pair(world, p, row_index(row0, p, 0u, 0u), patch_counts[world * sp.pair_count + p]);
        j += 1u;
        if (j >= n) {
            break;
        }
    }
}

// `count` Gauss-Seidel sweeps (position sweeps with the depenetration bias, velocity sweeps without; `bias`
// a constant at both call sites) on the rows sampled once at the current poses; none for count 0. The exit
// test ends the pass (see sweep).
fn sweep_runs(world: u32, row0: u32, h: f32, count: u32, bias: bool) {
    if (count == 0u) {
        return;
    }
    resample_rows(world, row0);
    var it = 0u;
    loop {
        sweep(world, row0, h, bias, false);
        it += 1u;
        if (it >= count) {
            break;
        }
    }
}

// integrate_velocity (positions false) or integrate_position (true) of every body of the world whose first
// body is `first`, over a substep h. `positions` is a constant at both call sites, so the untaken call
// compiles out after inlining (lavapipe would otherwise run it masked). The exit test ends the pass (see
// sweep); a world has at least one body.
fn integrate_bodies(first: u32, h: f32, positions: bool) {
    var b = 0u;
    loop {
        if (positions) {
            integrate_position(first, b, h);
        } else {
            integrate_velocity(first, b, h);
        }
        b += 1u;
        if (b >= sp.body_count) {
            break;
        }
    }
}

// Builds the world's rows from the frame's reduced contacts (the query element's point in body a's frame at
// the frame's start; build_patch_rows) and returns how many are contacts.
fn build_rows(world: u32, row0: u32, frame: u32) -> u32 {
    var n_rows = 0u;
    for (var p = 0u; p < sp.pair_count; p++) {
        let pw = world * sp.pair_count + p;
        let count = patch_counts[pw];
        if (count == 0u) {
            continue;
        }
        let pair = pairs[p];
        let va = view(world, pair.body_a);
        let vb = view(world, pair.body_b);
        for (var i = 0u; i < count; i++) {
            let g0 = row_index(row0, p, i, 0u);
            n_rows += build_patch_rows(g0, g0, p, p, pair, va, vb, patches[pw * MAX_PATCHES + i], frame);
        }
    }
    return n_rows;
}
