//! Analytic signed distance of a solid of revolution about the z axis (round pegs, shafts, pins, bowls,
//! rings): the profile is a polygon in the meridian half-plane (rho >= 0, z), counter-clockwise (outward
//! normal on its right), in one of two forms:
//! - **on the axis**: a polyline that starts and ends on the axis (rho = 0), e.g. along the bottom, up the
//!   side, back along the top; the polygon closes along the axis, which is no part of the surface;
//! - **a ring**: a closed polygon entirely off the axis (first vertex rho > 0, every vertex rho > 0), whose
//!   closing edge last -> first is part of the surface (a torus, a washer).
//!
//! The distance to the solid is exactly the 2D distance of (rho, z) to the profile, because every point of
//! the surface nearest to p lies in p's meridian plane; the sign comes from a crossing count along +rho (the
//! closing segment on the axis is never crossed). The gradient is g_rho r_hat + g_z z_hat.
//!
//! Why not the baked grid: a grid baked from a faceted mesh carries the facets' normals (a 128-sided 4 mm
//! peg's normals swing +-1.4 deg about the radial direction), and a peg's moment of inertia about its axis
//! is ~100 times smaller than about a diameter, so the bore's contact forces spin it about its axis. Dropped
//! into its frictionless bore (4 mm Table VII pair, 2 x 16 sweeps, patch_iters 8; measured), the
//! peg on the grid spins at 0.75 rad/s after 2 s; on this field at 0.07 rad/s. Procedural parts may use
//! analytic SDFs (docs/ARCHITECTURE.md section 4); the peg's profile is known exactly.
//! The WGSL twin is revolved.wgsl; both evaluate the same operations in the same order (the on-axis edges
//! first, then a ring's closing edge).

use crate::sdf::thread::{seg_closest, signed_from_closest};
use glam::{Vec2, Vec3};

/// Most profile vertices a revolved SDF may have (fixed size of its GPU parameter block).
pub const REVOLVED_MAX_VERTICES: usize = 16;
/// Words per revolved SDF in the GPU parameter layout: the vertex count, then (rho, z) per vertex.
pub const REVOLVED_WORDS: usize = 1 + 2 * REVOLVED_MAX_VERTICES;

/// A solid of revolution about z, described by its meridian profile.
#[derive(Clone, Debug, PartialEq)]
pub struct RevolvedSdf {
    /// (rho, z) vertices [m], counter-clockwise, at most [`REVOLVED_MAX_VERTICES`]: either first and last on
    /// the axis (rho = 0) and the rest off it, or (a ring) every vertex off the axis, closed last -> first.
    pub profile: Vec<Vec2>,
}

/// Orientation of (a, b, c) in f64: > 0 counter-clockwise, 0 collinear.
fn orient(a: Vec2, b: Vec2, c: Vec2) -> f64 {
    let (a, b, c) = (a.as_dvec2(), b.as_dvec2(), c.as_dvec2());
    (b - a).perp_dot(c - a)
}

/// Whether the closed segments ab and cd share a point (crossing, touching or overlapping).
fn segments_meet(a: Vec2, b: Vec2, c: Vec2, d: Vec2) -> bool {
    let (o1, o2, o3, o4) = (orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b));
    let on = |p: Vec2, q: Vec2, r: Vec2| r.cmpge(p.min(q)).all() && r.cmple(p.max(q)).all();
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    (o1 == 0.0 && on(a, b, c)) || (o2 == 0.0 && on(a, b, d)) || (o3 == 0.0 && on(c, d, a)) || (o4 == 0.0 && on(c, d, b))
}

/// Nearest-edge scan and crossing count of one sample (the CPU twin of `RevolvedScan` in revolved.wgsl).
struct Scan {
    best: (Vec2, bool),
    best_d2: f32,
    normal: Vec2,
    inside: bool,
}

impl Scan {
    fn edge(&mut self, x: Vec2, a: Vec2, b: Vec2) {
        let c = seg_closest(x, a, b);
        let d2 = (x - c.0).length_squared();
        if d2 < self.best_d2 {
            self.best_d2 = d2;
            self.best = c;
            let e = b - a;
            self.normal = Vec2::new(e.y, -e.x).normalize();
        }
        if (a.y > x.y) != (b.y > x.y) && x.x < a.x + (x.y - a.y) * (b.x - a.x) / (b.y - a.y) {
            self.inside = !self.inside;
        }
    }
}

