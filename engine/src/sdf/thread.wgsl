// Analytic SDF of a threaded bolt (sdf_kind 2): WGSL twin of engine/src/sdf/thread.rs, which documents the
// method. Parameters are 12 f32 words (ThreadSdf::to_words), read from `analytic_words`.

// An analytic SDF's parameter words (ThreadSdf::to_words, RevolvedSdf::to_words), copied from `sdf_values`
// once per pair (analytic_load_*; sdf_sample.wgsl sdf_bind) and read at constant indices while sampling.
// lavapipe reads storage memory one lane and one word at a time, even at a uniform index: reading the 11
// words per sample from `sdf_values` costs 30% of contact generation on the nut-bolt pair
// (measured); private words at constant indices stay in registers (on a GPU too). Written out, not looped:
// lavapipe counts every loop pass against one budget per invocation (contact/common.wgsl).
const ANALYTIC_WORDS: u32 = 33u; // REVOLVED_WORDS, the longest block
var<private> analytic_words: array<u32, ANALYTIC_WORDS>;

fn analytic_load_thread(base: u32) {
    analytic_words[0u] = sdf_values[base + 0u];
    analytic_words[1u] = sdf_values[base + 1u];
    analytic_words[2u] = sdf_values[base + 2u];
    analytic_words[3u] = sdf_values[base + 3u];
    analytic_words[4u] = sdf_values[base + 4u];
    analytic_words[5u] = sdf_values[base + 5u];
    analytic_words[6u] = sdf_values[base + 6u];
    analytic_words[7u] = sdf_values[base + 7u];
    analytic_words[8u] = sdf_values[base + 8u];
    analytic_words[9u] = sdf_values[base + 9u];
    analytic_words[10u] = sdf_values[base + 10u];
    analytic_words[11u] = sdf_values[base + 11u];
}

fn analytic_load_revolved(base: u32) {
    analytic_load_thread(base); // words 0-11
    analytic_words[12u] = sdf_values[base + 12u];
    analytic_words[13u] = sdf_values[base + 13u];
    analytic_words[14u] = sdf_values[base + 14u];
    analytic_words[15u] = sdf_values[base + 15u];
    analytic_words[16u] = sdf_values[base + 16u];
    analytic_words[17u] = sdf_values[base + 17u];
    analytic_words[18u] = sdf_values[base + 18u];
    analytic_words[19u] = sdf_values[base + 19u];
    analytic_words[20u] = sdf_values[base + 20u];
    analytic_words[21u] = sdf_values[base + 21u];
    analytic_words[22u] = sdf_values[base + 22u];
    analytic_words[23u] = sdf_values[base + 23u];
    analytic_words[24u] = sdf_values[base + 24u];
    analytic_words[25u] = sdf_values[base + 25u];
    analytic_words[26u] = sdf_values[base + 26u];
    analytic_words[27u] = sdf_values[base + 27u];
    analytic_words[28u] = sdf_values[base + 28u];
    analytic_words[29u] = sdf_values[base + 29u];
    analytic_words[30u] = sdf_values[base + 30u];
    analytic_words[31u] = sdf_values[base + 31u];
    analytic_words[32u] = sdf_values[base + 32u];
}

const SQRT3_T: f32 = 1.7320508;
const INV_SQRT2_T: f32 = 0.70710677;
// [m], see thread_sample.
const HEAD_SKIP_MARGIN: f32 = 1.0e-6;

fn tw(i: u32) -> f32 {
    return bitcast<f32>(analytic_words[i]);
}

struct Closest {
    c: vec2<f32>,
    interior: bool,
}

fn seg_closest(x: vec2<f32>, a: vec2<f32>, b: vec2<f32>) -> Closest {
    let ab = b - a;
    let t = clamp(dot(x - a, ab) / dot(ab, ab), 0.0, 1.0);
    return Closest(a + ab * t, t > 0.0 && t < 1.0);
}

struct Sample2 {
    d: f32,
    g: vec2<f32>,
}

fn signed_from_closest(x: vec2<f32>, c: Closest, inside: bool, normal: vec2<f32>) -> Sample2 {
    let d = x - c.c;
    let len = length(d);
    let sgn = select(1.0, -1.0, inside);
    if (c.interior || len <= 1.0e-12) {
        return Sample2(sgn * len, normal);
    }
    return Sample2(sgn * len, d * (sgn / len));
}

