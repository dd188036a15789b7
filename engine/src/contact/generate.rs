//! Contact generation kernel (generate.wgsl): pipeline, dispatch, and its CPU twin [`generate_cpu`].

use super::model::{FlatModel, JobGpu, PairGpu, ParamsGpu, PatchGpu, EMPTY_DEPTH};
use super::reduce::{Candidate, Reducer};
use super::ContactConfig;
use crate::gpu::{bind_compute, dispatch_compute};
use glam::{Vec3, Vec4};

pub(crate) const COMMON_WGSL: &str = include_str!("common.wgsl");
const REDUCE_PLAIN_WGSL: &str = include_str!("reduce_plain.wgsl");
const REDUCE_SUBGROUP_WGSL: &str = include_str!("reduce_subgroup.wgsl");
pub(crate) const GENERATE_WGSL: &str = concat!(
    include_str!("generate.wgsl"),
    include_str!("generate_core.wgsl"),
    include_str!("sdf_sample.wgsl"),
    include_str!("../sdf/thread.wgsl"),
    include_str!("../sdf/revolved.wgsl")
);

/// The WGSL module of a kernel with the patch budget substituted and the default workgroup size (for
/// kernels that do not reduce: normals, solver).
pub fn shader_source(kernel_wgsl: &str, max_patches: u32, kinds: SdfKinds) -> String {
    let c = ContactConfig::default();
    shader_source_wg(kernel_wgsl, max_patches, c.workgroup_size, c.candidates_per_invocation, kinds, false)
}

/// Whether the reducing kernels built on `gpu` with `cfg` use subgroup operations (reduce_subgroup.wgsl):
/// when the config allows it and the device has them, with at least 8 lanes per subgroup.
pub fn reduce_with_subgroups(gpu: &crate::gpu::GpuContext, cfg: &ContactConfig) -> bool {
    cfg.subgroups && gpu.device.features().contains(wgpu::Features::SUBGROUP) && gpu.info.subgroup_min_size >= 8
}

/// Which SDF kinds a pipeline's model uses. Each kind's branch in `sdf_sample` (sdf_sample.wgsl) is compiled
/// in only when used: lavapipe inlines every call and runs both sides of every branch under a lane mask, so an
/// unused kind costs its whole body at every sample site. Measured on the nut-bolt pair at 64 worlds: the
/// revolved field's 15 written-out segments double generate's run time (1300 vs 640 ms per
/// frame), the grid's 8 lane-by-lane reads make generation alone 1.6x slower.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SdfKinds {
    /// Some pair's SDF is a voxel grid (kind 0).
    pub grid: bool,
    /// Some pair's SDF is the half-space below a plane (kind 1).
    pub plane: bool,
    /// Some pair's SDF is the analytic thread (kind 2).
    pub thread: bool,
    /// Some pair's SDF is a solid of revolution (kind 3).
    pub revolved: bool,
}

impl SdfKinds {
    /// The kinds the pairs of a flattened model use.
    pub fn of(pairs: &[crate::contact::model::PairGpu]) -> Self {
        let has = |k: u32| pairs.iter().any(|p| p.sdf_kind == k);
        SdfKinds { grid: has(0), plane: has(1), thread: has(2), revolved: has(3) }
    }

    /// All 16 combinations (shader validation tests).
    #[cfg(test)]
    pub(crate) fn combinations() -> impl Iterator<Item = SdfKinds> {
        (0..16u32).map(|m| SdfKinds { grid: m & 1 != 0, plane: m & 2 != 0, thread: m & 4 != 0, revolved: m & 8 != 0 })
    }
}

