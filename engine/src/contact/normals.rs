//! Per-contact normal kernel (normals.wgsl) and its CPU twin [`contact_normal_cpu`].

use super::generate::{compute_pipeline, sdf_sample_cpu, shader_source, shape_world, RigidTransform};
use super::model::{FlatModel, PatchGpu};
use super::ContactConfig;
use glam::Vec3;

pub(crate) const NORMALS_WGSL: &str = concat!(
    include_str!("normals.wgsl"),
    include_str!("sdf_sample.wgsl"),
    include_str!("../sdf/thread.wgsl"),
    include_str!("../sdf/revolved.wgsl")
);

/// Invocations per workgroup along the contact slots.
pub const NORMALS_WG: u32 = 64;

/// The per-contact normal pipeline.
pub struct NormalsKernel {
    pub pipeline: wgpu::ComputePipeline,
}

impl NormalsKernel {
    pub fn new(device: &wgpu::Device, cfg: &ContactConfig, kinds: super::generate::SdfKinds) -> Self {
        NormalsKernel {
            pipeline: compute_pipeline(
                device,
                "contact-normals",
                &shader_source(NORMALS_WGSL, cfg.max_patches, kinds),
                "normals",
            ),
        }
    }

    /// Records one dispatch: (4 max_patches / 64) x pair_count x world_count workgroups.
    pub fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass,
        groups: [&wgpu::BindGroup; 3],
        max_patches: u32,
        pair_count: u32,
        world_count: u32,
    ) {
        pass.set_pipeline(&self.pipeline);
        for (i, g) in groups.iter().enumerate() {
            pass.set_bind_group(i as u32, *g, &[]);
        }
        pass.dispatch_workgroups((4 * max_patches).div_ceil(NORMALS_WG), pair_count, world_count);
    }
}

/// Outward normal (world frame) of the pair's SDF shape at contact `slot` of patch `p` in `world`.
pub fn contact_normal_cpu(
    flat: &FlatModel,
    pair_index: usize,
    p: &PatchGpu,
    slot: usize,
    body_q: &[RigidTransform],
    body_count: u32,
    world: u32,
) -> Vec3 {
    let pair = &flat.pairs[pair_index];
    let world_b = shape_world(body_q, body_count, world, pair.body_b, pair.b_pos, pair.b_rot);
    let c = p.slots[slot];
    let n_patch = Vec3::new(p.normal[0], p.normal[1], p.normal[2]);
    let x = world_b.inv().point(Vec3::new(c[0], c[1], c[2]) + pair.radius * n_patch);
    let (_, g) = sdf_sample_cpu(pair, &flat.sdf_values, x);
    let len = g.length();
    if len > 0.0 {
        world_b.rotate(g / len)
    } else {
        n_patch
    }
}