// Twin of thread.rs hex_prism, which explains the fold.
// `half_edge` = apothem / sqrt 3 (ThreadDerived).
fn hex_prism_sample(apothem: f32, half_edge: f32, z0: f32, z1: f32, p: vec3<f32>) -> Sample {
    let q = vec2<f32>(abs(p.x), abs(p.y));
    let a = apothem;
    let k = vec2<f32>(-0.5, 0.5 * SQRT3_T);
    let above = dot(k, q) > 0.0;
    let r = select(q, q - 2.0 * dot(k, q) * k, above);
    let dv = vec2<f32>(r.x - a, r.y - clamp(r.y, -half_edge, half_edge));
    let beside = abs(r.y) <= half_edge;
    let len = length(dv);
    let d2 = select(len, dv.x, beside);
    let gr = select(dv * (1.0 / len), vec2<f32>(1.0, 0.0), beside);
    let gq = select(gr, gr - 2.0 * dot(k, gr) * k, above);
    let g2 = vec2<f32>(select(gq.x, -gq.x, p.x < 0.0), select(gq.y, -gq.y, p.y < 0.0));
    let zc = 0.5 * (z0 + z1);
    let dz = abs(p.z - zc) - 0.5 * (z1 - z0);
    let sz = select(1.0, -1.0, p.z < zc);
    if (d2 > 0.0 && dz > 0.0) {
        let l3 = sqrt(d2 * d2 + dz * dz);
        let inv = 1.0 / l3;
        return Sample(l3, vec3<f32>(g2.x * (d2 * inv), g2.y * (d2 * inv), sz * (dz * inv)));
    } else if (d2 > dz) {
        return Sample(d2, vec3<f32>(g2.x, g2.y, 0.0));
    }
    return Sample(dz, vec3<f32>(0.0, 0.0, sz));
}

// What thread_sample needs of the words beyond the words themselves, derived once per pair by
// thread_derive (from sdf_bind) with the same operations it used per sample. Why: lavapipe keeps private
// values in memory and recomputes these at every sample (8 divisions, a square root; the disassembly of
// the generate kernel shows it); a GPU compiler would hoist them, but not out of the job's loops.
struct ThreadDerived {
    lead: f32,       // [m / rad]
    quarter: f32,    // pitch / 4 [m]
    // Profile corners (s, rho) [m] and segment vectors pb - pa, pc - pb, pd - pc with squared lengths.
    pa: vec2<f32>,
    pb: vec2<f32>,
    pc: vec2<f32>,
    ab: vec2<f32>,
    bc: vec2<f32>,
    cd: vec2<f32>,
    len2: vec3<f32>,
    flank_n: vec2<f32>,
    head_zc: f32,    // [m]
    head_half: f32,  // [m]
    head_half_edge: f32, // [m]
}
var<private> thr: ThreadDerived;

fn thread_derive() {
    let pitch = tw(0u);
    let pitch_radius = tw(2u);
    let min_radius = tw(3u);
    let max_radius = tw(4u);
    let a = max(0.25 * pitch - (max_radius - pitch_radius) / SQRT3_T, 0.0);
    let b = min(0.25 * pitch + (pitch_radius - min_radius) / SQRT3_T, 0.5 * pitch);
    thr.lead = pitch / 6.2831855;
    thr.quarter = 0.25 * pitch;
    thr.pa = vec2<f32>(0.0, max_radius);
    thr.pb = vec2<f32>(a, max_radius);
    thr.pc = vec2<f32>(b, min_radius);
    let pd = vec2<f32>(0.5 * pitch, min_radius);
    thr.ab = thr.pb - thr.pa;
    thr.bc = thr.pc - thr.pb;
    thr.cd = pd - thr.pc;
    thr.len2 = vec3<f32>(dot(thr.ab, thr.ab), dot(thr.bc, thr.bc), dot(thr.cd, thr.cd));
    thr.flank_n = normalize(vec2<f32>(max_radius - min_radius, b - a));
    thr.head_zc = 0.5 * (tw(9u) + tw(10u));
    thr.head_half = 0.5 * (tw(10u) - tw(9u));
    thr.head_half_edge = tw(8u) / SQRT3_T;
}

// seg_closest(x, a, a + ab) with ab and dot(ab, ab) given: the same operations.
fn seg_closest_from(x: vec2<f32>, a: vec2<f32>, ab: vec2<f32>, len2: f32) -> Closest {
    let t = clamp(dot(x - a, ab) / len2, 0.0, 1.0);
    return Closest(a + ab * t, t > 0.0 && t < 1.0);
}

