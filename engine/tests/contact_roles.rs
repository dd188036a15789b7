//! Pairs built by `contact::roles::pair_spec` from shape descriptions, run through the contact pipeline on
//! the GPU (lavapipe in CI) and its CPU twin: a sphere on a tagged box mesh (SDF-vs-primitive), a box on a
//! plane (analytic), two untagged box meshes (convex-convex through a baked hull SDF).

use factory_engine::contact::roles::{pair_spec, ShapeDesc, ShapeGeometry, CONVEX_SDF_RESOLUTION};
use factory_engine::contact::{
    ContactConfig, ContactModel, ContactPipeline, ContactsHost, PairSpec, SdfShape, TransformGpu,
};
use factory_engine::gpu::GpuContext;
use factory_engine::mesh::box_mesh;
use factory_engine::sdf::cache::SdfCache;
use glam::{Quat, Vec3};
use std::path::PathBuf;
use std::sync::Arc;

/// Depth of analytic (plane) contacts: exact up to f32 rounding.
const EXACT_TOL: f32 = 1e-6;

/// Depth tolerance [voxels] of contacts whose SDF is baked from a box and sampled facing one of its faces,
/// more than a voxel away from its edges. There the exact field is linear over every cell the sampling
/// touches (the distance to that face plane, inside and outside alike), so trilinear interpolation
/// reproduces it exactly; what remains is the 16-bit storage (a quantum of 1/256 voxel, so at most 1/512
/// voxel off after rounding, and interpolation is a convex combination) and f32 rounding of the poses.
/// 0.01 voxel is five times that quantisation bound; a wrong role, frame or sign is off by millimetres.
const LINEAR_FIELD_TOL_VOXELS: f32 = 0.01;

/// Normals of those contacts are the face normal up to quantisation noise in the gradient.
const NORMAL_MIN_COS: f32 = 0.9999;

fn gpu() -> &'static GpuContext {
    GpuContext::global().expect("a wgpu adapter (lavapipe in CI)")
}

