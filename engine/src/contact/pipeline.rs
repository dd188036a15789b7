//! The contact pipeline on the GPU: model buffers uploaded once, one or two dispatches per frame (generate,
//! then merge where a pair has several jobs), results left on the device for the solver; per-contact normals
//! are computed when the host reads the contacts back. [`ContactPipeline::contacts_cpu`] runs the CPU twin.

use super::generate::{generate_job_cpu, params, GenerateKernel, RigidTransform};
use super::merge::{merge_cpu, MergeKernel};
use super::model::{auto_chunk, ContactModel, FlatModel, ParamsGpu, PatchGpu};
use super::normals::{contact_normal_cpu, NormalsKernel};
use super::{Contact, ContactConfig, Patch};
use crate::error::{EngineError, Result};
use crate::gpu::GpuContext;
use glam::{Quat, Vec3, Vec4};

/// Body pose as the kernels read it: position xyz (w unused) and quaternion xyzw. 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable, PartialEq)]
pub struct TransformGpu {
    pub p: [f32; 4],
    pub q: [f32; 4],
}

impl TransformGpu {
    pub fn new(p: Vec3, q: Quat) -> Self {
        TransformGpu { p: [p.x, p.y, p.z, 0.0], q: [q.x, q.y, q.z, q.w] }
    }
    pub fn xf(&self) -> RigidTransform {
        RigidTransform { p: Vec3::new(self.p[0], self.p[1], self.p[2]), q: Vec4::from_array(self.q) }
    }
}

/// Reduced contacts of every pair in every world, read back to the host.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactsHost {
    /// Patches of pair p in world w at `patches[w * pair_count + p]`.
    pub patches: Vec<Vec<Patch>>,
    /// Candidates generated (before reduction) per `[w * pair_count + p]`.
    pub candidates: Vec<u32>,
}

impl ContactsHost {
    /// Contacts of one pair in one world.
    pub fn contact_count(&self, i: usize) -> usize {
        self.patches[i].iter().map(|p| p.contacts.len()).sum()
    }
}

/// Converts kernel output into host patches.
pub fn to_patches(raw: &[PatchGpu], normals: impl Fn(usize, usize) -> Vec3) -> Vec<Patch> {
    raw.iter()
        .enumerate()
        .map(|(i, p)| Patch {
            normal: Vec3::new(p.normal[0], p.normal[1], p.normal[2]),
            area: p.normal[3],
            contacts: p
                .slots
                .iter()
                .enumerate()
                .filter(|(_, s)| s[3] < 1e38)
                .map(|(k, s)| Contact { point: Vec3::new(s[0], s[1], s[2]), depth: s[3], normal: normals(i, k) })
                .collect(),
        })
        .collect()
}