fn thread_sample(p: vec3<f32>) -> Sample {
    let pitch = tw(0u);
    let phase = tw(1u);
    let pitch_radius = tw(2u);
    let min_radius = tw(3u);
    let max_radius = tw(4u);
    let rho = max(sqrt(p.x * p.x + p.y * p.y), 1.0e-9);
    let radial = vec3<f32>(p.x / rho, p.y / rho, 0.0);
    let theta = atan2(p.y, p.x);
    let lead = thr.lead;
    let u = p.z - phase - lead * theta;
    let w = u - pitch * round(u / pitch);
    let s = abs(w);
    let x = vec2<f32>(s, rho);
    let c1 = seg_closest_from(x, thr.pa, thr.ab, thr.len2.x);
    let c2 = seg_closest_from(x, thr.pb, thr.bc, thr.len2.y);
    let c3 = seg_closest_from(x, thr.pc, thr.cd, thr.len2.z);
    let d1 = dot(x - c1.c, x - c1.c);
    let d2 = dot(x - c2.c, x - c2.c);
    let d3 = dot(x - c3.c, x - c3.c);
    var c = c1;
    var fallback = vec2<f32>(0.0, 1.0);
    if (d2 < d1 && d2 <= d3) {
        c = c2;
        fallback = thr.flank_n;
    } else if (d3 < d1 && d3 < d2) {
        c = c3;
    }
    let r_at = clamp(pitch_radius + SQRT3_T * (thr.quarter - s), min_radius, max_radius);
    let s2 = signed_from_closest(x, c, rho < r_at, fallback);
    let sign_w = select(1.0, -1.0, w < 0.0);
    let tangential = vec3<f32>(-radial.y, radial.x, 0.0);
    var d = s2.d;
    var g = radial * s2.g.y + (vec3<f32>(0.0, 0.0, 1.0) - tangential * (lead / rho)) * (s2.g.x * sign_w);
    let below = tw(5u) - p.z;
    if (below > d) {
        d = below;
        g = vec3<f32>(0.0, 0.0, -1.0);
    }
    let above = p.z - tw(6u);
    if (above > d) {
        d = above;
        g = vec3<f32>(0.0, 0.0, 1.0);
    }
    // The tip chamfer (word 11, 0 for none).
    if (tw(11u) > 0.0) {
        let cone = (rho + (p.z - tw(6u)) - tw(11u)) * INV_SQRT2_T;
        if (cone > d) {
            d = cone;
            g = vec3<f32>(radial.x * INV_SQRT2_T, radial.y * INV_SQRT2_T, INV_SQRT2_T);
        }
    }
    // The head's field is at least its slab's (|z - zc| - half height; hex_prism_sample never returns
    // less, up to rounding: hence the 1 um margin), so beside the thread it cannot win: skip its two
    // segment projections and square roots (most samples of a nut on the thread are far above the head).
    let head_slab = abs(p.z - thr.head_zc) - thr.head_half;
    if (tw(7u) != 0.0 && head_slab < d + HEAD_SKIP_MARGIN) {
        let h = hex_prism_sample(tw(8u), thr.head_half_edge, tw(9u), tw(10u), p);
        if (h.d < d) {
            d = h.d;
            g = h.g;
        }
    }
    return Sample(d, g);
}

// Four samples (component k: point k; see thread_sample4).
struct Sample4 {
    d: vec4<f32>,
    gx: vec4<f32>,
    gy: vec4<f32>,
    gz: vec4<f32>,
}

// WGSL's dot and length for four 2-vectors held by component (x, y): each is the built-in on
// its vector, so the same bits as the one-vector code (written out as products and sums, a compiler may
// round otherwise; see common.wgsl dot4).
fn dot2v(ux: vec4<f32>, uy: vec4<f32>, v: vec2<f32>) -> vec4<f32> {
    return vec4<f32>(dot(vec2<f32>(ux.x, uy.x), v), dot(vec2<f32>(ux.y, uy.y), v), dot(vec2<f32>(ux.z, uy.z), v), dot(vec2<f32>(ux.w, uy.w), v));
}

