//! Pair roles: which shape of a pair provides the signed distance and which one is queried, built into a
//! ready-to-use [`PairSpec`] from two shape descriptions ([`pair_spec`]).
//!
//! # Rules
//! Factory (Narang et al., RSS 2022, section III-A) collides shapes through PhysX's SDF collisions, whose
//! pair rules docs/ARCHITECTURE.md section 5 restates: *both shapes tagged with an SDF -> SDF-mesh (the shape with more
//! triangles is the SDF, the other one's triangles are queried); one tagged -> convex-vs-mesh (the untagged
//! shape's convex hull is queried against the tagged one's SDF); none tagged -> convex-convex; primitives
//! collide analytically*. Here "tagged" means a mesh carrying Factory's `<sdf resolution="N"/>` URDF tag
//! ([`ShapeGeometry::Mesh`] with `sdf_resolution: Some(N)`). Shape `a` of the resulting [`PairSpec`] is always
//! the queried one and `b` the SDF one; ties go to the first argument as the SDF, as in [`pair_role`].
//!
//! | first / second shape | SDF (`b`) | query (`a`) |
//! |---|---|---|
//! | tagged mesh / tagged mesh | the mesh with more triangles, baked at its own resolution | the other mesh's triangles |
//! | tagged mesh / untagged mesh | the tagged mesh at its resolution | the untagged mesh's convex hull |
//! | tagged mesh / box, sphere, capsule | the tagged mesh at its resolution | the primitive ([`QueryShape::cuboid`], [`QueryShape::sphere`], [`QueryShape::capsule`]) |
//! | exact solid of revolution ([`ShapeGeometry::Revolved`]) / any mesh or primitive | the exact field ([`SdfShape::Revolved`]; both exact: more triangles) | as against a tagged mesh |
//! | anything / plane | [`SdfShape::Plane`] (exact) | a primitive as above; a tagged mesh's triangles; an untagged mesh's hull |
//! | untagged mesh / untagged mesh (convex-convex) | the hull with more triangles, baked at [`CONVEX_SDF_RESOLUTION`] | the other hull |
//! | untagged mesh / box, sphere, capsule | the mesh's hull at [`CONVEX_SDF_RESOLUTION`] | the primitive |
//! | primitive / primitive | box before capsule before sphere (see below) at [`CONVEX_SDF_RESOLUTION`] | the other primitive |
//! | plane / plane | refused with [`EngineError::Config`] | |
//!
//! The pipeline has no analytic convex-convex or primitive-primitive narrow phase yet, so those pairs are
//! run through the same SDF machinery: one convex shape is baked into a grid and the other is queried.
//! Primitives are kept as queries whenever possible because a sphere or capsule query is exact (a point or
//! segment with a radius), whereas its SDF would be a sampled approximation. Between two primitives, the
//! SDF is the box if there is one (baked from [`crate::mesh::box_mesh`] through the cache; the grid holds
//! exact box distances), else the capsule, else the (first) sphere; spheres and capsules are not
//! tessellated: their exact analytic distance is sampled on a grid laid out as the baker would lay out
//! their bounding box (no cache, sampling is cheap). Accuracy of those grids: trilinear interpolation of a
//! 1-Lipschitz field errs by at most sqrt(3)/2 voxel, and is exact where the field is linear over a cell
//! (e.g. facing a box face, away from its edges).
//!
//! Convex hulls are computed with parry3d's quickhull ([`parry3d::transformation::try_convex_hull`]).
//! Grids are baked through the given [`SdfCache`] with [`SdfCache::get_or_bake_shared`], so pairs whose
//! SDF shape is the same mesh at the same resolution share one grid (uploaded once). Every call builds a
//! fresh `Arc` for its query shape, so a mesh queried by two pairs is uploaded twice (clone the `Arc` of an
//! existing [`PairSpec`] to share it).

use super::{pair_role, PairRole, PairSpec, QueryShape, SdfShape, NO_BODY};
use crate::error::{EngineError, Result};
use crate::mesh::{box_mesh, TriMesh};
use crate::sdf::bake::{layout, BakeParams};
use crate::sdf::cache::SdfCache;
use crate::sdf::SdfGrid;
use glam::{Quat, Vec3};
use std::sync::Arc;

/// Resolution (samples along the longest axis) of the SDFs baked for untagged shapes: convex hulls and
/// primitives in convex-convex and primitive pairs. Coarse on purpose: a convex shape's field is smooth
/// (exactly linear facing its faces), and a 5 cm part gets a 0.8 mm voxel.
pub const CONVEX_SDF_RESOLUTION: u32 = 64;