/// GPU buffers and pipelines for one contact model at one world count.
pub struct ContactPipeline {
    pub cfg: ContactConfig,
    pub flat: FlatModel,
    pub body_count: u32,
    pub world_count: u32,
    generate: GenerateKernel,
    /// The merge pass and its bind groups; `None` where every pair is one job (FlatModel::single_job_pairs),
    /// whose patches generate writes as final.
    merge: Option<(MergeKernel, [wgpu::BindGroup; 3])>,
    /// Shape pairs (PairGpu), shared by all worlds.
    pub pairs: wgpu::Buffer,
    /// SDF values and analytic parameters (see model.rs).
    pub sdf_values: wgpu::Buffer,
    /// Body poses, shape [world_count * body_count]; written by the host or the solver.
    pub body_q: wgpu::Buffer,
    /// Per-job patches, shape [world_count * job_count * max_patches]; with one job per pair (no merge
    /// pass: FlatModel::single_job_pairs) the same buffer as `patches` (and `job_patch_count` as
    /// `patch_counts`).
    pub job_patches: wgpu::Buffer,
    pub job_patch_count: wgpu::Buffer,
    /// Candidates per pair and world before reduction, shape [world_count * pair_count].
    pub pair_candidates: wgpu::Buffer,
    /// Reduced patches, shape [world_count * pair_count * max_patches].
    pub patches: wgpu::Buffer,
    /// Patches in use per pair and world, shape [world_count * pair_count].
    pub patch_counts: wgpu::Buffer,
    /// Outward normal of the SDF shape at each reduced contact (xyz, w unused), world frame,
    /// shape [world_count * pair_count * max_patches * 4]; written by [`read`](Self::read).
    pub contact_normals: wgpu::Buffer,
    normals: NormalsKernel,
    normals_groups: [wgpu::BindGroup; 3],
    /// The first generate pass's bind groups, per run of jobs of one SDF kind (GenerateKernel::runs).
    gen_groups: Vec<[wgpu::BindGroup; 3]>,
    /// The retry passes' bind groups, per kind in use (generate.wgsl; automatic layouts belong to one
    /// pipeline).
    retry_groups: Vec<[wgpu::BindGroup; 3]>,
    /// Jobs listed for the evicting pass (overflowed in the first pass, or flagged since an earlier frame),
    /// per SDF kind, and the sticky eviction flags (layout: generate.wgsl).
    pub retry_jobs: wgpu::Buffer,
    /// The retry pass's indirect dispatch size.
    retry_args: wgpu::Buffer,
}

/// Checks the workgroup memory and the world count against the device.
fn check_device(gpu: &GpuContext, world_count: u32, cfg: &ContactConfig) -> Result<()> {
    let limits = gpu.limits();
    let need = cfg.workgroup_bytes();
    if need > limits.max_compute_workgroup_storage_size {
        return Err(EngineError::Gpu(format!(
            "max_patches = {} with batches of {} candidates needs {need} bytes of workgroup memory; adapter {:?} offers max_compute_workgroup_storage_size = {}; lower max_patches or candidates_per_invocation",
            cfg.max_patches, cfg.batch_size(), gpu.info.name, limits.max_compute_workgroup_storage_size
        )));
    }
    if world_count == 0 || world_count > limits.max_compute_workgroups_per_dimension {
        return Err(EngineError::Config {
            field: "world_count",
            value: world_count.to_string(),
            expected: format!("1..={}", limits.max_compute_workgroups_per_dimension),
        });
    }
    Ok(())
}

/// Query triangles per job: jobs short enough for one generate workgroup and few enough per pair for one
/// merge workgroup within lavapipe's loop limit (see ContactConfig::max_chunk_triangles); the CPU twin uses
/// the same jobs.
fn job_chunk(model: &ContactModel, world_count: u32, cfg: &ContactConfig) -> u32 {
    if cfg.chunk_triangles == 0 {
        let longest = model.max_triangles();
        let fewest_jobs = longest.div_ceil(cfg.max_jobs_per_pair()).next_multiple_of(256);
        let split_for = if cfg.chunk_world_count > 0 { cfg.chunk_world_count } else { world_count };
        auto_chunk(longest, split_for).min(cfg.max_chunk_triangles()).max(fewest_jobs)
    } else {
        cfg.chunk_triangles
    }
}

