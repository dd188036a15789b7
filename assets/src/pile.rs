//! Bowls and toruses for the paper's pile scenes (section III-D: 1024 bowls, "akin to [105]", and 1024
//! toruses falling into a pile in one environment; Table VI), each a solid of revolution with an exact
//! analytic SDF ([`RevolvedSdf`]) and a mesh that revolves the same polygon profile.
//!
//! The paper gives no dimensions, only Table VI's SDF grids and mesh sizes; the proportions come from the
//! grids, the absolute sizes are chosen as tabletop objects:
//! - **Torus**: grid 304 x 104 x 304. Less a band of a few voxels at each side (this engine bakes 4, see
//!   `factory_engine::sdf::bake`), 300 x 100 samples: outer diameter / thickness = 2 (R + r) / 2 r = 3, so
//!   R = 2 r. A ring of a hand's palm size: tube radius r = 8 mm, ring radius R = 16 mm (outer diameter
//!   48 mm, 16 mm thick). Table VI's mesh has 1024 vertices; 16 sides x 64 segments here are 1024 too.
//! - **Bowl**: grid 257 x 75 x 257: rim diameter / height between 257 / 75 = 3.4 and (257 - 8) / (75 - 8)
//!   = 3.7 depending on the band; 100 mm / 28 mm = 3.6, a small (dessert, ~10 cm) bowl, with a 40 mm flat
//!   foot and a 3 mm wall. Table VI's mesh has 582 vertices / 1160 triangles; the 16-vertex profile at 40
//!   segments gives 562 / 1120.
//! - **Density**: ABS plastic, 1050 kg/m^3 (general-purpose ABS 1.04-1.06 g/cm^3; SpecialChem Omnexus
//!   polymer density table lists ABS grades from 1.02 to 1.21 g/cm^3), a common moulded-plastic material
//!   for toy rings and picnic bowls. Both defaults are options.
//!
//! Frames: z is the axis of revolution. The bowl stands on z = 0 (its foot) with the rim at z = height; the
//! torus's mid-plane is z = 0. Both are centred on the axis.
//!
//! Meshes: the profile revolved with `segments` angular columns at theta_k = 2 pi k / N, so every mesh
//! vertex lies on the field's zero set (to f32 rounding) and facet centres lie off it by at most the
//! chord's sagitta rho (1 - cos(pi / N)): inside where the surface is convex around the axis, outside where
//! it faces the axis (the torus's hole, the bowl's inner wall). Each quad between two columns is planar (an isosceles trapezoid),
//! so the faceted solid is exact: its volume is N sin(2 pi / N) times the profile's first moment
//! integral of rho over the profile (Pappus' 2 pi rho_c A as N grows).

use crate::error::{AssetError, Result};
use crate::part::Part;
use factory_engine::mesh::TriMesh;
use factory_engine::sdf::revolved::{RevolvedSdf, REVOLVED_MAX_VERTICES};
use glam::{DVec2, Vec2, Vec3};

/// Default density of pile parts [kg/m^3]: ABS plastic (see the module documentation).
pub const ABS_DENSITY: f32 = 1050.0;
/// `<sdf resolution>` of a bowl: with this engine's 4-voxel band at each side, the baked grid is 257
/// samples across, Table VI's longest axis.
pub const BOWL_SDF_RESOLUTION: u32 = 249;
/// `<sdf resolution>` of a torus: baked grid 304 samples across, Table VI's longest axis.
pub const TORUS_SDF_RESOLUTION: u32 = 296;

/// A solid of revolution: its mesh part and the exact field of the same profile.
#[derive(Clone, Debug)]
pub struct RevolvedPart {
    /// The mesh (the profile revolved with `segments` columns), density and mass properties.
    pub part: Part,
    /// The exact signed distance field of the profile, for the engine's `ShapeGeometry::Revolved`.
    pub sdf: RevolvedSdf,
}

