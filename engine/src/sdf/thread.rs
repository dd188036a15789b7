//! Analytic signed distance of a threaded bolt: a right-hand helical sweep of the ISO 68-1 trapezoid
//! profile, clipped to its shank, united with a hexagonal head. Procedural parts may use analytic SDFs
//! where they beat the dense grid (docs/ARCHITECTURE.md section 4): here the grid's trilinear interpolation
//! under-estimates the distance near the concave root corners by 13-31 um at resolution 512-256 (docs/BENCHMARKS.md),
//! more than the 19 um flank clearance of a tight M16 pair, while the analytic field is exact up to the
//! lead-angle approximation below, needs no memory and no bake.
//!
//! Thread: at a point (rho, theta, z) the helical coordinate is u = z - phase - P theta / (2 pi). The
//! distance is taken in the meridian half-plane, to the profile curve rho = r(u) (ISO 68-1: crest flat,
//! 60-degree flanks, root flat). The profile is even in u and P-periodic, so folding u into s = |u| in
//! [0, P/2] and measuring to the three segments of that half period is exact in the plane (a reflection
//! never brings a mirrored copy of the curve closer). The meridian distance differs from the true 3D
//! distance to the helical surface by the factor cos(angle between the surface normal and the meridian
//! plane): tan of that angle is at most P / (2 pi rho) (M16 at the pitch radius: 0.043, so distances are
//! overestimated by at most 0.1%: 0.01 um at a 10 um gap). The gradient is the chain rule through u:
//! grad = g_rho r_hat + g_s sign(u) (z_hat - P / (2 pi rho) theta_hat), which carries the lead-angle tilt.
//! Clip and union use max/min of the fields (exact near faces, a lower bound near the clip edges).
//! The WGSL twin is thread.wgsl; both evaluate the same operations in the same order.

use glam::{Vec2, Vec3};

/// Hexagonal prism about the z axis, one flat's normal along +x (as the asset generator's hex).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HexPrism {
    /// Distance from the axis to each flat [m].
    pub apothem: f32,
    /// Bottom and top planes [m].
    pub z0: f32,
    pub z1: f32,
}

/// A threaded bolt (or threaded rod without head) in its own frame, axis along z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThreadSdf {
    /// Pitch P [m].
    pub pitch: f32,
    /// Height of a tooth centre at theta = 0 [m].
    pub phase: f32,
    /// Radius where the tooth is P/2 wide [m].
    pub pitch_radius: f32,
    /// Root radius [m].
    pub min_radius: f32,
    /// Crest radius [m].
    pub max_radius: f32,
    /// The thread occupies z_lo <= z <= z_hi [m].
    pub z_lo: f32,
    pub z_hi: f32,
    /// Optional head.
    pub head: Option<HexPrism>,
    /// Radius of the top face of a 45-degree chamfer at the thread's upper end [m]; 0 for none (a flat,
    /// sharp-edged cut). ISO 4753 ("chamfered end"): the chamfer reaches a diameter at or below the
    /// thread's minor diameter. Factory's M16 bolt has one (its mesh: crest radius 7.98 mm down to 6.72 mm
    /// over the top 1.3 mm), and a nut resting on the tip sits on it, centred by the cone.
    pub tip_radius: f32,
}

/// Words per thread SDF in the GPU parameter layout (see [`ThreadSdf::to_words`]).
pub const THREAD_WORDS: usize = 12;

const SQRT3: f32 = 1.732_050_8;
const INV_SQRT2: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// [m]: see [`ThreadSdf::sample`] (as `HEAD_SKIP_MARGIN` in thread.wgsl).
const HEAD_SKIP_MARGIN: f32 = 1e-6;

/// Closest point to `x` on segment (a, b) and whether it lies strictly inside the segment.
pub(crate) fn seg_closest(x: Vec2, a: Vec2, b: Vec2) -> (Vec2, bool) {
    let ab = b - a;
    let t = ((x - a).dot(ab) / ab.dot(ab)).clamp(0.0, 1.0);
    (a + ab * t, t > 0.0 && t < 1.0)
}

