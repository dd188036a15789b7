//! Patch merge kernel (merge.wgsl): combines a pair's per-job patches; CPU twin [`merge_cpu`].

use super::generate::{compute_pipeline, shader_source_wg};
use super::model::{PairGpu, PatchGpu};
use super::reduce::{Candidate, Reducer};
use super::ContactConfig;
use crate::gpu::dispatch_compute;
use glam::Vec4;

pub(crate) const MERGE_WGSL: &str = concat!(include_str!("merge.wgsl"), include_str!("merge_core.wgsl"));

/// The merge pipeline.
pub struct MergeKernel {
    pub pipeline: wgpu::ComputePipeline,
}

impl MergeKernel {
    /// `subgroups`: see [`reduce_with_subgroups`](super::generate::reduce_with_subgroups).
    pub fn new(device: &wgpu::Device, cfg: &ContactConfig, subgroups: bool) -> Self {
        MergeKernel {
            pipeline: compute_pipeline(
                device,
                "contact-merge",
                &shader_source_wg(
                    MERGE_WGSL,
                    cfg.max_patches,
                    cfg.workgroup_size,
                    cfg.candidates_per_invocation,
                    Default::default(),
                    subgroups,
                ),
                "merge",
            ),
        }
    }

    /// Records one dispatch: `pair_count` x `world_count` workgroups.
    pub fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass,
        groups: [&wgpu::BindGroup; 3],
        pair_count: u32,
        world_count: u32,
    ) {
        dispatch_compute(pass, &self.pipeline, groups, pair_count, world_count);
    }
}

/// CPU twin of one merge workgroup: the pair's job outputs in job order.
pub fn merge_cpu(pair: &PairGpu, job_patches: &[&[PatchGpu]], cfg: &ContactConfig) -> Vec<PatchGpu> {
    let mut red = Reducer::new(cfg.max_patches);
    // All jobs' slots as one stream cut into batches of the batch size, as merge.wgsl does.
    let stream: Vec<Candidate> = job_patches
        .iter()
        .flat_map(|patches| patches.iter())
        .flat_map(|p| {
            p.slots.iter().map(move |&sl| {
                if sl[3] >= 1e38 {
                    return Candidate::EMPTY;
                }
                let used = p.slots.iter().filter(|s| s[3] < 1e38).count() as u32;
                let units = p.normal[3] / (used as f32 * pair.area_unit);
                Candidate {
                    pd: Vec4::from_array(sl),
                    n: Vec4::new(p.normal[0], p.normal[1], p.normal[2], (units.round_ties_even() as u32).max(1) as f32),
                }
            })
        })
        .collect();
    for batch in stream.chunks(cfg.batch_size() as usize) {
        red.reduce_batch(batch, cfg.normal_cos, pair.contact_offset, pair.min_separation);
    }
    red.patches(pair.area_unit)
}

#[cfg(test)]
mod tests {
    use super::super::generate::{shader_source_wg, GENERATE_WGSL};
    use super::MERGE_WGSL;

    /// The reducing kernels validate with naga at every workgroup size, candidates per invocation and patch
    /// budget.
    #[test]
    fn reducing_kernels_validate_at_every_workgroup_size() {
        for (wg, per) in [(32, 1), (32, 4), (64, 1), (64, 2), (64, 4), (128, 2), (256, 1)] {
            for max_patches in [16, 64, 256] {
                for (name, wgsl) in [("generate", GENERATE_WGSL), ("merge", MERGE_WGSL)] {
                    for subgroups in [false, true] {
                        let src = shader_source_wg(wgsl, max_patches, wg, per, Default::default(), subgroups);
                        let module = naga::front::wgsl::parse_str(&src)
                            .unwrap_or_else(|e| panic!("{name} wg {wg}: {}", e.emit_to_string(&src)));
                        crate::contact::shader_tests::validator(subgroups)
                            .validate(&module)
                            .unwrap_or_else(|e| panic!("{name} wg {wg} max_patches {max_patches}: {e:?}"));
                        assert_eq!(module.entry_points[0].workgroup_size, [wg, 1, 1], "{name}");
                    }
                }
            }
        }
    }
}