/// The WGSL module of a kernel with the patch budget, the reduction's workgroup size and candidates per
/// invocation substituted, and the reduction's helpers with or without subgroup operations (the device must
/// have wgpu::Features::SUBGROUP).
pub fn shader_source_wg(
    kernel_wgsl: &str,
    max_patches: u32,
    workgroup_size: u32,
    per: u32,
    kinds: SdfKinds,
    subgroups: bool,
) -> String {
    let common = COMMON_WGSL
        .replace("MAX_PATCHES_VALUE", &format!("{max_patches}u"))
        .replace("WG_VALUE", &format!("{workgroup_size}u"))
        .replace("PER_VALUE", &format!("{per}u"));
    let flag = |b: bool| if b { "true" } else { "false" };
    let helpers = if subgroups { REDUCE_SUBGROUP_WGSL } else { REDUCE_PLAIN_WGSL };
    format!("{common}\n{helpers}\n{kernel_wgsl}")
        .replace("HAS_GRID_VALUE", flag(kinds.grid))
        .replace("HAS_PLANE_VALUE", flag(kinds.plane))
        .replace("HAS_THREAD_VALUE", flag(kinds.thread))
        .replace("HAS_REVOLVED_VALUE", flag(kinds.revolved))
}

/// Builds a compute pipeline from WGSL with an automatic layout.
pub(crate) fn compute_pipeline(device: &wgpu::Device, label: &str, source: &str, entry: &str) -> wgpu::ComputePipeline {
    compute_pipeline_with(device, label, source, entry, &[])
}

/// [`compute_pipeline`] with values for the module's `override` constants.
pub(crate) fn compute_pipeline_with(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry: &str,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
        cache: None,
    })
}

/// The generation pipelines: the first pass over every job, without eviction, and the retry pass over the
/// jobs whose patch budget overflowed, or overflowed last frame and is still flagged (generate.wgsl). The
/// first pass runs as one dispatch per run of consecutive jobs whose pairs share an SDF kind, each with a
/// pipeline compiled for that kind alone: in one pipeline for all kinds, lavapipe runs every other kind's
/// sampling, masked, at every descent step (the Franka Screw scene at 128 worlds: the thread pair's
/// generation takes 272 ms per frame alone, 381 ms beside the pads' grid pair, whose own work is a few
/// ms). The retry pass runs per kind too, one indirect dispatch per kind in use.
pub struct GenerateKernel {
    /// The first pass's pipelines, one per SDF kind (`model.rs` PairGpu::sdf_kind) in `runs`.
    pub first: Vec<(u32, wgpu::ComputePipeline)>,
    /// The first pass's dispatches: (index into `first`, first job, jobs), covering every job in order.
    pub runs: Vec<(usize, u32, u32)>,
    /// The retry pass's pipelines, one per SDF kind in use (its `RETRY_KIND`), in `first`'s order.
    pub retry: Vec<(u32, wgpu::ComputePipeline)>,
}

/// SDF kinds (model.rs PairGpu::sdf_kind 0..4: grid, plane, thread, revolved): generate.wgsl's `KINDS`.
pub(crate) const SDF_KINDS: u32 = 4;

impl SdfKinds {
    /// The one kind `kind` (0 grid, 1 plane, 2 thread, 3 revolved).
    pub fn only(kind: u32) -> Self {
        SdfKinds { grid: kind == 0, plane: kind == 1, thread: kind == 2, revolved: kind == 3 }
    }
}

