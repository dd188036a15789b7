//! A model built with `ModelBuilder` and replicated runs on the GPU: each world independent.

use factory_engine::builder::{box_mass_properties, ModelBuilder};
use factory_engine::contact::roles::ShapeGeometry;
use factory_engine::contact::{ContactConfig, ContactPipeline, TransformGpu};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::solver::gpu::GpuSolver;
use factory_engine::solver::{BodyState, SolverConfig};
use glam::{Quat, Vec3};

/// Resting height error after the drop [m] (the solver keeps penetration to micrometres).
const REST_TOL: f32 = 2e-5;

#[test]
fn replicated_worlds_drop_their_boxes_independently_onto_the_table() {
    let h = Vec3::new(0.02, 0.015, 0.01);
    let mut b = ModelBuilder::default();
    b.add_shape(None, (Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
    let body = b.add_dynamic_body(&box_mass_properties(h, 0.2));
    b.add_shape(Some(body), (Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Box { half_extents: h });
    let worlds = 4;
    let cache = SdfCache::new(std::env::temp_dir().join(format!("factory-builder-gpu-{}", std::process::id())));
    let model = b.replicate(worlds).build(&cache).unwrap();
    assert_eq!(model.contacts.pairs.len(), 1);
    let g = GpuContext::global().unwrap();
    let pipe = ContactPipeline::new(g, &model.contacts, model.world_count, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &pipe, &model.bodies, &SolverConfig::default()).unwrap();
    // World w starts 10 (w + 1)^2 mm above the table, turned differently.
    let start = BodyState {
        body_q: (0..worlds)
            .map(|w| {
                TransformGpu::new(
                    Vec3::new(0.0, 0.0, h.z + 0.01 * ((w + 1) * (w + 1)) as f32),
                    Quat::from_rotation_z(w as f32),
                )
            })
            .collect(),
        body_qd: vec![[Vec3::ZERO; 2]; worlds as usize],
    };
    solver.write_state(g, &pipe, &start);
    let mut landed = vec![None; worlds as usize];
    for frame in 0..90 {
        solver.submit_frame(g, &pipe);
        let (s, ok) = solver.read_state(g, &pipe);
        assert!(ok.iter().all(|&o| o));
        for w in 0..worlds as usize {
            if landed[w].is_none() && s.body_q[w].p[2] < h.z + 1e-4 {
                landed[w] = Some(frame);
            }
        }
    }
    let (end, _) = solver.read_state(g, &pipe);
    for w in 0..worlds as usize {
        assert!((end.body_q[w].p[2] - h.z).abs() < REST_TOL, "world {w}: z {}", end.body_q[w].p[2]);
    }
    // Higher drops land later: the worlds ran their own states (free fall from 10, 40, 90, 160 mm: 2.7,
    // 5.4, 8.1 and 10.8 frames).
    let l: Vec<u32> = landed.iter().map(|f| f.expect("landed")).collect();
    assert!(l.windows(2).all(|p| p[0] < p[1]), "landing frames {l:?}");
}
