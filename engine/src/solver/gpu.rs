//! The rigid-body step on the GPU (solver.wgsl): pipeline, buffers and dispatch. Its CPU reference is
//! [`super::step_cpu`]; `engine/tests/solver_gpu.rs` checks parity and bitwise determinism.

use super::{BodyModel, BodyState, Control, SolverConfig};
use crate::contact::generate::{compute_pipeline_with, shader_source, SdfKinds};
use crate::contact::ContactPipeline;
use crate::error::{EngineError, Result};
use crate::gpu::GpuContext;
use bytemuck::{Pod, Zeroable};

pub(crate) const SOLVER_WGSL: &str = concat!(
    include_str!("solver.wgsl"),
    include_str!("solver_sweep.wgsl"),
    include_str!("solver_core.wgsl"),
    include_str!("orthonormal.wgsl"),
    include_str!("../contact/sdf_sample.wgsl"),
    include_str!("../sdf/thread.wgsl"),
    include_str!("../sdf/revolved.wgsl")
);

/// Invocations (worlds) per workgroup.
pub const SOLVER_WG: u32 = 64;

/// GPU mirror of `SolverParams` in solver.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SolverParamsGpu {
    pub world_count: u32,
    pub body_count: u32,
    pub pair_count: u32,
    pub max_rows: u32,
    pub dt: f32,
    pub substeps: u32,
    pub pos_iters: u32,
    pub vel_iters: u32,
    pub max_depenetration_velocity: f32,
    pub rest_offset: f32,
    pub max_speed: f32,
    pub patch_iters: u32,
    pub gravity: [f32; 4],
    /// Loop passes one invocation may make (0: unlimited; see [`GpuSolver::new`]).
    pub loop_budget: u32,
    pub _pad: [u32; 3],
}

/// GPU mirror of `Body` in solver.wgsl: inverse inertia columns (16-byte aligned), COM + inverse mass,
/// flags.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct BodyGpu {
    pub inv_inertia: [[f32; 4]; 3],
    pub com_inv_mass: [f32; 4],
    /// x: 1 for a kinematic body.
    pub flags: [u32; 4],
}

impl SolverConfig {
    /// Refuses non-physical settings, naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad = |field: &'static str, value: String, expected: &str| {
            Err(EngineError::Config { field, value, expected: expected.into() })
        };
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad("dt", self.dt.to_string(), "a time step > 0 [s]");
        }
        if self.substeps == 0 {
            return bad("substeps", "0".into(), "at least 1");
        }
        if self.pos_iters == 0 {
            return bad("pos_iters", "0".into(), "at least 1");
        }
        if self.patch_iters == 0 {
            return bad("patch_iters", "0".into(), "at least 1");
        }
        if !(self.max_depenetration_velocity.is_finite() && self.max_depenetration_velocity >= 0.0) {
            return bad(
                "max_depenetration_velocity",
                self.max_depenetration_velocity.to_string(),
                "a speed >= 0 [m/s]",
            );
        }
        if !(self.max_speed.is_finite() && self.max_speed > 0.0) {
            return bad("max_speed", self.max_speed.to_string(), "a speed > 0 [m/s]");
        }
        Ok(())
    }
}

impl BodyModel {
    /// Refuses zero, negative or non-finite masses and inertias, naming the body.
    pub fn validate(&self) -> Result<()> {
        for (i, &m) in self.body_inv_mass.iter().enumerate() {
            let inertia_ok = self.body_inv_inertia[i].to_cols_array().iter().all(|v| v.is_finite());
            if !(m.is_finite() && m >= 0.0) || !inertia_ok {
                return Err(EngineError::Config {
                    field: "body mass",
                    value: format!("body {i}: inverse mass {m}"),
                    expected: "a finite mass > 0 [kg] (or a static body) and a finite, invertible inertia".into(),
                });
            }
        }
        Ok(())
    }
}

