//! Building a [`ManyBodyPipeline`](super::ManyBodyPipeline): the checks against the device, the uniform and storage
//! buffers, the layouts and pipelines, and the bind groups, each in its order of creation.

use super::{
    rest_offset, ManyBodyParamsGpu, PassParamsGpu, ARGS_WORDS, CONTACTS_WGSL, MANY_BODY_COMMON, MERGE_WGSL, M_HEAD,
    NEAR_WGSL, PHASES, SOLVE_WGSL,
};
use crate::contact::generate::{reduce_with_subgroups, shader_source_wg, SdfKinds};
use crate::contact::model::{PairGpu, ParamsGpu, PatchGpu};
use crate::contact::{ContactConfig, TransformGpu};
use crate::error::{EngineError, Result};
use crate::gpu::{Binding, ExplicitLayout, GpuContext};
use crate::many_body::{ManyBodyConfig, ManyBodyFlat, ManyBodyModel};
use crate::solver::gpu::{bodies_gpu, solver_constants, solver_params};
use crate::solver::{BodyModel, SolverConfig};
use glam::{Quat, Vec3};

/// Refuses a buffer of `bytes` above the device's storage-binding limit, naming `what` and a way out.
fn too_large(gpu: &GpuContext, what: String, bytes: u64, hint: &str) -> Result<()> {
    let limit = gpu.limits().max_storage_buffer_binding_size;
    if bytes > limit {
        return Err(EngineError::TooLarge { what, needed_bytes: bytes, limit_bytes: limit, hint: hint.into() });
    }
    Ok(())
}

/// Job sizes for many-body worlds: short jobs cull well, but each holds a patch budget of its own, so with the
/// default chunk the jobs grow until the per-job patches fit one binding (an M16 nut's 2872 triangles: 12
/// jobs of 256 for 10000 pairs would need 154 MB, 6 of 512 fit).
pub(super) fn fit_jobs(
    gpu: &GpuContext,
    model: &ManyBodyModel,
    world_count: u32,
    cfg: &ManyBodyConfig,
    contact: &ContactConfig,
) -> Result<ManyBodyFlat> {
    let mut flat = ManyBodyFlat::new(model, contact)?;
    let job_bytes = |f: &ManyBodyFlat| {
        world_count as u64
            * cfg.max_pairs as u64
            * f.jobs_per_pair as u64
            * contact.max_patches as u64
            * std::mem::size_of::<PatchGpu>() as u64
    };
    while contact.chunk_triangles == 0
        && job_bytes(&flat) > gpu.limits().max_storage_buffer_binding_size
        && flat.jobs_per_pair > 1
        && 2 * flat.chunk <= contact.max_chunk_triangles()
    {
        flat = ManyBodyFlat::new(model, &ContactConfig { chunk_triangles: 2 * flat.chunk, ..contact.clone() })?;
    }
    Ok(flat)
}

/// Bytes of a many-body pipeline's scratch buffer: the sleeping state, two vec4 per body, after the rows (solve.wgsl's
/// rest_index).
fn scratch_bytes(world_count: u32, body_count: u32, cfg: &ManyBodyConfig) -> u64 {
    rest_offset(world_count, body_count, cfg) + world_count as u64 * body_count as u64 * 32
}

/// Words of one world's meta block (many_body_common.wgsl).
fn meta_stride(body_count: u32, cfg: &ManyBodyConfig) -> u32 {
    M_HEAD + 4 * body_count + 9 * cfg.max_pairs
}