impl GenerateKernel {
    /// The pipelines for `flat`'s jobs. `subgroups`: see [`reduce_with_subgroups`].
    pub fn new(device: &wgpu::Device, cfg: &ContactConfig, flat: &FlatModel, subgroups: bool) -> Self {
        let source = |kinds| {
            shader_source_wg(
                GENERATE_WGSL,
                cfg.max_patches,
                cfg.workgroup_size,
                cfg.candidates_per_invocation,
                kinds,
                subgroups,
            )
        };
        let constants = [("INTERLEAVED_DESCENT", if cfg.interleaved_descent { 1.0 } else { 0.0 })];
        // A pipeline of `entry` compiled for SDF kind `kind` alone.
        let for_kind = |kind: u32, label: &str, entry: &str, constants: &[(&str, f64)]| {
            compute_pipeline_with(device, label, &source(SdfKinds::only(kind)), entry, constants)
        };
        let mut first: Vec<(u32, wgpu::ComputePipeline)> = Vec::new();
        let mut runs: Vec<(usize, u32, u32)> = Vec::new();
        for (j, job) in flat.jobs.iter().enumerate() {
            let kind = flat.pairs[job.pair as usize].sdf_kind;
            let p = match first.iter().position(|(k, _)| *k == kind) {
                Some(p) => p,
                None => {
                    first.push((kind, for_kind(kind, "contact-generate", "generate", &constants)));
                    first.len() - 1
                }
            };
            match runs.last_mut() {
                Some((q, _, n)) if *q == p => *n += 1,
                _ => runs.push((p, j as u32, 1)),
            }
        }
        let retry = first
            .iter()
            .map(|&(kind, _)| {
                let constants = [constants[0], ("RETRY_KIND", kind as f64)];
                (kind, for_kind(kind, "contact-generate-retry", "generate_retry", &constants))
            })
            .collect();
        GenerateKernel { first, runs, retry }
    }

    /// Records both passes: the first pass's runs, `groups[r]` binding run r (its group 0 holds the
    /// parameters with the run's first job), each over `world_count` worlds, then per kind in use the
    /// retry pass's indirect dispatch from its words of `retry_args`. The first pass's group 2 holds the
    /// retry lists and `retry_args`; `retry_groups[k]` bind `retry[k]` (group 2 with the retry lists only:
    /// `retry_args` is its dispatch size).
    pub fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass,
        groups: &[[wgpu::BindGroup; 3]],
        retry_groups: &[[wgpu::BindGroup; 3]],
        retry_args: &wgpu::Buffer,
        world_count: u32,
    ) {
        for (&(p, _, jobs), g) in self.runs.iter().zip(groups) {
            let [a, b, c] = g;
            dispatch_compute(pass, &self.first[p].1, [a, b, c], jobs, world_count);
        }
        for ((kind, pipeline), [a, b, c]) in self.retry.iter().zip(retry_groups) {
            bind_compute(pass, pipeline, [a, b, c]);
            pass.dispatch_workgroups_indirect(retry_args, 12 * *kind as u64);
        }
    }
}

/// Buffers of generate.wgsl's retry pass for `job_count` jobs in `world_count` worlds: `retry_jobs` (per
/// SDF kind a listed-job count; the sticky eviction flags, one per (world, job); per kind a list of (job,
/// world) pairs with room for every job) and `retry_args` (per kind an indirect dispatch size).
/// [`clear_retry`] zeroes the counts and dispatch sizes; the flags persist across frames.
pub(crate) fn retry_buffers(
    gpu: &crate::gpu::GpuContext,
    job_count: u32,
    world_count: u32,
) -> (wgpu::Buffer, wgpu::Buffer) {
    let jw = job_count as u64 * world_count as u64;
    let words = SDF_KINDS as u64 + jw * (1 + 2 * SDF_KINDS as u64);
    let jobs = gpu.storage_buffer_zeroed("retry_jobs", 4 * words);
    let args = gpu.storage_buffer("retry_args", &[0u32; 3 * SDF_KINDS as usize], wgpu::BufferUsages::INDIRECT);
    (jobs, args)
}

/// Records the clearing of the retry pass's counters (before each frame's generate pass); the sticky
/// eviction flags stay.
pub(crate) fn clear_retry(encoder: &mut wgpu::CommandEncoder, retry_jobs: &wgpu::Buffer, retry_args: &wgpu::Buffer) {
    encoder.clear_buffer(retry_jobs, 0, Some(4 * SDF_KINDS as u64));
    encoder.clear_buffer(retry_args, 0, None);
}

// --- CPU twin: the same float operations as generate.wgsl, in the same order. ---

fn quat_rotate(q: Vec4, v: Vec3) -> Vec3 {
    let u = q.truncate();
    let t = 2.0 * u.cross(v);
    v + q.w * t + u.cross(t)
}