/// The geometry of a collision shape, in the shape's own frame.
#[derive(Clone, Debug)]
pub enum ShapeGeometry {
    /// A triangle mesh [m]. `sdf_resolution: Some(n)` means the shape carries Factory's
    /// `<sdf resolution="n"/>` tag (an SDF with n samples along its longest axis); `None`, untagged (it
    /// collides through its convex hull).
    Mesh { mesh: Arc<TriMesh>, sdf_resolution: Option<u32> },
    /// A solid of revolution known exactly: its mesh [m] (queried, and for mass properties) and the
    /// analytic field of its profile (used wherever the shape is the SDF; no bake). It counts as a tagged
    /// mesh that wins the SDF role against any mesh without an exact field (an exact field beats a grid).
    Revolved { mesh: Arc<TriMesh>, sdf: crate::sdf::revolved::RevolvedSdf },
    /// The half-space z <= 0 (a table or the ground; normal +z).
    Plane,
    /// A box centred at the origin, half extents [m].
    Box { half_extents: Vec3 },
    /// A box that, where it is the queried shape, is queried at a grid of `points_per_edge` x
    /// `points_per_edge` points on each face besides its corners and face triangles (as Factory subdivides
    /// its finger meshes, PhysX making one contact per triangle): a finger pad wider than the flat it
    /// presses on then touches it at several points, not at a face triangle's single deepest point. As
    /// an SDF it is the plain box.
    GridBox { half_extents: Vec3, points_per_edge: u32 },
    /// A sphere centred at the origin, radius [m].
    Sphere { radius: f32 },
    /// A capsule along z centred at the origin: segment from -half_length to +half_length [m], radius [m].
    Capsule { radius: f32, half_length: f32 },
}

/// A collision shape: the body carrying it, where it sits on the body, and its geometry.
#[derive(Clone, Debug)]
pub struct ShapeDesc {
    /// Body index within a world, or [`NO_BODY`] for a shape fixed in the world frame.
    pub body: u32,
    /// Shape frame in the body frame (or in the world frame for [`NO_BODY`]): position [m], rotation.
    pub pose: (Vec3, Quat),
    pub geometry: ShapeGeometry,
}

impl ShapeDesc {
    /// A shape at the origin of `body`.
    pub fn new(body: u32, geometry: ShapeGeometry) -> Self {
        ShapeDesc { body, pose: (Vec3::ZERO, Quat::IDENTITY), geometry }
    }

    /// A shape fixed in the world frame at `pose`.
    pub fn fixed(pose: (Vec3, Quat), geometry: ShapeGeometry) -> Self {
        ShapeDesc { body: NO_BODY, pose, geometry }
    }
}

/// How a shape takes part in the rules.
#[derive(Clone, Copy)]
enum Kind<'a> {
    Plane,
    Primitive,
    Tagged(&'a Arc<TriMesh>, u32),
    Untagged(&'a Arc<TriMesh>),
    Exact(&'a Arc<TriMesh>, &'a crate::sdf::revolved::RevolvedSdf),
}

fn bad(field: &'static str, value: String, expected: &str) -> EngineError {
    EngineError::Config { field, value, expected: expected.into() }
}

fn check_shape<'a>(s: &'a ShapeDesc, which: &str) -> Result<Kind<'a>> {
    let positive = |v: f32| v.is_finite() && v > 0.0;
    if !(s.pose.0.is_finite() && s.pose.1.is_finite() && s.pose.1.length() > 0.5) {
        return Err(bad("pose", format!("{:?} ({which} shape)", s.pose), "a finite position and a unit quaternion"));
    }
    Ok(match &s.geometry {
        ShapeGeometry::Plane => Kind::Plane,
        ShapeGeometry::Box { half_extents: h } | ShapeGeometry::GridBox { half_extents: h, .. } => {
            if !(positive(h.x) && positive(h.y) && positive(h.z)) {
                return Err(bad("half_extents", format!("{h} ({which} shape)"), "finite and > 0 [m] on every axis"));
            }
            if let ShapeGeometry::GridBox { points_per_edge: n, .. } = s.geometry {
                if !(2..=16).contains(&n) {
                    return Err(bad("points_per_edge", format!("{n} ({which} shape)"), "2 to 16"));
                }
            }
            Kind::Primitive
        }
        ShapeGeometry::Sphere { radius } => {
            if !positive(*radius) {
                return Err(bad("radius", format!("{radius} ({which} shape)"), "finite and > 0 [m]"));
            }
            Kind::Primitive
        }
        ShapeGeometry::Capsule { radius, half_length } => {
            if !positive(*radius) {
                return Err(bad("radius", format!("{radius} ({which} shape)"), "finite and > 0 [m]"));
            }
            if !(half_length.is_finite() && *half_length >= 0.0) {
                return Err(bad("half_length", format!("{half_length} ({which} shape)"), "finite and >= 0 [m]"));
            }
            Kind::Primitive
        }
        ShapeGeometry::Mesh { mesh, .. } | ShapeGeometry::Revolved { mesh, .. }
            if mesh.triangle_count() == 0 || mesh.positions.iter().any(|p| !p.is_finite()) =>
        {
            return Err(bad(
                "mesh",
                format!("{} triangles ({which} shape)", mesh.triangle_count()),
                "at least one triangle and finite vertices",
            ));
        }
        ShapeGeometry::Mesh { mesh, sdf_resolution } => match sdf_resolution {
            Some(r) => Kind::Tagged(mesh, *r),
            None => Kind::Untagged(mesh),
        },
        ShapeGeometry::Revolved { mesh, sdf } => Kind::Exact(mesh, sdf),
    })
}