/// Signed distance and gradient of a 2D field from its closest boundary point `c`. When `c` is inside a
/// segment the gradient is that segment's outward `normal` (exact, and free of the cancellation error of
/// x - c near the surface); at a corner it is the direction from the corner.
pub(crate) fn signed_from_closest(x: Vec2, c: (Vec2, bool), inside: bool, normal: Vec2) -> (f32, Vec2) {
    let d = x - c.0;
    let len = d.length();
    let sgn = if inside { -1.0 } else { 1.0 };
    if c.1 || len <= 1e-12 {
        (sgn * len, normal)
    } else {
        (sgn * len, d * (sgn / len))
    }
}

impl ThreadSdf {
    /// A test bolt: ISO 68-1's basic M16 x 2 profile (H = sqrt(3)/2 P, pitch diameter d - 0.6495 P, root
    /// d - 1.2269 P with its P/4 flat), 25 mm of thread over a 16 mm head of 12 mm apothem, the tip cut
    /// flat. The project's bolts come from `factory_assets` (ISO 965 tolerance classes).
    pub fn basic_m16() -> ThreadSdf {
        ThreadSdf {
            pitch: 0.002,
            phase: 0.016,
            pitch_radius: 0.5 * (0.016 - 0.649519 * 0.002),
            min_radius: 0.5 * (0.016 - 1.226869 * 0.002),
            max_radius: 0.008,
            z_lo: 0.016,
            z_hi: 0.041,
            head: Some(HexPrism { apothem: 0.012, z0: 0.0, z1: 0.016 }),
            tip_radius: 0.0,
        }
    }

    /// Half width of the crest flat [m].
    fn crest_half_width(&self) -> f32 {
        (0.25 * self.pitch - (self.max_radius - self.pitch_radius) / SQRT3).max(0.0)
    }
    /// Axial offset where the root flat starts [m].
    fn root_start(&self) -> f32 {
        (0.25 * self.pitch + (self.pitch_radius - self.min_radius) / SQRT3).min(0.5 * self.pitch)
    }

    /// Signed distance [m] and gradient of the thread alone (unclipped).
    fn thread(&self, p: Vec3) -> (f32, Vec3) {
        let rho = (p.x * p.x + p.y * p.y).sqrt().max(1e-9);
        let radial = Vec3::new(p.x / rho, p.y / rho, 0.0);
        let theta = p.y.atan2(p.x);
        let lead = self.pitch / std::f32::consts::TAU;
        let u = p.z - self.phase - lead * theta;
        let w = u - self.pitch * (u / self.pitch).round();
        let s = w.abs();
        let (a, b) = (self.crest_half_width(), self.root_start());
        let x = Vec2::new(s, rho);
        let pa = Vec2::new(0.0, self.max_radius);
        let pb = Vec2::new(a, self.max_radius);
        let pc = Vec2::new(b, self.min_radius);
        let pd = Vec2::new(0.5 * self.pitch, self.min_radius);
        let c1 = seg_closest(x, pa, pb);
        let c2 = seg_closest(x, pb, pc);
        let c3 = seg_closest(x, pc, pd);
        let (d1, d2, d3) = ((x - c1.0).length_squared(), (x - c2.0).length_squared(), (x - c3.0).length_squared());
        let flank_n = Vec2::new(self.max_radius - self.min_radius, b - a).normalize();
        let (mut c, mut fallback) = (c1, Vec2::Y);
        if d2 < d1 && d2 <= d3 {
            (c, fallback) = (c2, flank_n);
        } else if d3 < d1 && d3 < d2 {
            c = c3;
        }
        let r_at = (self.pitch_radius + SQRT3 * (0.25 * self.pitch - s)).clamp(self.min_radius, self.max_radius);
        let (d, g) = signed_from_closest(x, c, rho < r_at, fallback);
        let sign_w = if w < 0.0 { -1.0 } else { 1.0 };
        let tangential = Vec3::new(-radial.y, radial.x, 0.0);
        let grad = radial * g.y + (Vec3::Z - tangential * (lead / rho)) * (g.x * sign_w);
        (d, grad)
    }