/// Checks the flattened model's jobs and buffer sizes against the settings and the device.
fn check_flat(
    gpu: &GpuContext,
    model: &ContactModel,
    flat: &FlatModel,
    chunk: u32,
    world_count: u32,
    cfg: &ContactConfig,
) -> Result<()> {
    let limits = gpu.limits();
    let max_jobs = cfg.max_jobs_per_pair();
    let too_many_jobs = flat.pairs.iter().find(|p| p.job_count > max_jobs);
    if chunk > cfg.max_chunk_triangles() || too_many_jobs.is_some() {
        let triangles = too_many_jobs.map_or(model.max_triangles(), |p| p.tri_count);
        return Err(EngineError::Config {
            field: "chunk_triangles",
            value: chunk.to_string(),
            expected: format!(
                "jobs of at most {} triangles and at most {max_jobs} jobs per pair with these settings (lavapipe's loop limit; a pair has {} query triangles): use fewer triangles per pair, a smaller max_patches or a larger workgroup_size",
                cfg.max_chunk_triangles(),
                triangles
            ),
        });
    }
    for (what, bytes) in
        [("SDF values", flat.sdf_values.len() as u64 * 4), ("query triangles", flat.tri_verts.len() as u64 * 16)]
    {
        if bytes > limits.max_storage_buffer_binding_size {
            return Err(EngineError::TooLarge {
                what: format!("the {what} buffer"),
                needed_bytes: bytes,
                limit_bytes: limits.max_storage_buffer_binding_size,
                hint: format!(
                    "adapter {:?} limits max_storage_buffer_binding_size; lower the SDF resolution or the mesh size",
                    gpu.info.name
                ),
            });
        }
    }
    let job_count = flat.jobs.len() as u32;
    let job_patch_bytes = job_patch_bytes(flat, world_count, cfg);
    if job_patch_bytes > limits.max_storage_buffer_binding_size {
        return Err(EngineError::TooLarge {
            what: format!(
                "per-job patch buffer for {world_count} worlds x {job_count} jobs x {} patches",
                cfg.max_patches
            ),
            needed_bytes: job_patch_bytes,
            limit_bytes: limits.max_storage_buffer_binding_size,
            hint: "use fewer worlds per pipeline, a larger chunk_triangles, or a smaller max_patches".into(),
        });
    }
    Ok(())
}

/// Bytes of the per-job patches of every world.
fn job_patch_bytes(flat: &FlatModel, world_count: u32, cfg: &ContactConfig) -> u64 {
    let patch_bytes = std::mem::size_of::<PatchGpu>() as u64;
    world_count as u64 * flat.jobs.len() as u64 * cfg.max_patches as u64 * patch_bytes
}

/// The model and frame buffers that the generate, merge and normals passes bind.
struct Buffers {
    uniform: wgpu::Buffer,
    pairs: wgpu::Buffer,
    jobs: wgpu::Buffer,
    tri_verts: wgpu::Buffer,
    sdf_values: wgpu::Buffer,
    body_q: wgpu::Buffer,
    pair_candidates: wgpu::Buffer,
    patches: wgpu::Buffer,
    patch_counts: wgpu::Buffer,
    job_patches: wgpu::Buffer,
    job_patch_count: wgpu::Buffer,
}

impl Buffers {
    /// Uploads the model; with one job per pair (`merges` false) the per-job patches are the final ones.
    fn new(
        gpu: &GpuContext,
        flat: &FlatModel,
        p: &ParamsGpu,
        body_count: u32,
        cfg: &ContactConfig,
        merges: bool,
    ) -> Self {
        let (world_count, job_count, pair_count) = (p.world_count, flat.jobs.len() as u32, flat.pairs.len() as u32);
        let patch_bytes = std::mem::size_of::<PatchGpu>() as u64;
        let none = wgpu::BufferUsages::empty();
        let uniform = gpu.uniform_buffer("contact-params", bytemuck::bytes_of(p));
        let pairs = gpu.storage_buffer("pairs", &flat.pairs, none);
        let jobs = gpu.storage_buffer("jobs", &flat.jobs, none);
        let tri_verts = gpu.storage_buffer("tri_verts", &flat.tri_verts, none);
        let sdf_values = gpu.storage_buffer("sdf_values", &flat.sdf_values, none);
        let identity = vec![TransformGpu::new(Vec3::ZERO, Quat::IDENTITY); (world_count * body_count.max(1)) as usize];
        let body_q = gpu.storage_buffer("body_q", &identity, none);
        let pair_candidates = gpu.storage_buffer_zeroed("pair_candidates", 4 * (world_count * pair_count) as u64);
        let patches = gpu.storage_buffer_zeroed(
            "patches",
            world_count as u64 * pair_count as u64 * cfg.max_patches as u64 * patch_bytes,
        );
        let patch_counts = gpu.storage_buffer_zeroed("patch_counts", 4 * (world_count * pair_count) as u64);
        // One job per pair: generate writes the final patches (job j is pair j, so the layouts agree) and no
        // merge runs (FlatModel::single_job_pairs).
        let (job_patches, job_patch_count) = if merges {
            (
                gpu.storage_buffer_zeroed("job_patches", job_patch_bytes(flat, world_count, cfg)),
                gpu.storage_buffer_zeroed("job_patch_count", 4 * (world_count * job_count) as u64),
            )
        } else {
            (patches.clone(), patch_counts.clone())
        };
        Buffers {
            uniform,
            pairs,
            jobs,
            tri_verts,
            sdf_values,
            body_q,
            pair_candidates,
            patches,
            patch_counts,
            job_patches,
            job_patch_count,
        }
    }
}

