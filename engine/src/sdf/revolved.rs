//! Analytic signed distance of a solid of revolution about the z axis (round pegs, shafts, pins): the
//! profile is a polyline in the meridian half-plane (rho >= 0, z) that starts and ends on the axis and runs
//! counter-clockwise (outward normal on its right: along the bottom, up the side, back along the top).
//! The distance to the solid is exactly the 2D distance of (rho, z) to the profile, because every point of
//! the surface nearest to p lies in p's meridian plane; the sign comes from a crossing count along +rho (the
//! closing segment on the axis is never crossed). The gradient is g_rho r_hat + g_z z_hat.
//!
//! Why not the baked grid: a grid baked from a faceted mesh carries the facets' normals (a 128-sided 4 mm
//! peg's normals swing +-1.4 deg about the radial direction), and a peg's moment of inertia about its axis
//! is ~100 times smaller than about a diameter, so the bore's contact forces spin it about its axis. Dropped
//! into its frictionless bore (4 mm Table VII pair, 2 x 16 sweeps, patch_iters 8, measured 2026-11-22), the
//! peg on the grid spins at 0.75 rad/s after 2 s; on this field at 0.07 rad/s. DESIGN 4.1 allows analytic
//! SDFs for procedural parts; the peg's profile is known exactly.
//! The WGSL twin is revolved.wgsl; both evaluate the same operations in the same order.

use crate::sdf::thread::{seg_closest, signed_from_closest};
use glam::{Vec2, Vec3};

/// Most profile vertices a revolved SDF may have (fixed size of its GPU parameter block).
pub const REVOLVED_MAX_VERTICES: usize = 16;
/// Words per revolved SDF in the GPU parameter layout: the vertex count, then (rho, z) per vertex.
pub const REVOLVED_WORDS: usize = 1 + 2 * REVOLVED_MAX_VERTICES;

/// A solid of revolution about z, described by its meridian profile.
#[derive(Clone, Debug, PartialEq)]
pub struct RevolvedSdf {
    /// (rho, z) vertices [m]: first and last on the axis (rho = 0), counter-clockwise, at most
    /// [`REVOLVED_MAX_VERTICES`].
    pub profile: Vec<Vec2>,
}

impl RevolvedSdf {
    /// A profile, checked: 3..=16 vertices, the ends on the axis, rho >= 0, no zero-length segment, and a
    /// positive (counter-clockwise) area. The error says which rule a profile breaks.
    pub fn new(profile: Vec<Vec2>) -> Result<Self, String> {
        let n = profile.len();
        if !(3..=REVOLVED_MAX_VERTICES).contains(&n) {
            return Err(format!("{n} profile vertices; expected 3 to {REVOLVED_MAX_VERTICES}"));
        }
        if profile[0].x != 0.0 || profile[n - 1].x != 0.0 {
            return Err("the profile must start and end on the axis (rho = 0)".into());
        }
        if let Some(v) = profile.iter().find(|v| !(v.x >= 0.0 && v.is_finite())) {
            return Err(format!("vertex {v}: rho must be finite and >= 0"));
        }
        if profile.windows(2).any(|w| w[0] == w[1]) {
            return Err("two consecutive vertices coincide".into());
        }
        // Shoelace over the closed polygon (the closing segment runs down the axis).
        let area: f32 = (0..n).map(|i| profile[i].perp_dot(profile[(i + 1) % n])).sum::<f32>() * 0.5;
        if area <= 0.0 {
            return Err(format!(
                "the profile must run counter-clockwise in (rho, z) (bottom, side, top); signed area {area}"
            ));
        }
        Ok(RevolvedSdf { profile })
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
        let mut best = (Vec2::ZERO, false);
        let mut best_d2 = f32::INFINITY;
        let mut normal = Vec2::ZERO;
        let mut inside = false;
        for w in self.profile.windows(2) {
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
    }

    #[test]
    fn words_round_trip() {
        let s = peg();
        assert_eq!(RevolvedSdf::from_words(&s.to_words()), s);
    }
}