fn dot2vv(ux: vec4<f32>, uy: vec4<f32>, vx: vec4<f32>, vy: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        dot(vec2<f32>(ux.x, uy.x), vec2<f32>(vx.x, vy.x)),
        dot(vec2<f32>(ux.y, uy.y), vec2<f32>(vx.y, vy.y)),
        dot(vec2<f32>(ux.z, uy.z), vec2<f32>(vx.z, vy.z)),
        dot(vec2<f32>(ux.w, uy.w), vec2<f32>(vx.w, vy.w)),
    );
}

fn len2v(ux: vec4<f32>, uy: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(length(vec2<f32>(ux.x, uy.x)), length(vec2<f32>(ux.y, uy.y)), length(vec2<f32>(ux.z, uy.z)), length(vec2<f32>(ux.w, uy.w)));
}

// Four samples at once (component k of each vector: point k), each the same operations as thread_sample's,
// so the same bits. Why: on lavapipe a sample is a chain of dependent divisions, square roots and the
// atan2 polynomial run 8 lanes wide, and the CPU waits on each link (the generate kernel's disassembly under
// perf: its hot instructions are those after vdivps, vsqrtps and vroundps); four independent
// chains side by side let the core overlap them. On a GPU it is the same arithmetic in more registers.
fn thread_sample4(px: vec4<f32>, py: vec4<f32>, pz: vec4<f32>) -> Sample4 {
    let pitch = tw(0u);
    let phase = tw(1u);
    let pitch_radius = tw(2u);
    let min_radius = tw(3u);
    let max_radius = tw(4u);
    let rho = max(sqrt(px * px + py * py), vec4<f32>(1.0e-9));
    let rx = px / rho;
    let ry = py / rho;
    let theta = atan2(py, px);
    let lead = thr.lead;
    let u = pz - phase - lead * theta;
    let w = u - pitch * round(u / pitch);
    let s = abs(w);
    let c1 = seg_closest_from4(s, rho, thr.pa, thr.ab, thr.len2.x);
    let c2 = seg_closest_from4(s, rho, thr.pb, thr.bc, thr.len2.y);
    let c3 = seg_closest_from4(s, rho, thr.pc, thr.cd, thr.len2.z);
    let d1 = dot2vv(s - c1.cx, rho - c1.cy, s - c1.cx, rho - c1.cy);
    let d2 = dot2vv(s - c2.cx, rho - c2.cy, s - c2.cx, rho - c2.cy);
    let d3 = dot2vv(s - c3.cx, rho - c3.cy, s - c3.cx, rho - c3.cy);
    let m2 = (d2 < d1) & (d2 <= d3);
    let m3 = !m2 & (d3 < d1) & (d3 < d2);
    let cx = select(select(c1.cx, c3.cx, m3), c2.cx, m2);
    let cy = select(select(c1.cy, c3.cy, m3), c2.cy, m2);
    let interior = select(select(c1.interior, c3.interior, m3), c2.interior, m2);
    let fx = select(vec4<f32>(0.0), vec4<f32>(thr.flank_n.x), m2);
    let fy = select(vec4<f32>(1.0), vec4<f32>(thr.flank_n.y), m2);
    let r_at = clamp(pitch_radius + SQRT3_T * (thr.quarter - s), vec4<f32>(min_radius), vec4<f32>(max_radius));
    // signed_from_closest
    let ex = s - cx;
    let ey = rho - cy;
    let len = len2v(ex, ey);
    let sgn = select(vec4<f32>(1.0), vec4<f32>(-1.0), rho < r_at);
    let own = interior | (len <= vec4<f32>(1.0e-12));
    let k = sgn / len;
    let s2d = sgn * len;
    let s2x = select(ex * k, fx, own);
    let s2y = select(ey * k, fy, own);
    let sign_w = select(vec4<f32>(1.0), vec4<f32>(-1.0), w < vec4<f32>(0.0));
    let tx = -ry;
    let ty = rx;
    let lr = lead / rho;
    let q = s2x * sign_w;
    var d = s2d;
    var gx = rx * s2y + (0.0 - tx * lr) * q;
    var gy = ry * s2y + (0.0 - ty * lr) * q;
    var gz = 0.0 * s2y + (1.0 - 0.0 * lr) * q;
    let below = tw(5u) - pz;
    let mb = below > d;
    d = select(d, below, mb);
    gx = select(gx, vec4<f32>(0.0), mb);
    gy = select(gy, vec4<f32>(0.0), mb);
    gz = select(gz, vec4<f32>(-1.0), mb);
    let above = pz - tw(6u);
    let ma = above > d;
    d = select(d, above, ma);
    gx = select(gx, vec4<f32>(0.0), ma);
    gy = select(gy, vec4<f32>(0.0), ma);
    gz = select(gz, vec4<f32>(1.0), ma);
    if (tw(11u) > 0.0) {
        let cone = (rho + (pz - tw(6u)) - tw(11u)) * INV_SQRT2_T;
        let mc = cone > d;
        d = select(d, cone, mc);
        gx = select(gx, rx * INV_SQRT2_T, mc);
        gy = select(gy, ry * INV_SQRT2_T, mc);
        gz = select(gz, vec4<f32>(INV_SQRT2_T), mc);
    }
    // The head, where it may win (see thread_sample).
    let head_slab = abs(pz - thr.head_zc) - thr.head_half;
    let mh = vec4<bool>(tw(7u) != 0.0) & (head_slab < d + HEAD_SKIP_MARGIN);
    if (any(mh)) {
        let h = hex_prism_sample4(tw(8u), thr.head_half_edge, tw(9u), tw(10u), px, py, pz);
        let take = mh & (h.d < d);
        d = select(d, h.d, take);
        gx = select(gx, h.gx, take);
        gy = select(gy, h.gy, take);
        gz = select(gz, h.gz, take);
    }
    return Sample4(d, gx, gy, gz);
}

