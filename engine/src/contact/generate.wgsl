// Contact generation (paper III-A; Macklin et al. 2020, "Local optimization for robust signed distance
// field collision") fused with the first level of contact reduction. One workgroup per (job, world): a job
// is a run of up to `chunk` query triangles of one shape pair. Each invocation takes one triangle per
// batch, moves the triangle's point of least signed distance (in the SDF shape's frame) by projected
// gradient descent on the triangle with an adaptive step, and keeps it as a candidate when it lies within
// the contact offset. The batch is then reduced into patches in workgroup memory (common.wgsl); only the
// job's patches reach global memory, for merge.wgsl to combine per pair.

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

struct Candidate {
    x: vec3<f32>,
    s: Sample,
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
    let corners = array<vec2<f32>, 3>(vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(0.0, 1.0));
    for (var i = 0u; i < 3u; i++) {
        let xi = a + corners[i].x * e1 + corners[i].y * e2;
        let si = sdf_sample(pair, xi);
        if (si.d < s.d) {
            uv = corners[i];
            x = xi;
            s = si;
        }
    }
    let longest = max(g11, max(g22, dot(c - b, c - b)));
    if (longest <= 0.0) {
        return Candidate(x, s);
    }
    let planar = det > 1.0e-6 * g11 * g22;
    // Segment direction for degenerate triangles: the longer edge from a.
    let seg = select(e2, e1, g11 >= g22);
    let seg_len2 = max(g11, g22);
    var step = 0.5 * sqrt(longest);
    for (var it = 0u; it < iterations; it++) {
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
    }
    return Candidate(x, s);
}

@compute @workgroup_size(WG)
fn generate(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let job_index = wid.x;
    let world = wid.y + params.world_offset;
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
        return;
    }
    let b_from_a = xf_mul(xf_inv(world_b), world_a);
    let offset = pair.contact_offset;
    reset_patches(lid);
    var pc = 0u;
    var found = 0u;
    for (var base = 0u; base < job.tri_count; base += WG) {
        var cand = vec4<f32>(0.0, 0.0, 0.0, EMPTY);
        var normal = vec4<f32>(0.0);
        let t = base + lid;
        if (t < job.tri_count) {
            let v = (job.tri_first + t) * 3u;
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
                    cand = vec4<f32>(m.x - pair.radius * n, depth);
                    let area = 0.5 * length(cross(b - a, c - a));
                    normal = vec4<f32>(n, f32(max(1u, u32(round(area / pair.area_unit)))));
                    found += 1u;
                }
            }
        }
        put_candidate(lid, cand, normal);
        pc = reduce_batch(lid, pc, params.normal_cos, offset, pair.min_separation);
    }
    if (found > 0u) {
        atomicAdd(&pair_candidates[world * params.pair_count + job.pair], found);
    }
    workgroupBarrier(); // the last batch's slot writes
    // Write this job's patches in world coordinates.
    let out_base = (world * params.job_count + job_index) * MAX_PATCHES;
    for (var p = lid; p < pc; p += WG) {
        var o: PatchOut;
        o.normal = vec4<f32>(quat_rotate(world_b.q, patch_n[p].xyz), f32(atomicLoad(&patch_area[p])) * pair.area_unit);
        for (var s = 0u; s < 4u; s++) {
            let sl = patch_slot[p * 4u + s];
            if (sl.w < VALID_BELOW) {
                o.slots[s] = vec4<f32>(xf_point(world_b, sl.xyz), sl.w);
            } else {
                o.slots[s] = vec4<f32>(0.0, 0.0, 0.0, EMPTY);
            }
        }
        job_patches[out_base + p] = o;
    }
    if (lid == 0u) {
        job_patch_count[world * params.job_count + job_index] = pc;
    }
}