/// Torus options. The meridian section is the regular `tube_sides`-gon inscribed in the circle of radius
/// `tube_radius` about (rho = `ring_radius`, z = 0), with vertices at the outermost, top, innermost and
/// bottom points, so the bounding box is exactly 2 (R + r) x 2 (R + r) x 2 r.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TorusOptions {
    /// R: distance from the axis to the tube's centre [m]. Default 16 mm.
    pub ring_radius: f64,
    /// r: the tube's radius [m], less than `ring_radius`. Default 8 mm.
    pub tube_radius: f64,
    /// Sides of the tube's section polygon, a multiple of 4 from 4 to 16 (the field's vertex limit).
    /// Default 16.
    pub tube_sides: usize,
    /// Angular segments around the axis, 8 to 4096. Default 64 (1024 vertices, 2048 triangles).
    pub segments: usize,
    /// Density [kg/m^3]. Default [`ABS_DENSITY`].
    pub density: f32,
}

impl Default for TorusOptions {
    fn default() -> Self {
        TorusOptions { ring_radius: 0.016, tube_radius: 0.008, tube_sides: 16, segments: 64, density: ABS_DENSITY }
    }
}

/// Bowl options: a shell of uniform `thickness`. Outside, a flat foot of `base_radius`, then a circular
/// arc (tangent to the foot) up to the rim at (`rim_radius`, `height`); inside, the same arc's concentric
/// offset by `thickness` and a flat bottom at z = `thickness`; the rim is flat at z = `height`. Each arc
/// is `wall_facets` chords at the same angles, so inner and outer chords are parallel, `thickness` x
/// cos(half the chord angle) apart (the smooth shell's thickness is exactly `thickness`); the inner arc's
/// last chord is cut short by the rim plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BowlOptions {
    /// Outer radius at the rim [m]. Default 50 mm (a 100 mm bowl).
    pub rim_radius: f64,
    /// Height from the foot to the rim [m], at most `rim_radius - base_radius` (so the wall does not
    /// curl inwards). Default 28 mm.
    pub height: f64,
    /// Radius of the flat foot [m], more than 0 and at most `rim_radius - height`. Default 20 mm.
    pub base_radius: f64,
    /// Wall thickness [m], more than 0 and at most `height / 3`. Default 3 mm.
    pub thickness: f64,
    /// Chords per curved wall (outside and inside), 1 to 6 (the profile then has 2 wall_facets + 4 <= 16
    /// vertices). Default 6.
    pub wall_facets: usize,
    /// Angular segments around the axis, 8 to 4096. Default 40 (562 vertices, 1120 triangles).
    pub segments: usize,
    /// Density [kg/m^3]. Default [`ABS_DENSITY`].
    pub density: f32,
}

impl Default for BowlOptions {
    fn default() -> Self {
        BowlOptions {
            rim_radius: 0.05,
            height: 0.028,
            base_radius: 0.02,
            thickness: 0.003,
            wall_facets: 6,
            segments: 40,
            density: ABS_DENSITY,
        }
    }
}

fn invalid(name: &'static str, value: impl std::fmt::Display, expected: String) -> AssetError {
    AssetError::InvalidOption { name, value: value.to_string(), expected }
}

/// Checks `lo < x <= hi` for a finite length `x`, naming the option and what it accepts.
fn check_length(name: &'static str, x: f64, lo: f64, hi: f64, expected: &str) -> Result<()> {
    if x.is_finite() && x > lo && x <= hi {
        Ok(())
    } else {
        Err(invalid(name, format!("{x} m"), expected.to_string()))
    }
}

fn check_common(segments: usize, density: f32) -> Result<()> {
    if !(8..=4096).contains(&segments) {
        return Err(invalid("segments", segments, "8 to 4096".into()));
    }
    if !(density.is_finite() && density > 0.0) {
        return Err(invalid("density", format!("{density} kg/m^3"), "finite and more than 0".into()));
    }
    Ok(())
}

/// A length [m] for a message, without f64 noise: 0.022, not 0.022000000000000002.
fn metres(x: f64) -> String {
    format!("{} m", (x * 1e9).round() / 1e9)
}