/// The generate passes' bind groups: the first pass's per run of jobs of one SDF kind (each with a uniform
/// holding the parameters with its first job), then the retry passes' per kind in use.
fn generate_groups(
    gpu: &GpuContext,
    generate: &GenerateKernel,
    p: &ParamsGpu,
    b: &Buffers,
    retry_jobs: &wgpu::Buffer,
    retry_args: &wgpu::Buffer,
) -> (Vec<[wgpu::BindGroup; 3]>, Vec<[wgpu::BindGroup; 3]>) {
    let gen_groups = generate
        .runs
        .iter()
        .map(|&(pi, base, _)| {
            let gp = &generate.first[pi].1;
            let run_params =
                gpu.uniform_buffer("contact-params", bytemuck::bytes_of(&ParamsGpu { job_base: base, ..*p }));
            gpu.bind_groups(
                gp,
                [
                    &[&run_params, &b.pairs, &b.jobs, &b.tri_verts, &b.sdf_values],
                    &[&b.body_q],
                    &[&b.job_patches, &b.job_patch_count, &b.pair_candidates, retry_jobs, retry_args],
                ],
            )
        })
        .collect();
    let retry_groups = generate
        .retry
        .iter()
        .map(|(_, rp)| {
            gpu.bind_groups(
                rp,
                [
                    &[&b.uniform, &b.pairs, &b.jobs, &b.tri_verts, &b.sdf_values],
                    &[&b.body_q],
                    &[&b.job_patches, &b.job_patch_count, &b.pair_candidates, retry_jobs],
                ],
            )
        })
        .collect();
    (gen_groups, retry_groups)
}

impl ContactPipeline {
    /// Validates the configuration against the model and the device, uploads the model, builds pipelines.
    pub fn new(gpu: &GpuContext, model: &ContactModel, world_count: u32, cfg: &ContactConfig) -> Result<Self> {
        cfg.validate()?;
        check_device(gpu, world_count, cfg)?;
        let chunk = job_chunk(model, world_count, cfg);
        let flat = model.flatten_ordered(chunk, cfg.orders_by_normal())?;
        check_flat(gpu, model, &flat, chunk, world_count, cfg)?;
        let job_count = flat.jobs.len() as u32;
        let pair_count = flat.pairs.len() as u32;
        let p = params(&flat, model.body_count, world_count, cfg);
        let dev = &gpu.device;
        let merges = !flat.single_job_pairs();
        let b = Buffers::new(gpu, &flat, &p, model.body_count, cfg, merges);
        let kinds = super::generate::SdfKinds::of(&flat.pairs);
        let subgroups = super::generate::reduce_with_subgroups(gpu, cfg);
        let generate = GenerateKernel::new(dev, cfg, &flat, subgroups);
        let normals = NormalsKernel::new(dev, cfg, kinds);
        let contact_normals = gpu.storage_buffer_zeroed(
            "contact_normals",
            world_count as u64 * pair_count as u64 * cfg.max_patches as u64 * 4 * 16,
        );
        let (retry_jobs, retry_args) = super::generate::retry_buffers(gpu, job_count, world_count);
        let (gen_groups, retry_groups) = generate_groups(gpu, &generate, &p, &b, &retry_jobs, &retry_args);
        let merge = merges.then(|| {
            let merge = MergeKernel::new(dev, cfg, subgroups);
            let groups = gpu.bind_groups(
                &merge.pipeline,
                [&[&b.uniform, &b.pairs], &[&b.job_patches, &b.job_patch_count], &[&b.patches, &b.patch_counts]],
            );
            (merge, groups)
        });
        let normals_groups = gpu.bind_groups(
            &normals.pipeline,
            [&[&b.uniform, &b.pairs, &b.sdf_values], &[&b.body_q, &b.patches, &b.patch_counts], &[&contact_normals]],
        );
        Ok(ContactPipeline {
            cfg: cfg.clone(),
            flat,
            body_count: model.body_count,
            world_count,
            generate,
            merge,
            body_q: b.body_q,
            job_patches: b.job_patches,
            job_patch_count: b.job_patch_count,
            pair_candidates: b.pair_candidates,
            patches: b.patches,
            patch_counts: b.patch_counts,
            gen_groups,
            retry_groups,
            retry_jobs,
            retry_args,
            contact_normals,
            normals,
            normals_groups,
            pairs: b.pairs,
            sdf_values: b.sdf_values,
        })
    }