/// Checks the dispatch sizes, the workgroup memory and every buffer's size against the device.
pub(super) fn check_sizes(
    gpu: &GpuContext,
    flat: &ManyBodyFlat,
    world_count: u32,
    n: u32,
    cfg: &ManyBodyConfig,
    contact: &ContactConfig,
) -> Result<()> {
    let limits = gpu.limits();
    let max_dim = limits.max_compute_workgroups_per_dimension;
    if world_count == 0 || world_count > max_dim {
        return Err(EngineError::Config {
            field: "world_count",
            value: world_count.to_string(),
            expected: format!("1..={max_dim}"),
        });
    }
    let jobs = flat.jobs_per_pair;
    if cfg.max_pairs > max_dim {
        return Err(EngineError::Config {
            field: "max_pairs",
            value: cfg.max_pairs.to_string(),
            expected: format!("at most {max_dim} (workgroups per dispatch dimension)"),
        });
    }
    if contact.workgroup_bytes() > limits.max_compute_workgroup_storage_size {
        return Err(EngineError::Gpu(format!(
            "max_patches = {} with batches of {} candidates needs {} bytes of workgroup memory; adapter {:?} offers {}; lower max_patches or candidates_per_invocation",
            contact.max_patches,
            contact.batch_size(),
            contact.workgroup_bytes(),
            gpu.info.name,
            limits.max_compute_workgroup_storage_size
        )));
    }
    let (w, cap, mp) = (world_count as u64, cfg.max_pairs as u64, contact.max_patches as u64);
    let meta_stride = meta_stride(n, cfg);
    let patch_bytes = std::mem::size_of::<PatchGpu>() as u64;
    let hint = "use fewer worlds per pipeline, a smaller max_pairs, max_patches or max_patches_per_world";
    too_large(
        gpu,
        format!("near-pair job patches ({w} worlds x {cap} pairs x {jobs} jobs x {mp} patches)"),
        w * cap * jobs as u64 * mp * patch_bytes,
        hint,
    )?;
    too_large(
        gpu,
        format!("solver rows ({w} worlds x {} patches x 2 frames)", cfg.max_patches_per_world),
        scratch_bytes(world_count, n, cfg),
        hint,
    )?;
    too_large(gpu, "SDF values".into(), flat.flat.sdf_values.len() as u64 * 4, "lower the SDF resolution")?;
    too_large(
        gpu,
        format!("per-world bookkeeping ({w} worlds x {meta_stride} words)"),
        w * meta_stride as u64 * 4,
        hint,
    )?;
    too_large(
        gpu,
        format!("near-pair records ({w} worlds x {cap} pairs)"),
        w * cap * std::mem::size_of::<PairGpu>() as u64,
        hint,
    )
}

/// The many_body's uniform parameters.
pub(super) fn many_body_params(
    model: &ManyBodyModel,
    flat: &ManyBodyFlat,
    world_count: u32,
    cfg: &ManyBodyConfig,
) -> ManyBodyParamsGpu {
    let n = model.body_count;
    ManyBodyParamsGpu {
        world_count,
        body_count: n,
        cap: cfg.max_pairs,
        jobs_per_pair: flat.jobs_per_pair,
        chunk: flat.chunk,
        class_count: model.class_count,
        static_count: model.static_count,
        max_colours: cfg.max_colours,
        meta_stride: meta_stride(n, cfg),
        patch_budget: cfg.max_patches_per_world,
        sleep_frames: cfg.sleep.frames,
        sleep_distance: cfg.sleep.distance,
        sleep_half_cos: cfg.sleep.half_cos(),
        rest_base: (rest_offset(world_count, n, cfg) / 16) as u32,
        _pad: [0; 2],
    }
}

/// Per-dispatch parameters, one slot of `pass_stride` bytes each: the colouring rounds, then 5 solver phases x
/// 32 colours.
fn pass_bytes(cfg: &ManyBodyConfig, pass_stride: u64) -> Vec<u8> {
    let mut passes = Vec::new();
    for r in 0..cfg.colour_rounds {
        passes.push(PassParamsGpu { index: r, bias: 0, _pad: [0; 2] });
    }
    for [_, bias, _] in PHASES {
        for c in 0..32 {
            passes.push(PassParamsGpu { index: c, bias, _pad: [0; 2] });
        }
    }
    let mut pass_bytes = vec![0u8; passes.len() * pass_stride as usize];
    for (i, p) in passes.iter().enumerate() {
        let at = i * pass_stride as usize;
        pass_bytes[at..at + 16].copy_from_slice(bytemuck::bytes_of(p));
    }
    pass_bytes
}