struct Closest4 {
    cx: vec4<f32>,
    cy: vec4<f32>,
    interior: vec4<bool>,
}

// seg_closest_from for four points (xs, xr): the same operations.
fn seg_closest_from4(xs: vec4<f32>, xr: vec4<f32>, a: vec2<f32>, ab: vec2<f32>, len2: f32) -> Closest4 {
    let t = clamp(dot2v(xs - a.x, xr - a.y, ab) / len2, vec4<f32>(0.0), vec4<f32>(1.0));
    return Closest4(a.x + ab.x * t, a.y + ab.y * t, (t > vec4<f32>(0.0)) & (t < vec4<f32>(1.0)));
}

// hex_prism_sample for four points: the same operations.
fn hex_prism_sample4(apothem: f32, half_edge: f32, z0: f32, z1: f32, px: vec4<f32>, py: vec4<f32>, pz: vec4<f32>) -> Sample4 {
    let qx = abs(px);
    let qy = abs(py);
    let k = vec2<f32>(-0.5, 0.5 * SQRT3_T);
    let kq = dot2v(qx, qy, k);
    let above = kq > vec4<f32>(0.0);
    let rx = select(qx, qx - 2.0 * kq * k.x, above);
    let ry = select(qy, qy - 2.0 * kq * k.y, above);
    let dvx = rx - apothem;
    let dvy = ry - clamp(ry, vec4<f32>(-half_edge), vec4<f32>(half_edge));
    let beside = abs(ry) <= vec4<f32>(half_edge);
    let len = len2v(dvx, dvy);
    let d2 = select(len, dvx, beside);
    let il = 1.0 / len;
    let grx = select(dvx * il, vec4<f32>(1.0), beside);
    let gry = select(dvy * il, vec4<f32>(0.0), beside);
    let kg = dot2v(grx, gry, k);
    let gqx = select(grx, grx - 2.0 * kg * k.x, above);
    let gqy = select(gry, gry - 2.0 * kg * k.y, above);
    let g2x = select(gqx, -gqx, px < vec4<f32>(0.0));
    let g2y = select(gqy, -gqy, py < vec4<f32>(0.0));
    let zc = 0.5 * (z0 + z1);
    let dz = abs(pz - zc) - 0.5 * (z1 - z0);
    let sz = select(vec4<f32>(1.0), vec4<f32>(-1.0), pz < vec4<f32>(zc));
    let corner = (d2 > vec4<f32>(0.0)) & (dz > vec4<f32>(0.0));
    let l3 = sqrt(d2 * d2 + dz * dz);
    let inv = 1.0 / l3;
    let side = !corner & (d2 > dz);
    let cap = !corner & !side;
    let d = select(select(l3, d2, side), dz, cap);
    let gx = select(select(g2x * (d2 * inv), g2x, side), vec4<f32>(0.0), cap);
    let gy = select(select(g2y * (d2 * inv), g2y, side), vec4<f32>(0.0), cap);
    let gz = select(select(sz * (dz * inv), vec4<f32>(0.0), side), sz, cap);
    return Sample4(d, gx, gy, gz);
}