    /// Uploads body poses (shape [world_count * body_count]).
    pub fn write_body_q(&self, gpu: &GpuContext, body_q: &[TransformGpu]) {
        assert_eq!(body_q.len(), (self.world_count * self.body_count) as usize, "body_q shape");
        if !body_q.is_empty() {
            gpu.queue.write_buffer(&self.body_q, 0, bytemuck::cast_slice(body_q));
        }
    }

    /// Records one frame of contact handling (clear counters, generate, merge) into `encoder`. The
    /// per-contact normals that [`read`](Self::read) returns are not part of it: the solver samples its
    /// own at every row, so a stepped frame does not pay for them (normals.wgsl: 4-5% of the nut-bolt
    /// pair's contact handling); `read` computes them.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.pair_candidates, 0, None);
        super::generate::clear_retry(encoder, &self.retry_jobs, &self.retry_args);
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("contacts"), timestamp_writes: None });
        self.generate.dispatch(&mut pass, &self.gen_groups, &self.retry_groups, &self.retry_args, self.world_count);
        if let Some((merge, groups)) = &self.merge {
            merge.dispatch(&mut pass, refs(groups), self.flat.pairs.len() as u32, self.world_count);
        }
    }

    /// Jobs the last frame's evicting pass redid, all kinds together (reads back; waits for the GPU):
    /// those whose patch budget overflowed in the first pass and those still flagged from an earlier frame.
    pub fn retried_jobs(&self, gpu: &GpuContext) -> u32 {
        let counts: Vec<u32> = gpu.read_buffer_prefix(&self.retry_jobs, 4 * super::generate::SDF_KINDS as u64);
        counts.iter().sum()
    }

    /// Encodes and submits one frame.
    pub fn run(&self, gpu: &GpuContext) {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.encode(&mut enc);
        gpu.queue.submit([enc.finish()]);
    }

    /// Reads the reduced contacts back (waits for the GPU), with each contact's normal: the SDF shape's
    /// outward normal at the contact, sampled now (normals.wgsl) at the current body poses, which are those
    /// the contacts were generated at unless a solver step moved the bodies since.
    pub fn read(&self, gpu: &GpuContext) -> ContactsHost {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass =
                enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("normals"), timestamp_writes: None });
            let pair_count = self.flat.pairs.len() as u32;
            self.normals.dispatch(
                &mut pass,
                refs(&self.normals_groups),
                self.cfg.max_patches,
                pair_count,
                self.world_count,
            );
        }
        gpu.queue.submit([enc.finish()]);
        let normals: Vec<[f32; 4]> = gpu.read_buffer(&self.contact_normals);
        self.read_with(gpu, Some(&normals))
    }

    /// [`read`](Self::read) without the per-contact normals: each contact carries its patch's normal. For
    /// the host solve, which samples its own normal at every row: the normals' pass and readback took ~7% of
    /// the Franka scene's contact handling while screwing (128 worlds, 94 against 101 ms per frame).
    pub fn read_for_solver(&self, gpu: &GpuContext) -> ContactsHost {
        self.read_with(gpu, None)
    }

    /// The patches, counts and candidates read back; each contact's normal from `normals` (normals.wgsl's
    /// output) or, without, its patch's.
    fn read_with(&self, gpu: &GpuContext, normals: Option<&[[f32; 4]]>) -> ContactsHost {
        let raw: Vec<PatchGpu> = gpu.read_buffer(&self.patches);
        let counts: Vec<u32> = gpu.read_buffer(&self.patch_counts);
        let candidates: Vec<u32> = gpu.read_buffer(&self.pair_candidates);
        let m = self.cfg.max_patches as usize;
        let n = (self.world_count as usize) * self.flat.pairs.len();
        ContactsHost {
            patches: (0..n)
                .map(|i| {
                    let raw = &raw[i * m..i * m + counts[i] as usize];
                    to_patches(raw, |p, k| match normals {
                        Some(normals) => {
                            let v = normals[(i * m + p) * 4 + k];
                            Vec3::new(v[0], v[1], v[2])
                        }
                        None => Vec3::new(raw[p].normal[0], raw[p].normal[1], raw[p].normal[2]),
                    })
                })
                .collect(),
            candidates: candidates[..n].to_vec(),
        }
    }

    /// The CPU twin of [`encode`](Self::encode) + [`read`](Self::read) for the given poses.
    pub fn contacts_cpu(&self, body_q: &[TransformGpu]) -> ContactsHost {
        contacts_cpu(&self.flat, self.body_count, self.world_count, body_q, &self.cfg, self.merge.is_some())
    }
}