/// A private SDF cache directory per test.
fn cache(name: &str) -> (SdfCache, PathBuf) {
    let dir = std::env::temp_dir().join(format!("factory-contact-roles-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    (SdfCache::new(&dir), dir)
}

/// GPU result and CPU-twin result for one world.
fn run(pair: PairSpec, body_q: &[TransformGpu]) -> [ContactsHost; 2] {
    let model = ContactModel { body_count: body_q.len() as u32, pairs: vec![pair] };
    let g = gpu();
    let pipe = ContactPipeline::new(g, &model, 1, &ContactConfig::default()).unwrap();
    pipe.write_body_q(g, body_q);
    pipe.run(g);
    [pipe.read(g), pipe.contacts_cpu(body_q)]
}

fn spacing(pair: &PairSpec) -> f32 {
    match &pair.sdf {
        SdfShape::Grid(g) => g.spacing,
        other => panic!("expected a baked grid, got {other:?}"),
    }
}

#[test]
fn sphere_resting_on_a_tagged_box_mesh() {
    let (c, dir) = cache("sphere-box");
    let h = Vec3::new(0.05, 0.04, 0.02);
    let r = 0.01;
    let pen = 5e-4;
    // Body 0: the sphere; body 1: the box, tagged with an SDF of 64 samples along x.
    let sphere = ShapeDesc::new(0, ShapeGeometry::Sphere { radius: r });
    let boxm = ShapeDesc {
        body: 1,
        pose: (Vec3::new(0.0, 0.0, 0.003), Quat::from_rotation_z(0.2)),
        geometry: ShapeGeometry::Mesh { mesh: Arc::new(box_mesh(h)), sdf_resolution: Some(64) },
    };
    let pair = pair_spec(&boxm, &sphere, 2e-3, &c).unwrap();
    assert_eq!((pair.body_a, pair.body_b, pair.query.radius), (0, 1, r));
    let voxel = spacing(&pair);
    assert!((voxel - 0.1 / 63.0).abs() < 1e-7, "voxel {voxel}");

    let (box_p, box_q) = (Vec3::new(0.3, -0.2, 0.1), Quat::from_rotation_x(0.3) * Quat::from_rotation_y(-0.2));
    // Shape frame of the box in the world, and the sphere over its top face, away from the edges.
    let (shape_p, shape_q) = (box_p + box_q * boxm.pose.0, box_q * boxm.pose.1);
    let up = shape_q * Vec3::Z;
    let centre = shape_p + shape_q * Vec3::new(0.012, -0.009, h.z + r - pen);
    let [g, cpu] = run(pair, &[TransformGpu::new(centre, Quat::from_rotation_y(1.0)), TransformGpu::new(box_p, box_q)]);
    for (name, out) in [("gpu", &g), ("cpu", &cpu)] {
        let patches = &out.patches[0];
        assert_eq!(patches.len(), 1, "{name}: {patches:?}");
        assert!(patches[0].normal.dot(up) >= NORMAL_MIN_COS, "{name}: normal {} vs {up}", patches[0].normal);
        assert_eq!(patches[0].contacts.len(), 1, "{name}");
        let contact = patches[0].contacts[0];
        let err = (contact.depth + pen).abs();
        assert!(
            err <= LINEAR_FIELD_TOL_VOXELS * voxel,
            "{name}: depth {} vs {} ({:.4} voxels off)",
            contact.depth,
            -pen,
            err / voxel
        );
        // The contact point is the sphere's lowest point.
        assert!((contact.point - (centre - r * up)).length() <= LINEAR_FIELD_TOL_VOXELS * voxel, "{name}");
        eprintln!("{name}: sphere on tagged box: depth error {:.5} voxels", err / voxel);
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn box_on_a_plane_gives_its_four_corners() {
    let (c, dir) = cache("box-plane");
    let h = Vec3::new(0.05, 0.03, 0.02);
    let pen = 0.002;
    let (plane_p, plane_q) = (Vec3::new(0.0, 0.0, 0.1), Quat::from_rotation_x(0.25));
    let plane = ShapeDesc::fixed((plane_p, plane_q), ShapeGeometry::Plane);
    let bx = ShapeDesc::new(0, ShapeGeometry::Box { half_extents: h });
    let pair = pair_spec(&plane, &bx, 5e-3, &c).unwrap();
    assert!(matches!(pair.sdf, SdfShape::Plane));
    // The box lies flat on the tilted plane, turned about the plane normal, 2 mm into it.
    let q = plane_q * Quat::from_rotation_z(0.7);
    let p = plane_p + plane_q * Vec3::new(0.02, -0.01, h.z - pen);
    let up = plane_q * Vec3::Z;
    let corners: Vec<Vec3> = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .iter()
        .map(|&(sx, sy)| p + q * Vec3::new(sx * h.x, sy * h.y, -h.z))
        .collect();
    for (name, out) in ["gpu", "cpu"].iter().zip(run(pair, &[TransformGpu::new(p, q)])) {
        let patches = &out.patches[0];
        assert_eq!(patches.len(), 1, "{name}: {patches:?}");
        assert!((patches[0].normal - up).length() < EXACT_TOL, "{name}");
        assert_eq!(patches[0].contacts.len(), 4, "{name}");
        for contact in &patches[0].contacts {
            assert!((contact.depth + pen).abs() < EXACT_TOL, "{name}: depth {}", contact.depth);
            let nearest = corners.iter().map(|k| (*k - contact.point).length()).fold(f32::MAX, f32::min);
            assert!(nearest < 1e-5, "{name}: contact {} is no corner", contact.point);
        }
        // Four distinct corners.
        let mut hit: Vec<usize> = patches[0]
            .contacts
            .iter()
            .map(|ct| {
                (0..4)
                    .min_by(|&i, &j| (corners[i] - ct.point).length().total_cmp(&(corners[j] - ct.point).length()))
                    .unwrap()
            })
            .collect();
        hit.sort();
        hit.dedup();
        assert_eq!(hit.len(), 4, "{name}");
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn untagged_boxes_collide_convex_convex() {
    let (c, dir) = cache("convex");
    let (big, small) = (Vec3::splat(0.04), Vec3::new(0.015, 0.02, 0.01));
    let overlap = 1e-3;
    let mesh = |h: Vec3| ShapeGeometry::Mesh { mesh: Arc::new(box_mesh(h)), sdf_resolution: None };
    // Equal hull triangle counts (12): the first shape's hull is the SDF, the second is queried.
    let a = ShapeDesc::new(1, mesh(big));
    let b = ShapeDesc::new(0, mesh(small));
    let pair = pair_spec(&a, &b, 2e-3, &c).unwrap();
    assert_eq!((pair.body_a, pair.body_b, pair.query.triangles.len()), (0, 1, 12));
    let voxel = spacing(&pair);
    assert!((voxel - 2.0 * big.x / (CONVEX_SDF_RESOLUTION - 1) as f32).abs() < 1e-7, "voxel {voxel}");

    // Both boxes turned alike; the small one overlaps the big one's +x face by 1 mm, its face well inside
    // that face (the nearest big-box edge is 15 voxels away).
    let rot = Quat::from_rotation_z(0.4) * Quat::from_rotation_x(-0.3);
    let base = Vec3::new(-0.2, 0.1, 0.05);
    let rel = Vec3::new(big.x + small.x - overlap, 0.006, -0.004);
    let poses = [TransformGpu::new(base + rot * rel, rot), TransformGpu::new(base, rot)];
    let axis = rot * Vec3::X;
    for (name, out) in ["gpu", "cpu"].iter().zip(run(pair, &poses)) {
        let patches = &out.patches[0];
        assert!(!patches.is_empty(), "{name}: no contact");
        let mut deepest = f32::MAX;
        for patch in patches {
            assert!(patch.normal.dot(axis) >= NORMAL_MIN_COS, "{name}: normal {} vs {axis}", patch.normal);
            for ct in &patch.contacts {
                let err = (ct.depth + overlap).abs();
                assert!(
                    err <= LINEAR_FIELD_TOL_VOXELS * voxel,
                    "{name}: depth {} vs {} ({:.4} voxels off)",
                    ct.depth,
                    -overlap,
                    err / voxel
                );
                deepest = deepest.min(ct.depth);
                // Every contact lies on the small box's penetrating face.
                let local = rot.inverse() * (ct.point - base) - rel;
                assert!((local.x + small.x).abs() < 1e-5, "{name}: contact {local} (small-box frame)");
            }
        }
        eprintln!("{name}: convex-convex: {} patches, deepest {deepest}", patches.len());
    }
    std::fs::remove_dir_all(dir).ok();
}

/// An exact solid of revolution takes the SDF role against a tagged mesh with more triangles (an exact field
/// beats a grid) and runs on the GPU and its CPU twin alike (sdf kind 3): a box resting across a round peg's
/// top face touches it along the face (depth -overlap, normal +z, exact up to f32 rounding).
#[test]
fn an_exact_solid_of_revolution_is_the_sdf_and_its_contacts_are_exact() {
    let (c, dir) = cache("revolved");
    let profile = factory_engine::sdf::revolved::RevolvedSdf::chamfered_cylinder(0.01, 0.03, 0.001).unwrap();
    // Its mesh (queried when it is not the SDF) is a stand-in here: 12 triangles.
    let peg = ShapeDesc::new(0, ShapeGeometry::Revolved { mesh: Arc::new(box_mesh(Vec3::splat(0.01))), sdf: profile });
    let tagged = |h: Vec3| ShapeGeometry::Mesh {
        mesh: Arc::new(box_mesh(h).split_long_triangles(0.01)),
        sdf_resolution: Some(64),
    };
    let lid_h = Vec3::new(0.004, 0.004, 0.002);
    let lid = ShapeDesc::new(1, tagged(lid_h));
    let pair = pair_spec(&lid, &peg, 2e-3, &c).unwrap();
    assert!(matches!(pair.sdf, SdfShape::Revolved(_)), "the exact field is the SDF: {:?}", pair.sdf);
    assert!(pair.query.triangles.len() > 12, "the tagged mesh is queried");
    let overlap = 0.2e-3;
    let poses = [
        TransformGpu::new(Vec3::ZERO, Quat::IDENTITY),
        TransformGpu::new(Vec3::new(0.001, -0.002, 0.03 + lid_h.z - overlap), Quat::IDENTITY),
    ];
    for (name, out) in ["gpu", "cpu"].iter().zip(run(pair, &poses)) {
        let contacts: Vec<_> = out.patches[0].iter().flat_map(|p| p.contacts.iter()).collect();
        assert!(contacts.len() >= 3, "{name}: {} contacts", contacts.len());
        for ct in contacts {
            assert!((ct.depth + overlap).abs() < 1e-6, "{name}: depth {}", ct.depth);
            assert!(ct.normal.dot(Vec3::Z) > 0.99999, "{name}: normal {}", ct.normal);
        }
    }
    std::fs::remove_dir_all(dir).ok();
}

/// Pairs whose SDF shape is the same tagged mesh share one baked grid (one `Arc`, uploaded once), as the
/// nuts of a pile must; a different resolution is a different grid.
#[test]
fn pairs_built_from_one_tagged_mesh_share_its_sdf_grid() {
    let (c, dir) = cache("shared");
    let nut = Arc::new(box_mesh(Vec3::new(0.01, 0.01, 0.005)).split_long_triangles(0.004));
    let tagged = |r: u32| ShapeGeometry::Mesh { mesh: nut.clone(), sdf_resolution: Some(r) };
    let ball = ShapeGeometry::Sphere { radius: 0.002 };
    let pairs: Vec<PairSpec> = (0..3)
        .map(|i| pair_spec(&ShapeDesc::new(i, tagged(32)), &ShapeDesc::new(3, ball.clone()), 1e-3, &c).unwrap())
        .collect();
    let other = pair_spec(&ShapeDesc::new(0, tagged(40)), &ShapeDesc::new(3, ball), 1e-3, &c).unwrap();
    let grid = |p: &PairSpec| match &p.sdf {
        SdfShape::Grid(g) => g.clone(),
        s => panic!("expected a grid, got {s:?}"),
    };
    assert!(Arc::ptr_eq(&grid(&pairs[0]), &grid(&pairs[1])) && Arc::ptr_eq(&grid(&pairs[0]), &grid(&pairs[2])));
    assert!(!Arc::ptr_eq(&grid(&pairs[0]), &grid(&other)));
    // Uploaded once: the flattened model holds one grid's 16-bit values (two per word).
    let g = grid(&pairs[0]);
    let one_grid_words = g.values.len().div_ceil(2);
    let flat = ContactModel { body_count: 4, pairs }.flatten(256).unwrap();
    assert!(
        flat.sdf_values.len() < 2 * one_grid_words,
        "{} words for a {one_grid_words}-word grid",
        flat.sdf_values.len()
    );
    std::fs::remove_dir_all(dir).ok();
}

/// Regression: flattening with 0 triangles per job ran until the process was killed for memory.
#[test]
fn flattening_with_a_bad_chunk_is_refused_naming_it() {
    let pair = pair_spec(
        &ShapeDesc::new(0, ShapeGeometry::Sphere { radius: 0.01 }),
        &ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane),
        1e-3,
        &cache("chunk").0,
    )
    .unwrap();
    let model = ContactModel { body_count: 1, pairs: vec![pair] };
    for bad in [0, 100] {
        let e = model.flatten(bad).unwrap_err().to_string();
        assert!(e.contains("chunk") && e.contains("multiple of 256"), "{e}");
    }
    assert!(model.flatten(256).is_ok());
}
