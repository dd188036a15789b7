// The work of one contact-generation job, shared by generate.wgsl (a static job list) and
// many_body/generate.wgsl (the broad phase's list of near pairs): see generate.wgsl's header for the method.

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
// caller declares params, tri_verts and job_patches (generate.wgsl; many_body/contacts.wgsl).
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
        // This invocation's PER triangles, one after another, or with VEC4_DESCENT four side by side
        // (consecutive triangles, which the pipelines order by normal where PER > 1, so that they mostly
        // fall into one patch: see common.wgsl).
        var cs = cands_empty();
        if (VEC4_DESCENT) {
            cs = triangles4(pair, lid, base, tri_first, tri_count, b_from_a, offset, &found);
        } else {
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
        }
        pc = reduce_batch(lid, cs, pc, params.normal_cos, offset, pair.min_separation, evicting);
        if (!evicting && red_overflow) {
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

// The vectorised descent: an invocation's four query triangles side by side (component k of each vector:
// triangle k), each by the same operations as minimise_on_triangle and the cull of generate_job, so the
// same candidates to the last bit. Used where every SDF of the model is the analytic thread (VEC4_DESCENT):
// its samples are long chains of dependent divisions and square roots, and on lavapipe four independent
// chains side by side overlap (thread.wgsl thread_sample4): the nut-bolt pair's contact handling 1.24x
// faster (docs/BENCHMARKS.md). With grid
// SDFs lavapipe reads every voxel lane by lane anyway, and a culled triangle in one batch slot would cost
// the other three their skip, so the piles keep the one-triangle path.
// INTERLEAVED_DESCENT: ContactConfig::interleaved_descent (set by generate.rs; the many-body kernels, whose SDFs
// are grids, keep the default).
override INTERLEAVED_DESCENT: bool = true;
override VEC4_DESCENT: bool = INTERLEAVED_DESCENT && HAS_THREAD && !HAS_GRID && !HAS_REVOLVED && PER == 4u;

struct Candidate4 {
    x: V3x4,
    s: Sample4,
}

// Corner (cx, cy, cz) with barycentric (u, v) replaces the start where lower (corner_step).
fn corner_step4(pair: Pair, c: V3x4, u: f32, v: f32, uvx: ptr<function, vec4<f32>>, uvy: ptr<function, vec4<f32>>, m: ptr<function, Candidate4>) {
    let si = sdf_sample4(pair, c.x, c.y, c.z);
    let lower = si.d < (*m).s.d;
    *uvx = select(*uvx, vec4<f32>(u), lower);
    *uvy = select(*uvy, vec4<f32>(v), lower);
    (*m).x.x = select((*m).x.x, c.x, lower);
    (*m).x.y = select((*m).x.y, c.y, lower);
    (*m).x.z = select((*m).x.z, c.z, lower);
    (*m).s.d = select((*m).s.d, si.d, lower);
    (*m).s.gx = select((*m).s.gx, si.gx, lower);
    (*m).s.gy = select((*m).s.gy, si.gy, lower);
    (*m).s.gz = select((*m).s.gz, si.gz, lower);
}

// minimise_on_triangle for the triangles of `live` (the others' results are not used).
fn minimise_on_triangle4(pair: Pair, a: V3x4, b: V3x4, c: V3x4, start: Candidate4, live_in: vec4<bool>, iterations: u32) -> Candidate4 {
    let e1 = V3x4(b.x - a.x, b.y - a.y, b.z - a.z);
    let e2 = V3x4(c.x - a.x, c.y - a.y, c.z - a.z);
    let g11 = dot3vv(e1, e1);
    let g12 = dot3vv(e1, e2);
    let g22 = dot3vv(e2, e2);
    let det = g11 * g22 - g12 * g12;
    var uvx = vec4<f32>(1.0 / 3.0);
    var uvy = vec4<f32>(1.0 / 3.0);
    var m = start;
    corner_step4(pair, a, 0.0, 0.0, &uvx, &uvy, &m);
    corner_step4(pair, b, 1.0, 0.0, &uvx, &uvy, &m);
    corner_step4(pair, c, 0.0, 1.0, &uvx, &uvy, &m);
    let cb = V3x4(c.x - b.x, c.y - b.y, c.z - b.z);
    let longest = max(g11, max(g22, dot3vv(cb, cb)));
    var live = live_in & !(longest <= vec4<f32>(0.0));
    let planar = det > 1.0e-6 * g11 * g22;
    let first = g11 >= g22;
    let seg = V3x4(select(e2.x, e1.x, first), select(e2.y, e1.y, first), select(e2.z, e1.z, first));
    let seg_len2 = max(g11, g22);
    var step = 0.5 * sqrt(longest);
    if (iterations > 0u && any(live)) {
        var it = 0u;
        loop {
            let sg = V3x4(m.s.gx, m.s.gy, m.s.gz);
            let r1 = -dot3vv(e1, sg);
            let r2 = -dot3vv(e2, sg);
            let pu = (g22 * r1 - g12 * r2) / det;
            let pv = (g11 * r2 - g12 * r1) / det;
            let t = -dot3vv(seg, sg) / seg_len2;
            let duvx = select(select(vec4<f32>(0.0), t, first), pu, planar);
            let duvy = select(select(t, vec4<f32>(0.0), first), pv, planar);
            let dw = V3x4(
                select(t * seg.x, pu * e1.x + pv * e2.x, planar),
                select(t * seg.y, pu * e1.y + pv * e2.y, planar),
                select(t * seg.z, pu * e1.z + pv * e2.z, planar),
            );
            let len = len3v(dw);
            live = live & !(len <= vec4<f32>(0.0));
            let f = step / len;
            var nu = max(uvx + duvx * f, vec4<f32>(0.0));
            var nv = max(uvy + duvy * f, vec4<f32>(0.0));
            let sum = nu + nv;
            let over = sum > vec4<f32>(1.0);
            nu = select(nu, nu / sum, over);
            nv = select(nv, nv / sum, over);
            let nx = V3x4(a.x + nu * e1.x + nv * e2.x, a.y + nu * e1.y + nv * e2.y, a.z + nu * e1.z + nv * e2.z);
            let ns = sdf_sample4(pair, nx.x, nx.y, nx.z);
            let better = live & (ns.d < m.s.d);
            uvx = select(uvx, nu, better);
            uvy = select(uvy, nv, better);
            m.x.x = select(m.x.x, nx.x, better);
            m.x.y = select(m.x.y, nx.y, better);
            m.x.z = select(m.x.z, nx.z, better);
            m.s.d = select(m.s.d, ns.d, better);
            m.s.gx = select(m.s.gx, ns.gx, better);
            m.s.gy = select(m.s.gy, ns.gy, better);
            m.s.gz = select(m.s.gz, ns.gz, better);
            step = select(step * 0.5, step * 1.5, better);
            it += 1u;
            if (it >= iterations || !any(live)) {
                break;
            }
        }
    }
    return m;
}

// The candidates of an invocation's four query triangles base + lid * 4 + k (k = 0..3; past tri_count: none),
// posed by b_from_a: generate_job's per-triangle work for four at once. Returns them and adds their number to
// *found.
fn triangles4(pair: Pair, lid: u32, base: u32, tri_first: u32, tri_count: u32, b_from_a: Transform, offset: f32, found: ptr<function, u32>) -> Cands {
    let t = vec4<u32>(base + lid * 4u) + LANES4;
    let valid = t < vec4<u32>(tri_count);
    // Past the job's end: its last triangle, whose candidate `valid` drops.
    let v = (vec4<u32>(tri_first) + min(t, vec4<u32>(tri_count - 1u))) * 3u;
    let a0 = xf_point(b_from_a, tri_verts[v.x].xyz);
    let a1 = xf_point(b_from_a, tri_verts[v.y].xyz);
    let a2 = xf_point(b_from_a, tri_verts[v.z].xyz);
    let a3 = xf_point(b_from_a, tri_verts[v.w].xyz);
    let b0 = xf_point(b_from_a, tri_verts[v.x + 1u].xyz);
    let b1 = xf_point(b_from_a, tri_verts[v.y + 1u].xyz);
    let b2 = xf_point(b_from_a, tri_verts[v.z + 1u].xyz);
    let b3 = xf_point(b_from_a, tri_verts[v.w + 1u].xyz);
    let c0 = xf_point(b_from_a, tri_verts[v.x + 2u].xyz);
    let c1 = xf_point(b_from_a, tri_verts[v.y + 2u].xyz);
    let c2 = xf_point(b_from_a, tri_verts[v.z + 2u].xyz);
    let c3 = xf_point(b_from_a, tri_verts[v.w + 2u].xyz);
    let a = V3x4(vec4<f32>(a0.x, a1.x, a2.x, a3.x), vec4<f32>(a0.y, a1.y, a2.y, a3.y), vec4<f32>(a0.z, a1.z, a2.z, a3.z));
    let b = V3x4(vec4<f32>(b0.x, b1.x, b2.x, b3.x), vec4<f32>(b0.y, b1.y, b2.y, b3.y), vec4<f32>(b0.z, b1.z, b2.z, b3.z));
    let c = V3x4(vec4<f32>(c0.x, c1.x, c2.x, c3.x), vec4<f32>(c0.y, c1.y, c2.y, c3.y), vec4<f32>(c0.z, c1.z, c2.z, c3.z));
    // The cull of generate_job, with the same rounding.
    let third = 1.0 / 3.0;
    let cen = V3x4(
        a.x + third * (b.x - a.x) + third * (c.x - a.x),
        a.y + third * (b.y - a.y) + third * (c.y - a.y),
        a.z + third * (b.z - a.z) + third * (c.z - a.z),
    );
    let ra = V3x4(a.x - cen.x, a.y - cen.y, a.z - cen.z);
    let rb = V3x4(b.x - cen.x, b.y - cen.y, b.z - cen.z);
    let rc = V3x4(c.x - cen.x, c.y - cen.y, c.z - cen.z);
    let reach = sqrt(max(dot3vv(ra, ra), max(dot3vv(rb, rb), dot3vv(rc, rc))));
    let sc = sdf_sample4(pair, cen.x, cen.y, cen.z);
    let slack = select(pair.sdf_origin.w, 0.0, pair.sdf_kind == 1u);
    let near = valid & (sc.d - reach - pair.radius - slack <= vec4<f32>(offset));
    var cs = cands_empty();
    if (!any(near)) {
        return cs;
    }
    let m = minimise_on_triangle4(pair, a, b, c, Candidate4(cen, sc), near, params.iterations);
    let depth = m.s.d - pair.radius;
    let glen = len3v(V3x4(m.s.gx, m.s.gy, m.s.gz));
    let ok = near & (depth < vec4<f32>(offset)) & (glen > vec4<f32>(0.0));
    let nx = m.s.gx / glen;
    let ny = m.s.gy / glen;
    let nz = m.s.gz / glen;
    let area = 0.5 * vec4<f32>(
        length(cross(b0 - a0, c0 - a0)),
        length(cross(b1 - a1, c1 - a1)),
        length(cross(b2 - a2, c2 - a2)),
        length(cross(b3 - a3, c3 - a3)),
    );
    let units = vec4<f32>(max(vec4<u32>(1u), vec4<u32>(round(area / pair.area_unit))));
    let z = vec4<f32>(0.0);
    cs.px = select(z, m.x.x - pair.radius * nx, ok);
    cs.py = select(z, m.x.y - pair.radius * ny, ok);
    cs.pz = select(z, m.x.z - pair.radius * nz, ok);
    cs.depth = select(vec4<f32>(EMPTY), depth, ok);
    cs.nx = select(z, nx, ok);
    cs.ny = select(z, ny, ok);
    cs.nz = select(z, nz, ok);
    cs.units = select(z, units, ok);
    *found += sum4(select(vec4<u32>(0u), vec4<u32>(1u), ok));
    return cs;
}