/// Plain-Rust contact generation and reduction for every pair and world (parallel over worlds' jobs).
/// `merges`: whether the pipeline twinned runs the second level (merge_cpu) on every pair; false only where
/// every pair is one job (ContactPipeline with FlatModel::single_job_pairs), whose patches are then final.
pub fn contacts_cpu(
    flat: &FlatModel,
    body_count: u32,
    world_count: u32,
    body_q: &[TransformGpu],
    cfg: &ContactConfig,
    merges: bool,
) -> ContactsHost {
    use rayon::prelude::*;
    let xf: Vec<RigidTransform> = body_q.iter().map(|t| t.xf()).collect();
    let pair_count = flat.pairs.len();
    let results: Vec<(Vec<Patch>, u32)> = (0..world_count as usize * pair_count)
        .into_par_iter()
        .map(|i| {
            let (world, pair) = ((i / pair_count) as u32, i % pair_count);
            let p = &flat.pairs[pair];
            let outs: Vec<_> = flat.jobs[p.job_first as usize..(p.job_first + p.job_count) as usize]
                .iter()
                .map(|job| generate_job_cpu(flat, job, &xf, body_count, world, cfg))
                .collect();
            let merged = if !merges {
                assert_eq!(outs.len(), 1, "without the merge pass every pair is one job");
                outs[0].patches.clone()
            } else {
                let slices: Vec<&[PatchGpu]> = outs.iter().map(|o| o.patches.as_slice()).collect();
                merge_cpu(p, &slices, cfg)
            };
            let patches =
                to_patches(&merged, |i, k| contact_normal_cpu(flat, pair, &merged[i], k, &xf, body_count, world));
            (patches, outs.iter().map(|o| o.candidates).sum())
        })
        .collect();
    let (patches, candidates) = results.into_iter().unzip();
    ContactsHost { patches, candidates }
}

fn refs(g: &[wgpu::BindGroup; 3]) -> [&wgpu::BindGroup; 3] {
    [&g[0], &g[1], &g[2]]
}