/// The convex hull of a mesh's vertices (outward-wound triangles). `for_sdf`: it will be baked, so it
/// must enclose a volume.
pub fn convex_hull(mesh: &TriMesh, for_sdf: bool) -> Result<TriMesh> {
    let (positions, triangles) = parry3d::transformation::try_convex_hull(&mesh.positions).map_err(|e| {
        bad("mesh", format!("{} vertices", mesh.positions.len()), &format!("a mesh with a convex hull ({e:?})"))
    })?;
    let hull = TriMesh::new(positions, triangles);
    if for_sdf {
        require_volume(&hull, mesh)?;
    }
    Ok(hull)
}

/// Refuses to bake the hull of a flat mesh.
fn require_volume(hull: &TriMesh, mesh: &TriMesh) -> Result<()> {
    if hull.signed_volume() > 0.0 {
        return Ok(());
    }
    Err(bad(
        "mesh",
        format!("a flat mesh of {} vertices", mesh.positions.len()),
        "an untagged mesh whose convex hull has a volume (its hull is baked into an SDF)",
    ))
}

/// Query triangles of a box, sphere or capsule.
fn primitive_query(g: &ShapeGeometry) -> QueryShape {
    match *g {
        ShapeGeometry::Box { half_extents } => QueryShape::cuboid(half_extents),
        ShapeGeometry::GridBox { half_extents, points_per_edge } => {
            QueryShape::cuboid_grid(half_extents, points_per_edge)
        }
        ShapeGeometry::Sphere { radius } => QueryShape::sphere(radius),
        ShapeGeometry::Capsule { radius, half_length } => QueryShape::capsule(radius, half_length),
        _ => unreachable!("only primitives"),
    }
}

/// Preference of a primitive as the SDF of a primitive pair (higher first): its query would be the least
/// exact (a box queries 12 triangles and 8 corners; a capsule a segment; a sphere a point).
fn sdf_preference(g: &ShapeGeometry) -> u8 {
    match g {
        ShapeGeometry::Box { .. } | ShapeGeometry::GridBox { .. } => 2,
        ShapeGeometry::Capsule { .. } => 1,
        _ => 0,
    }
}

fn bake_mesh(mesh: &TriMesh, resolution: u32, cache: &SdfCache) -> Result<SdfShape> {
    Ok(SdfShape::Grid(cache.get_or_bake_shared(mesh, &BakeParams { resolution, ..Default::default() })?))
}

/// An exact analytic distance sampled on the grid the baker would use for a box of half extents `aabb`.
fn sampled(aabb: Vec3, resolution: u32, distance: impl Fn(Vec3) -> f32) -> Result<SdfGrid> {
    let l = layout(&box_mesh(aabb), &BakeParams { resolution, ..Default::default() })?;
    let mut grid = SdfGrid { origin: l.origin, spacing: l.spacing, dims: l.dims, values: Vec::new() };
    grid.values.reserve(l.sample_count() as usize);
    for k in 0..l.dims.z {
        for j in 0..l.dims.y {
            for i in 0..l.dims.x {
                grid.values.push(distance(grid.point(i, j, k)));
            }
        }
    }
    Ok(grid)
}

