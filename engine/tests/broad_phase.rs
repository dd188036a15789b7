//! The broad phase (`pair_far`, common.wgsl; `generate::pair_far_cpu`): a pair whose bounding spheres are
//! farther apart than the contact offset is skipped, and so is a pair whose query shape's sphere lies
//! farther than the offset above a plane. It must be conservative: no query triangle of a skipped
//! pair may have a candidate within the offset (checked against a brute-force search of every triangle), and
//! it must skip (else it buys nothing). The GPU pipeline gives a skipped pair no patches, as the CPU twin does.

use factory_engine::contact::generate::{pair_far_cpu, shape_world, triangle_candidate_cpu, RigidTransform};
use factory_engine::contact::model::FlatModel;
use factory_engine::contact::roles::{pair_spec, ShapeDesc, ShapeGeometry};
use factory_engine::contact::{
    ContactConfig, ContactModel, ContactPipeline, PairSpec, QueryShape, SdfShape, TransformGpu,
};
use factory_engine::gpu::GpuContext;
use factory_engine::mesh::box_mesh;
use factory_engine::rng::SplitMix64;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::sdf::revolved::RevolvedSdf;
use factory_engine::sdf::thread::ThreadSdf;
use glam::{Quat, Vec3, Vec4};
use std::sync::Arc;

const OFFSET: f32 = 0.004;

fn unit_vector(rng: &mut SplitMix64) -> Vec3 {
    Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5).normalize_or(Vec3::X)
}

fn rotation(rng: &mut SplitMix64) -> Quat {
    Quat::from_axis_angle(unit_vector(rng), std::f32::consts::TAU * rng.unit())
}

/// Pairs in the order `model` lists them.
const PAIRS: [&str; 4] = ["grid", "ring", "thread", "plane"];

/// Two bodies: a box mesh (queried) against (a) a baked grid of a tagged box, (b) an exact ring (a 16-gon
/// torus, revolved ring profile), (c) an exact M16 x 2 bolt with its head and a chamfered tip and (d) a
/// plane.
fn model(cache: &SdfCache) -> ContactModel {
    let cube = Arc::new(box_mesh(Vec3::new(0.01, 0.006, 0.004)));
    let query = ShapeDesc::new(0, ShapeGeometry::Mesh { mesh: cube.clone(), sdf_resolution: None });
    let tagged_box = ShapeDesc::new(
        1,
        ShapeGeometry::Mesh { mesh: Arc::new(box_mesh(Vec3::new(0.012, 0.012, 0.003))), sdf_resolution: Some(32) },
    );
    let ring = RevolvedSdf::polygon_ring(0.016, 0.008, 0.0, 16).unwrap();
    let ring_mesh = Arc::new(box_mesh(Vec3::splat(0.024)));
    let ring_shape = ShapeDesc::new(1, ShapeGeometry::Revolved { mesh: ring_mesh, sdf: ring });
    let grid_pair = pair_spec(&query, &tagged_box, OFFSET, cache).unwrap();
    // The ring is the SDF (an exact field takes the SDF role); the cube's triangles are queried.
    let ring_pair = pair_spec(&query, &ring_shape, OFFSET, cache).unwrap();
    // ISO 68-1 basic M16 x 2, the tip chamfered to the root.
    let bolt = ThreadSdf { tip_radius: ThreadSdf::basic_m16().min_radius, ..ThreadSdf::basic_m16() };
    let thread_pair = PairSpec {
        body_a: 0,
        a_pose: (Vec3::ZERO, Quat::IDENTITY),
        query: Arc::new(QueryShape::mesh(&cube)),
        body_b: 1,
        b_pose: (Vec3::ZERO, Quat::IDENTITY),
        sdf: SdfShape::Thread(bolt),
        contact_offset: OFFSET,
        friction: 0.3,
    };
    let plane_pair = pair_spec(&query, &ShapeDesc::new(1, ShapeGeometry::Plane), OFFSET, cache).unwrap();
    ContactModel { body_count: 2, pairs: vec![grid_pair, ring_pair, thread_pair, plane_pair] }
}