/// The many_body's uniform buffers.
pub(super) struct Uniforms {
    many_body: wgpu::Buffer,
    contact: wgpu::Buffer,
    solver: wgpu::Buffer,
    /// The per-dispatch slots of [`pass_bytes`], bound with a dynamic offset.
    passes: wgpu::Buffer,
}

impl Uniforms {
    /// The uniform buffers and the stride of the per-dispatch slots [bytes].
    pub(super) fn new(
        gpu: &GpuContext,
        params: &ManyBodyParamsGpu,
        bodies: &BodyModel,
        cfg: &ManyBodyConfig,
        contact: &ContactConfig,
        solver: &SolverConfig,
    ) -> (Self, u64) {
        let world_count = params.world_count;
        let contact_params = ParamsGpu {
            world_count,
            body_count: params.body_count,
            pair_count: cfg.max_pairs,
            job_count: params.jobs_per_pair,
            normal_cos: contact.normal_cos,
            iterations: contact.iterations,
            world_offset: 0,
            job_base: 0,
        };
        let sp = solver_params(solver, bodies, world_count, cfg.max_pairs, cfg.max_patches_per_world * 4, 0);
        let many_body = gpu.uniform_buffer("many_body-params", bytemuck::bytes_of(params));
        let contact = gpu.uniform_buffer("many_body-contact-params", bytemuck::bytes_of(&contact_params));
        let solver = gpu.uniform_buffer("many_body-solver-params", bytemuck::bytes_of(&sp));
        let pass_stride = (gpu.limits().min_uniform_buffer_offset_alignment as u64).max(16);
        let passes = gpu.uniform_buffer("many_body-passes", &pass_bytes(cfg, pass_stride));
        (Uniforms { many_body, contact, solver, passes }, pass_stride)
    }
}

/// The many_body's storage and indirect buffers.
pub(super) struct Storage {
    pub(super) templates: wgpu::Buffer,
    pub(super) rules: wgpu::Buffer,
    pub(super) tri_verts: wgpu::Buffer,
    pub(super) job_bounds: wgpu::Buffer,
    pub(super) sdf_values: wgpu::Buffer,
    pub(super) body_q: wgpu::Buffer,
    pub(super) body_qd: wgpu::Buffer,
    pub(super) scratch: wgpu::Buffer,
    pub(super) many_body_pairs: wgpu::Buffer,
    pub(super) meta: wgpu::Buffer,
    pub(super) args: wgpu::Buffer,
    pub(super) job_patches: wgpu::Buffer,
    pub(super) job_patch_count: wgpu::Buffer,
    pub(super) patches: wgpu::Buffer,
    pub(super) bodies: wgpu::Buffer,
}