impl RevolvedSdf {
    /// A profile, checked, with an error naming the rule it breaks: 3..=16 finite vertices; either the ends
    /// on the axis and every other vertex off it (rho > 0), or a ring with every vertex off the axis; no
    /// zero-length edge; no two non-adjacent edges meeting (self-intersection) and no edge folding back
    /// over the previous one; a positive (counter-clockwise) area.
    pub fn new(profile: Vec<Vec2>) -> Result<Self, String> {
        let n = profile.len();
        if !(3..=REVOLVED_MAX_VERTICES).contains(&n) {
            return Err(format!("{n} profile vertices; expected 3 to {REVOLVED_MAX_VERTICES}"));
        }
        if let Some(v) = profile.iter().find(|v| !(v.x >= 0.0 && v.is_finite())) {
            return Err(format!("vertex {v}: rho must be finite and >= 0"));
        }
        let ring = profile[0].x > 0.0;
        if !ring && profile[n - 1].x != 0.0 {
            return Err("the profile must start and end on the axis (rho = 0), or be a closed ring with every \
                        vertex off the axis (rho > 0); it starts on the axis and ends off it"
                .into());
        }
        let interior = if ring { 0..n } else { 1..n - 1 };
        if let Some(i) = interior.clone().find(|&i| profile[i].x == 0.0) {
            let what = if ring { "a closed ring profile (first vertex off the axis)" } else { "the profile" };
            return Err(format!(
                "vertex {i} {} touches the axis (rho = 0): {what} may touch the axis only at its two ends",
                profile[i]
            ));
        }
        // Edges of the surface: consecutive vertices, and for a ring the closing edge last -> first.
        let edges = if ring { n } else { n - 1 };
        let edge = |k: usize| (profile[k], profile[(k + 1) % n]);
        if let Some(k) = (0..edges).find(|&k| edge(k).0 == edge(k).1) {
            return Err(format!("vertices {k} and {} coincide (a zero-length edge)", (k + 1) % n));
        }
        for k in 0..edges {
            for l in k + 1..edges {
                let adjacent = l == k + 1 || (ring && k == 0 && l == n - 1);
                let ((a, b), (c, d)) = (edge(k), edge(l));
                let meets = if adjacent {
                    // Sharing one vertex: they must not run back over each other.
                    let (v, p, q) = if l == k + 1 { (b, a, d) } else { (a, b, c) };
                    orient(v, p, q) == 0.0 && (p - v).dot(q - v) > 0.0
                } else {
                    segments_meet(a, b, c, d)
                };
                if meets {
                    return Err(format!("edges {k} and {l} of the profile intersect (it must be a simple polygon)"));
                }
            }
        }
        // Shoelace over the closed polygon (for an on-axis profile the closing segment runs down the axis).
        let area: f32 = (0..n).map(|i| profile[i].perp_dot(profile[(i + 1) % n])).sum::<f32>() * 0.5;
        if area <= 0.0 {
            return Err(format!(
                "the profile must run counter-clockwise in (rho, z) (bottom, side, top); signed area {area}"
            ));
        }
        Ok(RevolvedSdf { profile })
    }

    /// Whether the profile is a closed ring off the axis (its first vertex has rho > 0).
    pub fn is_ring(&self) -> bool {
        self.profile.first().is_some_and(|v| v.x > 0.0)
    }