/// The SDF grid of a primitive at [`CONVEX_SDF_RESOLUTION`].
fn primitive_sdf(g: &ShapeGeometry, cache: &SdfCache) -> Result<SdfShape> {
    let grid = match *g {
        ShapeGeometry::Box { half_extents } | ShapeGeometry::GridBox { half_extents, .. } => {
            return bake_mesh(&box_mesh(half_extents), CONVEX_SDF_RESOLUTION, cache)
        }
        ShapeGeometry::Sphere { radius } => {
            sampled(Vec3::splat(radius), CONVEX_SDF_RESOLUTION, |p| p.length() - radius)?
        }
        ShapeGeometry::Capsule { radius, half_length } => {
            sampled(Vec3::new(radius, radius, half_length + radius), CONVEX_SDF_RESOLUTION, |p| {
                (p - Vec3::new(0.0, 0.0, p.z.clamp(-half_length, half_length))).length() - radius
            })?
        }
        _ => unreachable!("only primitives"),
    };
    Ok(SdfShape::Grid(Arc::new(grid)))
}

/// Builds the [`PairSpec`] of two shapes following Factory's pair rules (see the module documentation):
/// the queried shape becomes `a` and the SDF shape `b`. Bakes (or loads from `cache`) the SDF it needs.
/// `contact_offset` [m]: candidates farther apart are ignored.
///
/// Errors ([`EngineError::Config`]): two planes, a negative or non-finite offset, non-positive sizes, an
/// empty mesh, an untagged mesh without a solid hull where its hull must be baked; bake errors from the
/// cache (a resolution out of range, a grid over the memory limit).
/// The pair's friction starts at 0; set `PairSpec::friction` on the result.
pub fn pair_spec(a: &ShapeDesc, b: &ShapeDesc, contact_offset: f32, cache: &SdfCache) -> Result<PairSpec> {
    if !(contact_offset.is_finite() && contact_offset >= 0.0) {
        return Err(bad("contact_offset", contact_offset.to_string(), "a finite distance >= 0 [m]"));
    }
    let shapes = [a, b];
    let kinds = [check_shape(a, "first")?, check_shape(b, "second")?];
    // (index of the SDF shape, its SDF, the other's query)
    let (sdf, field, query): (usize, SdfShape, QueryShape) = match kinds {
        [Kind::Plane, Kind::Plane] => {
            return Err(bad(
                "shapes",
                "plane and plane".into(),
                "at most one plane per pair (two planes never collide)",
            ))
        }
        [_, Kind::Plane] | [Kind::Plane, _] => {
            let sdf = if matches!(kinds[1], Kind::Plane) { 1 } else { 0 };
            let query = match kinds[1 - sdf] {
                Kind::Primitive => primitive_query(&shapes[1 - sdf].geometry),
                Kind::Tagged(mesh, _) | Kind::Exact(mesh, _) => QueryShape::mesh(mesh),
                Kind::Untagged(mesh) => QueryShape::mesh(&convex_hull(mesh, false)?),
                Kind::Plane => unreachable!(),
            };
            (sdf, SdfShape::Plane, query)
        }
        // An exact field is the SDF (both exact: Factory's triangle-count rule); the other shape is queried
        // as it would be against a tagged mesh.
        [Kind::Exact(m0, f0), Kind::Exact(m1, f1)] => {
            let PairRole::SdfMesh { sdf, query } = pair_role([true, true], [m0.triangle_count(), m1.triangle_count()])
            else {
                unreachable!("both tagged")
            };
            (sdf, SdfShape::Revolved([f0, f1][sdf].clone()), QueryShape::mesh([m0, m1][query]))
        }
        [Kind::Exact(_, f), other] | [other, Kind::Exact(_, f)] => {
            let sdf = if matches!(kinds[0], Kind::Exact(..)) { 0 } else { 1 };
            let query = match other {
                Kind::Primitive => primitive_query(&shapes[1 - sdf].geometry),
                Kind::Tagged(mesh, _) => QueryShape::mesh(mesh),
                Kind::Untagged(mesh) => QueryShape::mesh(&convex_hull(mesh, false)?),
                Kind::Plane | Kind::Exact(..) => unreachable!("handled above"),
            };
            (sdf, SdfShape::Revolved(f.clone()), query)
        }
        [Kind::Tagged(m0, r0), Kind::Tagged(m1, r1)] => {
            let PairRole::SdfMesh { sdf, query } = pair_role([true, true], [m0.triangle_count(), m1.triangle_count()])
            else {
                unreachable!("both tagged")
            };
            let (meshes, res) = ([m0, m1], [r0, r1]);
            (sdf, bake_mesh(meshes[sdf], res[sdf], cache)?, QueryShape::mesh(meshes[query]))
        }
        [Kind::Tagged(m0, r0), Kind::Untagged(m1)] | [Kind::Untagged(m1), Kind::Tagged(m0, r0)] => {
            let tagged = [matches!(kinds[0], Kind::Tagged(..)), matches!(kinds[1], Kind::Tagged(..))];
            let PairRole::ConvexMesh { sdf, hull: _ } = pair_role(tagged, [0, 0]) else { unreachable!("one tagged") };
            (sdf, bake_mesh(m0, r0, cache)?, QueryShape::mesh(&convex_hull(m1, false)?))
        }
        [Kind::Tagged(m, r), Kind::Primitive] | [Kind::Primitive, Kind::Tagged(m, r)] => {
            let sdf = if matches!(kinds[0], Kind::Tagged(..)) { 0 } else { 1 };
            (sdf, bake_mesh(m, r, cache)?, primitive_query(&shapes[1 - sdf].geometry))
        }
        [Kind::Untagged(m0), Kind::Untagged(m1)] => {
            let hulls = [convex_hull(m0, false)?, convex_hull(m1, false)?];
            let sdf = if hulls[1].triangle_count() > hulls[0].triangle_count() { 1 } else { 0 };
            require_volume(&hulls[sdf], [m0, m1][sdf])?;
            (sdf, bake_mesh(&hulls[sdf], CONVEX_SDF_RESOLUTION, cache)?, QueryShape::mesh(&hulls[1 - sdf]))
        }
        [Kind::Untagged(m), Kind::Primitive] | [Kind::Primitive, Kind::Untagged(m)] => {
            let sdf = if matches!(kinds[0], Kind::Untagged(..)) { 0 } else { 1 };
            let hull = convex_hull(m, true)?;
            (sdf, bake_mesh(&hull, CONVEX_SDF_RESOLUTION, cache)?, primitive_query(&shapes[1 - sdf].geometry))
        }
        [Kind::Primitive, Kind::Primitive] => {
            let sdf = if sdf_preference(&b.geometry) > sdf_preference(&a.geometry) { 1 } else { 0 };
            (sdf, primitive_sdf(&shapes[sdf].geometry, cache)?, primitive_query(&shapes[1 - sdf].geometry))
        }
    };
    let (qs, ss) = (shapes[1 - sdf], shapes[sdf]);
    Ok(PairSpec {
        body_a: qs.body,
        a_pose: qs.pose,
        query: Arc::new(query),
        body_b: ss.body,
        b_pose: ss.pose,
        sdf: field,
        contact_offset,
        friction: 0.0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf::bake::MIN_MARGIN_VOXELS;
    use std::path::PathBuf;

    /// A private cache directory per test (tests run in parallel).
    fn cache(name: &str) -> (SdfCache, PathBuf) {
        let dir = std::env::temp_dir().join(format!("factory-roles-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        (SdfCache::new(&dir), dir)
    }

    /// A convex polyhedron with many triangles: the hull of `n` Fibonacci points on a sphere of radius r.
    fn ball_mesh(r: f32, n: usize) -> TriMesh {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        let pts: Vec<Vec3> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let s = (1.0 - z * z).sqrt();
                let t = golden * i as f32;
                r * Vec3::new(s * t.cos(), s * t.sin(), z)
            })
            .collect();
        convex_hull(&TriMesh::new(pts, vec![[0, 1, 2]]), true).unwrap()
    }

    fn mesh(m: TriMesh, tag: Option<u32>) -> ShapeGeometry {
        ShapeGeometry::Mesh { mesh: Arc::new(m), sdf_resolution: tag }
    }

    fn grid(spec: &PairSpec) -> &SdfGrid {
        match &spec.sdf {
            SdfShape::Grid(g) => g,
            other => panic!("expected a grid, got {other:?}"),
        }
    }

    /// The grid is the bake (same layout) of `mesh` at `resolution`: identifies which shape was baked.
    fn assert_baked_from(spec: &PairSpec, mesh: &TriMesh, resolution: u32) {
        let g = grid(spec);
        let l = layout(mesh, &BakeParams { resolution, ..Default::default() }).unwrap();
        assert_eq!((g.dims, g.origin, g.spacing), (l.dims, l.origin, l.spacing));
    }

    fn bodies(spec: &PairSpec) -> (u32, u32) {
        (spec.body_a, spec.body_b)
    }

    #[test]
    fn both_tagged_the_finer_mesh_is_the_sdf_at_its_resolution() {
        let (c, dir) = cache("tagged");
        let fine = ball_mesh(0.03, 200); // 396 triangles
        let coarse = box_mesh(Vec3::new(0.05, 0.04, 0.01)); // 12 triangles
        let a = ShapeDesc::new(0, mesh(coarse.clone(), Some(20)));
        let b = ShapeDesc::new(1, mesh(fine.clone(), Some(24)));
        for (x, y) in [(&a, &b), (&b, &a)] {
            let s = pair_spec(x, y, 1e-3, &c).unwrap();
            assert_baked_from(&s, &fine, 24);
            assert_eq!(s.query.triangles.len(), 12);
            assert_eq!(s.query.radius, 0.0);
            assert_eq!(bodies(&s), (0, 1));
            assert_eq!(s.contact_offset, 1e-3);
        }
        // Equal counts: the first shape is the SDF (pair_role's tie rule).
        let a2 = ShapeDesc::new(2, mesh(coarse.clone(), Some(20)));
        let s = pair_spec(&a, &a2, 0.0, &c).unwrap();
        assert_eq!(bodies(&s), (2, 0));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn one_tagged_queries_the_hull_of_the_other() {
        let (c, dir) = cache("one-tagged");
        // A non-convex untagged mesh: two separate boxes; its hull is one box-like solid.
        let mut two = box_mesh(Vec3::splat(0.01));
        two.append(&box_mesh(Vec3::splat(0.01)).map_positions(|p| p + Vec3::new(0.05, 0.0, 0.0)));
        let hull = convex_hull(&two, true).unwrap();
        assert!(hull.signed_volume() > 0.0);
        // Hull of 16 box corners spanning x in [-0.01, 0.06]: the 8 extreme corners, 12 triangles.
        assert_eq!((hull.positions.len(), hull.triangle_count()), (8, 12));
        let tagged = box_mesh(Vec3::splat(0.02)); // fewer triangles than `two`, still the SDF
        let a = ShapeDesc::new(3, mesh(two, None));
        let b = ShapeDesc::fixed((Vec3::X, Quat::IDENTITY), mesh(tagged.clone(), Some(16)));
        for (x, y) in [(&a, &b), (&b, &a)] {
            let s = pair_spec(x, y, 1e-3, &c).unwrap();
            assert_baked_from(&s, &tagged, 16);
            assert_eq!(s.query.triangles.len(), 12);
            assert_eq!(bodies(&s), (3, NO_BODY));
            assert_eq!(s.b_pose.0, Vec3::X);
            let vol: f32 = s.query.triangles.iter().map(|[p, q, r]| p.dot(q.cross(*r)) / 6.0).sum();
            assert!((vol - 0.07 * 0.02 * 0.02).abs() < 1e-9, "hull volume {vol}");
        }
        std::fs::remove_dir_all(dir).ok();
    }

    /// Regression (the Franka's pads let a gripped nut turn and slide in the hand): a pad wider than the flat
    /// it presses on touched it only at its two face triangles' deepest points. A grid box adds points at
    /// the centres of n x n cells on every face, all on the box's surface, and is refused outside 2..=16.
    #[test]
    fn grid_box_queries_its_faces_at_grid_points() {
        let h = Vec3::new(0.00875, 0.004, 0.0088);
        let q = primitive_query(&ShapeGeometry::GridBox { half_extents: h, points_per_edge: 4 });
        assert_eq!(q.triangles.len(), 12 + 8 + 6 * 16);
        let points: Vec<Vec3> = q.triangles[20..].iter().map(|t| t[0]).collect();
        for p in &points {
            let on_face = (0..3).filter(|&k| (p[k].abs() - h[k]).abs() < 1e-7).count();
            assert_eq!(on_face, 1, "{p} is not inside one face");
            assert!((0..3).all(|k| p[k].abs() <= h[k] + 1e-7));
        }
        // The face y = +h.y: 16 points, 4 distinct x and 4 distinct z, spread over the face.
        let face: Vec<&Vec3> = points.iter().filter(|p| (p.y - h.y).abs() < 1e-7).collect();
        assert_eq!(face.len(), 16);
        assert!(face.iter().any(|p| p.x < -0.5 * h.x) && face.iter().any(|p| p.x > 0.5 * h.x));
        let bad = ShapeDesc::new(0, ShapeGeometry::GridBox { half_extents: h, points_per_edge: 1 });
        let (c, dir) = cache("gridbox");
        let table = ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
        let err = pair_spec(&bad, &table, 1e-3, &c).unwrap_err().to_string();
        assert!(err.contains("points_per_edge"), "{err}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn primitives_against_a_tagged_mesh_are_queried() {
        let (c, dir) = cache("prim-tagged");
        let tagged = ball_mesh(0.03, 60);
        let m = ShapeDesc::new(0, mesh(tagged.clone(), Some(16)));
        let cases = [
            (ShapeGeometry::Sphere { radius: 0.01 }, 1, 0.01),
            (ShapeGeometry::Capsule { radius: 0.004, half_length: 0.02 }, 1, 0.004),
            (ShapeGeometry::Box { half_extents: Vec3::new(0.01, 0.02, 0.03) }, 12 + 8, 0.0),
        ];
        for (g, tris, radius) in cases {
            let p = ShapeDesc::new(1, g);
            for (x, y) in [(&m, &p), (&p, &m)] {
                let s = pair_spec(x, y, 1e-3, &c).unwrap();
                assert_baked_from(&s, &tagged, 16);
                assert_eq!((s.query.triangles.len(), s.query.radius), (tris, radius));
                assert_eq!(bodies(&s), (1, 0));
            }
        }
        // The capsule query is its segment along z.
        let cap = ShapeDesc::new(1, ShapeGeometry::Capsule { radius: 0.004, half_length: 0.02 });
        let s = pair_spec(&m, &cap, 1e-3, &c).unwrap();
        assert_eq!(s.query.triangles[0][0], Vec3::new(0.0, 0.0, -0.02));
        assert_eq!(s.query.triangles[0][1], Vec3::new(0.0, 0.0, 0.02));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn planes_are_the_sdf_and_two_planes_are_refused() {
        let (c, dir) = cache("plane");
        let plane = ShapeDesc::fixed((Vec3::new(0.0, 0.0, 0.7), Quat::IDENTITY), ShapeGeometry::Plane);
        let ball = ball_mesh(0.03, 100);
        let hull_tris = convex_hull(&ball, true).unwrap().triangle_count();
        // A ball with one vertex pushed in: the untagged mesh collides through its hull (fewer triangles).
        let mut dented = ball.clone();
        dented.positions[0] *= 0.5;
        let dented_hull = convex_hull(&dented, true).unwrap().triangle_count();
        assert!(dented_hull < dented.triangle_count());
        let cases = [
            (ShapeGeometry::Sphere { radius: 0.01 }, 1, 0.01),
            (ShapeGeometry::Capsule { radius: 0.004, half_length: 0.02 }, 1, 0.004),
            (ShapeGeometry::Box { half_extents: Vec3::splat(0.01) }, 20, 0.0),
            (mesh(dented.clone(), Some(32)), dented.triangle_count(), 0.0),
            (mesh(dented, None), dented_hull, 0.0),
            (mesh(ball, None), hull_tris, 0.0),
        ];
        for (g, tris, radius) in cases {
            let s = ShapeDesc::new(4, g);
            for (x, y) in [(&s, &plane), (&plane, &s)] {
                let p = pair_spec(x, y, 2e-3, &c).unwrap();
                assert!(matches!(p.sdf, SdfShape::Plane));
                assert_eq!((p.query.triangles.len(), p.query.radius), (tris, radius));
                assert_eq!(bodies(&p), (4, NO_BODY));
                assert_eq!(p.b_pose.0.z, 0.7);
            }
        }
        let e = pair_spec(&plane, &plane, 1e-3, &c).unwrap_err().to_string();
        assert!(e.contains("plane and plane"), "{e}");
        // Nothing was baked for plane pairs.
        assert!(c.entries().unwrap().is_empty());
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn convex_convex_bakes_the_finer_hull() {
        let (c, dir) = cache("convex");
        let ball = ball_mesh(0.02, 80); // 156 hull triangles
        let cube = box_mesh(Vec3::splat(0.01));
        let a = ShapeDesc::new(0, mesh(cube.clone(), None));
        let b = ShapeDesc::new(1, mesh(ball.clone(), None));
        for (x, y) in [(&a, &b), (&b, &a)] {
            let s = pair_spec(x, y, 1e-3, &c).unwrap();
            // The ball's hull is the ball itself (convex): baked at the default resolution.
            assert_baked_from(&s, &ball, CONVEX_SDF_RESOLUTION);
            assert_eq!((s.query.triangles.len(), s.query.radius), (12, 0.0));
            assert_eq!(bodies(&s), (0, 1));
        }
        // Untagged mesh vs primitive: the mesh's hull is the SDF, the primitive is queried.
        let sphere = ShapeDesc::new(5, ShapeGeometry::Sphere { radius: 0.05 });
        for (x, y) in [(&a, &sphere), (&sphere, &a)] {
            let s = pair_spec(x, y, 1e-3, &c).unwrap();
            assert_baked_from(&s, &cube, CONVEX_SDF_RESOLUTION);
            assert_eq!((s.query.triangles.len(), s.query.radius), (1, 0.05));
            assert_eq!(bodies(&s), (5, 0));
        }
        // A flat untagged mesh has no solid hull to bake.
        let flat = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE.with_z(0.0)], vec![[0, 1, 2], [1, 3, 2]]);
        let f = ShapeDesc::new(2, mesh(flat, None));
        let e = pair_spec(&f, &sphere, 1e-3, &c).unwrap_err().to_string();
        assert!(e.contains("flat mesh"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn primitive_pairs_bake_box_then_capsule_then_sphere() {
        let (c, dir) = cache("prims");
        let bx = ShapeDesc::new(0, ShapeGeometry::Box { half_extents: Vec3::new(0.03, 0.02, 0.01) });
        let cap = ShapeDesc::new(1, ShapeGeometry::Capsule { radius: 0.01, half_length: 0.02 });
        let sph = ShapeDesc::new(2, ShapeGeometry::Sphere { radius: 0.015 });
        let sph2 = ShapeDesc::new(3, ShapeGeometry::Sphere { radius: 0.005 });
        // Box vs capsule and box vs sphere: the box is baked (exact box distances at the grid points).
        for other in [&cap, &sph] {
            for (x, y) in [(&bx, other), (other, &bx)] {
                let s = pair_spec(x, y, 1e-3, &c).unwrap();
                assert_baked_from(&s, &box_mesh(Vec3::new(0.03, 0.02, 0.01)), CONVEX_SDF_RESOLUTION);
                assert_eq!(s.query.triangles.len(), 1);
                assert_eq!(bodies(&s), (other.body, 0));
            }
        }
        // Capsule vs sphere: the capsule's analytic distance is sampled; the sphere is queried.
        let s = pair_spec(&sph, &cap, 1e-3, &c).unwrap();
        assert_eq!((bodies(&s), s.query.radius), ((2, 1), 0.015));
        let g = grid(&s);
        let h = 0.06 / (CONVEX_SDF_RESOLUTION - 1) as f32;
        assert!((g.spacing - h).abs() < 1e-9);
        assert!((g.origin - Vec3::new(-0.01, -0.01, -0.03) + Vec3::splat(MIN_MARGIN_VOXELS * h)).length() < 1e-6);
        for p in [Vec3::new(0.01, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.03), Vec3::new(0.004, -0.007, 0.025)] {
            let exact = (p - Vec3::new(0.0, 0.0, p.z.clamp(-0.02, 0.02))).length() - 0.01;
            assert!((g.sample(p).0 - exact).abs() <= 0.5 * 3f32.sqrt() * h, "{p}");
        }
        // Two spheres: the first is sampled, the second queried.
        let s = pair_spec(&sph, &sph2, 1e-3, &c).unwrap();
        assert_eq!((bodies(&s), s.query.radius), ((3, 2), 0.005));
        let g = grid(&s);
        let h = 0.03 / (CONVEX_SDF_RESOLUTION - 1) as f32;
        // The centre is the cone tip of |p| - r, here at a cell centre: the worst case of the general
        // interpolation bound (sqrt(3)/2 voxel, reached exactly; 1e-3 relative slack for rounding).
        assert!((g.sample(Vec3::ZERO).0 + 0.015).abs() <= 0.5 * 3f32.sqrt() * h * 1.001);
        // On the surface the field is smooth: the error is second order (~h^2 / r, 15 um here).
        let on_surface = Vec3::new(2.0, -1.0, 3.0).normalize() * 0.015;
        assert!(g.sample(on_surface).0.abs() < h * h / 0.015, "{}", g.sample(on_surface).0);
        // Box vs box: the first is the SDF, the second is queried with its corners.
        let bx2 = ShapeDesc::new(7, ShapeGeometry::Box { half_extents: Vec3::splat(0.01) });
        let s = pair_spec(&bx, &bx2, 1e-3, &c).unwrap();
        assert_eq!((bodies(&s), s.query.triangles.len()), ((7, 0), 20));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn bad_inputs_are_refused_with_the_field() {
        let (c, dir) = cache("bad");
        let ok = ShapeDesc::new(0, ShapeGeometry::Sphere { radius: 0.01 });
        let cases: [(ShapeGeometry, &str); 5] = [
            (ShapeGeometry::Sphere { radius: 0.0 }, "radius"),
            (ShapeGeometry::Capsule { radius: 0.01, half_length: -1.0 }, "half_length"),
            (ShapeGeometry::Box { half_extents: Vec3::new(0.01, f32::NAN, 0.01) }, "half_extents"),
            (mesh(TriMesh::new(vec![], vec![]), None), "mesh"),
            (mesh(box_mesh(Vec3::splat(0.01)), Some(1)), "resolution"),
        ];
        for (g, field) in cases {
            let e = pair_spec(&ok, &ShapeDesc::new(1, g), 1e-3, &c).unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
        let e = pair_spec(&ok, &ok, -1.0, &c).unwrap_err().to_string();
        assert!(e.contains("contact_offset"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }
}