fn quat_mul(a: Vec4, b: Vec4) -> Vec4 {
    let (au, bu) = (a.truncate(), b.truncate());
    (a.w * bu + b.w * au + au.cross(bu)).extend(a.w * b.w - au.dot(bu))
}

/// A rigid transform as the kernels store it: position and quaternion (x, y, z, w).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    pub p: Vec3,
    pub q: Vec4,
}

impl RigidTransform {
    pub const IDENTITY: RigidTransform = RigidTransform { p: Vec3::ZERO, q: Vec4::new(0.0, 0.0, 0.0, 1.0) };
    pub fn mul(&self, b: &RigidTransform) -> RigidTransform {
        RigidTransform { p: self.p + quat_rotate(self.q, b.p), q: quat_mul(self.q, b.q) }
    }
    pub fn inv(&self) -> RigidTransform {
        let qi = Vec4::new(-self.q.x, -self.q.y, -self.q.z, self.q.w);
        RigidTransform { p: -quat_rotate(qi, self.p), q: qi }
    }
    pub fn point(&self, v: Vec3) -> Vec3 {
        self.p + quat_rotate(self.q, v)
    }
    pub fn rotate(&self, v: Vec3) -> Vec3 {
        quat_rotate(self.q, v)
    }
    fn from_arrays(p: [f32; 4], q: [f32; 4]) -> RigidTransform {
        RigidTransform { p: Vec3::new(p[0], p[1], p[2]), q: Vec4::from_array(q) }
    }
}

/// Signed distance and gradient of the pair's SDF shape at `p` (shape frame), as `sdf_sample` in WGSL.
pub fn sdf_sample_cpu(pair: &PairGpu, sdf_values: &[u32], p: Vec3) -> (f32, Vec3) {
    if pair.sdf_kind == 1 {
        return (p.z, Vec3::Z);
    }
    if pair.sdf_kind == 2 {
        let base = pair.sdf_dims[3] as usize;
        return crate::sdf::thread::ThreadSdf::from_words(&sdf_values[base..base + crate::sdf::thread::THREAD_WORDS])
            .sample(p);
    }
    if pair.sdf_kind == 3 {
        let base = pair.sdf_dims[3] as usize;
        return crate::sdf::revolved::RevolvedSdf::from_words(
            &sdf_values[base..base + crate::sdf::revolved::REVOLVED_WORDS],
        )
        .sample(p);
    }
    let lo = Vec3::new(pair.sdf_origin[0], pair.sdf_origin[1], pair.sdf_origin[2]);
    let dims = glam::UVec3::new(pair.sdf_dims[0], pair.sdf_dims[1], pair.sdf_dims[2]);
    crate::sdf::trilinear(lo, pair.sdf_origin[3], dims, p, |i, j, k| {
        let idx = pair.sdf_dims[3] + i + dims.x * (j + dims.y * k);
        let word = sdf_values[(idx >> 1) as usize];
        let half = if idx & 1 == 1 { word & 0xffff_0000 } else { word << 16 };
        ((half as i32) >> 16) as f32 * pair.sdf_scale
    })
}

