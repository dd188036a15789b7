//! Two-body contact scenes for the contact benchmark: our generated ISO nut-and-bolt and round peg-in-hole,
//! or any pair of OBJ meshes (e.g. Factory's M16 and 4 mm meshes). Both parts are given in their assembled
//! zero pose; the query part (body 0) is moved relative to the SDF part (body 1).

use factory_engine::contact::{
    pair_role, ContactConfig, ContactModel, ContactPipeline, PairRole, PairSpec, QueryShape, SdfShape, TransformGpu,
};
use factory_engine::gpu::GpuContext;
use factory_engine::mesh::TriMesh;
use factory_engine::sdf::bake::BakeParams;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::sdf::thread::ThreadSdf;
use factory_engine::sdf::SdfGrid;
use glam::{Quat, Vec3};
use std::sync::Arc;

/// Both parts of a pair, in the assembled pose.
#[derive(Clone, Debug)]
pub struct PartPair {
    /// Short name for reports.
    pub name: String,
    /// First part (the moving one for nut-bolt and peg-hole), assembled pose [m].
    pub a: TriMesh,
    /// Second part (fixed), assembled pose [m].
    pub b: TriMesh,
    /// Thread pitch [m] for threaded pairs (poses keep the threads in phase), else 0.
    pub pitch: f32,
    /// Sideways shift [m] that brings a round peg against its hole's wall (half the clearance).
    pub side_shift: f32,
}

impl PartPair {
    /// A generated nut (part a, moving) and bolt (part b, fixed) in their assembled pose.
    pub fn nut_bolt(nb: &factory_assets::NutBolt) -> Self {
        PartPair {
            name: format!("nut-bolt {} {}", nb.spec.size.name(), nb.spec.fit.name()),
            a: nb.nut.mesh.clone(),
            b: nb.bolt.mesh.clone(),
            pitch: nb.pitch,
            side_shift: 0.0,
        }
    }
}

/// A contact scene: the model plus one set of body poses per world.
pub struct ContactScene {
    pub pair: PartPair,
    pub model: ContactModel,
    /// SDF grid of the SDF part (None for an analytic SDF).
    pub grid: Option<Arc<SdfGrid>>,
    /// Index (0 = a, 1 = b) of the part whose SDF is used; the other is queried.
    pub sdf_part: usize,
    pub query_triangles: usize,
    pub sdf_triangles: usize,
}

impl ContactScene {
    /// Builds the scene with Factory's roles: both parts carry an SDF tag, so the one with more triangles
    /// is the SDF (baked at `sdf_resolution`, through the cache) and the other's triangles are queried.
    pub fn new(
        pair: PartPair,
        sdf_resolution: u32,
        contact_offset: f32,
        cache: &SdfCache,
    ) -> factory_engine::Result<Self> {
        let PairRole::SdfMesh { sdf, .. } = pair_role([true, true], [pair.a.triangle_count(), pair.b.triangle_count()])
        else {
            unreachable!("both parts are tagged")
        };
        let mesh = if sdf == 0 { &pair.a } else { &pair.b };
        let grid = Arc::new(cache.get_or_bake(mesh, &BakeParams { resolution: sdf_resolution, ..Default::default() })?);
        Ok(Self::with_sdf(pair, sdf, SdfShape::Grid(grid.clone()), Some(grid), contact_offset))
    }

    /// Builds the scene with the exact analytic SDF of a generated bolt (part b); part a's triangles are
    /// queried against it.
    pub fn with_thread_sdf(pair: PartPair, bolt: ThreadSdf, contact_offset: f32) -> Self {
        Self::with_sdf(pair, 1, SdfShape::Thread(bolt), None, contact_offset)
    }

    fn with_sdf(pair: PartPair, sdf: usize, shape: SdfShape, grid: Option<Arc<SdfGrid>>, contact_offset: f32) -> Self {
        let query = 1 - sdf;
        let meshes = [&pair.a, &pair.b];
        let model = ContactModel {
            body_count: 2,
            pairs: vec![PairSpec {
                body_a: query as u32,
                a_pose: (Vec3::ZERO, Quat::IDENTITY),
                query: Arc::new(QueryShape::mesh(meshes[query])),
                body_b: sdf as u32,
                b_pose: (Vec3::ZERO, Quat::IDENTITY),
                sdf: shape,
                contact_offset,
                friction: 0.0,
            }],
        };
        ContactScene {
            query_triangles: meshes[query].triangle_count(),
            sdf_triangles: meshes[sdf].triangle_count(),
            pair,
            model,
            grid,
            sdf_part: sdf,
        }
    }

    /// Poses of both bodies in every world: part a turned by `phase[w]` about z and raised by `lift` plus the
    /// matching fraction of a pitch (threads stay in phase), and shifted sideways by `side_shift`.
    pub fn poses(&self, lift: f32, phases: &[f32]) -> Vec<TransformGpu> {
        phases
            .iter()
            .flat_map(|&phase| {
                let z = lift + self.pair.pitch * phase / std::f32::consts::TAU;
                [
                    TransformGpu::new(Vec3::new(self.pair.side_shift, 0.0, z), Quat::from_rotation_z(phase)),
                    TransformGpu::new(Vec3::ZERO, Quat::IDENTITY),
                ]
            })
            .collect()
    }
}

/// Deepest signed distance over all patches of world 0 (None: no contact).
pub fn min_depth(contacts: &factory_engine::contact::ContactsHost) -> Option<f32> {
    contacts.patches[0].iter().flat_map(|p| p.contacts.iter().map(|c| c.depth)).reduce(f32::min)
}

/// Lowers part a along z from `lift_hi` (separated) until it touches part b (deepest contact within
/// `tol` [m] of zero), by bisection with the GPU pipeline; returns the lift.
pub fn lower_until_touch(
    gpu: &GpuContext,
    scene: &ContactScene,
    lift_hi: f32,
    lift_lo: f32,
    tol: f32,
) -> factory_engine::Result<f32> {
    let pipe = ContactPipeline::new(gpu, &scene.model, 1, &ContactConfig::default())?;
    let depth_at = |lift: f32| {
        pipe.write_body_q(gpu, &scene.poses(lift, &[0.0]));
        pipe.run(gpu);
        min_depth(&pipe.read(gpu)).unwrap_or(f32::INFINITY)
    };
    let (mut hi, mut lo) = (lift_hi, lift_lo);
    let d_hi = depth_at(hi);
    if d_hi <= 0.0 {
        return Err(factory_engine::EngineError::Config {
            field: "lift_hi",
            value: format!("{hi} m (deepest contact {d_hi} m)"),
            expected: "a separated start pose".into(),
        });
    }
    if depth_at(lo) >= 0.0 {
        return Err(factory_engine::EngineError::Config {
            field: "lift_lo",
            value: format!("{lo} m"),
            expected: "a penetrating end pose".into(),
        });
    }
    for _ in 0..40 {
        let mid = 0.5 * (hi + lo);
        let d = depth_at(mid);
        if d.abs() <= tol {
            return Ok(mid);
        }
        if d > 0.0 {
            hi = mid
        } else {
            lo = mid
        }
    }
    Ok(0.5 * (hi + lo))
}