/// The closest candidate of any query triangle of pair `p` [m] (brute force, every triangle).
fn closest(flat: &FlatModel, p: usize, xf: &[RigidTransform]) -> f32 {
    let pair = &flat.pairs[p];
    let wa = shape_world(xf, 2, 0, pair.body_a, pair.a_pos, pair.a_rot);
    let wb = shape_world(xf, 2, 0, pair.body_b, pair.b_pos, pair.b_rot);
    let b_from_a = wb.inv().mul(&wa);
    (0..pair.tri_count as usize)
        .map(|t| {
            let v = (pair.tri_first as usize + t) * 3;
            let c = |k: usize| b_from_a.point(Vec4::from_array(flat.tri_verts[v + k]).truncate());
            let cand = triangle_candidate_cpu(pair, &flat.sdf_values, c(0), c(1), c(2), 20);
            if cand.pd.w < 1e38 {
                cand.pd.w
            } else {
                f32::INFINITY
            }
        })
        .fold(f32::INFINITY, f32::min)
}

#[test]
fn skipped_pairs_have_no_candidate_within_the_offset_and_far_pairs_are_skipped() {
    let dir = std::env::temp_dir().join(format!("factory-broad-phase-{}", std::process::id()));
    let cache = SdfCache::new(&dir);
    let flat = model(&cache).flatten(256).unwrap();
    let mut rng = SplitMix64(7);
    let (mut skipped, mut near_without_contact, mut with_contact) = ([0; 4], [0; 4], [0; 4]);
    for _ in 0..400 {
        // Body 1 at the origin, body 0 at 0..60 mm in a random direction, both randomly turned.
        let body_q = [
            TransformGpu::new(unit_vector(&mut rng) * 0.06 * rng.unit(), rotation(&mut rng)),
            TransformGpu::new(Vec3::ZERO, rotation(&mut rng)),
        ];
        let xf: Vec<RigidTransform> = body_q.iter().map(|t| t.xf()).collect();
        for p in 0..PAIRS.len() {
            let pair = &flat.pairs[p];
            let wa = shape_world(&xf, 2, 0, pair.body_a, pair.a_pos, pair.a_rot);
            let wb = shape_world(&xf, 2, 0, pair.body_b, pair.b_pos, pair.b_rot);
            let d = closest(&flat, p, &xf);
            if pair_far_cpu(pair, &wa, &wb) {
                skipped[p] += 1;
                assert!(d >= OFFSET, "{} pair: skipped, but a triangle has a candidate at {d} m", PAIRS[p]);
            } else if d < OFFSET {
                with_contact[p] += 1;
            } else {
                near_without_contact[p] += 1;
            }
        }
    }
    eprintln!("per pair {PAIRS:?}: skipped {skipped:?}, kept without contact {near_without_contact:?}, with contact {with_contact:?}");
    for p in 0..PAIRS.len() {
        assert!(skipped[p] > 50 && with_contact[p] > 20, "{} pair: the sample does not exercise both sides", PAIRS[p]);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_gpu_pipeline_skips_far_pairs_like_its_cpu_twin() {
    let dir = std::env::temp_dir().join(format!("factory-broad-phase-gpu-{}", std::process::id()));
    let cache = SdfCache::new(&dir);
    let model = model(&cache);
    let g = GpuContext::global().unwrap();
    let worlds = 3;
    let pipe = ContactPipeline::new(g, &model, worlds, &ContactConfig::default()).unwrap();
    // World 0 touching, world 1 far apart, world 2 touching again: skipped jobs must not leave last frame's
    // patches behind.
    // Far is as far above the plane as it is aside.
    let at = |x: f32| TransformGpu::new(Vec3::new(x, 0.0, 0.006 + x), Quat::IDENTITY);
    let rest = TransformGpu::new(Vec3::ZERO, Quat::IDENTITY);
    for frame in 0..2 {
        let far = if frame == 0 { [0.0, 0.5, 0.0] } else { [0.5, 0.0, 0.5] };
        let body_q: Vec<TransformGpu> = far.iter().flat_map(|&x| [at(x), rest]).collect();
        pipe.write_body_q(g, &body_q);
        pipe.run(g);
        let (gpu, cpu) = (pipe.read(g), pipe.contacts_cpu(&body_q));
        for w in 0..worlds as usize {
            for p in 0..PAIRS.len() {
                let i = w * PAIRS.len() + p;
                let n = gpu.patches[i].len();
                assert_eq!(n, cpu.patches[i].len(), "frame {frame} world {w} pair {p}: patch counts differ");
                assert_eq!(gpu.candidates[i], cpu.candidates[i], "frame {frame} world {w} pair {p}");
                if far[w] > 0.0 {
                    assert_eq!(n, 0, "frame {frame} world {w} pair {p}: a far pair has patches");
                } else {
                    assert!(n > 0, "frame {frame} world {w} pair {p}: a touching pair has none");
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
