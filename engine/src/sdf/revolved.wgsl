// Analytic SDF of a solid of revolution about z (sdf_kind 3): WGSL twin of engine/src/sdf/revolved.rs, which
// documents the method. Parameters in `analytic_words` (thread.wgsl; RevolvedSdf::to_words): the vertex
// count, then (rho, z) per vertex. Uses Closest, seg_closest and signed_from_closest from thread.wgsl (concatenated
// before). No loops: lavapipe charges every loop pass against one budget per invocation (see
// contact/common.wgsl), and this is sampled many times per invocation, so the 15 segments are written out,
// then a ring profile's closing edge (first vertex off the axis: last -> first is part of the surface).

struct RevolvedScan {
    best: Closest,
    best_d2: f32,
    normal: vec2<f32>,
    inside: bool,
}

fn revolved_vertex(i: u32) -> vec2<f32> {
    return vec2<f32>(bitcast<f32>(analytic_words[1u + 2u * i]), bitcast<f32>(analytic_words[2u + 2u * i]));
}

// One edge a -> b of the profile: nearest point so far, and the crossing count along +rho.
fn revolved_edge(a: vec2<f32>, b: vec2<f32>, x: vec2<f32>, scan: ptr<function, RevolvedScan>) {
    let c = seg_closest(x, a, b);
    let d2 = dot(x - c.c, x - c.c);
    if (d2 < (*scan).best_d2) {
        (*scan).best_d2 = d2;
        (*scan).best = c;
        let e = b - a;
        (*scan).normal = normalize(vec2<f32>(e.y, -e.x));
    }
    if ((a.y > x.y) != (b.y > x.y) && x.x < a.x + (x.y - a.y) * (b.x - a.x) / (b.y - a.y)) {
        (*scan).inside = !(*scan).inside;
    }
}

// Segment i - 1 -> i of the profile, if the profile has vertex i.
fn revolved_segment(n: u32, i: u32, x: vec2<f32>, scan: ptr<function, RevolvedScan>) {
    if (i >= n) {
        return;
    }
    revolved_edge(revolved_vertex(i - 1u), revolved_vertex(i), x, scan);
}

fn revolved_sample(p: vec3<f32>) -> Sample {
    let rho = sqrt(p.x * p.x + p.y * p.y);
    var radial = vec3<f32>(1.0, 0.0, 0.0);
    if (rho > 1.0e-12) {
        radial = vec3<f32>(p.x / rho, p.y / rho, 0.0);
    }
    let x = vec2<f32>(rho, p.z);
    let n = analytic_words[0];
    var scan = RevolvedScan(Closest(vec2<f32>(0.0), false), 3.0e38, vec2<f32>(0.0), false);
    revolved_segment(n, 1u, x, &scan);
    revolved_segment(n, 2u, x, &scan);
    revolved_segment(n, 3u, x, &scan);
    revolved_segment(n, 4u, x, &scan);
    revolved_segment(n, 5u, x, &scan);
    revolved_segment(n, 6u, x, &scan);
    revolved_segment(n, 7u, x, &scan);
    revolved_segment(n, 8u, x, &scan);
    revolved_segment(n, 9u, x, &scan);
    revolved_segment(n, 10u, x, &scan);
    revolved_segment(n, 11u, x, &scan);
    revolved_segment(n, 12u, x, &scan);
    revolved_segment(n, 13u, x, &scan);
    revolved_segment(n, 14u, x, &scan);
    revolved_segment(n, 15u, x, &scan);
    let first = revolved_vertex(0u);
    if (first.x > 0.0) {
        revolved_edge(revolved_vertex(n - 1u), first, x, &scan);
    }
    let s2 = signed_from_closest(x, scan.best, scan.inside, scan.normal);
    return Sample(s2.d, radial * s2.g.x + vec3<f32>(0.0, 0.0, 1.0) * s2.g.y);
}
