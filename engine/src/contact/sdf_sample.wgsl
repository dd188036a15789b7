// SDF sampling shared by the kernels that read an SDF shape (generate.wgsl, normals.wgsl): the host
// concatenates it after the kernel, which must bind `sdf_values: array<u32>` (16-bit grid values packed in
// pairs, or analytic parameters; see model.rs).

// Which SDF kinds the model has (substituted by the host, generate.rs SdfKinds): the others' branches are
// compiled out. lavapipe inlines every call and runs both sides of every branch under a lane mask, so an
// unused kind still costs its whole body at every sample site: the grid's 8 lane-by-lane reads make the thread
// samples of the nut-bolt pair 1.6x slower (measured), the revolved field's 15 segments double them.
const HAS_GRID: bool = HAS_GRID_VALUE;
const HAS_PLANE: bool = HAS_PLANE_VALUE;
const HAS_THREAD: bool = HAS_THREAD_VALUE;
const HAS_REVOLVED: bool = HAS_REVOLVED_VALUE;

struct Sample {
    d: f32,
    g: vec3<f32>,
}

fn sdf_at(pair: Pair, i: u32, j: u32, k: u32) -> f32 {
    let dims = pair.sdf_dims.xyz;
    let idx = pair.sdf_dims.w + i + dims.x * (j + dims.y * k);
    let word = sdf_values[idx >> 1u];
    let half = select(word << 16u, word & 0xffff0000u, (idx & 1u) == 1u);
    return f32(bitcast<i32>(half) >> 16u) * pair.sdf_scale;
}

// Trilinear value and its exact gradient; outside the grid box the distance to the box is added.
// Mirrors SdfGrid::sample (kind 0), the half-space z < 0 of the shape frame (kind 1) and the analytic
// threaded bolt (kind 2, thread.wgsl) and the solid of revolution (kind 3, revolved.wgsl).
// The analytic kinds read their parameters from `analytic_words`: call sdf_bind(pair) first, in the same
// invocation, whenever the pair changes.
fn sdf_sample(pair: Pair, p: vec3<f32>) -> Sample {
    if (HAS_PLANE && pair.sdf_kind == 1u) {
        return Sample(p.z, vec3<f32>(0.0, 0.0, 1.0));
    }
    if (HAS_THREAD && pair.sdf_kind == 2u) {
        return thread_sample(p);
    }
    if (HAS_REVOLVED && pair.sdf_kind == 3u) {
        return revolved_sample(p);
    }
    if (!HAS_GRID) {
        return Sample(3.0e38, vec3<f32>(0.0, 0.0, 1.0)); // no such pair in this model
    }
    let lo = pair.sdf_origin.xyz;
    let h = pair.sdf_origin.w;
    let dims = pair.sdf_dims.xyz;
    let hi = lo + h * vec3<f32>(dims - vec3<u32>(1u));
    let q = clamp(p, lo, hi);
    let g = (q - lo) / h;
    let cell = min(vec3<u32>(floor(g)), dims - vec3<u32>(2u));
    let f = g - vec3<f32>(cell);
    let c000 = sdf_at(pair, cell.x, cell.y, cell.z);
    let c100 = sdf_at(pair, cell.x + 1u, cell.y, cell.z);
    let c010 = sdf_at(pair, cell.x, cell.y + 1u, cell.z);
    let c110 = sdf_at(pair, cell.x + 1u, cell.y + 1u, cell.z);
    let c001 = sdf_at(pair, cell.x, cell.y, cell.z + 1u);
    let c101 = sdf_at(pair, cell.x + 1u, cell.y, cell.z + 1u);
    let c011 = sdf_at(pair, cell.x, cell.y + 1u, cell.z + 1u);
    let c111 = sdf_at(pair, cell.x + 1u, cell.y + 1u, cell.z + 1u);
    let x00 = c000 + (c100 - c000) * f.x;
    let x10 = c010 + (c110 - c010) * f.x;
    let x01 = c001 + (c101 - c001) * f.x;
    let x11 = c011 + (c111 - c011) * f.x;
    let y0 = x00 + (x10 - x00) * f.y;
    let y1 = x01 + (x11 - x01) * f.y;
    let d = y0 + (y1 - y0) * f.z;
    let ya = (c100 - c000) + ((c110 - c010) - (c100 - c000)) * f.y;
    let yb = (c101 - c001) + ((c111 - c011) - (c101 - c001)) * f.y;
    let dx = ya + (yb - ya) * f.z;
    let dy = (x10 - x00) + ((x11 - x01) - (x10 - x00)) * f.z;
    let dz = y1 - y0;
    let out = p - q;
    let out_len = length(out);
    if (out_len > 0.0) {
        return Sample(d + out_len, out / out_len);
    }
    return Sample(d, vec3<f32>(dx, dy, dz) / h);
}

// Loads the pair's analytic SDF parameters (thread, revolved) into analytic_words for sdf_sample.
fn sdf_bind(pair: Pair) {
    if (HAS_THREAD && pair.sdf_kind == 2u) {
        analytic_load_thread(pair.sdf_dims.w);
        thread_derive();
    }
    if (HAS_REVOLVED && pair.sdf_kind == 3u) {
        analytic_load_revolved(pair.sdf_dims.w);
    }
}

// Four samples held by component (Sample4, thread.wgsl), for the descent that runs four query triangles side
// by side (generate_core.wgsl): component k is what sdf_sample returns for point k.
fn sdf_sample4(pair: Pair, px: vec4<f32>, py: vec4<f32>, pz: vec4<f32>) -> Sample4 {
    if (HAS_THREAD && pair.sdf_kind == 2u) {
        return thread_sample4(px, py, pz);
    }
    let s0 = sdf_sample(pair, vec3<f32>(px.x, py.x, pz.x));
    let s1 = sdf_sample(pair, vec3<f32>(px.y, py.y, pz.y));
    let s2 = sdf_sample(pair, vec3<f32>(px.z, py.z, pz.z));
    let s3 = sdf_sample(pair, vec3<f32>(px.w, py.w, pz.w));
    return Sample4(
        vec4<f32>(s0.d, s1.d, s2.d, s3.d),
        vec4<f32>(s0.g.x, s1.g.x, s2.g.x, s3.g.x),
        vec4<f32>(s0.g.y, s1.g.y, s2.g.y, s3.g.y),
        vec4<f32>(s0.g.z, s1.g.z, s2.g.z, s3.g.z),
    );
}

// Four 3-vectors held by component; dot3vv and len3v are WGSL's dot and length on each (see dot2v).
struct V3x4 {
    x: vec4<f32>,
    y: vec4<f32>,
    z: vec4<f32>,
}

fn v3x4_at(v: V3x4, k: u32) -> vec3<f32> {
    return vec3<f32>(v.x[k], v.y[k], v.z[k]);
}

fn dot3vv(u: V3x4, v: V3x4) -> vec4<f32> {
    return vec4<f32>(dot(v3x4_at(u, 0u), v3x4_at(v, 0u)), dot(v3x4_at(u, 1u), v3x4_at(v, 1u)), dot(v3x4_at(u, 2u), v3x4_at(v, 2u)), dot(v3x4_at(u, 3u), v3x4_at(v, 3u)));
}

fn len3v(u: V3x4) -> vec4<f32> {
    return vec4<f32>(length(v3x4_at(u, 0u)), length(v3x4_at(u, 1u)), length(v3x4_at(u, 2u)), length(v3x4_at(u, 3u)));
}