/// Point of least signed distance on triangle (a, b, c) and the sample there (`minimise_on_triangle`),
/// starting from `start`: the centroid and its sample.
pub fn minimise_on_triangle_cpu(
    pair: &PairGpu,
    sdf: &[u32],
    a: Vec3,
    b: Vec3,
    c: Vec3,
    start: (Vec3, (f32, Vec3)),
    iterations: u32,
) -> (Vec3, (f32, Vec3)) {
    let (e1, e2) = (b - a, c - a);
    let (g11, g12, g22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let det = g11 * g22 - g12 * g12;
    let mut uv = glam::Vec2::splat(1.0 / 3.0);
    let (mut x, mut s) = start;
    // The corners themselves (not a + u e1 + v e2, which rounds b and c; as the kernel).
    for (corner, xi) in [(glam::Vec2::ZERO, a), (glam::Vec2::X, b), (glam::Vec2::Y, c)] {
        let si = sdf_sample_cpu(pair, sdf, xi);
        if si.0 < s.0 {
            (uv, x, s) = (corner, xi, si);
        }
    }
    let longest = g11.max(g22.max((c - b).dot(c - b)));
    if longest <= 0.0 {
        return (x, s);
    }
    let planar = det > 1.0e-6 * g11 * g22;
    let seg = if g11 >= g22 { e1 } else { e2 };
    let seg_len2 = g11.max(g22);
    let mut step = 0.5 * longest.sqrt();
    for _ in 0..iterations {
        let (duv, dw) = if planar {
            let (r1, r2) = (-e1.dot(s.1), -e2.dot(s.1));
            let duv = glam::Vec2::new((g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det);
            (duv, duv.x * e1 + duv.y * e2)
        } else {
            let t = -seg.dot(s.1) / seg_len2;
            (if g11 >= g22 { glam::Vec2::new(t, 0.0) } else { glam::Vec2::new(0.0, t) }, t * seg)
        };
        let len = dw.length();
        if len <= 0.0 {
            break;
        }
        let mut nuv = (uv + duv * (step / len)).max(glam::Vec2::ZERO);
        let sum = nuv.x + nuv.y;
        if sum > 1.0 {
            nuv /= sum;
        }
        let nx = a + nuv.x * e1 + nuv.y * e2;
        let ns = sdf_sample_cpu(pair, sdf, nx);
        if ns.0 < s.0 {
            (uv, x, s) = (nuv, nx, ns);
            step *= 1.5;
        } else {
            step *= 0.5;
        }
    }
    (x, s)
}

/// The candidate of one query triangle given in the SDF shape's frame (or EMPTY), as in `generate`.
pub fn triangle_candidate_cpu(pair: &PairGpu, sdf: &[u32], a: Vec3, b: Vec3, c: Vec3, iterations: u32) -> Candidate {
    // As the descent's barycentric start, which reuses this sample (same rounding).
    let centroid = a + (1.0f32 / 3.0) * (b - a) + (1.0f32 / 3.0) * (c - a);
    let reach = (a - centroid)
        .dot(a - centroid)
        .max((b - centroid).dot(b - centroid).max((c - centroid).dot(c - centroid)))
        .sqrt();
    let sc = sdf_sample_cpu(pair, sdf, centroid);
    let slack = if pair.sdf_kind == 1 { 0.0 } else { pair.sdf_origin[3] };
    if sc.0 - reach - pair.radius - slack > pair.contact_offset {
        return Candidate::EMPTY;
    }
    let (x, (d, g)) = minimise_on_triangle_cpu(pair, sdf, a, b, c, (centroid, sc), iterations);
    let depth = d - pair.radius;
    let glen = g.length();
    if !(depth < pair.contact_offset && glen > 0.0) {
        return Candidate::EMPTY;
    }
    let n = g / glen;
    let area = 0.5 * (b - a).cross(c - a).length();
    let units = ((area / pair.area_unit).round_ties_even() as u32).max(1);
    Candidate { pd: (x - pair.radius * n).extend(depth), n: n.extend(units as f32) }
}

/// Output of one generation job: its patches (world frame) and how many candidates it produced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JobOutput {
    pub patches: Vec<PatchGpu>,
    pub candidates: u32,
}

/// Pose of a shape in the world: body pose (or identity for NO_BODY) times the shape's local pose.
pub fn shape_world(
    body_q: &[RigidTransform],
    body_count: u32,
    world: u32,
    body: u32,
    pos: [f32; 4],
    rot: [f32; 4],
) -> RigidTransform {
    let body_pose = if body == super::model::NO_BODY {
        RigidTransform::IDENTITY
    } else {
        body_q[(world * body_count + body) as usize]
    };
    body_pose.mul(&RigidTransform::from_arrays(pos, rot))
}

/// The broad phase (common.wgsl's `pair_far`): whether no query triangle can have a candidate: the query
/// shape's bounding sphere lies farther than the contact offset above a plane, or the pair's bounding
/// spheres, the shapes posed at `world_a` and `world_b`, are farther apart than the offset.
pub fn pair_far_cpu(pair: &PairGpu, world_a: &RigidTransform, world_b: &RigidTransform) -> bool {
    if pair.sdf_kind == 1 {
        let c = world_b.inv().point(world_a.point(Vec3::from_slice(&pair.a_bound[..3])));
        return c.z - pair.a_bound[3] > pair.contact_offset;
    }
    if pair.b_bound[3] < 0.0 {
        return false;
    }
    let ca = world_a.point(Vec3::from_slice(&pair.a_bound[..3]));
    let cb = world_b.point(Vec3::from_slice(&pair.b_bound[..3]));
    let d = ca - cb;
    let reach = pair.a_bound[3] + pair.b_bound[3] + pair.contact_offset;
    d.dot(d) > reach * reach
}

/// CPU twin of one generate workgroup: job `job` in world `world`.
pub fn generate_job_cpu(
    flat: &FlatModel,
    job: &JobGpu,
    body_q: &[RigidTransform],
    body_count: u32,
    world: u32,
    cfg: &ContactConfig,
) -> JobOutput {
    let pair = &flat.pairs[job.pair as usize];
    let world_a = shape_world(body_q, body_count, world, pair.body_a, pair.a_pos, pair.a_rot);
    let world_b = shape_world(body_q, body_count, world, pair.body_b, pair.b_pos, pair.b_rot);
    if pair_far_cpu(pair, &world_a, &world_b) {
        return JobOutput { patches: Vec::new(), candidates: 0 };
    }
    let b_from_a = world_b.inv().mul(&world_a);
    let mut red = Reducer::new(cfg.max_patches);
    let mut found = 0;
    let mut base = 0;
    while base < job.tri_count {
        let n = (job.tri_count - base).min(cfg.batch_size());
        let cands: Vec<Candidate> = (0..n)
            .map(|t| {
                let v = ((job.tri_first + base + t) * 3) as usize;
                let corner = |k: usize| b_from_a.point(Vec4::from_array(flat.tri_verts[v + k]).truncate());
                triangle_candidate_cpu(pair, &flat.sdf_values, corner(0), corner(1), corner(2), cfg.iterations)
            })
            .collect();
        found += cands.iter().filter(|c| c.pd.w < 1e38).count() as u32;
        red.reduce_batch(&cands, cfg.normal_cos, pair.contact_offset, pair.min_separation);
        base += cfg.batch_size();
    }
    let patches = red
        .patches(pair.area_unit)
        .into_iter()
        .map(|mut p| {
            let n = world_b.rotate(Vec3::new(p.normal[0], p.normal[1], p.normal[2]));
            p.normal = [n.x, n.y, n.z, p.normal[3]];
            for s in p.slots.iter_mut() {
                if s[3] < 1e38 {
                    let w = world_b.point(Vec3::new(s[0], s[1], s[2]));
                    *s = [w.x, w.y, w.z, s[3]];
                } else {
                    *s = [0.0, 0.0, 0.0, EMPTY_DEPTH];
                }
            }
            p
        })
        .collect();
    JobOutput { patches, candidates: found }
}

/// Parameters uniform for a model and world count.
pub fn params(flat: &FlatModel, body_count: u32, world_count: u32, cfg: &ContactConfig) -> ParamsGpu {
    ParamsGpu {
        world_count,
        body_count,
        pair_count: flat.pairs.len() as u32,
        job_count: flat.jobs.len() as u32,
        normal_cos: cfg.normal_cos,
        iterations: cfg.iterations,
        world_offset: 0,
        job_base: 0,
    }
}