    /// Signed distance [m] (negative inside) and its gradient (not normalised) at `p` (part frame).
    pub fn sample(&self, p: Vec3) -> (f32, Vec3) {
        let (mut d, mut g) = self.thread(p);
        // Clip to the shank: max with the two half-spaces.
        let below = self.z_lo - p.z;
        if below > d {
            (d, g) = (below, Vec3::NEG_Z);
        }
        let above = p.z - self.z_hi;
        if above > d {
            (d, g) = (above, Vec3::Z);
        }
        // The tip chamfer: max with the cone rho + z <= tip_radius + z_hi (its meridian line's distance,
        // exact beside the cone's surface).
        if self.tip_radius > 0.0 {
            let rho = (p.x * p.x + p.y * p.y).sqrt().max(1e-9);
            let cone = (rho + (p.z - self.z_hi) - self.tip_radius) * INV_SQRT2;
            if cone > d {
                (d, g) = (cone, Vec3::new(p.x / rho * INV_SQRT2, p.y / rho * INV_SQRT2, INV_SQRT2));
            }
        }
        // The head's field is at least its slab's (hex_prism never returns less, up to rounding: hence the
        // margin), so beside the thread it cannot win and is skipped (most samples of a nut on the thread
        // lie far above the head).
        if let Some(h) =
            self.head.filter(|h| (p.z - 0.5 * (h.z0 + h.z1)).abs() - 0.5 * (h.z1 - h.z0) < d + HEAD_SKIP_MARGIN)
        {
            let (dh, gh) = hex_prism(h, p);
            if dh < d {
                (d, g) = (dh, gh);
            }
        }
        (d, g)
    }

    /// Bounding sphere of the solid (thread, chamfered tip and head) in its frame: centre xyz on the axis,
    /// radius w [m]. Beyond it the field may still read less than the distance to the solid (see
    /// `contact::model::THREAD_BOUND_SLACK`).
    pub fn bound(&self) -> [f32; 4] {
        let (mut z0, mut z1, mut rho) = (self.z_lo, self.z_hi, self.max_radius);
        if let Some(h) = self.head {
            z0 = z0.min(h.z0);
            z1 = z1.max(h.z1);
            // The hexagon's corners lie 2 / sqrt(3) apothems from the axis.
            rho = rho.max(h.apothem * 2.0 / SQRT3);
        }
        // One part in 1e5 of slack for the rounding of the world-frame test (as bounding_sphere).
        [0.0, 0.0, 0.5 * (z0 + z1), rho.hypot(0.5 * (z1 - z0)) * (1.0 + 1e-5)]
    }

    /// GPU parameter words (f32 bit patterns): pitch, phase, pitch radius, root radius, crest radius,
    /// z_lo, z_hi, has_head (0/1), head apothem, head z0, head z1, tip radius.
    pub fn to_words(&self) -> [u32; THREAD_WORDS] {
        let h = self.head.unwrap_or(HexPrism { apothem: 0.0, z0: 0.0, z1: 0.0 });
        [
            self.pitch,
            self.phase,
            self.pitch_radius,
            self.min_radius,
            self.max_radius,
            self.z_lo,
            self.z_hi,
            if self.head.is_some() { 1.0 } else { 0.0 },
            h.apothem,
            h.z0,
            h.z1,
            self.tip_radius,
        ]
        .map(f32::to_bits)
    }

    /// Inverse of [`to_words`](Self::to_words).
    pub fn from_words(w: &[u32]) -> ThreadSdf {
        let f = |i: usize| f32::from_bits(w[i]);
        ThreadSdf {
            pitch: f(0),
            phase: f(1),
            pitch_radius: f(2),
            min_radius: f(3),
            max_radius: f(4),
            z_lo: f(5),
            z_hi: f(6),
            head: if f(7) != 0.0 { Some(HexPrism { apothem: f(8), z0: f(9), z1: f(10) }) } else { None },
            tip_radius: f(11),
        }
    }
}