impl Storage {
    pub(super) fn new(
        gpu: &GpuContext,
        model: &ManyBodyModel,
        bodies: &BodyModel,
        flat: &ManyBodyFlat,
        params: &ManyBodyParamsGpu,
        cfg: &ManyBodyConfig,
        contact: &ContactConfig,
    ) -> Self {
        let (n, jobs) = (params.body_count, params.jobs_per_pair);
        let (w, cap, mp) = (params.world_count as u64, cfg.max_pairs as u64, contact.max_patches as u64);
        let patch_bytes = std::mem::size_of::<PatchGpu>() as u64;
        let none = wgpu::BufferUsages::empty();
        let templates = gpu.storage_buffer("many_body-templates", &flat.flat.pairs, none);
        let mut rules = model.body_class.clone();
        rules.extend(&model.body_rule);
        rules.extend(&model.static_rule);
        let rules = gpu.storage_buffer("many_body-rules", &rules, none);
        let tri_verts = gpu.storage_buffer("many_body-tri-verts", &flat.flat.tri_verts, none);
        let job_bounds = gpu.storage_buffer("many_body-job-bounds", &flat.job_bounds, none);
        let sdf_values = gpu.storage_buffer("many_body-sdf-values", &flat.flat.sdf_values, none);
        let identity = vec![TransformGpu::new(Vec3::ZERO, Quat::IDENTITY); (w * n as u64) as usize];
        let body_q = gpu.storage_buffer("many_body-body-q", &identity, none);
        let body_qd = gpu.storage_buffer_zeroed("many_body-body-qd", w * n as u64 * 32);
        let scratch = gpu.storage_buffer_zeroed("many_body-scratch", scratch_bytes(params.world_count, n, cfg));
        let many_body_pairs =
            gpu.storage_buffer_zeroed("many_body-pairs", w * cap * std::mem::size_of::<PairGpu>() as u64);
        let meta = gpu.storage_buffer_zeroed("many_body-meta", w * params.meta_stride as u64 * 4);
        let args = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("many_body-args"),
            size: ARGS_WORDS * 4,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::INDIRECT
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let job_patches = gpu.storage_buffer_zeroed("many_body-job-patches", w * cap * jobs as u64 * mp * patch_bytes);
        let job_patch_count = gpu.storage_buffer_zeroed("many_body-job-patch-count", w * cap * jobs as u64 * 4);
        let patches = gpu.storage_buffer_zeroed("many_body-patches", w * cap * mp * patch_bytes);
        let bodies = gpu.storage_buffer("many_body-bodies", &bodies_gpu(bodies), none);
        Storage {
            templates,
            rules,
            tri_verts,
            job_bounds,
            sdf_values,
            body_q,
            body_qd,
            scratch,
            many_body_pairs,
            meta,
            args,
            job_patches,
            job_patch_count,
            patches,
            bodies,
        }
    }
}

/// The many_body's layouts and pipelines.
pub(super) struct Kernels {
    pub(super) near_layout: ExplicitLayout,
    pub(super) contact_layout: ExplicitLayout,
    pub(super) merge_layout: ExplicitLayout,
    pub(super) solve_layout: ExplicitLayout,
    pub(super) near: [wgpu::ComputePipeline; 8],
    pub(super) contacts: [wgpu::ComputePipeline; 2],
    pub(super) merge: wgpu::ComputePipeline,
    pub(super) solve: [wgpu::ComputePipeline; 9],
}

impl Kernels {
    pub(super) fn new(
        gpu: &GpuContext,
        flat: &ManyBodyFlat,
        cfg: &ManyBodyConfig,
        contact: &ContactConfig,
        solver: &SolverConfig,
    ) -> Self {
        let ro = Binding::Storage { read_only: true };
        let rw = Binding::Storage { read_only: false };
        let kinds = SdfKinds::of(&flat.flat.pairs);
        let wg = contact.workgroup_size;
        let per = contact.candidates_per_invocation;
        let subgroups = reduce_with_subgroups(gpu, contact);
        let source = |body: &str| {
            shader_source_wg(&format!("{MANY_BODY_COMMON}\n{body}"), contact.max_patches, wg, per, kinds, subgroups)
        };
        let near_layout = gpu.explicit_layout(
            "many_body-near",
            &[&[Binding::Uniform, ro, ro], &[ro, ro], &[rw, rw, rw], &[Binding::UniformDynamic]],
        );
        let contact_layout = gpu.explicit_layout(
            "many_body-contacts",
            &[&[Binding::Uniform, Binding::Uniform, ro, ro, ro], &[ro, ro], &[rw, rw, rw]],
        );
        let merge_layout =
            gpu.explicit_layout("many_body-merge", &[&[Binding::Uniform, Binding::Uniform], &[ro, ro, ro], &[rw, rw]]);
        let solve_layout = gpu.explicit_layout(
            "many_body-solve",
            &[&[Binding::Uniform, Binding::Uniform, ro, ro], &[ro, ro, ro], &[rw, rw, rw], &[Binding::UniformDynamic]],
        );
        let near_src = source(NEAR_WGSL);
        let near: [wgpu::ComputePipeline; 8] = [
            "keep_keys",
            "near_count",
            "near_scan",
            "near_emit",
            "incidence",
            "colour_round",
            "colour_sort",
            "near_dormant",
        ]
        .map(|e| gpu.pipeline_on(&near_layout, e, &near_src, e));
        let contacts_src = source(CONTACTS_WGSL);
        let contacts: [wgpu::ComputePipeline; 2] =
            ["many_body_generate", "many_body_alloc"].map(|e| gpu.pipeline_on(&contact_layout, e, &contacts_src, e));
        let merge = gpu.pipeline_on(&merge_layout, "many_body_merge", &source(MERGE_WGSL), "many_body_merge");
        let solve_src = source(SOLVE_WGSL);
        let mut constants = solver_constants(solver).to_vec();
        constants.push(("SLEEP", if cfg.sleep.enabled() { 1.0 } else { 0.0 }));
        let solve: [wgpu::ComputePipeline; 9] = [
            "many_body_build_rows",
            "many_body_velocities",
            "many_body_pass",
            "many_body_positions",
            "many_body_finish",
            "many_body_pass_resample",
            "many_body_pass_warm",
            "many_body_wake",
            "many_body_sleep",
        ]
        .map(|e| gpu.pipeline_on_with(&solve_layout, e, &solve_src, e, &constants));
        Kernels { near_layout, contact_layout, merge_layout, solve_layout, near, contacts, merge, solve }
    }