    /// A torus-like ring: the regular `sides`-gon inscribed in the circle of radius `r` about (`big_r`, `z`)
    /// in the meridian plane, with a vertex at the outermost point (rho = big_r + r) [m].
    pub fn polygon_ring(big_r: f32, r: f32, z: f32, sides: usize) -> Result<Self, String> {
        if !(r > 0.0 && big_r > r && z.is_finite() && (3..=REVOLVED_MAX_VERTICES).contains(&sides)) {
            return Err(format!(
                "ring radius {big_r}, tube radius {r}, {sides} sides: expected 0 < r < ring radius and 3 to \
                 {REVOLVED_MAX_VERTICES} sides"
            ));
        }
        let p = (0..sides)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / sides as f64;
                Vec2::new((big_r as f64 + r as f64 * a.cos()) as f32, (z as f64 + r as f64 * a.sin()) as f32)
            })
            .collect();
        Self::new(p)
    }

    /// A round peg of `radius` from z = 0 to `length` [m] with 45-degree chamfers of `chamfer` [m] at both
    /// ends (0 for none).
    pub fn chamfered_cylinder(radius: f32, length: f32, chamfer: f32) -> Result<Self, String> {
        if !(radius > 0.0 && length > 0.0 && chamfer >= 0.0 && chamfer < radius && 2.0 * chamfer < length) {
            return Err(format!(
                "radius {radius}, length {length}, chamfer {chamfer}: expected radius, length > 0 and \
                 0 <= chamfer < min(radius, length / 2)"
            ));
        }
        let c = chamfer;
        let mut p = vec![Vec2::new(0.0, 0.0)];
        if c > 0.0 {
            p.extend([Vec2::new(radius - c, 0.0), Vec2::new(radius, c), Vec2::new(radius, length - c)]);
            p.extend([Vec2::new(radius - c, length)]);
        } else {
            p.extend([Vec2::new(radius, 0.0), Vec2::new(radius, length)]);
        }
        p.push(Vec2::new(0.0, length));
        Self::new(p)
    }

    /// Signed distance [m] (negative inside) and its gradient (unit) at `p` (part frame).
    pub fn sample(&self, p: Vec3) -> (f32, Vec3) {
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        let radial = if rho > 1e-12 { Vec3::new(p.x / rho, p.y / rho, 0.0) } else { Vec3::X };
        let x = Vec2::new(rho, p.z);
        let mut scan = Scan { best: (Vec2::ZERO, false), best_d2: f32::INFINITY, normal: Vec2::ZERO, inside: false };
        for w in self.profile.windows(2) {
            scan.edge(x, w[0], w[1]);
        }
        if self.is_ring() {
            scan.edge(x, self.profile[self.profile.len() - 1], self.profile[0]);
        }
        let (d, g) = signed_from_closest(x, scan.best, scan.inside, scan.normal);
        (d, radial * g.x + Vec3::Z * g.y)
    }

    /// The GPU parameter block (revolved.wgsl): vertex count, then (rho, z) pairs, zero-padded.
    pub fn to_words(&self) -> [u32; REVOLVED_WORDS] {
        let mut w = [0u32; REVOLVED_WORDS];
        w[0] = self.profile.len() as u32;
        for (i, v) in self.profile.iter().enumerate() {
            w[1 + 2 * i] = v.x.to_bits();
            w[2 + 2 * i] = v.y.to_bits();
        }
        w
    }

    /// Inverse of [`to_words`](Self::to_words) (the CPU twin reads the same block).
    pub fn from_words(w: &[u32]) -> Self {
        let n = w[0] as usize;
        let profile = (0..n).map(|i| Vec2::new(f32::from_bits(w[1 + 2 * i]), f32::from_bits(w[2 + 2 * i]))).collect();
        RevolvedSdf { profile }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peg() -> RevolvedSdf {
        RevolvedSdf::chamfered_cylinder(0.002, 0.05, 0.0005).unwrap()
    }

    #[test]
    fn distances_match_a_chamfered_cylinder_in_closed_form() {
        let s = peg();
        // (point, distance): outside the side, inside near the side, above the top, beside the chamfer,
        // on the axis deep inside (nearest: the side, 2 mm away).
        let cases = [
            (Vec3::new(0.003, 0.0, 0.02), 0.001),
            (Vec3::new(0.0, -0.0015, 0.02), -0.0005),
            (Vec3::new(0.0005, 0.0005, 0.052), 0.002),
            (Vec3::new(0.0, 0.0, 0.025), -0.002),
        ];
        for (p, want) in cases {
            let (d, g) = s.sample(p);
            assert!((d - want).abs() < 1e-7, "{p}: {d} vs {want}");
            assert!((g.length() - 1.0).abs() < 1e-5, "{p}: gradient {g}");
        }
        // Outside the bottom chamfer, along its outward normal (1, -1)/sqrt 2 from its midpoint.
        let mid = Vec2::new(0.00175, 0.00025);
        let q = mid + Vec2::new(1.0, -1.0).normalize() * 1e-4;
        let (d, g) = s.sample(Vec3::new(0.0, q.x, q.y));
        assert!((d - 1e-4).abs() < 1e-8, "chamfer distance {d}");
        assert!((g - Vec3::new(0.0, 1.0, -1.0).normalize()).length() < 1e-5, "chamfer normal {g}");
    }

    #[test]
    fn normals_are_radial_all_round_the_side() {
        // The property the grid lacks: no tangential component anywhere around the side.
        let s = peg();
        for k in 0..360 {
            let a = (k as f32).to_radians();
            let r = Vec3::new(a.cos(), a.sin(), 0.0);
            for rho in [0.00195, 0.00205, 0.0025] {
                let (_, g) = s.sample(r * rho + Vec3::Z * 0.02);
                assert!(g.cross(r).length() < 1e-6, "angle {k}: gradient {g} not radial");
            }
        }
    }

    #[test]
    fn bad_profiles_are_refused_saying_why() {
        let e = RevolvedSdf::new(vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0)]).unwrap_err();
        assert!(e.contains("3 to 16"), "{e}");
        let e = RevolvedSdf::new(vec![Vec2::new(0.1, 0.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0)]).unwrap_err();
        assert!(e.contains("axis"), "{e}");
        let cw = vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0)];
        assert!(RevolvedSdf::new(cw).unwrap_err().contains("counter-clockwise"));
        assert!(RevolvedSdf::chamfered_cylinder(0.002, 0.05, 0.003).unwrap_err().contains("chamfer"));
        let v = |x: f32, y: f32| Vec2::new(x, y);
        // Too many vertices (a 17-gon ring).
        let e = RevolvedSdf::polygon_ring(0.02, 0.01, 0.0, 17).unwrap_err();
        assert!(e.contains("3 to 16"), "{e}");
        let e =
            RevolvedSdf::new((0..17).map(|k| v(1.0 + (k as f32 * 0.37).cos() * 0.5, k as f32)).collect()).unwrap_err();
        assert!(e.contains("3 to 16"), "{e}");
        // On the axis at one end only.
        let e = RevolvedSdf::new(vec![v(0.0, 0.0), v(1.0, 0.0), v(1.0, 1.0)]).unwrap_err();
        assert!(e.contains("start and end on the axis"), "{e}");
        // An on-axis profile touching the axis between its ends, and a ring touching it.
        let e = RevolvedSdf::new(vec![v(0.0, 0.0), v(1.0, 0.0), v(0.0, 1.0), v(1.0, 2.0), v(0.0, 2.0)]).unwrap_err();
        assert!(e.contains("vertex 2") && e.contains("touches the axis"), "{e}");
        let e = RevolvedSdf::new(vec![v(1.0, 0.0), v(2.0, 0.0), v(2.0, 1.0), v(0.0, 1.0)]).unwrap_err();
        assert!(e.contains("vertex 3") && e.contains("touches the axis"), "{e}");
        // A clockwise ring, a self-intersecting (bow-tie) ring, a zero-length closing edge, a negative rho.
        let cw = vec![v(1.0, 0.0), v(1.0, 1.0), v(2.0, 1.0), v(2.0, 0.0)];
        assert!(RevolvedSdf::new(cw).unwrap_err().contains("counter-clockwise"));
        let e = RevolvedSdf::new(vec![v(1.0, 0.0), v(2.0, 1.0), v(2.0, 0.0), v(1.0, 1.0)]).unwrap_err();
        assert!(e.contains("intersect"), "{e}");
        let e = RevolvedSdf::new(vec![v(1.0, 0.0), v(2.0, 0.0), v(2.0, 1.0), v(1.0, 0.0)]).unwrap_err();
        assert!(e.contains("coincide"), "{e}");
        let e = RevolvedSdf::new(vec![v(0.0, 0.0), v(-1.0, 0.0), v(0.0, 1.0)]).unwrap_err();
        assert!(e.contains(">= 0"), "{e}");
        // An edge folding back over the previous one.
        let e = RevolvedSdf::new(vec![v(0.0, 0.0), v(2.0, 0.0), v(1.0, 0.0), v(1.0, 1.0), v(0.0, 1.0)]).unwrap_err();
        assert!(e.contains("intersect"), "{e}");
        // An on-axis profile whose side crosses its bottom.
        let e = RevolvedSdf::new(vec![v(0.0, 0.0), v(2.0, 0.0), v(2.0, 1.0), v(1.0, -1.0), v(0.0, 1.0)]).unwrap_err();
        assert!(e.contains("intersect"), "{e}");
        assert!(RevolvedSdf::polygon_ring(0.01, 0.01, 0.0, 16).unwrap_err().contains("ring radius"));
    }

    #[test]
    fn words_round_trip() {
        let s = peg();
        assert_eq!(RevolvedSdf::from_words(&s.to_words()), s);
        let r = RevolvedSdf::polygon_ring(0.016, 0.008, 0.0, 16).unwrap();
        assert_eq!(RevolvedSdf::from_words(&r.to_words()), r);
    }

    /// The square ring [R - h, R + h] x [-h, h] in (rho, z).
    fn square_ring(big_r: f32, h: f32) -> RevolvedSdf {
        let v = |x: f32, y: f32| Vec2::new(x, y);
        RevolvedSdf::new(vec![v(big_r - h, -h), v(big_r + h, -h), v(big_r + h, h), v(big_r - h, h)]).unwrap()
    }

    fn in_meridian(angle_deg: f32, rho: f32, z: f32) -> (Vec3, Vec3) {
        let a = angle_deg.to_radians();
        let r = Vec3::new(a.cos(), a.sin(), 0.0);
        (r * rho + Vec3::Z * z, r)
    }

    #[test]
    fn a_square_ring_has_closed_form_distances_signs_and_normals() {
        let (big_r, h) = (0.02, 0.005);
        let s = square_ring(big_r, h);
        assert!(s.is_ring() && !peg().is_ring());
        let diag = std::f32::consts::FRAC_1_SQRT_2;
        // (rho, z, distance, gradient (rho, z)) in several meridian planes. The inner wall (rho = R - h) is the
        // closing edge last -> first: the points near it and on the axis side need it.
        let cases = [
            (big_r + h + 0.003, 0.0, 0.003, (1.0, 0.0)),
            (big_r + h - 0.001, 0.001, -0.001, (1.0, 0.0)),
            (big_r, h + 0.002, 0.002, (0.0, 1.0)),
            (big_r + 0.001, -h + 0.0005, -0.0005, (0.0, -1.0)),
            (big_r - h + 0.001, 0.0, -0.001, (-1.0, 0.0)),
            (big_r - h - 0.004, 0.002, 0.004, (-1.0, 0.0)),
            (1e-4, 0.0, big_r - h - 1e-4, (-1.0, 0.0)),
            (big_r + h + 0.003, h + 0.003, 0.003 * std::f32::consts::SQRT_2, (diag, diag)),
            (big_r - h - 0.002, -h - 0.002, 0.002 * std::f32::consts::SQRT_2, (-diag, -diag)),
        ];
        for angle in [0.0, 37.0, 145.0, 270.0] {
            for (rho, z, want, (gr, gz)) in cases {
                let (p, radial) = in_meridian(angle, rho, z);
                let (d, g) = s.sample(p);
                assert!((d - want).abs() < 2e-7, "{angle} deg, ({rho}, {z}): {d} vs {want}");
                let gw = radial * gr + Vec3::Z * gz;
                assert!((g - gw).length() < 1e-5, "{angle} deg, ({rho}, {z}): gradient {g} vs {gw}");
            }
        }
        // Deep inside: the centre of the section is h from every side.
        assert!((s.sample(Vec3::new(0.0, big_r, 0.0)).0 + h).abs() < 1e-7);
    }

    #[test]
    fn a_16_gon_ring_has_closed_form_distances_signs_and_normals() {
        let (big_r, r, z0, n) = (0.016f32, 0.008f32, 0.01f32, 16usize);
        let s = RevolvedSdf::polygon_ring(big_r, r, z0, n).unwrap();
        assert_eq!(s.profile.len(), n);
        let step = std::f32::consts::TAU / n as f32;
        let apothem = r * (0.5 * step).cos();
        let centre = Vec2::new(big_r, z0);
        for angle in [0.0, 90.0, 200.0] {
            for k in 0..n {
                // Along an edge's normal through its midpoint: u - apothem, gradient the normal.
                let mid = (k as f32 + 0.5) * step;
                let dir = Vec2::new(mid.cos(), mid.sin());
                for u in [0.2 * r, 0.7 * r, 0.99 * apothem, 1.01 * apothem, 1.5 * r, 3.0 * r] {
                    if big_r + u * dir.x <= 0.0 {
                        continue;
                    }
                    let q = centre + dir * u;
                    let (p, radial) = in_meridian(angle, q.x, q.y);
                    let (d, g) = s.sample(p);
                    // Beyond the apothem only the edge's own normal slab is its: far out along the middle of
                    // an edge, that edge is still the nearest; inside, every other edge is further.
                    assert!((d - (u - apothem)).abs() < 3e-7, "edge {k}, u {u}: {d} vs {}", u - apothem);
                    assert_eq!(d < 0.0, u < apothem, "edge {k}, u {u}: sign");
                    let gw = radial * dir.x + Vec3::Z * dir.y;
                    assert!((g - gw).length() < 1e-5, "edge {k}, u {u}: gradient {g} vs {gw}");
                }
                // Outside a vertex, within its normal cone: u - r, gradient from the vertex.
                let a = k as f32 * step;
                let dir = Vec2::new(a.cos(), a.sin());
                let q = centre + dir * (r + 0.002);
                let (p, radial) = in_meridian(angle, q.x, q.y);
                let (d, g) = s.sample(p);
                assert!((d - 0.002).abs() < 3e-7, "vertex {k}: {d}");
                assert!((g - (radial * dir.x + Vec3::Z * dir.y)).length() < 1e-4, "vertex {k}: gradient {g}");
            }
        }
        // The hole of the ring is outside: on the axis, R - r from the innermost vertex (angle pi).
        let (d, _) = s.sample(Vec3::new(0.0, 0.0, z0));
        assert!((d - (big_r - r)).abs() < 3e-7, "axis: {d}");
    }

    /// The on-axis sample as it was before rings existed (a copy kept as the reference): the ring's closing
    /// edge must not change one bit of an on-axis profile's field.
    fn sample_before_rings(s: &RevolvedSdf, p: Vec3) -> (f32, Vec3) {
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        let radial = if rho > 1e-12 { Vec3::new(p.x / rho, p.y / rho, 0.0) } else { Vec3::X };
        let x = Vec2::new(rho, p.z);
        let mut best = (Vec2::ZERO, false);
        let mut best_d2 = f32::INFINITY;
        let mut normal = Vec2::ZERO;
        let mut inside = false;
        for w in s.profile.windows(2) {
            let (a, b) = (w[0], w[1]);
            let c = seg_closest(x, a, b);
            let d2 = (x - c.0).length_squared();
            if d2 < best_d2 {
                best_d2 = d2;
                best = c;
                let e = b - a;
                normal = Vec2::new(e.y, -e.x).normalize();
            }
            if (a.y > x.y) != (b.y > x.y) && x.x < a.x + (x.y - a.y) * (b.x - a.x) / (b.y - a.y) {
                inside = !inside;
            }
        }
        let (d, g) = signed_from_closest(x, best, inside, normal);
        (d, radial * g.x + Vec3::Z * g.y)
    }

    /// Deterministic points in [-half, half]^3 + centre (a 64-bit LCG).
    fn points(n: usize, centre: Vec3, half: Vec3, seed: u64) -> Vec<Vec3> {
        let mut state = seed;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        };
        (0..n).map(|_| centre + Vec3::new(next(), next(), next()) * half).collect()
    }

    #[test]
    fn on_axis_profiles_sample_bitwise_as_before_rings() {
        let profiles = [peg(), RevolvedSdf::chamfered_cylinder(0.01, 0.03, 0.0).unwrap()];
        for s in &profiles {
            for p in points(4000, Vec3::new(0.0, 0.0, 0.02), Vec3::new(0.015, 0.015, 0.04), 7) {
                let (d0, g0) = sample_before_rings(s, p);
                let (d1, g1) = s.sample(p);
                assert_eq!(d0.to_bits(), d1.to_bits(), "{p}");
                assert_eq!(g0.to_array().map(f32::to_bits), g1.to_array().map(f32::to_bits), "{p}");
            }
        }
    }

    /// A kernel that samples revolved.wgsl at given points: `points[i].w` holds the profile's word offset.
    fn parity_shader() -> String {
        let head = "
@group(0) @binding(0) var<storage, read> sdf_values: array<u32>;
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> out: array<vec4<f32>>;
struct Sample {
    d: f32,
    g: vec3<f32>,
}
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= arrayLength(&points)) {
        return;
    }
    analytic_load_revolved(bitcast<u32>(points[i].w));
    let s = revolved_sample(points[i].xyz);
    out[i] = vec4<f32>(s.g, s.d);
}
";
        format!("{head}{}{}", include_str!("thread.wgsl"), include_str!("revolved.wgsl"))
    }

    #[test]
    fn the_parity_kernel_validates_with_naga() {
        let src = parity_shader();
        let module = naga::front::wgsl::parse_str(&src).unwrap_or_else(|e| panic!("{}", e.emit_to_string(&src)));
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{e:?}"));
    }

    /// revolved.wgsl against this file on the GPU (lavapipe in CI), on-axis profiles and rings alike: the
    /// same distances and gradients up to f32 rounding (the GPU may fuse or round sqrt and division
    /// differently by an ulp).
    #[test]
    fn gpu_and_cpu_sample_alike_on_axis_profiles_and_rings() {
        let g = crate::gpu::GpuContext::global().expect("a wgpu adapter (lavapipe in CI)");
        let shapes = [
            (peg(), Vec3::new(0.0, 0.0, 0.025), Vec3::new(0.004, 0.004, 0.03)),
            (RevolvedSdf::chamfered_cylinder(0.01, 0.03, 0.001).unwrap(), Vec3::Z * 0.015, Vec3::splat(0.02)),
            (square_ring(0.02, 0.005), Vec3::ZERO, Vec3::new(0.03, 0.03, 0.01)),
            (RevolvedSdf::polygon_ring(0.016, 0.008, 0.003, 16).unwrap(), Vec3::ZERO, Vec3::new(0.03, 0.03, 0.015)),
            (RevolvedSdf::polygon_ring(0.01, 0.002, 0.0, 3).unwrap(), Vec3::ZERO, Vec3::new(0.015, 0.015, 0.005)),
        ];
        let mut words = Vec::new();
        let mut pts: Vec<[f32; 4]> = Vec::new();
        let mut cpu = Vec::new();
        for (k, (s, c, h)) in shapes.iter().enumerate() {
            let base = words.len() as u32;
            words.extend_from_slice(&s.to_words());
            for p in points(2048, *c, *h, 11 + k as u64) {
                pts.push([p.x, p.y, p.z, f32::from_bits(base)]);
                cpu.push(s.sample(p));
            }
        }
        let pipeline = {
            let src = parity_shader();
            let module = g.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("revolved parity"),
                source: wgpu::ShaderSource::Wgsl(src.into()),
            });
            g.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("revolved parity"),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let values = g.storage_buffer("revolved words", &words, wgpu::BufferUsages::empty());
        let points_buf = g.storage_buffer("revolved points", &pts, wgpu::BufferUsages::empty());
        let out = g.storage_buffer_zeroed("revolved out", 16 * pts.len() as u64);
        let group = g.bind_group(&pipeline, 0, &[&values, &points_buf, &out]);
        let mut enc = g.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups((pts.len() as u32).div_ceil(64), 1, 1);
        }
        g.queue.submit([enc.finish()]);
        let gpu: Vec<[f32; 4]> = g.read_buffer(&out);
        let mut worst = (0.0f32, 0.0f32);
        for (i, ((d, grad), o)) in cpu.iter().zip(&gpu).enumerate() {
            let (dg, gg) = (o[3], Vec3::new(o[0], o[1], o[2]));
            let p = Vec3::new(pts[i][0], pts[i][1], pts[i][2]);
            assert!((d - dg).abs() < 1e-7, "point {i} {p}: cpu {d}, gpu {dg}");
            assert!((*grad - gg).length() < 1e-4, "point {i} {p}: cpu {grad}, gpu {gg}");
            worst = (worst.0.max((d - dg).abs()), worst.1.max((*grad - gg).length()));
        }
        eprintln!(
            "revolved GPU/CPU parity over {} points: worst distance {:e} m, gradient {:e}",
            cpu.len(),
            worst.0,
            worst.1
        );
    }
}