/// `x` [m] in mm for a part name: "48", "100.5".
fn mm(x: f64) -> String {
    let v = (x * 1e4).round() / 10.0;
    if v.fract() == 0.0 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

/// The profile revolved about z with `n` columns: a vertex on the axis is one pole vertex, every other
/// vertex a ring of `n`. `ring`: the closing edge last -> first is part of the surface. Counter-clockwise
/// profiles give outward-wound triangles.
fn revolve(profile: &[Vec2], ring: bool, n: usize) -> TriMesh {
    let mut positions = Vec::new();
    let ids: Vec<Vec<u32>> = profile
        .iter()
        .map(|v| {
            let (rho, z) = (v.x as f64, v.y as f64);
            if rho == 0.0 {
                positions.push(Vec3::new(0.0, 0.0, v.y));
                vec![positions.len() as u32 - 1; n]
            } else {
                (0..n)
                    .map(|k| {
                        let (s, c) = (std::f64::consts::TAU * k as f64 / n as f64).sin_cos();
                        positions.push(Vec3::new((rho * c) as f32, (rho * s) as f32, z as f32));
                        positions.len() as u32 - 1
                    })
                    .collect()
            }
        })
        .collect();
    let m = profile.len();
    let edges = if ring { m } else { m - 1 };
    let mut triangles = Vec::new();
    for i in 0..edges {
        let (a, b) = (&ids[i], &ids[(i + 1) % m]);
        for k in 0..n {
            let k1 = (k + 1) % n;
            // (a_k, a_k+1, b_k) winds counter-clockwise seen from outside: e_theta x t = the profile's
            // outward normal (on the right of its direction t in (rho, z)).
            if a[k] != a[k1] {
                triangles.push([a[k], a[k1], b[k]]);
            }
            if b[k] != b[k1] {
                triangles.push([a[k1], b[k1], b[k]]);
            }
        }
    }
    TriMesh::new(positions, triangles)
}

fn finish(name: String, profile: Vec<DVec2>, segments: usize, density: f32, resolution: u32) -> Result<RevolvedPart> {
    let profile: Vec<Vec2> = profile.iter().map(|v| v.as_vec2()).collect();
    let sdf = RevolvedSdf::new(profile).map_err(|e| AssetError::Profile(format!("{name}: {e}")))?;
    let mesh = revolve(&sdf.profile, sdf.is_ring(), segments);
    Ok(RevolvedPart { part: Part::new(name, mesh, density, resolution), sdf })
}

/// A torus (see [`TorusOptions`]), named `torus_<outer diameter>mm` (default `torus_48mm`: 1024 vertices,
/// 2048 triangles, 19.67 cm^3, 20.6 g of ABS; Izz 6.24e-6, Ixx = Iyy 3.44e-6 kg m^2).
pub fn torus(opts: &TorusOptions) -> Result<RevolvedPart> {
    let (big_r, r) = (opts.ring_radius, opts.tube_radius);
    check_length("ring radius", big_r, 0.0, 1.0, "more than 0 and at most 1 m")?;
    check_length(
        "tube radius",
        r,
        0.0,
        0.95 * big_r,
        &format!("more than 0 and at most 0.95 x ring radius ({})", metres(0.95 * big_r)),
    )?;
    let n = opts.tube_sides;
    if !(4..=REVOLVED_MAX_VERTICES).contains(&n) || !n.is_multiple_of(4) {
        return Err(invalid("tube sides", n, format!("a multiple of 4 from 4 to {REVOLVED_MAX_VERTICES}")));
    }
    check_common(opts.segments, opts.density)?;
    let profile = (0..n)
        .map(|k| {
            // Exact quarter turns (k = 0, n/4, n/2, 3n/4) keep the box exact.
            let (s, c) = match (4 * k / n, (4 * k) % n) {
                (q, 0) => [(0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0)][q],
                _ => (std::f64::consts::TAU * k as f64 / n as f64).sin_cos(),
            };
            DVec2::new(big_r + r * c, r * s)
        })
        .collect();
    finish(format!("torus_{}mm", mm(2.0 * (big_r + r))), profile, opts.segments, opts.density, TORUS_SDF_RESOLUTION)
}

/// The bowl's profile (see [`BowlOptions`]), counter-clockwise from the outer bottom on the axis: foot,
/// outer wall up to the rim, across the rim, inner wall down, inner bottom back to the axis.
fn bowl_profile(o: &BowlOptions) -> Vec<DVec2> {
    let (ro, h, b, t) = (o.rim_radius, o.height, o.base_radius, o.thickness);
    // The outer arc: centre (b, rw) above the foot's edge, through the rim (ro, h).
    let rw = ((ro - b) * (ro - b) + h * h) / (2.0 * h);
    let centre = DVec2::new(b, rw);
    let start = -std::f64::consts::FRAC_PI_2;
    let end = (h - rw).atan2(ro - b);
    let f = o.wall_facets;
    let dir = |j: usize| {
        let a = start + (end - start) * j as f64 / f as f64;
        DVec2::new(a.cos(), a.sin())
    };
    let mut p = vec![DVec2::ZERO, DVec2::new(b, 0.0)];
    p.extend((1..f).map(|j| centre + dir(j) * rw));
    p.push(DVec2::new(ro, h));
    // The inner arc at the same angles (chords parallel to the outer ones), its bottom point exactly
    // (b, t) so the inner bottom is flat; cut by the rim plane z = h: points above it are dropped and the
    // chord that crosses it ends there (the rim is flat, the wall's chords stay parallel).
    let mut inner: Vec<DVec2> = (0..=f).map(|j| centre + dir(j) * (rw - t)).collect();
    inner[0] = DVec2::new(b, t);
    let below = inner.iter().rposition(|q| q.y < h).expect("the inner bottom z = t < h");
    if below + 1 < inner.len() {
        let (q0, q1) = (inner[below], inner[below + 1]);
        inner.truncate(below + 1);
        inner.push(q0 + (q1 - q0) * ((h - q0.y) / (q1.y - q0.y)));
    }
    p.extend(inner.iter().rev());
    p.push(DVec2::new(0.0, t));
    p
}

/// A bowl (see [`BowlOptions`]), named `bowl_<rim diameter>mm` (default `bowl_100mm`: 562 vertices,
/// 1120 triangles, 33.66 cm^3, 35.3 g of ABS, centre of mass 11.6 mm up; Izz 5.19e-5, Ixx = Iyy
/// 2.84e-5 kg m^2).
pub fn bowl(opts: &BowlOptions) -> Result<RevolvedPart> {
    let o = opts;
    check_length("rim radius", o.rim_radius, 0.0, 1.0, "more than 0 and at most 1 m")?;
    check_length(
        "height",
        o.height,
        0.0,
        o.rim_radius,
        &format!("more than 0 and at most the rim radius ({})", metres(o.rim_radius)),
    )?;
    let max_base = o.rim_radius - o.height;
    check_length(
        "base radius",
        o.base_radius,
        0.0,
        max_base,
        &format!(
            "more than 0 and at most rim radius - height ({}), so the wall does not curl inwards",
            metres(max_base)
        ),
    )?;
    check_length(
        "thickness",
        o.thickness,
        0.0,
        o.height / 3.0,
        &format!("more than 0 and at most height / 3 ({})", metres(o.height / 3.0)),
    )?;
    let max_facets = (REVOLVED_MAX_VERTICES - 4) / 2;
    if !(1..=max_facets).contains(&o.wall_facets) {
        return Err(invalid(
            "wall facets",
            o.wall_facets,
            format!("1 to {max_facets} (the profile has 2 x wall facets + 4 <= {REVOLVED_MAX_VERTICES} vertices)"),
        ));
    }
    check_common(o.segments, o.density)?;
    finish(format!("bowl_{}mm", mm(2.0 * o.rim_radius)), bowl_profile(o), o.segments, o.density, BOWL_SDF_RESOLUTION)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_in_mm() {
        assert_eq!(mm(0.048), "48");
        assert_eq!(mm(0.1005), "100.5");
    }

    #[test]
    fn the_default_bowl_profile_has_16_vertices_and_a_flat_inner_bottom() {
        let p = bowl_profile(&BowlOptions::default());
        assert_eq!(p.len(), 16);
        assert_eq!(p[0], DVec2::ZERO);
        assert_eq!(p[15], DVec2::new(0.0, 0.003));
        assert_eq!(p[14], DVec2::new(0.02, 0.003));
        assert_eq!(p[7], DVec2::new(0.05, 0.028));
        // The rim is flat at the height: as wide as the last chords' separation t cos(step / 2) seen along
        // their normal, at angle (end - step / 2) below the horizontal.
        assert_eq!(p[8].y, 0.028);
        let rw = (0.03f64 * 0.03 + 0.028 * 0.028) / (2.0 * 0.028);
        let end = (0.028 - rw).atan2(0.03);
        let step = (end + std::f64::consts::FRAC_PI_2) / 6.0;
        let want = 0.003 * (0.5 * step).cos() / (end - 0.5 * step).cos();
        assert!((p[7].x - p[8].x - want).abs() < 1e-12, "{} vs {want}", p[7].x - p[8].x);
    }
}