    /// The bind groups: near, colouring rounds, contacts, merge, solve.
    pub(super) fn bind_groups(&self, gpu: &GpuContext, u: &Uniforms, s: &Storage) -> [Vec<wgpu::BindGroup>; 5] {
        let passes = Some(&u.passes);
        let near_groups = explicit_groups(
            gpu,
            &self.near_layout,
            &[
                &[&u.many_body, &s.templates, &s.rules],
                &[&s.body_q, &s.scratch],
                &[&s.many_body_pairs, &s.meta, &s.args],
            ],
            passes,
        );
        // The colouring rounds are dispatched indirectly from many_body_args, which a dispatch may not also bind
        // for writing: they get a stand-in (they never touch the arguments).
        let stand_in = gpu.storage_buffer_zeroed("many_body-args-stand-in", ARGS_WORDS * 4);
        let round_groups = explicit_groups(
            gpu,
            &self.near_layout,
            &[
                &[&u.many_body, &s.templates, &s.rules],
                &[&s.body_q, &s.scratch],
                &[&s.many_body_pairs, &s.meta, &stand_in],
            ],
            passes,
        );
        let contact_groups = explicit_groups(
            gpu,
            &self.contact_layout,
            &[
                &[&u.contact, &u.many_body, &s.tri_verts, &s.sdf_values, &s.job_bounds],
                &[&s.body_q, &s.many_body_pairs],
                &[&s.job_patches, &s.job_patch_count, &s.meta],
            ],
            None,
        );
        let merge_groups = explicit_groups(
            gpu,
            &self.merge_layout,
            &[
                &[&u.contact, &u.many_body],
                &[&s.many_body_pairs, &s.job_patches, &s.job_patch_count],
                &[&s.meta, &s.patches],
            ],
            None,
        );
        let solve_groups = explicit_groups(
            gpu,
            &self.solve_layout,
            &[
                &[&u.solver, &u.many_body, &s.sdf_values, &s.bodies],
                &[&s.many_body_pairs, &s.patches, &s.meta],
                &[&s.body_q, &s.body_qd, &s.scratch],
            ],
            passes,
        );
        [near_groups, round_groups, contact_groups, merge_groups, solve_groups]
    }
}

/// Bind groups 0, 1, ... of `layout` with the buffers of `groups`, then, where given, the next group with the
/// per-dispatch parameters (one [`PassParamsGpu`] slot, its offset set at dispatch).
fn explicit_groups(
    gpu: &GpuContext,
    layout: &ExplicitLayout,
    groups: &[&[&wgpu::Buffer]],
    passes: Option<&wgpu::Buffer>,
) -> Vec<wgpu::BindGroup> {
    let mut out: Vec<wgpu::BindGroup> =
        groups.iter().enumerate().map(|(i, buffers)| gpu.bind_explicit(layout, i, buffers, 0)).collect();
    if let Some(passes) = passes {
        out.push(gpu.bind_explicit(layout, groups.len(), &[passes], 16));
    }
    out
}