/// Signed distance and gradient of a hexagonal prism (flat normal +x).
///
/// The hexagon is symmetric about both axes and about the line at 30 degrees in the first quadrant, so the
/// point is folded onto one edge, x = a with |y| <= a / sqrt 3, and the gradient unfolded (a reflection is
/// its own inverse). Written for the GPU (thread.wgsl, the same operations): one square root and one
/// division in 2D, where the closest-segment search cost two of each and two more for the sign (lavapipe
/// runs the head's code, masked, at every thread sample: 13% of the nut-bolt pair's contact handling).
pub fn hex_prism(h: HexPrism, p: Vec3) -> (f32, Vec3) {
    let q = Vec2::new(p.x.abs(), p.y.abs());
    let a = h.apothem;
    // Unit normal of the 30 degree line: points above it are nearer the upper edge.
    let k = Vec2::new(-0.5, 0.5 * SQRT3);
    let above = k.dot(q) > 0.0;
    let r = if above { q - 2.0 * k.dot(q) * k } else { q };
    let half_edge = a / SQRT3;
    let dv = Vec2::new(r.x - a, r.y - r.y.clamp(-half_edge, half_edge));
    // Beside the edge (inside the hexagon always is): its plane's distance and normal; past a corner
    // (always outside): the distance from the corner.
    let beside = r.y.abs() <= half_edge;
    let len = dv.length();
    let d2 = if beside { dv.x } else { len };
    let gr = if beside { Vec2::X } else { dv * (1.0 / len) };
    let gq = if above { gr - 2.0 * k.dot(gr) * k } else { gr };
    let g2 = Vec2::new(if p.x < 0.0 { -gq.x } else { gq.x }, if p.y < 0.0 { -gq.y } else { gq.y });
    // Extrude along z.
    let zc = 0.5 * (h.z0 + h.z1);
    let dz = (p.z - zc).abs() - 0.5 * (h.z1 - h.z0);
    let sz = if p.z < zc { -1.0 } else { 1.0 };
    if d2 > 0.0 && dz > 0.0 {
        let len = (d2 * d2 + dz * dz).sqrt();
        let inv = 1.0 / len;
        (len, Vec3::new(g2.x * (d2 * inv), g2.y * (d2 * inv), sz * (dz * inv)))
    } else if d2 > dz {
        (d2, Vec3::new(g2.x, g2.y, 0.0))
    } else {
        (dz, Vec3::new(0.0, 0.0, sz))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m16() -> ThreadSdf {
        ThreadSdf::basic_m16()
    }

    /// The broad phase's promise (contact::model::THREAD_BOUND_SLACK): the solid lies inside the bound,
    /// and every point the broad phase culls for a query at contact offset c (farther from the bound's
    /// centre than its radius plus (1 + slack) c) reads more than c, with and without the tip's chamfer.
    #[test]
    fn the_bound_holds_the_solid_and_culls_only_beyond_the_offset() {
        let mut rng = crate::rng::SplitMix64(7);
        for t in [m16(), ThreadSdf { tip_radius: m16().min_radius, ..m16() }] {
            let [cx, cy, cz, r] = t.bound();
            let centre = Vec3::new(cx, cy, cz);
            // Points of the solid (field <= 0) drawn from the box around the head and the shank.
            let mut inside = 0;
            for _ in 0..200_000 {
                let p = Vec3::new((rng.unit() - 0.5) * 0.03, (rng.unit() - 0.5) * 0.03, -0.002 + rng.unit() * 0.046);
                if t.sample(p).0 <= 0.0 {
                    inside += 1;
                    assert!(p.distance(centre) <= r, "{p} of the solid lies outside the bound {:?}", t.bound());
                }
            }
            assert!(inside > 10_000, "only {inside} samples fell in the solid");
            for c in [0.0005f32, 0.002, 0.005] {
                let reach = r + (1.0 + crate::contact::model::THREAD_BOUND_SLACK) * c;
                let mut least = f32::INFINITY;
                for _ in 0..20_000 {
                    let d = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
                    if d.length() < 1e-3 {
                        continue;
                    }
                    let p = centre + d.normalize() * reach * (1.0 + 1e-6);
                    least = least.min(t.sample(p).0);
                }
                assert!(least > c, "a culled point reads {least} m, within the offset {c} m");
            }
        }
    }

    #[test]
    fn words_round_trip() {
        let t = m16();
        assert_eq!(ThreadSdf::from_words(&t.to_words()), t);
    }

    #[test]
    fn crest_root_and_flank_distances() {
        let t = m16();
        // On the crest flat at a tooth centre (theta = 0 => u = z - phase): 0.1 mm outside.
        let (d, g) = t.sample(Vec3::new(0.0081, 0.0, 0.016 + 5.0 * 0.002));
        assert!((d - 0.0001).abs() < 1e-7, "{d}");
        assert!(g.normalize().dot(Vec3::X) > 0.99, "{g}");
        // Half a pitch away (root flat), 0.05 mm above the root: outside by 0.05 mm.
        let (d, _) = t.sample(Vec3::new(t.min_radius + 0.00005, 0.0, 0.016 + 5.0 * 0.002 + 0.001));
        assert!((d - 0.00005).abs() < 1e-7, "{d}");
        // Inside the core.
        assert!(t.sample(Vec3::new(0.005, 0.0, 0.03)).0 < -0.0015);
        // Upper flank at the pitch radius: the normal is 30 degrees from the axis, tilted by the lead.
        let z = 0.016 + 5.0 * 0.002 + 0.0005; // u = P/4: the flank crosses the pitch radius here
        let (d, g) = t.sample(Vec3::new(t.pitch_radius, 0.0, z));
        assert!(d.abs() < 1e-7, "{d}");
        let n = g.normalize();
        let expect = (Vec3::Z + 30f32.to_radians().tan() * Vec3::X
            - 0.002 / (std::f32::consts::TAU * t.pitch_radius) * Vec3::Y)
            .normalize();
        assert!(n.dot(expect) > 0.99999, "{n} vs {expect}");
    }

    /// The tip chamfer in closed form: beside the cone (well outside the crest, where the thread's own
    /// field is farther) the distance is the meridian line's, the gradient its normal (1, 1) / sqrt 2;
    /// above the top face inside the tip radius the face wins; a turn below the chamfer nothing changes.
    #[test]
    fn tip_chamfer_distances_in_closed_form() {
        let plain = m16();
        let t = ThreadSdf { tip_radius: plain.min_radius, ..plain };
        // rho = crest + 0.5 mm, 0.2 mm below the top: the cone's surface point at that height has rho =
        // tip + 0.2 mm, so the distance to the 45-degree line is (rho - tip - 0.2 mm) / sqrt 2.
        for theta in [0.0f32, 1.0, 2.5, 4.0] {
            let (rho, z) = (t.max_radius + 5e-4, t.z_hi - 2e-4);
            let p = Vec3::new(rho * theta.cos(), rho * theta.sin(), z);
            let (d, g) = t.sample(p);
            let expect = (rho - t.tip_radius - 2e-4) * INV_SQRT2;
            assert!((d - expect).abs() < 1e-7, "theta {theta}: {d} vs {expect}");
            let n = Vec3::new(theta.cos(), theta.sin(), 1.0).normalize();
            assert!(g.normalize().dot(n) > 0.99999, "theta {theta}: {g}");
            assert!(d > plain.sample(p).0 + 1e-4, "the chamfer removes material there");
        }
        // Above the top face, inside the tip radius: the face.
        let (d, g) = t.sample(Vec3::new(0.5 * t.tip_radius, 0.0, t.z_hi + 1e-4));
        assert!((d - 1e-4).abs() < 1e-7 && g == Vec3::Z, "{d} {g}");
        // Below the chamfer (it is max_radius - tip_radius = 1.2 mm deep): unchanged, bitwise.
        for z in [t.z_hi - 2.0 * t.pitch, t.z_hi - 1.6e-3] {
            let p = Vec3::new(t.pitch_radius, 0.0, z);
            assert_eq!(t.sample(p), plain.sample(p), "z {z}");
        }
    }

    #[test]
    fn helix_is_right_handed_and_periodic() {
        let t = m16();
        let p = Vec3::new(0.0075, 0.0, 0.027);
        // Turning by theta and rising by P theta / 2 pi gives the same value.
        for theta in [0.3f32, 1.7, 4.0] {
            let q =
                Vec3::new(0.0075 * theta.cos(), 0.0075 * theta.sin(), 0.027 + 0.002 * theta / std::f32::consts::TAU);
            assert!((t.sample(q).0 - t.sample(p).0).abs() < 2e-7, "theta {theta}");
        }
    }

    /// The folded hexagon against a brute force over its six edges (distance to the nearest edge segment,
    /// negative inside), on seeded points in and around the head: values within 1e-7 m, unit gradients that
    /// match central differences.
    #[test]
    fn hex_prism_matches_the_distance_to_its_six_edges() {
        let h = HexPrism { apothem: 0.012, z0: 0.0, z1: 0.01 };
        let corners: Vec<Vec2> = (0..6)
            .map(|i| {
                let t = (30.0 + 60.0 * i as f32).to_radians();
                Vec2::new(t.cos(), t.sin()) * (2.0 * h.apothem / SQRT3)
            })
            .collect();
        let brute2 = |q: Vec2| {
            let d = (0..6)
                .map(|i| (q - seg_closest(q, corners[i], corners[(i + 1) % 6]).0).length())
                .fold(f32::MAX, f32::min);
            let inside = (0..6).all(|i| {
                let n = Vec2::new((60.0 * i as f32).to_radians().cos(), (60.0 * i as f32).to_radians().sin());
                q.dot(n) <= h.apothem
            });
            if inside {
                -d
            } else {
                d
            }
        };
        let mut rng = crate::rng::SplitMix64(0x9E3779B97F4A7C15);
        let mut rnd = move || rng.unit();
        for _ in 0..2000 {
            let p = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.25) * 0.04;
            let (d, g) = hex_prism(h, p);
            let d2 = brute2(Vec2::new(p.x, p.y));
            let dz = (p.z - 0.005).abs() - 0.005;
            let expect = if d2 > 0.0 && dz > 0.0 { (d2 * d2 + dz * dz).sqrt() } else { d2.max(dz) };
            assert!((d - expect).abs() < 1e-7, "{p}: {d} vs {expect}");
            assert!((g.length() - 1.0).abs() < 1e-5, "{p}: {g}");
            let e = 1e-5;
            let fd = Vec3::new(
                hex_prism(h, p + Vec3::X * e).0 - hex_prism(h, p - Vec3::X * e).0,
                hex_prism(h, p + Vec3::Y * e).0 - hex_prism(h, p - Vec3::Y * e).0,
                hex_prism(h, p + Vec3::Z * e).0 - hex_prism(h, p - Vec3::Z * e).0,
            ) / (2.0 * e);
            // Away from the medial axis the field is smooth and its gradient is the difference quotient's.
            if fd.length() > 0.999 && fd.length() < 1.001 {
                assert!(fd.normalize().dot(g) > 0.999, "{p}: {g} vs {fd}");
            }
        }
    }

    #[test]
    fn head_and_clip() {
        let t = m16();
        // Beside the head's flat and above its top face.
        let (d, g) = t.sample(Vec3::new(0.013, 0.0, 0.008));
        assert!((d - 0.001).abs() < 1e-7 && g.x > 0.99);
        let (d, g) = t.sample(Vec3::new(0.011, 0.0, 0.0165));
        assert!((d - 0.0005).abs() < 1e-7 && g.z > 0.99, "{d} {g}");
        // Above the tip.
        let (d, g) = t.sample(Vec3::new(0.0, 0.0, 0.042));
        assert!((d - 0.001).abs() < 1e-6 && g.z > 0.99, "{d} {g}");
        // Head corner direction is +y at 2a/sqrt(3).
        assert!(t.sample(Vec3::new(0.0, 0.0138, 0.008)).0 < 0.0 && t.sample(Vec3::new(0.0, 0.0140, 0.008)).0 > 0.0);
    }
}
