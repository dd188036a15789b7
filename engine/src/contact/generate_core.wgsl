// The work of one contact-generation job, shared by generate.wgsl (a static job list) and
// crowd/generate.wgsl (the broad phase's list of near pairs): see generate.wgsl's header for the method.

struct Candidate {
    x: vec3<f32>,
    s: Sample,
}

// Corner xi (barycentric `corner`) of the triangle replaces the start (*uv, *x, *s) where lower.
fn corner_step(pair: Pair, xi: vec3<f32>, corner: vec2<f32>, uv: ptr<function, vec2<f32>>, x: ptr<function, vec3<f32>>, s: ptr<function, Sample>) {
    let si = sdf_sample(pair, xi);
    if (si.d < (*s).d) {
        *uv = corner;
        *x = xi;
        *s = si;
    }
}

// Projected gradient descent of the SDF over triangle (a, b, c); degenerate triangles (spheres: three
// equal corners, capsules: two) descend along their segment or stay at their point. `start` is the
// centroid and its sample, which the caller's cull has taken already (a sample is most of an iteration's
// cost with the analytic thread SDF).
fn minimise_on_triangle(
    pair: Pair,
    a: vec3<f32>,
    b: vec3<f32>,
    c: vec3<f32>,
    start: Candidate,
    iterations: u32,
) -> Candidate {
    let e1 = b - a;
    let e2 = c - a;
    let g11 = dot(e1, e1);
    let g12 = dot(e1, e2);
    let g22 = dot(e2, e2);
    let det = g11 * g22 - g12 * g12;
    // Start from the lowest of the corners and the centroid.
    var uv = vec2<f32>(1.0 / 3.0, 1.0 / 3.0);
    var x = start.x;
    var s = start.s;
    // Written out, not looped: lavapipe runs a loop's body once more, masked, after its last pass (the
    // exit test at the top of the pass), and here that pass is an SDF sample (see common.wgsl on loops).
    // The corners themselves: computed as a + u e1 + v e2 they were b and c rounded, or, where the compiler
    // saw the constant u and v, exactly b and c (it simplifies a + (b - a)); the CPU twin takes them so too.
    corner_step(pair, a, vec2<f32>(0.0, 0.0), &uv, &x, &s);
    corner_step(pair, b, vec2<f32>(1.0, 0.0), &uv, &x, &s);
    corner_step(pair, c, vec2<f32>(0.0, 1.0), &uv, &x, &s);
    let longest = max(g11, max(g22, dot(c - b, c - b)));
    if (longest <= 0.0) {
        return Candidate(x, s);
    }
    let planar = det > 1.0e-6 * g11 * g22;
    // Segment direction for degenerate triangles: the longer edge from a.
    let seg = select(e2, e1, g11 >= g22);
    let seg_len2 = max(g11, g22);
    var step = 0.5 * sqrt(longest);
    // The exit test at the end of the pass (a do-while, inside a test for 0 iterations): see the corners.
    if (iterations > 0u) {
        var it = 0u;
        loop {
            var duv: vec2<f32>;
            var dw: vec3<f32>;
            if (planar) {
                let r1 = -dot(e1, s.g);
                let r2 = -dot(e2, s.g);
                duv = vec2<f32>((g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det);
                dw = duv.x * e1 + duv.y * e2;
            } else {
                let t = -dot(seg, s.g) / seg_len2;
                duv = select(vec2<f32>(0.0, t), vec2<f32>(t, 0.0), g11 >= g22);
                dw = t * seg;
            }
            let len = length(dw);
            if (len <= 0.0) {
                break;
            }
            var nuv = max(uv + duv * (step / len), vec2<f32>(0.0));
            let sum = nuv.x + nuv.y;
            if (sum > 1.0) {
                nuv = nuv / sum;
            }
            let nx = a + nuv.x * e1 + nuv.y * e2;
            let ns = sdf_sample(pair, nx);
            if (ns.d < s.d) {
                uv = nuv;
                x = nx;
                s = ns;
                step = step * 1.5;
            } else {
                step = step * 0.5;
            }
            it += 1u;
            if (it >= iterations) {
                break;
            }
        }
    }
    return Candidate(x, s);
}

// One job's work (the body of a generate workgroup): query triangles [tri_first, tri_first + tri_count) of
// shape A posed at world_a against the SDF of shape B posed at world_b, reduced in workgroup memory; the
// job's patches are written, in world coordinates, to job_patches[out_base..]. Returns (patches,
// candidates). Called in uniform control flow (it holds the reduction's barriers), after sdf_bind(pair). The
// caller declares params, tri_verts and job_patches (generate.wgsl; crowd/contacts.wgsl).
//
// `evicting` false (a constant: see reduce_batch): the job stops where its patch budget would overflow and
// returns (NONE, 0) without writing anything, for a pass with `evicting` to redo.
fn generate_job(lid: u32, pair: Pair, tri_first: u32, tri_count: u32, world_a: Transform, world_b: Transform, out_base: u32, evicting: bool) -> vec2<u32> {
    let b_from_a = xf_mul(xf_inv(world_b), world_a);
    let offset = pair.contact_offset;
    reset_patches(lid);
    red_overflow = false;
    var pc = 0u;
    var found = 0u;
    // Batches and each invocation's PER triangles loop with the exit test at the end of the pass (see
    // minimise_on_triangle): a job has triangles, and a batch past them would be one of empty candidates.
    var base = 0u;
    loop {
        // This invocation's PER triangles, one after another (consecutive triangles, which the pipelines
        // order by normal where PER > 1, so that they mostly fall into one patch: see common.wgsl).
        var cs = cands_empty();
        var j = 0u;
        loop {
            let t = base + lid * PER + j;
            if (t < tri_count) {
                let v = (tri_first + t) * 3u;
                let a = xf_point(b_from_a, tri_verts[v].xyz);
                let b = xf_point(b_from_a, tri_verts[v + 1u].xyz);
                let c = xf_point(b_from_a, tri_verts[v + 2u].xyz);
                // Cull: the SDF at the centroid bounds the distance of the whole triangle (1-Lipschitz,
                // plus one voxel for interpolation error).
                // (Written as the descent's barycentric start, which reuses this sample: same rounding.)
                let centroid = a + (1.0 / 3.0) * (b - a) + (1.0 / 3.0) * (c - a);
                let reach = sqrt(max(dot(a - centroid, a - centroid), max(dot(b - centroid, b - centroid), dot(c - centroid, c - centroid))));
                let sc = sdf_sample(pair, centroid);
                let slack = select(pair.sdf_origin.w, 0.0, pair.sdf_kind == 1u);
                if (sc.d - reach - pair.radius - slack <= offset) {
                    let m = minimise_on_triangle(pair, a, b, c, Candidate(centroid, sc), params.iterations);
                    let depth = m.s.d - pair.radius;
                    let glen = length(m.s.g);
                    if (depth < offset && glen > 0.0) {
                        let n = m.s.g / glen;
                        let area = 0.5 * length(cross(b - a, c - a));
                        cands_set(&cs, j, vec4<f32>(m.x - pair.radius * n, depth), vec4<f32>(n, f32(max(1u, u32(round(area / pair.area_unit))))));
                        found += 1u;
                    }
                }
            }
            j += 1u;
            if (j >= PER) {
                break;
            }
        }
        pc = reduce_batch(lid, cs, pc, params.normal_cos, offset, pair.min_separation, evicting);
        if (red_overflow) {
            return vec2<u32>(NONE, 0u);
        }
        base += BATCH;
        if (base >= tri_count) {
            break;
        }
    }
    workgroupBarrier(); // the last batch's slot writes
    // Write this job's patches in world coordinates.
    for (var p = lid; p < pc; p += WG) {
        var o: PatchOut;
        o.normal = vec4<f32>(quat_rotate(world_b.q, patch_data[pd_normal(p)].xyz), f32(atomicLoad(&patch_ak[ak_area(p)])) * pair.area_unit);
        for (var s = 0u; s < 4u; s++) {
            let sl = patch_data[pd_slot(p, s)];
            if (sl.w < VALID_BELOW) {
                o.slots[s] = vec4<f32>(xf_point(world_b, sl.xyz), sl.w);
            } else {
                o.slots[s] = vec4<f32>(0.0, 0.0, 0.0, EMPTY);
            }
        }
        job_patches[out_base + p] = o;
    }
    return vec2<u32>(pc, found);
}