/// The solver's uniform for `world_count` worlds of `model` (pair_count and max_rows as the kernel lays out
/// its rows; loop_budget 0: unlimited).
pub(crate) fn solver_params(
    cfg: &SolverConfig,
    model: &BodyModel,
    world_count: u32,
    pair_count: u32,
    max_rows: u32,
    loop_budget: u32,
) -> SolverParamsGpu {
    SolverParamsGpu {
        world_count,
        body_count: model.body_count() as u32,
        pair_count,
        max_rows,
        dt: cfg.dt,
        substeps: cfg.substeps,
        pos_iters: cfg.pos_iters,
        vel_iters: cfg.vel_iters,
        max_depenetration_velocity: cfg.max_depenetration_velocity,
        rest_offset: cfg.rest_offset,
        max_speed: cfg.max_speed,
        patch_iters: cfg.patch_iters,
        gravity: model.gravity.extend(0.0).to_array(),
        loop_budget,
        _pad: [0; 3],
    }
}

/// Values of solver_core.wgsl's `override` constants for `cfg`.
pub(crate) fn solver_constants(cfg: &SolverConfig) -> [(&'static str, f64); 2] {
    [("FRICTION_PER_PATCH", if cfg.friction_per_patch { 1.0 } else { 0.0 }), ("PATCH_ITERS", cfg.patch_iters as f64)]
}

/// The bodies as the kernels read them.
pub(crate) fn bodies_gpu(model: &BodyModel) -> Vec<BodyGpu> {
    (0..model.body_count())
        .map(|i| {
            let m = model.body_inv_inertia[i];
            BodyGpu {
                inv_inertia: [
                    m.x_axis.extend(0.0).to_array(),
                    m.y_axis.extend(0.0).to_array(),
                    m.z_axis.extend(0.0).to_array(),
                ],
                com_inv_mass: model.body_com[i].extend(model.body_inv_mass[i]).to_array(),
                flags: [model.is_kinematic(i) as u32, 0, 0, 0],
            }
        })
        .collect()
}

/// GPU solver state for one contact pipeline: body velocities, per-world scratch, pipeline.
pub struct GpuSolver {
    pub cfg: SolverConfig,
    /// Body velocities (linear, angular) [m/s, rad/s], shape [world_count * body_count * 2] vec4.
    pub body_qd: wgpu::Buffer,
    /// [world_count] status vec4 (x: 1 ok, 0 diverged; y: rows used), then the external wrenches
    /// ([world_count * body_count] x (force, torque) vec4, [`Control::body_f`]), then the rows.
    pub scratch: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    groups: [wgpu::BindGroup; 3],
    world_count: u32,
    body_count: u32,
    /// Rows per world (4 per patch slot of every pair).
    max_rows: u32,
}

/// Byte offset and size of the external wrenches in a solver scratch buffer (status per world first,
/// then two vec4 per body; solver.wgsl's control_index).
pub(crate) fn control_range(world_count: u32, body_count: u32) -> (u64, u64) {
    (world_count as u64 * 16, world_count as u64 * body_count as u64 * 32)
}

/// The status vec4s at the front of a solver scratch buffer: per world whether its last step was skipped
/// for lavapipe's loop budget (z = 1).
pub(crate) fn worlds_over_loop_budget(gpu: &GpuContext, scratch: &wgpu::Buffer, world_count: u32) -> Vec<bool> {
    let status: Vec<[f32; 4]> = gpu.read_buffer_prefix(scratch, world_count as u64 * 16);
    status.iter().map(|s| s[2] == 1.0).collect()
}

/// vec4s per contact row in a solver scratch buffer (solver_core.wgsl's ROW).
pub(crate) const ROW_VEC4: u64 = 4;

/// Byte offset of the rows in a solver scratch buffer: the status per world, then two vec4 of wrench per
/// body (solver_core.wgsl's rows_base).
pub(crate) fn rows_offset(world_count: u32, body_count: u32) -> u64 {
    world_count as u64 * (1 + 2 * body_count as u64) * 16
}

/// Clears world `world`'s status and warm-start rows in a solver scratch buffer (laid out as
/// [`rows_offset`] says, `max_rows` rows per world): after a reset, last frame's impulses belong to contacts
/// that no longer exist.
pub(crate) fn clear_world_rows(gpu: &GpuContext, scratch: &wgpu::Buffer, counts: (u32, u32, u32), world: u32) {
    let (world_count, body_count, max_rows) = counts;
    let rows = max_rows as u64 * ROW_VEC4 * 16;
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    enc.clear_buffer(scratch, world as u64 * 16, Some(16));
    enc.clear_buffer(scratch, rows_offset(world_count, body_count) + world as u64 * rows, Some(rows));
    gpu.queue.submit([enc.finish()]);
}

/// Writes `control`'s wrenches into `scratch` at `(offset, size)` (an empty control clears them).
pub(crate) fn write_wrenches(gpu: &GpuContext, scratch: &wgpu::Buffer, (offset, size): (u64, u64), control: &Control) {
    if control.body_f.is_empty() {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(scratch, offset, Some(size));
        gpu.queue.submit([enc.finish()]);
        return;
    }
    assert_eq!(control.body_f.len() as u64 * 32, size, "Control::body_f shape [world_count * body_count]");
    gpu.queue.write_buffer(scratch, offset, bytemuck::cast_slice(&crate::gpu::pack_vec3_pairs(&control.body_f)));
}

/// Writes the poses and velocities of world `world` (shape [body_count] each) into `body_q` and `body_qd`
/// (laid out [world_count * body_count], velocities as two vec4 per body).
pub(crate) fn write_world_bodies(
    gpu: &GpuContext,
    body_q: &wgpu::Buffer,
    body_qd: &wgpu::Buffer,
    world: u32,
    q: &[crate::contact::TransformGpu],
    qd: &[[glam::Vec3; 2]],
) {
    let n = q.len() as u64;
    let v = crate::gpu::pack_vec3_pairs(qd);
    if n > 0 {
        gpu.queue.write_buffer(body_q, world as u64 * n * 32, bytemuck::cast_slice(q));
        gpu.queue.write_buffer(body_qd, world as u64 * n * 32, bytemuck::cast_slice(&v));
    }
}

impl GpuSolver {
    /// Builds the solver over `contacts` (which owns body_q, the patches, pairs and SDF values).
    pub fn new(gpu: &GpuContext, contacts: &ContactPipeline, model: &BodyModel, cfg: &SolverConfig) -> Result<Self> {
        cfg.validate()?;
        model.validate()?;
        if let Some(i) = (0..model.body_count()).find(|&i| model.link(i).is_some()) {
            return Err(EngineError::Config {
                field: "body_link",
                value: format!("body {i} is an articulation link"),
                expected: "no articulated bodies: the GPU solver does not step articulations yet; use \
                           solver::step_cpu_articulated"
                    .into(),
            });
        }
        if model.body_count() as u32 != contacts.body_count {
            return Err(EngineError::Config {
                field: "body_count",
                value: model.body_count().to_string(),
                expected: format!("the contact model's {} bodies", contacts.body_count),
            });
        }
        let world_count = contacts.world_count;
        let pair_count = contacts.flat.pairs.len() as u32;
        let max_rows = (pair_count * contacts.cfg.max_patches * 4).max(1);
        // llvmpipe (lavapipe) gives each invocation one budget of 65535 loop passes shared by all its loops
        // and silently cuts every loop short beyond it (see ContactConfig::max_chunk_triangles). The step
        // counts its passes from the frame's real patch counts and, over 7/8 of the budget, flags the world
        // instead of stepping it (`worlds_over_loop_budget`); refused here is only a step that could not be
        // taken even without contacts. Loop passes (solver.wgsl): counting and building visit every pair,
        // each sweep, each warm start and each of the two resample_rows visits the pairs, the body loops run
        // twice per substep.
        let loop_budget = if gpu.is_software() { crate::contact::LOOP_ITERATION_LIMIT / 8 * 7 } else { 0 };
        if loop_budget > 0 {
            let (pairs, bodies) = (pair_count as u64 + 1, model.body_count() as u64 + 1);
            let sweeps = (cfg.pos_iters + cfg.vel_iters + 1) as u64;
            let passes =
                2 * pairs + cfg.substeps as u64 * (sweeps * (pairs + 2) + 4 * pairs + 2 * bodies + 1) + bodies + 1;
            if passes > loop_budget as u64 {
                return Err(EngineError::Config {
                    field: "substeps x (pos_iters + vel_iters) x pairs",
                    value: format!(
                        "{} x ({} + {}) x {pair_count} = {passes} loop passes before any contact",
                        cfg.substeps, cfg.pos_iters, cfg.vel_iters
                    ),
                    expected: format!(
                        "at most {loop_budget} on a software adapter (llvmpipe's loop limit); use fewer substeps, iterations or shape pairs per world"
                    ),
                });
            }
        }
        let params = solver_params(cfg, model, world_count, pair_count, max_rows, loop_budget);
        let bodies = bodies_gpu(model);
        let dev = &gpu.device;
        let uniform = gpu.uniform_buffer("solver-params", bytemuck::bytes_of(&params));
        let none = wgpu::BufferUsages::empty();
        let bodies_buf = gpu.storage_buffer("bodies", &bodies, none);
        let nbw = (world_count * contacts.body_count) as u64;
        let body_qd = gpu.storage_buffer_zeroed("body_qd", nbw * 2 * 16);
        let scratch_bytes =
            rows_offset(world_count, contacts.body_count) + world_count as u64 * max_rows as u64 * ROW_VEC4 * 16;
        if scratch_bytes > gpu.limits().max_storage_buffer_binding_size {
            return Err(EngineError::TooLarge {
                what: format!("solver rows for {world_count} worlds x {max_rows} contacts"),
                needed_bytes: scratch_bytes,
                limit_bytes: gpu.limits().max_storage_buffer_binding_size,
                hint: "use fewer worlds per pipeline or a smaller max_patches".into(),
            });
        }
        let scratch = gpu.storage_buffer_zeroed("solver_scratch", scratch_bytes);
        let pipeline = compute_pipeline_with(
            dev,
            "solver-step",
            &shader_source(SOLVER_WGSL, contacts.cfg.max_patches, SdfKinds::of(&contacts.flat.pairs)),
            "step",
            &solver_constants(cfg),
        );
        let group = |index: u32, buffers: &[&wgpu::Buffer]| gpu.bind_group(&pipeline, index, buffers);
        let groups = [
            group(0, &[&uniform, &contacts.pairs, &contacts.sdf_values, &bodies_buf]),
            group(1, &[&contacts.patches, &contacts.patch_counts]),
            group(2, &[&contacts.body_q, &body_qd, &scratch]),
        ];
        Ok(GpuSolver {
            cfg: cfg.clone(),
            body_qd,
            scratch,
            pipeline,
            groups,
            world_count,
            body_count: contacts.body_count,
            max_rows,
        })
    }

    /// Uploads a state (poses go to the contact pipeline's body_q); every world starts cold (its
    /// warm-start impulses are forgotten, as with a fresh [`super::WarmStart`] on the CPU).
    pub fn write_state(&self, gpu: &GpuContext, contacts: &ContactPipeline, state: &BodyState) {
        self.forget_warm_start(gpu);
        contacts.write_body_q(gpu, &state.body_q);
        let qd = crate::gpu::pack_vec3_pairs(&state.body_qd);
        if !qd.is_empty() {
            gpu.queue.write_buffer(&self.body_qd, 0, bytemuck::cast_slice(&qd));
        }
    }

    /// Forgets every world's warm-start impulses (the twin of a fresh [`super::WarmStart`]); the
    /// external wrenches stay.
    pub fn forget_warm_start(&self, gpu: &GpuContext) {
        let (status, control) = self.control_range();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.scratch, 0, Some(status));
        enc.clear_buffer(&self.scratch, status + control, None);
        gpu.queue.submit([enc.finish()]);
    }

    /// Resets world `world` alone (the auto-reset of one finished or diverged world): its poses and
    /// velocities (shape [body_count] each), its status and its warm-start rows; every other world, and
    /// the external wrenches, stay as they are.
    pub fn reset_world(
        &self,
        gpu: &GpuContext,
        contacts: &ContactPipeline,
        world: u32,
        body_q: &[crate::contact::TransformGpu],
        body_qd: &[[glam::Vec3; 2]],
    ) {
        assert!(world < self.world_count, "world {world} of {}", self.world_count);
        let n = self.body_count as usize;
        assert!(body_q.len() == n && body_qd.len() == n, "one world's bodies: shape [body_count = {n}]");
        write_world_bodies(gpu, &contacts.body_q, &self.body_qd, world, body_q, body_qd);
        clear_world_rows(gpu, &self.scratch, (self.world_count, self.body_count, self.max_rows), world);
    }

    fn control_range(&self) -> (u64, u64) {
        control_range(self.world_count, self.body_count)
    }

    /// Sets the external wrenches applied from the next step on (they stay until set again). An empty
    /// `control` clears them; otherwise `body_f` must have world_count * body_count entries.
    pub fn write_control(&self, gpu: &GpuContext, control: &Control) {
        write_wrenches(gpu, &self.scratch, self.control_range(), control);
    }

    /// Records one solver step (after the contact pipeline's dispatches of the same frame).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("solver"), timestamp_writes: None });
        pass.set_pipeline(&self.pipeline);
        for (i, g) in self.groups.iter().enumerate() {
            pass.set_bind_group(i as u32, g, &[]);
        }
        pass.dispatch_workgroups(self.world_count.div_ceil(SOLVER_WG), 1, 1);
    }

    /// Submits one whole frame: the contact pipeline's dispatches, then this step, in one submission.
    pub fn submit_frame(&self, gpu: &GpuContext, contacts: &ContactPipeline) {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        contacts.encode(&mut enc);
        self.encode(&mut enc);
        gpu.queue.submit([enc.finish()]);
    }

    /// Per world, whether its last step was skipped because its contacts would have taken more loop passes
    /// than a software adapter allows (such a world is also flagged not ok by [`read_state`](Self::read_state)
    /// and left as it was; fewer iterations, patches or pairs per world fit).
    pub fn worlds_over_loop_budget(&self, gpu: &GpuContext) -> Vec<bool> {
        worlds_over_loop_budget(gpu, &self.scratch, self.world_count)
    }

    /// Reads poses, velocities and per-world status back (waits for the GPU).
    pub fn read_state(&self, gpu: &GpuContext, contacts: &ContactPipeline) -> (BodyState, Vec<bool>) {
        let q: Vec<crate::contact::TransformGpu> = gpu.read_buffer(&contacts.body_q);
        let qd: Vec<[f32; 4]> = gpu.read_buffer(&self.body_qd);
        // Only the per-world status at the front of the scratch buffer, not the rows behind it.
        let scratch: Vec<[f32; 4]> = gpu.read_buffer_prefix(&self.scratch, self.world_count as u64 * 16);
        let n = (self.world_count * contacts.body_count) as usize;
        let body_qd = crate::gpu::unpack_vec3_pairs(&qd[..2 * n]);
        let ok = scratch[..self.world_count as usize].iter().map(|s| s[0] == 1.0).collect();
        (BodyState { body_q: q[..n].to_vec(), body_qd }, ok)
    }
}
